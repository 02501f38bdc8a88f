"""Differentiable shadow maps: a pre-filtered (variance) shadow map drawn with a smooth rasterizer (lecture 12).

The route of Worchel and Alexa ("Differentiable Shadow Mapping for Efficient Inverse Graphics", CVPR 2023):
a shadow map whose every stage is smooth, so that the shadow term has a gradient at a shadow map's cost.

1. **The map, smooth** (``moment_map``): the scene seen from a directional light (an orthographic view along
   the light, ``light_frame``), R × R texels. Each face covers a texel centre with probability
   ``sigmoid(d / sigma)``, d the signed distance (texels) from the centre to the face's outline, positive
   inside (SoftRas's coverage, Liu et al. 2019); the faces are composited front to back with that coverage as
   alpha (sorted by depth at the texel: the weight of face k is ``α_k Π_{j nearer} (1 - α_j)``, the rest goes
   to a far background), so nothing is fattened, and the texel stores the first two moments of the composited
   depth, (E[z], E[z²]). Differentiable in the vertices and the light.
2. **Pre-filtering**: the moment maps are blurred by a Gaussian of ``blur`` texels: what a variance shadow map
   (Donnelly and Lauritzen 2006) filters instead of the depths, so that a texel holds a depth distribution.
3. **The test, smooth** (``variance_visibility``): at a receiver at depth d, with μ = E[z] and
   σ² = E[z²] - μ², ``p = σ² / (σ² + (d - μ)²)`` for d > μ (1 otherwise) is taken as the fraction lit. The
   true fraction is P(z ≥ d), which two moments do not determine; p is the one-sided Chebyshev (Cantelli)
   inequality, an *upper* bound on it, exact for one planar occluder over a planar receiver (the texel then
   holds the occluder's depth and the receiver's own) and too bright otherwise. Continuous in d, μ and σ: the
   gradient flows to the occluders through μ and σ, to the receiver through d.
4. **The image** (``shadow_map_image``): the camera's visible surface at ``supersample``² points per pixel
   (hard rasterization: this route differentiates the shadow term only, not the primary silhouettes), each
   shaded ``c · (a + (1 - a) · p)`` (0 for faces turned from the light, as in ``shadow_gradients``), averaged.

The bias it trades for smoothness: the shadow edge is blurred over roughly ``sqrt((pi sigma / sqrt(3))² +
blur²)`` texels, the two widths in quadrature (its gradient is spread over that band, not concentrated on the edge), light bleeds where two occluders overlap
(the bound is an upper bound), and receivers close to their occluders come out too bright. Every face is in
the map, receivers too, and the blur pads the map by repeating its border texels: within about two texels
of the map's edge that flattens a receiver's depth ramp, so with a wide blur the receiver lies behind its own
blurred mean there and darkens itself (lecture 12, section 5: up to 0.17 at 32 texels with blur 2). The
exact answer of the same image model is ``shadow_gradients.shadowed_coverage``; ``python -m course bench
shadow-gradients`` measures the gap.
"""
from __future__ import annotations

import torch

from ..mesh import Mesh
from ..raster import rasterize
from ..camera import Camera
from ..tensors import as_tensor, unit
from .gradients import GRAZING, _check_ambient, _check_colors, _check_scene

__all__ = ["light_frame", "moment_map", "variance_visibility", "shadow_map_image"]


def light_frame(light, verts, resolution: int):
    """The light's orthographic view: (to_light_space, texel) where ``to_light_space(points (N, 3))`` gives
    (N, 2) texel coordinates (x right, y down, the map's pixel convention) and (N,) depth along the light,
    differentiable in the points and ``light`` (3,) (the way the light travels). The map spans the bounding box
    of ``verts`` seen from the light, plus 2 texels of margin; that placement is part of the function, and
    differentiated with it: the blur and the coverage's softness are in texels, so where the map lies and how
    large its texels are change the image when the light turns or a vertex of the box moves. (Placed under
    ``no_grad``, the light gradient missed that part: 49 % off converged finite differences of the same image.)"""
    d = unit(light)
    ref = torch.zeros(3, dtype=d.dtype, device=d.device)
    ref[1 if abs(float(d.detach()[1])) < 0.9 else 0] = 1.0                  # a reference axis not along d
    right = torch.linalg.cross(d, ref, dim=0)
    right = right / right.norm()
    up = torch.linalg.cross(right, d, dim=0)
    frame = torch.stack([right, -up])                                       # (2, 3): image x, y (y down)
    xy = verts @ frame.T                                                    # (V, 2)
    lo, hi = xy.amin(0), xy.amax(0)
    span = (hi - lo).amax()
    if float(span.detach()) == 0:
        span = torch.ones_like(span)                                        # one point: any size
    texel = span / (resolution - 4)
    origin = lo - 2 * texel - (span - (hi - lo)) / 2                        # centre the square map

    def to_light_space(points):
        return (points @ frame.T - origin) / texel, points @ d
    return to_light_space, texel


def moment_map(mesh, light, resolution: int = 64, *, sigma: float = 0.5, blur: float = 1.0, region=None):
    """(moments (R, R, 2), to_light_space): E[z] and E[z²] of the smoothly rasterized, blurred depth from the
    light (module docstring, steps 1-2). sigma: the coverage's softness in texels; blur: the Gaussian
    pre-filter's standard deviation in texels (0: none); region: (N, 3) points the map must span (default every
    vertex; pass the occluders to spend the texels on them: ``variance_visibility`` counts a lookup beyond the
    map's outer texel centres as lit)."""
    verts, faces, d = _check_scene(mesh, light)
    R = int(resolution)
    if R < 8:
        raise ValueError(f"resolution must be at least 8 texels, got {resolution!r}")
    if not sigma > 0:
        raise ValueError(f"sigma must be positive (texels), got {sigma!r}")
    if not blur >= 0:
        raise ValueError(f"blur must be >= 0 texels, got {blur!r}")
    span = verts if region is None else as_tensor(region, dtype=verts.dtype, name="region").reshape(-1, 3)
    to_ls, _ = light_frame(d, span, R)
    xy, z = to_ls(verts)                                                    # (V, 2) texels, (V,) depth
    far = z.max() + 0.1 * (z.max() - z.min()).clamp_min(1e-12)              # the background's depth
    ticks = torch.arange(R, dtype=xy.dtype, device=xy.device) + 0.5
    j, i = torch.meshgrid(ticks, ticks, indexing="xy")                      # j along columns
    centres = torch.stack([j, i], -1).reshape(-1, 1, 2)                     # (R², 1, 2) texel centres
    tri = xy[faces]                                                         # (F, 3, 2)
    a, b = tri, tri.roll(-1, 1)
    e = b - a                                                               # (F, 3, 2) edges
    area = e[:, 0, 0] * (tri[:, 2, 1] - tri[:, 0, 1]) - e[:, 0, 1] * (tri[:, 2, 0] - tri[:, 0, 0])
    sign = torch.where(area >= 0, 1.0, -1.0).to(xy.dtype)                   # either winding
    length = e.norm(dim=-1).clamp_min(1e-12)                                # (F, 3)
    rel = centres[:, :, None, :] - a[None]                                  # (R², F, 3, 2)
    dist = sign[None, :, None] * (e[None, ..., 0] * rel[..., 1] - e[None, ..., 1] * rel[..., 0]) / length
    inside = dist.amin(-1)                                                  # (R², F) > 0 inside
    cover = torch.sigmoid(inside / sigma)
    lam = _barycentric(tri, centres[:, 0, :])                               # (R², F, 3), extrapolated
    zf = (lam * z[faces][None]).sum(-1)                                     # (R², F) the face's plane
    zf, order = zf.sort(1)                                                  # nearest first, per texel
    cover = cover.gather(1, order)
    clear = torch.cumprod(torch.cat([torch.ones_like(cover[:, :1]), 1 - cover], 1), 1)   # (R², F + 1)
    w = torch.cat([cover, torch.ones_like(cover[:, :1])], 1) * clear        # alpha, front to back
    zs = torch.cat([zf, far.expand_as(zf[:, :1])], 1)
    moments = torch.stack([(w * zs).sum(1), (w * zs * zs).sum(1)], -1).reshape(R, R, 2)
    return _gaussian_blur(moments, blur), to_ls


def _barycentric(tri, p):
    """(N, F, 3) barycentric coordinates of the points p (N, 2) in the triangles tri (F, 3, 2), outside too."""
    v0, v1, v2 = tri[:, 0], tri[:, 1], tri[:, 2]
    den = (v1[:, 0] - v0[:, 0]) * (v2[:, 1] - v0[:, 1]) - (v1[:, 1] - v0[:, 1]) * (v2[:, 0] - v0[:, 0])
    den = torch.where(den.abs() < 1e-12, torch.full_like(den, 1e-12), den)  # an edge-on face: no nan
    q = p[:, None, :] - v0[None]
    l1 = (q[..., 0] * (v2[:, 1] - v0[:, 1]) - q[..., 1] * (v2[:, 0] - v0[:, 0])) / den
    l2 = ((v1[:, 0] - v0[:, 0]) * q[..., 1] - (v1[:, 1] - v0[:, 1]) * q[..., 0]) / den
    return torch.stack([1 - l1 - l2, l1, l2], -1)


def _gaussian_blur(maps, blur):
    """maps (R, R, C) blurred by a separable Gaussian of standard deviation ``blur`` texels (edges clamped)."""
    if blur == 0:
        return maps
    r = max(1, int(3 * blur + 0.5))
    x = torch.arange(-r, r + 1, dtype=maps.dtype, device=maps.device)
    k = torch.exp(-0.5 * (x / blur) ** 2)
    k = k / k.sum()
    m = maps.permute(2, 0, 1)[:, None]                                      # (C, 1, R, R)
    m = torch.nn.functional.pad(m, (r, r, r, r), mode="replicate")
    m = torch.nn.functional.conv2d(m, k.view(1, 1, 1, -1))
    m = torch.nn.functional.conv2d(m, k.view(1, 1, -1, 1))
    return m[:, 0].permute(1, 2, 0)


def variance_visibility(moments, coords, depth, *, min_variance: float = 1e-6):
    """(N,) the fraction lit at receivers with texel coordinates ``coords`` (N, 2) and depths ``depth`` (N,)
    along the light, from the moment maps (R, R, 2) looked up bilinearly: the one-sided Chebyshev bound
    ``σ² / (σ² + (d - μ)²)`` where d > μ, 1 elsewhere (module docstring, step 3; an upper bound on the true
    lit fraction). A receiver beyond the map's
    outer texel centres is lit: the map spans its occluders (``moment_map``'s region), and clamping to its
    border would compare a tilted receiver with the border's depth."""
    R = moments.shape[0]
    grid = (coords / R * 2 - 1).view(1, -1, 1, 2)                           # grid_sample's [-1, 1], x first
    m = torch.nn.functional.grid_sample(moments.permute(2, 0, 1)[None], grid.to(moments.dtype),
                                        mode="bilinear", padding_mode="border", align_corners=False)
    mu, m2 = m[0, 0, :, 0], m[0, 1, :, 0]                                   # (N,)
    var = (m2 - mu * mu).clamp_min(min_variance)
    gap = (depth - mu).clamp_min(0)
    inside = ((coords >= 0.5) & (coords <= R - 0.5)).all(1)                 # between the outer texel centres
    return torch.where(inside, var / (var + gap * gap), torch.ones_like(var))    # beyond the map: lit


def shadow_map_image(mesh, camera, face_colors, light, ambient=0.3, background=(0.0, 0.0, 0.0), *,
                     resolution: int = 64, sigma: float = 0.5, blur: float = 1.0, region=None,
                     supersample: int = 2) -> torch.Tensor:
    """The shadowed image by a variance shadow map (module docstring): (H, W, 3), differentiable w.r.t.
    ``mesh.verts`` (V, 3) and ``light`` (3,) through the shadow term. face_colors: (F, 3); the other arguments
    as ``shadow_gradients.shadowed_coverage``, plus the map's resolution and the
    camera's ``supersample``² shading points per pixel (``moment_map``: sigma, blur, region)."""
    verts, faces, d = _check_scene(mesh, light)
    colors = _check_colors(face_colors, faces.shape[0], verts)
    ambient = _check_ambient(ambient)
    s = int(supersample)
    if s < 1:
        raise ValueError(f"supersample must be a positive integer, got {supersample!r}")
    moments, to_ls = moment_map(mesh, d, resolution, sigma=sigma, blur=blur, region=region)
    K = camera.K.detach().clone()
    K[:2] *= s
    big = Camera(K, camera.R, camera.t, camera.width * s, camera.height * s, camera.near, camera.far,
                 camera.orthographic)
    frags = rasterize(Mesh(verts, faces), big)
    fid = frags.face_id.reshape(-1)
    hit = (fid >= 0).nonzero().squeeze(1)
    f = fid[hit]
    points = (frags.bary.reshape(-1, 3)[hit][:, :, None] * verts[faces[f]]).sum(1)   # (N, 3) world
    tri = verts[faces[f]]
    normal = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], dim=1)
    facing = (normal @ -unit(d)) / normal.norm(dim=1).clamp_min(1e-300) > GRAZING
    coords, depth = to_ls(points)
    p = variance_visibility(moments, coords, depth) * facing.to(verts.dtype)
    c = colors.to(verts.dtype)[f] * (ambient + (1 - ambient) * p)[:, None]
    bg = as_tensor(background, dtype=verts.dtype, device=verts.device, name="background")
    if bg.shape != (3,):
        raise ValueError(f"background must have shape (3,), got {tuple(bg.shape)}")
    image = bg.expand(fid.shape[0], 3).index_put((hit,), c)
    H, W = camera.height, camera.width
    return image.view(H, s, W, s, 3).mean((1, 3))
