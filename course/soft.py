"""Differentiable rasterization: soft rasterization (lecture 08), and the screen triangles it shares with the
Neural 3D Mesh Renderer's approximate gradient (``course.nmr``).

A rasterized pixel is a step function of every vertex position: as a vertex moves, the pixel's colour
jumps when an edge crosses the pixel centre and is constant in between, so its derivative is zero almost
everywhere. Two classic cures, both built from the hard rasterizer's pieces (``course.raster``): the Neural
3D Mesh Renderer keeps the image and invents a gradient (``course.nmr``); soft rasterization, here, blurs the
image until it has one.

**Soft rasterization** (Liu, Li, Chen and Li, "Soft Rasterizer", ICCV 2019), ``soft_rasterize``. Every face
covers every pixel a little: ``D = sigmoid(δ d² / σ)``, with d the distance from the pixel centre to the
projected triangle and δ = +1 inside, -1 outside. As in the paper, d is measured in normalised device
coordinates, where the image is 2 wide: ``d_ndc = 2 d_px / W``, so ``d_ndc² / σ = d_px² / σ_px`` with
``σ_px = σ W² / 4`` (σ = 1e-4 on a 256-pixel image is σ_px = 1.64 px²). A silhouette aggregates the faces
with a probabilistic OR, ``1 - Π_j (1 - D_j)``; a colour image with a softmax over depth,

    I = (Σ_j w_j C_j + w_b C_b) / (Σ_j w_j + w_b),   w_j = D_j exp(z_j / γ),   w_b = exp(ε / γ),

where z_j ∈ [0, 1] is the face's normalised inverse depth at the pixel (1 at the near plane, 0 at the far
one; see ``_nearness``) and the background C_b is one more term at z = ε. C_j is the face's colour at the
pixel: flat, or interpolated from its vertices, or read from a texture at the uv of the pixel's
perspective-correct barycentrics in the face (SoftRas's per-pixel lookup), times a lighting factor. With
``blend="alpha"`` the background leaves the softmax and the faces' blend is composited over it by the
silhouette, ``I = α Σ_j w_j C_j / Σ_j w_j + (1 - α) C_b``: no fattening (below). Everything is computed in logs
(``logsigmoid``, the max subtracted before ``exp``), so float32 stays finite for σ down to 1e-7 and γ down to
1e-5. Only (pixel, face) pairs that can matter are computed: a face's weight relative to the largest term
at the pixel must reach ``threshold`` (sigmoid *and* softmax factor, so the error stays bounded as γ → 0).
The candidates come from a screen-space radius around each face (``_candidate_pairs``, row by row as in
``scan.pixel_triangle_pairs``), built for a group of faces at a time (about CHUNK pairs) and thresholded
group by group, so only the pairs that matter are ever stored (at γ = 1e-4 a 512² image has some 10⁸
candidates and a few million that matter, stored as two int32 ids each); the per-pair work runs on (N,)
vectors of pairs, CHUNK at a time, each chunk's terms added into per-pixel sums and forgotten, its graph
recomputed during backward instead of stored (``_ColorSums``; the silhouette's groups are checkpointed), so
neither a faces × pixels tensor nor a tensor per kept pair beyond their ids is ever formed.
Faces crossing the near plane are clipped there, as ``rasterize`` does.

The limits: σ → 0 alone makes each D a step, but a fixed γ still blends overlapping faces; γ → 0 alone
picks the nearest face among all those with D > 0, and every face has D > 0 everywhere, so a nearer face
far outside a pixel wins over the background: the silhouette of the colour image fattens by about
``sqrt(σ (z - ε) / γ)`` (NDC). That is the uncut formula, which the default ``cutoff="relative"`` follows
to within ``threshold``; the reference SoftRas code drops every pair with D < 1e-4 (``cutoff="absolute"``)
and PyTorch3D every face beyond ``blur_radius``, which bounds the fattening by that radius. Both also
normalise depth linearly, (far - z) / (far - near) (``depth="linear"``), where the default here is inverse
depth. Along σ = γ² both go to 0 together and the image tends to the hard
rasterizer's, at pixels farther than a pixel from any edge (``tests/test_soft.py`` measures both).

It gives a gradient with respect to ``mesh.verts``, the colours, and the camera's K, R, t.

**A camera batch** (one mesh, a list of N cameras: a fit's views) is one call, not N: every view's triangles
are projected together (``_screen_views``), then each triangle's pairs are listed in its own image (its rows
and columns only: no blur crosses into another view) and numbered ``view · H · W + pixel``, and from there
the pair search, the thresholds and the chunked sums run once over all views' pairs as over one image of
N · H · W pixels. Per pixel the terms are those of the call for its view alone, added in the same order.
"""
from __future__ import annotations

import math

import torch
from torch.utils.checkpoint import checkpoint

from .raster import _check_views, _clip_near, _project
from .scan import _expand, _max3, _min3
from .tensors import _check_finite, _check_flag, _check_real, as_tensor
from .textures import sample_texture

__all__ = ["soft_rasterize"]

CHUNK = 1 << 18      # (pixel, face) pairs computed at once: bounds the memory of the intermediates (the tests
                     # set it small to force many chunks)


# -------------------------------------------------------------------------------- shared: screen triangles

def _screen_faces(verts, faces, camera, cull_backfaces, attr=None):
    """The faces projected by one camera: ``_screen_views`` of a batch of one, without the view ids.
    Returns xy (T, 3, 2), q (T, 3), face (T,) and attr (T, 3, C) or None."""
    return _screen_views(verts, faces, [camera], cull_backfaces, attr)[:4]


def _screen_views(verts, faces, cameras, cull_backfaces, attr=None):
    """Faces projected to the screens of N cameras at once, differentiable in verts and every camera's K, R, t.

    Faces behind the camera or beyond the far plane are dropped, back faces too if asked; faces crossing
    the near plane are clipped there in camera space (``raster._clip_near``), so nothing is divided by a
    depth <= 0. The decisions are made on detached float64 copies (as ``rasterize`` makes them).
    cameras: a list of N cameras sharing near, far and orthographic (each has its own K, R, t); every step
    runs on all of them together, one row of (N, V, 3) camera-space vertices per camera.
    attr: optional (V, C) per-vertex values (vertex colours), clipped along with the positions.
    Returns xy (T, 3, 2) pixels, q (T, 3) = 1/z (perspective) or z (orthographic), face (T,) ids,
    attr (T, 3, C) or None, and view (T,) the camera each triangle is seen by: the whole faces view by view,
    then the clipped ones (so each view's triangles come in the order a call for that view alone gives).
    """
    cam, N, V, F = cameras[0], len(cameras), verts.shape[0], faces.shape[0]   # cam: near, far, orthographic
    dtype = _dtype(verts, cameras)
    K, R, t = (torch.stack([getattr(c, name) for c in cameras]).to(dtype) for name in ("K", "R", "t"))
    verts_cam = verts.to(dtype) @ R.mT + t[:, None]                         # (N, V, 3) differentiable
    with torch.no_grad():
        R64, t64 = R.detach().double(), t.detach().double()
        v = (verts.detach().double() @ R64.mT + t64[:, None])[:, faces].reshape(N * F, 3, 3)   # float64
        z = v[..., 2]
        keep = (_max3(z) >= cam.near) & (_min3(z) <= cam.far)
        if cull_backfaces:                                                  # front faces are CCW to the viewer
            normal = torch.linalg.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
            keep &= (normal[:, 2] < 0) if cam.orthographic else ((normal * v[:, 0]).sum(-1) < 0)
        whole = (keep & (_min3(z) >= cam.near)).nonzero().squeeze(1)      # view * F + face
        crossing = (keep & (_min3(z) < cam.near)).nonzero().squeeze(1)
    xy_v, q_v = _project_safe(verts_cam, cam, K)                            # each vertex projected once a view
    view, face = whole // F, whole % F
    corner = faces.index_select(0, face)                                    # (T, 3)
    idx = corner + V * view[:, None]                                        # rows of the (N * V) vertices
    xy, q = xy_v.reshape(N * V, 2)[idx], q_v.reshape(N * V)[idx]
    a = None if attr is None else attr.to(dtype)[corner]
    if crossing.numel():
        # clip the attributes with the positions: _clip_near interpolates every column along the edge
        full = verts_cam if attr is None else torch.cat([verts_cam, attr.to(dtype).expand(N, V, -1)], 2)
        rows = (faces + V * torch.arange(N, device=faces.device)[:, None, None]).reshape(N * F, 3)
        tri, ids = _clip_near(full.reshape(N * V, -1), rows, crossing, cam.near)   # (C, 3, 3 + attr)
        xy_c, q_c = _project(tri[..., :3], cam, K[ids // F])
        xy, q, face, view = torch.cat([xy, xy_c]), torch.cat([q, q_c]), torch.cat([face, ids % F]), \
            torch.cat([view, ids // F])
        a = None if attr is None else torch.cat([a, tri[..., 3:]])
    return xy, q, face, a, view


def _dtype(verts, cameras):
    """The working dtype: promote(verts, every camera)."""
    dtype = verts.dtype
    for c in cameras:
        dtype = torch.promote_types(dtype, c.dtype)
    return dtype


def _project_safe(verts_cam, camera, K):
    """``raster._project`` of every vertex, differentiably, those far behind the near plane (z < near / 2)
    first replaced by a harmless point: no face uses them, but dividing by their z <= 0 would send
    0 · inf = NaN into the backward pass. verts_cam: (V, 3) with K (3, 3), or (N, V, 3) with K (N, 3, 3).
    Returns xy (..., V, 2) and q (..., V)."""
    if not camera.orthographic:
        ok = verts_cam[..., 2].detach() >= 0.5 * camera.near
        verts_cam = torch.where(ok[..., None], verts_cam, torch.ones_like(verts_cam))
    return _project(verts_cam, camera, K)


def _nearness(q, camera, depth: str = "inverse"):
    """Normalised depth z ∈ [0, 1] from q: 1 at the near plane, 0 at the far plane, larger = nearer.
    Perspective, ``depth="inverse"`` (the default): ``(1/depth - 1/far) / (1/near - 1/far)``, affine in
    q = 1/depth and so affine on screen; ``depth="linear"`` (the reference SoftRas code and PyTorch3D):
    ``(far - depth) / (far - near)`` with depth = 1/q. Orthographic (q = depth): ``(far - depth) / (far - near)``
    either way."""
    n, f = camera.near, camera.far
    if camera.orthographic:
        return (f - q) / (f - n)
    if depth == "linear":
        return (f - 1 / q) / (f - n)
    return (q - 1 / f) / (1 / n - 1 / f)


# ------------------------------------------------------------------------------------- soft rasterization

def _groups(count, size):
    """Consecutive ranges ``(lo, hi)`` of the items 0..n-1, each holding about ``size`` of the work ``count``
    (n,) int64 (at most size plus one item's count): how the loops below cut their work into chunks. No
    items: one empty range, so that an empty mesh still runs (and backpropagates) through the same code."""
    if count.numel() == 0:
        return [(0, 0)]
    before = torch.cumsum(count, 0) - count                                 # the work of the items before each
    _, n = torch.unique_consecutive(torch.div(before, size, rounding_mode="floor"), return_counts=True)
    ends = torch.cumsum(n, 0).tolist()
    return list(zip([0] + ends[:-1], ends))


def _pad(xy, radius):
    """(T,) the candidate radius in pixels, plus a margin for rounding."""
    return 1e-9 * (1 + xy.abs().amax((1, 2))) + radius


def _triangle_groups(xy, radius, W, H, images: int = 1):
    """Consecutive groups ``(lo, hi)`` of the triangles, about CHUNK candidate pairs each. A triangle's pairs
    lie in its bounding box widened by the radius, whose pixel count bounds their number.
    images: the triangles of a batch of that many images are cut into at least as many groups (about one
    image's pairs each, at most CHUNK): the vectors a call per image would work on. One group of the whole
    batch ran up to 1.4 times slower per pair on a CPU, its vectors too long for the caches."""
    pad = _pad(xy, radius)[:, None]
    first = torch.ceil(xy.amin(1) - pad - 0.5).clamp(min=0)                # (T, 2) first column, first row
    last = torch.minimum(torch.floor(xy.amax(1) + pad - 0.5), xy.new_tensor([W - 1, H - 1]))
    count = (last - first + 1).clamp(min=0).prod(1).long()                  # (T,)
    return _groups(count, min(CHUNK, max(1, -(-int(count.sum()) // images))))   # ⌈pairs / images⌉


def _candidate_pairs(xy, radius, W, H):
    """Every (pixel, triangle) pair whose pixel centre may lie within ``radius`` pixels of the triangle.

    xy: (T, 3, 2) float64; radius: (T,) pixels. Returns pixel (N,) and tri (N,), grouped by triangle.
    Row by row (centre y_c), the triangle is cut to the band [y_c - r, y_c + r] (as in
    ``scan.pixel_triangle_pairs``); the band's x-extent widened by r gives the columns. Conservative: every
    point within r of the triangle is listed; a few pixels near the corners farther than r are too.
    Each triangle's pairs depend on it alone, so a group of triangles (``_triangle_groups``) gives the same
    pairs as the whole mesh, in the same order.
    """
    pad = _pad(xy, radius)                                                  # (T,) r and rounding
    y = xy[..., 1]
    first = torch.ceil(_min3(y) - pad - 0.5).clamp(min=0)
    last = torch.floor(_max3(y) + pad - 0.5).clamp(max=H - 1)
    tri_of_seg, seg_start = _expand((last - first + 1).clamp(min=0).long())
    n = torch.arange(tri_of_seg.numel(), device=xy.device)
    yc = first[tri_of_seg] + (n - seg_start[tri_of_seg]) + 0.5               # (S,) row centres
    r = pad[tri_of_seg, None]
    a = xy[tri_of_seg]                                                      # (S, 3, 2)
    b = a.roll(-1, 1)                                                       # edges a→b
    dy = b[..., 1] - a[..., 1]
    flat = dy == 0
    dy = torch.where(flat, torch.ones_like(dy), dy)
    t0, t1 = (yc[:, None] - r - a[..., 1]) / dy, (yc[:, None] + r - a[..., 1]) / dy
    t_in = torch.where(flat, 0.0, torch.minimum(t0, t1).clamp(min=0))     # the part of the edge in the band
    t_out = torch.where(flat, 1.0, torch.maximum(t0, t1).clamp(max=1))
    ok = torch.where(flat, (a[..., 1] - yc[:, None]).abs() <= r, t_in <= t_out)   # (S, 3)
    dx = b[..., 0] - a[..., 0]
    x_in, x_out = a[..., 0] + t_in * dx, a[..., 0] + t_out * dx
    x_lo = torch.where(ok, torch.minimum(x_in, x_out), math.inf).amin(1)   # (S,)
    x_hi = torch.where(ok, torch.maximum(x_in, x_out), -math.inf).amax(1)
    meets = torch.isfinite(x_lo)
    col0 = torch.where(meets, torch.ceil(x_lo - r[:, 0] - 0.5), 0.0).clamp(min=0)
    col1 = torch.where(meets, torch.floor(x_hi + r[:, 0] - 0.5), -1.0).clamp(max=W - 1)
    count = (col1 - col0 + 1).clamp(min=0).long()
    base = ((yc - 0.5) * W + col0.clamp(max=W - 1)).long()
    seg_of_px, px_start = _expand(count)
    pixel = base[seg_of_px] + torch.arange(seg_of_px.numel(), device=xy.device) - px_start[seg_of_px]
    return pixel, tri_of_seg[seg_of_px]


def _pair_terms(xy, tri, pixel, W, s, bary: bool = True, H=None):
    """Signed, scaled squared distance and clamped barycentrics of each pair's pixel centre.

    xy: (T, 3, 2) triangles on screen (either winding); tri, pixel: (N,) the pairs; s: 1/σ_px. H: None (the
    pixel ids are one image's), or the image height when they run over a batch of images (view · H · W +
    the pixel's own id): the row is then taken modulo H.
    Returns x (N,) = δ d² / σ_px (δ = +1 inside, -1 outside) and, if asked, bary: three (N,) tensors, the
    screen-space barycentrics clamped to [0, 1] and renormalised (the paper's choice: outside a face, its
    attributes are those of the nearest point). Finite for degenerate triangles (zero area: never inside,
    bary 1/3 each). Written one coordinate at a time on (N,) vectors: several times faster than (N, 3, 2)
    tensors.
    """
    px = (pixel % W).to(xy.dtype) + 0.5                                     # (N,) pixel centre
    py = (pixel // W if H is None else pixel // W % H).to(xy.dtype) + 0.5
    X = [xy[:, k, 0].index_select(0, tri) for k in range(3)]                # (N,) each corner's x
    Y = [xy[:, k, 1].index_select(0, tri) for k in range(3)]
    d2, cross = None, []
    for k in range(3):                                                      # edge a→b = v_k→v_k+1
        ax, ay, bx, by = X[k], Y[k], X[(k + 1) % 3], Y[(k + 1) % 3]
        ex, ey, wx, wy = bx - ax, by - ay, px - ax, py - ay
        with torch.no_grad():                                               # the closest point's parameter
            ee = ex * ex + ey * ey
            t = ((wx * ex + wy * ey) / torch.where(ee > 0, ee, 1.0)).clamp_(0, 1)
        # t held constant gives the exact gradient (d² is minimal in t) and no 1/|e|² that could blow up
        rx, ry = wx - t * ex, wy - t * ey
        dk = rx * rx + ry * ry                                              # squared distance to the edge
        d2 = dk if d2 is None else torch.minimum(d2, dk)
        cross.append(ex * wy - ey * wx)                                     # edge function of the centre
    with torch.no_grad():
        area = cross[0] + cross[1] + cross[2]                               # 2 × area, wherever the point
        inside = (cross[0] * area > 0) & (cross[1] * area > 0) & (cross[2] * area > 0)
    x = torch.where(inside, d2, -d2) * s
    if not bary:
        return x, None
    area = cross[0] + cross[1] + cross[2]
    flat = area == 0                                                        # zero area: 1/3 each
    safe = torch.where(flat, torch.ones_like(area), area)
    b = [torch.where(flat, 1 / 3, cross[(k + 1) % 3] / safe).clamp(0, 1) for k in range(3)]   # b_k: edge k+1
    total = b[0] + b[1] + b[2]                                              # >= 1/3 after the clamp
    return x, [bk / total for bk in b]


def _check_soft(mode, sigma, gamma, threshold, eps, cutoff="relative", depth="inverse"):
    """The checked scalar options of ``soft_rasterize``, as floats (ValueError naming the one that is wrong)."""
    for name, value, allowed in (("mode", mode, ("silhouette", "color")), ("cutoff", cutoff, ("relative", "absolute")),
                                 ("depth", depth, ("inverse", "linear"))):
        if not isinstance(value, str) or value not in allowed:
            raise ValueError(f"{name} must be {allowed[0]!r} or {allowed[1]!r}, got {value!r}")
    sigma = _check_real(sigma, "sigma", low=0, low_open=True)
    gamma = _check_real(gamma, "gamma", low=0, low_open=True)
    threshold = _check_real(threshold, "threshold", low=0, high=1, low_open=True, high_open=True)
    eps = _check_real(eps, "eps (the background's normalised depth)", low=0, high=1, high_open=True)
    return sigma, gamma, threshold, eps


def _colors(face_colors, vertex_colors, verts, faces, dtype):
    """Checked colour arguments: (F, C) face colours or (V, C) vertex colours (exactly one), finite, C >= 1.
    Integers become floats (as ``as_tensor`` does everywhere); the dtype is promoted with the mesh's."""
    if (face_colors is None) == (vertex_colors is None):
        raise ValueError("mode='color' needs exactly one of face_colors (F, C) or vertex_colors (V, C)")
    name, n = ("face_colors", faces.shape[0]) if vertex_colors is None else ("vertex_colors", verts.shape[0])
    c = as_tensor(face_colors if vertex_colors is None else vertex_colors, device=verts.device, name=name)
    if c.dim() != 2 or c.shape[0] != n or c.shape[1] < 1:
        raise ValueError(f"{name} must have shape ({n}, C) with C >= 1 channels, got {tuple(c.shape)}")
    _check_finite(c, name)
    return c.to(torch.promote_types(dtype, c.dtype))


def _background(background, C, dtype, device):
    """The background as (C,): a number (or one-element array) for every channel, or one value per channel;
    finite. A ValueError naming ``background`` otherwise (``expand`` would fail, or broadcast silently)."""
    bg = as_tensor(background, dtype=dtype, device=device, name="background")
    if bg.numel() == 1:
        bg = bg.reshape(1)
    elif tuple(bg.shape) != (C,):
        raise ValueError(f"background must be a number or ({C},), one value per channel, got shape "
                         f"{tuple(bg.shape)}")
    _check_finite(bg, "background")
    return bg.expand(C)


def _pair_colors(face_colors, vertex_colors, texture, uvs, specular, verts, faces, dtype):
    """The checked colour arguments of colour mode, as ``_ColorSums`` takes them.

    Without a texture: (colors, None, vert_attr, None), colors (F, C) or (V, C) with ``specular`` already
    added (interpolation is linear, so adding before or after is the same), vert_attr the vertex colours to
    clip with the faces (or None). With a texture (Ht, Wt, C) and uvs (V, 2): (None, texture, vert_attr,
    face_attr), the per-vertex (V, A_v) and per-face (F, A_f) attributes whose concatenation, per corner, is
    ``[uv (2) | colour factor (C), if given | specular (C), if given]`` (``_shade_pairs`` reads it back)."""
    if (texture is None) != (uvs is None):
        raise ValueError("a texture needs uvs (V, 2), and uvs need a texture (Ht, Wt, C): give both or neither")
    if texture is None:
        colors = _colors(face_colors, vertex_colors, verts, faces, dtype)
        if specular is not None:
            colors = colors + _like_colors(specular, colors, "specular", "face_colors" if vertex_colors is None
                                           else "vertex_colors")
        return colors, None, (colors if vertex_colors is not None else None), None
    tex = as_tensor(texture, device=verts.device, name="texture")
    if tex.dim() != 3 or min(tex.shape) < 1:
        raise ValueError(f"texture must have shape (Ht, Wt, C), none of them 0, got {tuple(tex.shape)}")
    _check_finite(tex, "texture")
    uv = as_tensor(uvs, device=verts.device, name="uvs")
    if tuple(uv.shape) != (verts.shape[0], 2):
        raise ValueError(f"uvs must have shape ({verts.shape[0]}, 2), one (u, v) per vertex, got {tuple(uv.shape)}")
    _check_finite(uv, "uvs")
    dtype = torch.promote_types(dtype, tex.dtype)
    C = tex.shape[2]
    vert_attr, face_attr = [uv.to(dtype)], []
    if face_colors is not None and vertex_colors is not None:
        raise ValueError("give at most one of face_colors (F, C) or vertex_colors (V, C) with a texture")
    if face_colors is not None or vertex_colors is not None:
        colors = _colors(face_colors, vertex_colors, verts, faces, dtype)
        if colors.shape[1] != C:
            raise ValueError(f"the colours multiply the texture: they need its {C} channels, got {colors.shape[1]}")
        parts = vert_attr if vertex_colors is not None else face_attr
        parts.append(colors.to(dtype))
        if specular is not None:
            parts.append(_like_colors(specular, colors, "specular", "face_colors" if vertex_colors is None
                                      else "vertex_colors").to(dtype))
    elif specular is not None:
        raise ValueError("specular needs face_colors or vertex_colors (the factor the texture is multiplied by): "
                         "it is given per face or per vertex like them")
    return None, tex.to(dtype), torch.cat(vert_attr, 1), torch.cat(face_attr, 1) if face_attr else None


def _like_colors(x, colors, name, kind):
    """``x`` checked to have the shape of ``colors`` (``kind`` names them in the error)."""
    t = as_tensor(x, dtype=colors.dtype, device=colors.device, name=name)
    if t.shape != colors.shape:
        raise ValueError(f"{name} must have the shape of {kind}, {tuple(colors.shape)}, got {tuple(t.shape)}")
    _check_finite(t, name)
    return t


def soft_rasterize(mesh, camera, *, mode: str = "silhouette", sigma: float = 1e-4, gamma: float = 1e-4,
                   face_colors=None, vertex_colors=None, background=0.0, threshold: float = 1e-4,
                   eps: float = 1e-3, cull_backfaces: bool = True, cutoff: str = "relative",
                   depth: str = "inverse", texture=None, uvs=None, specular=None,
                   blend: str = "softmax") -> torch.Tensor:
    """Soft rasterization (Liu et al. 2019): a silhouette or colour image smooth in every vertex position.

    mesh: ``verts`` (V, 3) world space, ``faces`` (F, 3) int64; camera: a ``Camera`` (perspective or
    orthographic), or a list of N cameras of one image size sharing near, far and the projection (a camera
    batch: the images come back stacked, (N, H, W) or (N, H, W, C), each equal to its own call's, computed in
    one pass: ``_screen_views``, then every view's pairs together, each kept to its own view's pixels).
    mode: ``"silhouette"`` returns (H, W), the probabilistic OR ``1 - Π (1 - D_j)``;
    ``"color"`` returns (H, W, C), the softmax over depth with the background as one more term, the colour of
    a face being ``face_colors`` (F, C) or ``vertex_colors`` (V, C) interpolated with perspective-correct
    barycentrics (clamped to the triangle outside it); finite, integers are taken as floats.
    texture: (Ht, Wt, C) with uvs (V, 2) (u right, v up; ``textures.sample_texture``): a face's colour at a
    pixel is the texture, bilinearly filtered, at the uv of that pixel's perspective-correct barycentrics in
    the face (clamped outside it), the lookup SoftRas makes per pixel and face; ``face_colors`` or
    ``vertex_colors`` (C channels, optional) then multiply it, and ``specular`` ((F, C) or (V, C), like them)
    is added: ``texel · colour + specular``, the shape of a lighting model's ``base · diffuse + specular``
    (SoftRas likewise multiplies its textures by the lighting). Without a texture ``specular`` is simply added.
    background: (C,) or a number (colour mode; a silhouette's background is 0).
    blend: ``"softmax"`` (default, the paper) puts the background into the depth softmax as described
    below; ``"alpha"`` blends the faces alone and composites the result over the background with the
    silhouette's coverage α: ``I = α Σ_j w_j C_j / Σ_j w_j + (1 - α) C_b``. The softmax lets a face outweigh the
    background far outside its edge (the fattening below); alpha compositing puts the object's edge where
    D = 1/2, on the true edge, whatever γ (γ then only decides occlusion between faces).
    sigma: sharpness, in the paper's NDC units (image width 2): ``σ_px = σ W² / 4`` px².
    gamma: the depth softmax's temperature; z is the normalised depth (``_nearness``); eps: the
    background's z. depth: ``"inverse"`` (default), z affine in 1/depth; ``"linear"``, z = (far - depth) /
    (far - near) as in the reference SoftRas code and PyTorch3D (the same for an orthographic camera): γ
    values tuned for one do not carry over to the other.
    threshold and cutoff: which pairs (pixel, face) are skipped. ``cutoff="relative"`` (default): a pair whose
    term, relative to the pixel's largest (the background included), is below threshold: D_j < threshold for
    silhouettes, ``D_j exp(z_j/γ) < threshold · max_k(D_k exp(z_k/γ), exp(ε/γ))`` for colour, so the error per
    face against the uncut formula is below threshold however small γ is. Candidates come from a screen-space
    radius: for a silhouette ``r² = σ_px log(1/threshold)``; for colour the radius grows with
    ``(z_j - ε) / γ``, because a nearer face far outside a pixel can still outweigh the background (the
    fattening a tiny γ causes). ``cutoff="absolute"``: exactly the pairs with D_j < threshold are dropped,
    whatever their depth, as the reference SoftRas code does (it drops a face outside a pixel where
    d² >= σ log(1/ε_d - 1), i.e. D <= ε_d, ε_d = 1e-4 by default: threshold's default); the colour
    image then differs from the uncut formula, and no face spreads beyond ``r² = σ_px log(1/threshold - 1)``.
    cull_backfaces: skip faces facing away (front faces are CCW). Faces crossing the near plane are clipped.
    A mesh without faces gives the background. Memory is bounded by CHUNK pairs, not by the number of
    candidates. Differentiable w.r.t. verts, the colours, the texture, its uvs, specular and the camera's
    (every camera's) K, R and t; dtype and device of the inputs.
    """
    sigma, gamma, threshold, eps = _check_soft(mode, sigma, gamma, threshold, eps, cutoff, depth)
    cull_backfaces = _check_flag(cull_backfaces, "cull_backfaces")
    verts, faces, cameras, batched = _check_views(mesh, camera, ("near", "far", "orthographic"))
    camera, N = cameras[0], len(cameras)                                    # its near, far, projection: all's
    H, W = camera.height, camera.width
    dtype = _dtype(verts, cameras)
    if blend not in ("softmax", "alpha"):
        raise ValueError(f"blend must be 'softmax' or 'alpha', got {blend!r}")
    colors = bg = texture_ = vert_attr = None
    if mode == "color":
        colors, texture_, vert_attr, face_attr = _pair_colors(face_colors, vertex_colors, texture, uvs, specular,
                                                              verts, faces, dtype)
        like = texture_ if texture_ is not None else colors
        bg = _background(background, texture_.shape[2] if texture_ is not None else colors.shape[1], like.dtype,
                         verts.device)
    elif any(x is not None for x in (texture, uvs, specular)):
        raise ValueError("texture, uvs and specular are for mode='color'; a silhouette has no colours")
    # every view's triangles together; each one's pairs go to its own view's pixels, view · H · W onwards
    xy, q, face, attr, view = _screen_views(verts, faces, cameras, cull_backfaces, vert_attr)
    base = view * (H * W) if N > 1 else None                                # (T,) first pixel id of its view
    P = N * H * W                                                           # pixels in all
    shape = (N, H, W) if batched else (H, W)
    s = 4.0 / (W * W * sigma)                                               # 1 / σ_px
    x_max = math.log(1 / threshold)                                         # sigmoid(-x) >= thr ⇒ x <= this
    # cutoff="absolute": a pair is dropped exactly where D = sigmoid(x) < threshold, i.e. x < x_cut
    x_cut = math.log(threshold) - math.log1p(-threshold) if cutoff == "absolute" else None
    if mode == "silhouette":
        return _soft_silhouette(xy, base, P, W, H, s, x_max, x_cut, dtype).view(shape)
    if texture_ is not None:                                                # (T, 3, A) corner attributes:
        if face_attr is not None:                                           # [uv | per-face colour, specular]
            attr = torch.cat([attr, face_attr.to(attr.dtype)[face][:, None].expand(-1, 3, -1)], 2)
    elif attr is None:
        attr = colors                                                       # (F, C) flat colours, as they are
    near = _nearness(q.detach().double(), camera, depth)                    # (T, 3) z of the corners
    # (T,) the largest useful x: relative, a nearer face reaches farther; absolute, D >= threshold only
    x_reach = x_max + (_max3(near) - eps).clamp(min=0) / gamma * (x_cut is None)
    pixel, tri, top, z_top = _color_pairs(xy.detach(), near, (x_reach / s).sqrt(), W, H, s, gamma, eps,
                                          math.log(threshold), x_cut,
                                          q.detach().double() if depth == "linear" else None, camera, base, N)
    C = bg.shape[0]
    w_bg = torch.exp((eps / gamma - top).to(dtype))                        # (P,) the background's weight
    if blend == "alpha":                                                    # the faces alone: no background term
        w_bg = torch.zeros_like(w_bg)
    # the background's term plus every kept pair's w and w c, summed per pixel CHUNK pairs at a time; no
    # per-pair tensor outlives its chunk, in the forward or the backward pass (``_ColorSums``)
    num, den = _ColorSums.apply(w_bg[:, None] * bg, w_bg, xy, q, attr, texture_, face, tri, pixel,
                                (top - z_top / gamma).to(dtype), z_top.to(dtype),
                                (W, H if N > 1 else None, s, gamma, camera, depth, C))
    if blend == "softmax":
        return (num / den[:, None]).view(*shape, C)                         # (P, C) / (P, 1)
    faces_color = num / torch.where(den > 0, den, torch.ones_like(den))[:, None]   # (P, C); 0 where no face
    alpha = _soft_silhouette(xy, base, P, W, H, s, x_max, x_cut, dtype)[:, None]   # (P, 1)
    return (alpha * faces_color + (1 - alpha) * bg).view(*shape, C)


def _soft_silhouette(xy, base, P, W, H, s, x_max, x_cut, dtype):
    """(P,) the probabilistic OR ``1 - Π (1 - D_j)`` of the screen triangles xy (T, 3, 2) on P = N·H·W
    pixels: N images of H x W, triangle j drawn into the one starting at pixel id base (T,) (view · H · W;
    None: one image)."""
    radius = torch.full_like(xy[:, 0, 0], math.sqrt(x_max / s), dtype=torch.float64)   # (T,) pixels
    xy64 = xy.detach().double()
    images = P // (H * W)
    groups = _triangle_groups(xy64, radius, W, H, images)
    log_empty = torch.zeros(P, dtype=dtype, device=xy.device)
    recompute = len(groups) > images                                        # more than one group an image
    for lo, hi in groups:
        # each group of triangles adds its log(1 - D_j) to its pixels; with more groups than images, a
        # group's pairs and graph are rebuilt during backward instead of kept (memory: one group's, not all;
        # up to one group an image is kept, what a call per image would keep)
        log_empty = log_empty + _checkpointed(recompute, _silhouette_group, xy, xy64, radius, base, lo, hi,
                                              P, W, H, s, x_cut)
    return -torch.expm1(log_empty)                                          # 1 - Π (1 - D_j), stably


def _silhouette_group(xy, xy64, radius, base, lo, hi, P, W, H, s, x_cut=None):
    """(P,) the sum of log(1 - D_j) over the triangles lo..hi-1 at each pixel: their candidates in their own
    image (so no triangle reaches into another view's pixels), then ``_silhouette_terms``."""
    pixel, tri = _candidate_pairs(xy64[lo:hi], radius[lo:hi], W, H)       # tri: 0..hi-lo-1
    log_miss = _silhouette_terms(tri, pixel, xy[lo:hi], W, s, x_cut)
    if base is not None:
        pixel = pixel + base[lo:hi].index_select(0, tri)                    # the batch's pixel ids
    return torch.zeros(P, dtype=xy.dtype, device=xy.device).index_add(0, pixel, log_miss)


def _color_pairs(xy, near, radius, W, H, s, gamma, eps, log_thr, x_cut=None, q=None, camera=None, base=None,
                 images: int = 1):
    """Which pairs matter in colour mode, without gradients. xy: (T, 3, 2) detached, in the dtype the
    differentiable pass computes in (so both agree on what is kept); near: (T, 3) float64 corner z;
    radius: (T,) the candidate radius in pixels. Every candidate's log-weight is
    ``log_w = logsigmoid(x) + z/γ`` (float64: z/γ reaches 1e5); per pixel ``top`` is the largest log_w (at
    least the background's ε/γ) and ``z_top`` the largest z; a pair is kept if log_w - top >= log_thr.
    Returns pixel (N,), tri (N,) of the kept pairs (grouped by triangle; int32 when the image and the mesh
    allow, half the memory of int64) and top, z_top (P,) float64, P = images · H · W pixels: base (T,) the
    first pixel id of each triangle's image in a batch of ``images`` (None: one image), where its pairs go.
    x_cut: None (the relative cut-off above), or the absolute one: a pair is kept iff its x >= x_cut (its
    D >= threshold), whatever the other weights. q: None (z is affine on screen: interpolated from ``near``),
    or (T, 3) float64 corner q, interpolated and then turned into z by ``_nearness(.., camera, "linear")``.
    The differentiable pass takes each weight as ``exp((z - z_top)/γ + logsigmoid(x) - (top - z_top/γ))``:
    nothing of size 1/γ reaches float32.

    The candidates (10⁸ on a big mesh at γ = 1e-4) are never all stored: they are built and weighed a
    group of triangles at a time. ``top`` so far only grows, so a pair already below threshold relative to
    it will be below it at the end too, and is dropped at once; the few survivors are checked again against
    the final ``top`` (and pruned on the way whenever they pile up)."""
    xy64 = xy.double()
    P = images * H * W
    top = torch.full((P,), eps / gamma, dtype=torch.float64, device=xy.device)
    z_top = torch.full((P,), eps, dtype=torch.float64, device=xy.device)
    # the survivors are stored as int32 where every pixel and triangle id fits (the candidates stay int64:
    # scatter_reduce_ wants int64 indices); at a large σ there are tens of millions of them
    index = torch.int32 if max(P, xy.shape[0]) < 2 ** 31 else torch.int64
    kept = _Survivors(index, xy.device)
    with torch.no_grad():
        for lo, hi in _triangle_groups(xy64, radius, W, H, images):
            pix, t = _candidate_pairs(xy64[lo:hi], radius[lo:hi], W, H)
            t = t + lo                                                      # the group's → the mesh's ids
            x, b = _pair_terms(xy, t, pix, W, s)                            # as stage B computes them
            if q is None:
                nt = near.index_select(0, t)                                # (n, 3) float64
                z = b[0] * nt[:, 0] + b[1] * nt[:, 1] + b[2] * nt[:, 2]     # z is affine in q
            else:
                qt = q.index_select(0, t)                                   # linear depth: q, then z
                z = _nearness(b[0] * qt[:, 0] + b[1] * qt[:, 1] + b[2] * qt[:, 2], camera, "linear")
            log_w = torch.nn.functional.logsigmoid(x.double()) + z / gamma
            if base is not None:
                pix = pix + base.index_select(0, t)                         # the batch's pixel ids
            if x_cut is not None:                                           # absolute: D < threshold is dropped
                log_w = torch.where(x.double() >= x_cut, log_w, -math.inf)
            z_top.scatter_reduce_(0, pix, z, reduce="amax")
            top.scatter_reduce_(0, pix, log_w, reduce="amax")
            ok = (log_w > -math.inf) if x_cut is not None else (log_w - top[pix] >= log_thr)   # relative: the
            kept.add(pix[ok], t[ok], log_w[ok], top, log_thr if x_cut is None else -math.inf)  # best so far
        pixel, tri = kept.result(top, log_thr if x_cut is None else -math.inf)   # against the final top
    return pixel, tri, top, z_top


class _Survivors:
    """The pairs kept so far by ``_color_pairs``, (pixel, tri, log_w), in three buffers that grow by doubling.

    Not a list of small tensors, one per group of faces: those, left among each group's freed temporary
    tensors, fragment the C heap, and the process then holds many times what they hold (S1 at 512²,
    σ = 1e-4: 0.57 GB of memory for 0.03 GB of pairs). When the buffers are full the pairs already below
    threshold against the best so far are dropped first (in place, the order kept); only if more than half
    is still taken do the buffers double, so pruning costs O(1) per pair, amortised."""

    def __init__(self, index, device):
        self.bufs = [torch.empty(CHUNK, dtype=index, device=device), torch.empty(CHUNK, dtype=index, device=device),
                     torch.empty(CHUNK, dtype=torch.float64, device=device)]
        self.n = 0                                                          # the first n entries are pairs

    def add(self, pixel, tri, log_w, top, log_thr):
        k = pixel.numel()
        if self.n + k > self.bufs[0].numel():                               # full: prune against the best so far
            self.prune(top, log_thr)
            if 2 * (self.n + k) > self.bufs[0].numel():                     # still over half full: double
                for i, b in enumerate(self.bufs):                           # one at a time: one old buffer alive
                    self.bufs[i] = torch.cat([b[:self.n], b.new_empty(2 * (self.n + k) - self.n)])
        for b, v in zip(self.bufs, (pixel, tri, log_w)):
            b[self.n:self.n + k] = v                                        # int64 ids → int32 on the way
        self.n += k

    def prune(self, top, log_thr):
        """Keep, in place and in order, the pairs still within log_thr of ``top`` at their pixel."""
        pix, lw = self.bufs[0][:self.n], self.bufs[2][:self.n]
        keep = (lw - top[pix] >= log_thr).nonzero().squeeze(1)
        for b in self.bufs:
            b[:keep.numel()] = b[:self.n].index_select(0, keep)             # a copy first, then written back
        self.n = keep.numel()

    def result(self, top, log_thr):
        """pixel (N,), tri (N,): the pairs within log_thr of the final ``top``, in their own tensors (the
        buffers, up to twice as long, are freed)."""
        self.prune(top, log_thr)
        return self.bufs[0][:self.n].clone(), self.bufs[1][:self.n].clone()


def _checkpointed(recompute, fn, *args):
    """``fn(*args)``; when ``recompute`` and a gradient is being recorded, through ``torch.utils.checkpoint``:
    its graph is rebuilt during backward instead of stored, trading a second forward for memory."""
    grad = torch.is_grad_enabled() and any(isinstance(a, torch.Tensor) and a.requires_grad for a in args)
    return checkpoint(fn, *args, use_reentrant=False) if recompute and grad else fn(*args)


class _ColorSums(torch.autograd.Function):
    """The colour softmax's per-pixel sums, ``num = bg_num + Σ w c`` (H*W, C) and ``den = bg_den + Σ w``
    (H*W,), over the kept pairs (``_color_terms`` gives each pair's w and w c), in bounded memory.

    Stored per pair, w and w c (32 bytes a pair in float64, plus their gradients and a copy when chunks are
    joined) were most of the memory once σ is large (S1 at 512², σ = 1e-3: 14 million kept pairs). Here
    the forward pass adds each chunk of CHUNK pairs into the two sums (``index_add_``) and forgets it; the
    backward pass rebuilds one chunk at a time with its graph, pulls the pixels' gradients back through it
    and forgets it too (a checkpoint per chunk, without keeping a per-pair output). The sums are added in
    the pairs' order, the same numbers as one ``index_add`` over all of them.

    Inputs: bg_num (P, C) and bg_den (P,), the background's term (where the sums start) on the P pixels of
    the image or batch; xy (T, 3, 2), q (T, 3), colors ((F, C) face colours or (T, 3, A) corner attributes)
    and texture (Ht, Wt, C) or None: the differentiable ones; face (T,), tri and pixel (N,) the kept pairs;
    top, z_top (P,); rest: (W, H, s, gamma, camera, depth, C), the other arguments of ``_color_terms``.
    Differentiable once (no double backward)."""

    @staticmethod
    def forward(ctx, bg_num, bg_den, xy, q, colors, texture, face, tri, pixel, top, z_top, rest):
        ctx.save_for_backward(xy, q, colors, texture, face, tri, pixel, top, z_top)
        ctx.rest = rest
        num, den = bg_num.clone(), bg_den.clone()                           # forward runs without a graph
        for lo in range(0, pixel.numel(), CHUNK):
            p = pixel[lo:lo + CHUNK]
            w, wc = _color_terms(tri[lo:lo + CHUNK], p, xy, q, face, colors, texture, top, z_top, *rest)
            num.index_add_(0, p, wc)                                        # this chunk's terms, added in place
            den.index_add_(0, p, w)
        return num, den

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_num, g_den):
        xy, q, colors, texture, face, tri, pixel, top, z_top = ctx.saved_tensors
        inputs = (xy, q, colors, texture)
        need = ctx.needs_input_grad[2:6]                                    # xy, q, colors, texture
        grads = [torch.zeros_like(x) if n else None for x, n in zip(inputs, need)]
        if any(need):
            with torch.enable_grad():
                # detached copies: the chunk's graph starts here and is freed after each chunk's grad
                xy_, q_, colors_, texture_ = (None if x is None else x.detach().requires_grad_(n)
                                              for x, n in zip(inputs, need))
                wrt = [x for x, n in zip((xy_, q_, colors_, texture_), need) if n]
                for lo in range(0, pixel.numel(), CHUNK):
                    p = pixel[lo:lo + CHUNK]
                    w, wc = _color_terms(tri[lo:lo + CHUNK], p, xy_, q_, face, colors_, texture_, top, z_top,
                                         *ctx.rest)
                    # d(sum)/d(term) is 1 at the term's pixel: each pair's gradient is its pixel's
                    part = iter(torch.autograd.grad((w, wc), wrt, (g_den.index_select(0, p),
                                                                   g_num.index_select(0, p))))
                    for i, n in enumerate(need):
                        if n:
                            grads[i] += next(part)
        # bg_num, bg_den: the sums start from them (gradient 1); nothing for the integers and constants
        return (g_num, g_den, *grads) + (None,) * 6


def _silhouette_terms(tri, pixel, xy, W, s, x_cut=None):
    """log(1 - D) of each pair: ``logsigmoid(-δ d² / σ_px)``; 0 (the pair dropped) where x < x_cut, if given."""
    x, _ = _pair_terms(xy, tri, pixel, W, s, bary=False)
    log_miss = torch.nn.functional.logsigmoid(-x)
    return log_miss if x_cut is None else torch.where(x.detach().double() >= x_cut, log_miss, 0.0)


def _color_terms(tri, pixel, xy, q, face, colors, texture, top, z_top, W, H, s, gamma, camera, depth, C):
    """Each pair's softmax weight ``D exp((z - z_top)/γ - top)`` (N,) and weighted colour (N, C); colors is
    (F, C) face colours or (T, 3, A) the screen triangles' corner attributes: vertex colours, or with a
    texture (Ht, Wt, C) the layout of ``_pair_colors``. top, z_top: (P,) per pixel. H: None for one image,
    the height of each for a batch (``_pair_terms``)."""
    x, b = _pair_terms(xy, tri, pixel, W, s, H=H)                           # (N,), 3 × (N,)
    qt = [q[:, k].index_select(0, tri) for k in range(3)]                   # 3 × (N,)
    z = _nearness(b[0] * qt[0] + b[1] * qt[1] + b[2] * qt[2], camera, depth)   # q is affine on screen
    w = torch.exp(torch.nn.functional.logsigmoid(x) + (z - z_top[pixel]) / gamma - top[pixel])   # <= ~1
    if colors.dim() == 2:
        c = colors[face[tri]]                                               # (N, C) flat colour
    else:
        pc = b if camera.orthographic else [bk * qk for bk, qk in zip(b, qt)]   # perspective-correct
        total = pc[0] + pc[1] + pc[2]
        c = sum((pc[k] / total)[:, None] * colors[:, k].index_select(0, tri) for k in range(3))   # (N, A)
        if texture is not None:
            c = _shade_pairs(c, texture, C)                                 # (N, C)
    return w, w[:, None] * c


def _shade_pairs(attr, texture, C):
    """(N, C) a textured pair's colour from its interpolated attributes (N, A) (``_pair_colors``' layout):
    the texture looked up at the pair's uv (bilinear, ``textures.sample_texture``), times the colour factor,
    plus the specular term, where given. As in SoftRas, the texture is read at each pixel's own
    perspective-correct barycentrics of each face it blends, clamped to the face outside it."""
    texel = sample_texture(texture, attr[:, :2])                            # (N, C)
    if attr.shape[1] >= 2 + C:
        texel = texel * attr[:, 2:2 + C]
    if attr.shape[1] == 2 + 2 * C:
        texel = texel + attr[:, 2 + C:]
    return texel
