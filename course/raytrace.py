"""Ray tracing: ray–triangle tests, a BVH, ``raycast`` → Fragments, shadow rays and area lights (lecture 07).

Rasterization asks "which pixels does this triangle cover?"; ray tracing asks the transposed question,
"which triangle does this ray hit first?". Both answer with the same ``Fragments``, so every shader works on
both, and ``raycast`` takes its barycentrics and depth from the very function ``rasterize`` uses
(``raster._visible_surface``): the two visibility stages hand identical, differentiable inputs to shading.

The pieces live in three modules, one question each: ``course.intersect`` (does this ray hit this triangle,
this box?), ``course.bvh`` (which of a million triangles can this ray hit?) and this one (rays from a
camera and to a light). The names of the first two are imported here, so ``raytrace.intersect_triangles``
and ``raytrace.BVH`` work as well.

**Primary rays.** ``raycast`` shoots one ray per pixel centre through ``BVH.intersect`` and builds the same
``Fragments`` as ``rasterize``. **Shadow rays.** ``visible`` asks whether the segment from each point to a
light is free (any hit); area lights are sampled by ``rectangle_light_samples`` and ``disk_light_samples``
(stratified) and give soft shadows.
"""
from __future__ import annotations

import math

import torch

from . import kernels
from .bvh import BVH, Hits, morton_codes
from .intersect import _slab, _watertight, intersect_triangles, moller_trumbore, ray_box  # noqa: F401 (re-exported)
from .camera import Camera
from .mesh import Mesh
from .raster import Fragments, _check_inputs, _surface_scale, _visible_surface
from .tensors import _check_count, _check_finite, _check_flag, _check_real, _check_shape, as_tensor, unit

__all__ = ["intersect_triangles", "moller_trumbore", "ray_box", "morton_codes", "BVH", "Hits", "raycast", "visible",
           "rectangle_light_samples", "disk_light_samples"]


# --------------------------------------------------------------------------------- raycast → Fragments

def _camera_rays(camera):
    """One world-space ray per pixel centre, float64: origins (H*W, 3), directions (H*W, 3) and the
    directions' camera-space z (H*W,), so that ``t = depth / d_z`` (row-major pixels)."""
    H, W = camera.height, camera.width
    K, R, t = (camera.K.detach().double(), camera.R.detach().double(), camera.t.detach().double())
    dev = K.device
    y, x = torch.meshgrid(torch.arange(H, dtype=torch.float64, device=dev) + 0.5,
                          torch.arange(W, dtype=torch.float64, device=dev) + 0.5, indexing="ij")
    q = torch.stack([x.reshape(-1) - K[0, 2], y.reshape(-1) - K[1, 2],
                     torch.full((H * W,), 1.0, dtype=torch.float64, device=dev) - K[2, 2]], 1)
    e3 = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64, device=dev)
    cam = q @ torch.linalg.inv(K).T + e3                                    # K⁻¹ p, the offset formed first
    eye = -(R.T @ t)
    if camera.orthographic:                                                 # parallel rays along camera +z
        o_cam = torch.cat([cam[:, :2], torch.zeros_like(cam[:, :1])], 1)
        d_cam = e3.expand(H * W, 3)
        return o_cam @ R + eye, d_cam @ R, d_cam[:, 2]
    return eye.expand(H * W, 3), cam @ R, cam[:, 2]


def _tile_order(H, W, device, tile: int = 4):
    """Row-major pixel indices (H*W,) reordered tile by tile (``tile`` x ``tile`` tiles, row-major inside):
    16 consecutive rays then form one tile, a coherent packet for ``BVH.intersect``."""
    p = torch.arange(H * W, device=device)
    i, j = p // W, p % W
    key = ((i // tile) * ((W + tile - 1) // tile) + j // tile) * tile * tile + (i % tile) * tile + j % tile
    return torch.argsort(key)


def raycast(mesh, camera, *, bvh: BVH | None = None) -> Fragments:
    """Ray-cast a triangle mesh: the same ``Fragments`` as ``rasterize``, found by tracing rays.

    mesh: anything with ``verts`` (V, 3) and ``faces`` (F, 3); camera: a ``Camera`` (perspective or
    orthographic). bvh: a ``BVH`` of this mesh to reuse (built when None). One ray per pixel centre
    (j + 0.5, i + 0.5), traced in float64 (as ``rasterize`` decides coverage in float64), between the near
    and far planes: a ray whose direction has camera-space z component d_z runs over t in
    [near / d_z, far / d_z], so exactly the points with depth in [near, far] count. The BVH picks the visible
    face: the least t, compared exactly in float64, exact ties in t to the lower face id. That is the face
    nearest in float64, which ``rasterize`` also returns (its float32 z-buffer keys re-decide near-ties in
    float64), so the two agree on surfaces closer than float32 can tell apart (3.3e-8 in relative depth, and
    down to about 1e-12). Below that ``rasterize`` calls the depths a tie (lower face id), while here the
    rounding of t decides: on coplanar overlapping faces the two (and ``coverage.exact_coverage``, whose
    coplanarity tolerance is ~2e-9) may show different faces. The barycentrics and depth come from
    ``raster._visible_surface``, exactly as in ``rasterize``, so they are differentiable w.r.t. ``mesh.verts`` and
    K, R, t. Returns Fragments (H, W).

    Scale: a scene whose camera-space coordinates lie beyond 2^±32 (1e150 or 1e-150 units: the ray-triangle
    test's triple products would overflow or underflow float64) is traced scaled by a power of two, exactly,
    with a BVH built for it (a ``bvh`` passed in is then not used); the faces found are those of the scene.
    """
    verts, faces = _check_inputs(mesh, camera)
    H, W = camera.height, camera.width
    if bvh is not None and (not isinstance(bvh, BVH) or bvh.order.numel() != faces.shape[0]):
        raise ValueError("bvh must be a BVH built from this mesh")
    s = _surface_scale(None, verts, faces, camera)
    rays_of = camera
    if s != 1.0:                                                            # the whole scene by a power of two
        K = camera.K.detach().clone()
        if camera.orthographic:
            K[:2, :2] /= s                                                  # pixels per (scaled) world unit
        rays_of = Camera(K, camera.R.detach(), camera.t.detach() * s, W, H, camera.near * s, camera.far * s,
                         camera.orthographic)
        bvh = BVH(Mesh(verts.detach() * s, faces))
    elif bvh is None:
        bvh = BVH(mesh)
    o, d, dz = _camera_rays(rays_of)
    tiles = None if kernels.active(o, bvh.boxes) else _tile_order(H, W, o.device)   # 4 x 4 tiles: packets
    if tiles is not None:                                                   # (the compiled walk needs none)
        o, d, dz = o.index_select(0, tiles), d.index_select(0, tiles), dz.index_select(0, tiles)
    with torch.no_grad():                                                   # which face: not differentiable
        hit = bvh.intersect(o.to(bvh.device), d.to(bvh.device), t_min=(rays_of.near / dz).to(bvh.device),
                            t_max=(rays_of.far / dz).to(bvh.device)).face_id.to(verts.device)
    face = hit if tiles is None else torch.empty_like(hit).index_put_((tiles.to(verts.device),), hit)
    bary, depth = _visible_surface(face, verts, faces, camera, H, W)       # as rasterize: same numbers
    return Fragments(face.view(H, W), bary, depth)


# ------------------------------------------------------------------------------- shadow rays, area lights

def visible(points, light, bvh: BVH, *, directional: bool = False, offset: float | None = None,
            normals=None) -> torch.Tensor:
    """Shadow rays: can each point see the light?

    points: (N, 3) world space. light: a point light's position (3,) or (N, 3) (``PointLight.position``);
    with ``directional=True`` the direction the light *travels* (3,) or (N, 3) (``DirectionalLight.direction``;
    the shadow ray goes the other way, to infinity); or (N, S, 3) sample positions on an area light (see
    ``rectangle_light_samples``, ``disk_light_samples``). bvh: the BVH of the occluding mesh.
    Returns (N,) bool, True where nothing blocks the segment to the light, or for (N, S, 3) samples the
    fraction (N,) of samples visible, in [0, 1] (a soft shadow).

    Self-intersection: a point on a surface, rounded, lies a little above or below it, and its shadow ray could
    hit its own triangle. ``offset`` (world units; default 1e-4 times the diagonal of the BVH's bounds, far
    above float32 rounding of the scene's coordinates and far below its features) guards against it:

    * without ``normals``, each ray starts at the point and ignores hits closer than ``offset`` along the ray
      (and closer than ``offset`` to the light): t_min = offset. Needs nothing but the points; a surface
      point with the light behind its own surface is *not* shadowed by that surface (shade it with n · l).
    * with ``normals`` (N, 3), the geometric normals of the points' faces (the side they are seen from),
      each ray starts ``offset`` above the surface along its normal: a light behind the surface is then
      shadowed by it, as it should be; at grazing light the offset origin still clears the own triangle.
      A zero normal (a degenerate face) falls back to the first way for that point.

    Raises ValueError for NaN / inf points, lights or normals, a zero direction with ``directional=True``
    (a light travelling nowhere), a negative or non-numeric offset, or shapes that do not match.
    """
    if not isinstance(bvh, BVH):
        raise TypeError(f"bvh must be a BVH, got {type(bvh).__name__}")
    directional = _check_flag(directional, "directional")
    p = as_tensor(points, name="points")
    dtype = torch.promote_types(p.dtype, bvh.dtype)
    p = p.to(dtype=dtype, device=bvh.device)
    _check_shape(p, (None, 3), "points")
    N = p.shape[0]
    L = as_tensor(light, dtype=dtype, device=bvh.device, name="light")
    area = L.dim() == 3
    if L.shape == (3,):
        L = L.expand(N, 3)
    if not (L.shape == (N, 3) or (area and L.shape[0] == N and L.shape[2] == 3 and not directional)):
        raise ValueError(f"light must have shape (3,), (N, 3) or, for area-light samples, (N, S, 3) with "
                         f"N = {N}, got {tuple(L.shape)}")
    _check_finite(L, "light")
    if directional and bool((L.detach().abs().amax(-1) == 0).any()):
        raise ValueError("light must be a non-zero direction with directional=True (the way the light travels), "
                         "got a zero vector")
    if offset is None:
        diag = float((bvh.bounds[1] - bvh.bounds[0]).norm()) if bvh.num_nodes else 0.0
        offset = 1e-4 * diag if diag > 0 else 1e-4
    offset = _check_real(offset, "offset", low=0)
    S = L.shape[1] if area else 1
    L = L.reshape(N * S, 3)
    o = p.repeat_interleave(S, 0)
    if normals is not None:
        n = as_tensor(normals, dtype=dtype, device=bvh.device, name="normals")
        if n.shape != (N, 3):
            raise ValueError(f"normals must have shape (N, 3) with N = {N}, got {tuple(n.shape)}")
        _check_finite(n, "normals")
        flat = (n == 0).all(1, keepdim=True)                                # no normal: t_min = offset instead
        zero = flat.repeat_interleave(S, 0)[:, 0]
        n = torch.where(flat, torch.zeros_like(n), unit(torch.where(flat, torch.ones_like(n), n)))   # any length
        o = o + offset * n.repeat_interleave(S, 0)
    if directional:
        d = -unit(L)                                                        # any length: 1e-200 and 1e200 too
        t_lo, t_hi = torch.full((N * S,), offset, dtype=dtype, device=o.device), math.inf
    else:
        d = L - o                                                           # t = 1 at the light
        dist = d.norm(dim=1)
        safe = dist.clamp_min(torch.finfo(dtype).tiny)
        t_lo, t_hi = offset / safe, 1 - offset / safe
    if normals is not None:
        t_lo = torch.where(zero, t_lo, torch.zeros_like(t_lo))
    blocked = bvh.intersect(o, d, t_min=t_lo, t_max=t_hi, any_hit=True).hit
    free = ~blocked
    if area:
        return free.view(N, S).to(dtype).mean(1)
    return free


def _generator(seed, generator, device):
    if generator is not None:
        return generator
    return torch.Generator(device=device).manual_seed(int(seed))


def _stratified(n_points, grid, dtype, device, seed, generator):
    """(N, grid², 2) jittered samples in [0, 1)²: one uniform sample in each of grid × grid cells, per point."""
    n_points = _check_count(n_points, "n_points", minimum=0)
    grid = _check_count(grid, "grid")
    if generator is not None and not isinstance(generator, torch.Generator):
        raise TypeError(f"generator must be a torch.Generator or None, got {type(generator).__name__}")
    if generator is None:
        seed = _check_count(seed, "seed", minimum=0)
    g = _generator(seed, generator, device)
    cells = torch.arange(grid, dtype=dtype, device=device)
    i, j = torch.meshgrid(cells, cells, indexing="ij")
    base = torch.stack([i.reshape(-1), j.reshape(-1)], 1)                  # (S, 2) cell corners
    jitter = torch.rand((n_points, grid * grid, 2), generator=g, dtype=dtype, device=device)
    return (base + jitter) / grid


def rectangle_light_samples(corner, edge1, edge2, n_points: int, grid: int = 4, *, seed: int = 0,
                            generator: torch.Generator | None = None) -> torch.Tensor:
    """Stratified points on a rectangular area light, a fresh jittered set for each shaded point.

    corner, edge1, edge2: (3,) the rectangle ``corner + u edge1 + v edge2``, u, v in [0, 1]. n_points: N.
    grid: samples per side (S = grid² strata, one jittered sample each). seed / generator: the randomness
    (a ``torch.Generator`` wins over ``seed``). Returns (N, S, 3), for ``visible(points, samples, bvh)``.
    """
    c = as_tensor(corner, name="corner")
    e1 = as_tensor(edge1, dtype=c.dtype, device=c.device, name="edge1")
    e2 = as_tensor(edge2, dtype=c.dtype, device=c.device, name="edge2")
    for v, name in ((c, "corner"), (e1, "edge1"), (e2, "edge2")):
        _check_shape(v, (3,), name)
    if float(torch.linalg.cross(e1, e2).detach().norm()) == 0:
        raise ValueError("edge1 and edge2 must span a rectangle: they are parallel (or one is zero)")
    uv = _stratified(n_points, grid, c.dtype, c.device, seed, generator)
    return c + uv[..., :1] * e1 + uv[..., 1:] * e2


def disk_light_samples(centre, normal, radius: float, n_points: int, grid: int = 4, *, seed: int = 0,
                       generator: torch.Generator | None = None) -> torch.Tensor:
    """Stratified points on a disk light (centre (3,), normal (3,), radius), N sets of S = grid² samples.

    The strata of the unit square are carried to the disk by Shirley and Chiu's concentric map, which keeps
    them of equal area and compact (a polar map would make slivers). Returns (N, S, 3).
    """
    c = as_tensor(centre, name="centre")
    n = as_tensor(normal, dtype=c.dtype, device=c.device, name="normal")
    _check_shape(c, (3,), "centre"), _check_shape(n, (3,), "normal")
    if float(n.detach().norm()) == 0:
        raise ValueError("normal must be a non-zero vector")
    radius = _check_real(radius, "radius", low=0, low_open=True)
    n = n / n.norm()
    helper = torch.zeros_like(n)
    helper[int(n.abs().argmin())] = 1.0                                     # an axis far from the normal
    a = torch.linalg.cross(n, helper)
    a = a / a.norm()
    b = torch.linalg.cross(n, a)
    uv = 2 * _stratified(n_points, grid, c.dtype, c.device, seed, generator) - 1   # (N, S, 2) in [-1, 1)²
    x, y = uv[..., 0], uv[..., 1]
    wide = x.abs() > y.abs()
    r = torch.where(wide, x, y)
    safe = torch.where(r == 0, torch.ones_like(r), r)
    phi = torch.where(wide, (math.pi / 4) * y / safe, math.pi / 2 - (math.pi / 4) * x / safe)
    r = r * float(radius)
    return c + (r * torch.cos(phi))[..., None] * a + (r * torch.sin(phi))[..., None] * b
