"""The penumbra's gradient by the estimators a student meets, against the exact one (lecture 14).

A receiving point x sees a polygonal light L partly hidden by occluders. Its form factor is an integral over the
light, ``F(x) = ∫_L V(x, y) k(x, y) dA(y)`` with the visibility V ∈ {0, 1} and the smooth kernel
``k = cos θ_x cos θ_L / (π r²)``. ``area.light_form_factor`` gives F and its gradient exactly. The estimators:

* **shadow rays, autograd only** (``shadow_ray_form_factor``): S points y_s on the light (uniform, moving with the
  light's vertices), ``F ≈ A / S Σ V(x, y_s) k(x, y_s)``, V traced with the course's BVH. Autograd
  differentiates k and the samples' positions, not V: the moving silhouette of an occluder, seen from x, sweeps
  over the light, and that is missed. Unbiased for F, biased for its gradient: exactly 0 with respect to the
  occluders (they enter through V alone).
* **shadow rays + edge sampling** (``edge_samples``): the missing term is an integral over the boundary of the
  hidden part of the light (Reynolds transport; Li et al. 2018 sample it the same way for the secondary
  visibility in redner): ``∫_∂ k(y) (V⁻ - V⁺) v_n(y) dl`` with v_n the boundary's normal velocity, V⁺ the
  visibility on the side the normal points to. Its candidates: the occluders' edges projected from x onto the
  light's plane and clipped to the light (a point y on such a segment, projected back, lies on the occluder
  edge); an edge that is not a silhouette there (the same visibility on both sides, tested by two shadow rays a
  hair apart) contributes 0. ``edge_samples`` points per receiver, chosen along the segments in proportion to
  their length. Unbiased for the gradient with respect to the occluders' vertices (the light held still: the
  samples on the light then do not move relative to it).
* **finite differences** (``penumbra_gradient(..., method="finite_differences")``): central differences of the
  shadow-ray estimate, every coordinate in turn, the same random numbers at both ends (else the noise of the
  two estimates swamps the difference): each sample near the boundary flips at most once, so the estimate is
  unbiased up to O(h²) but its variance grows like 1 / (h S).
* **the variance shadow map averaged over the light** (``vsm_form_factor``): the light replaced by directional
  lights from a grid of its points, each shadow a variance shadow map of lecture 12, the kernel evaluated at
  each grid point. Smooth (a gradient everywhere) and biased twice: parallel rays instead of rays converging to
  each point (a directional light casts an occluder-sized shadow; a light twice the occluder's height above the
  floor casts one twice that size), and Chebyshev's bound for the map's test.

``penumbra_scene`` builds the bench's scenes and ``penumbra_gradient`` runs any estimator on one.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from ..bvh import BVH
from ..mesh import Mesh
from ..raytrace import visible
from ..tensors import as_tensor
from .area import check_light, light_form_factor
from .gradients import _area_vector
from .prefiltered import moment_map, variance_visibility

__all__ = ["PenumbraScene", "penumbra_scene", "shadow_ray_form_factor", "vsm_form_factor", "penumbra_gradient",
           "METHODS"]

METHODS = ("exact", "shadow_rays", "edge_sampling", "finite_differences", "vsm")


@dataclass(frozen=True)
class PenumbraScene:
    """Receiving points on the floor y = 0 (normals up) under a square light, the occluders between, and fixed
    weights: the bench differentiates ``Σ weights · F(points)`` with respect to ``occluders.verts``."""
    points: torch.Tensor        # (N, 3)
    normals: torch.Tensor       # (N, 3)
    weights: torch.Tensor       # (N,)
    light: torch.Tensor         # (4, 3) counter-clockwise about -y: it shines down
    occluders: Mesh
    floor: Mesh                 # the receiver as a mesh (for the shadow map, which needs it in its map)


def _square(half, height, dtype=torch.float64):
    v = [[-half, height, -half], [half, height, -half], [half, height, half], [-half, height, half]]
    return torch.tensor(v, dtype=dtype)


def penumbra_scene(name: str = "square", n: int = 12) -> PenumbraScene:
    """``square``: a unit light 2 above the floor, a tilted, roughly square occluder (two triangles, not quite
    coplanar) 0.9 to 1.05 above it,
    its shadow's edge running through the receivers; ``overlap``: two triangles at heights 0.9 and 1.3 that
    overlap as seen from most receivers (each part of the light hidden once). The receivers: an n × n grid
    over the floor's penumbra (``[-1.2, 1.2]²``), weights in [0.5, 1.5] (fixed, seeded)."""
    light = _square(0.5, 2.0)
    if name == "square":
        verts = torch.tensor([[-0.45, 0.95, -0.5], [0.35, 1.05, -0.45], [0.4, 1.0, 0.35], [-0.5, 0.9, 0.4]],
                             dtype=torch.float64)
        faces = torch.tensor([[0, 1, 2], [0, 2, 3]])
    elif name == "overlap":
        verts = torch.tensor([[-0.7, 0.9, -0.6], [0.45, 0.9, -0.5], [-0.1, 0.9, 0.6],
                              [-0.35, 1.3, -0.45], [0.55, 1.3, -0.3], [0.15, 1.3, 0.55]], dtype=torch.float64)
        faces = torch.tensor([[0, 1, 2], [3, 4, 5]])
    else:
        raise ValueError(f"unknown penumbra scene {name!r}: 'square' or 'overlap'")
    g = torch.linspace(-1.2, 1.2, n, dtype=torch.float64) + 0.0123         # off the scene's symmetry
    xs, zs = torch.meshgrid(g, g, indexing="xy")
    points = torch.stack([xs.reshape(-1), torch.zeros(n * n, dtype=torch.float64), zs.reshape(-1)], 1)
    normals = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64).expand(n * n, 3).clone()
    weights = 0.5 + torch.rand(n * n, generator=torch.Generator().manual_seed(14), dtype=torch.float64)
    floor = Mesh(torch.tensor([[-1.5, 0, -1.5], [1.5, 0, -1.5], [1.5, 0, 1.5], [-1.5, 0, 1.5]], dtype=torch.float64),
                 torch.tensor([[0, 2, 1], [0, 3, 2]]))
    return PenumbraScene(points, normals, weights, light, Mesh(verts, faces), floor)


def _kernel(x, n, y, n_L):
    """k(x, y) = cos θ_x cos θ_L / (π r²), 0 where y is behind x's tangent plane or x behind the light.
    x, n (N, 1, 3) or (N, 3); y (..., 3)."""
    r = y - x
    r2 = (r * r).sum(-1)
    cos_x = ((r * n).sum(-1)).clamp_min(0)
    cos_l = (-(r * n_L).sum(-1)).clamp_min(0)
    return cos_x * cos_l / (math.pi * r2 * r2)


def _light_samples(L, N, S, generator):
    """(N, S, 3) uniform points on the convex light L (K, 3): a fan triangle chosen in proportion to its area,
    then a uniform point in it; they move with L's vertices (autograd reaches them). Also L's area."""
    K = L.shape[0]
    a = L[0].expand(K - 2, 3)
    b, c = L[1:-1], L[2:]
    areas = 0.5 * torch.linalg.cross(b - a, c - a, dim=1).norm(dim=1)
    tri = torch.multinomial((areas / areas.sum()).detach(), N * S, replacement=True, generator=generator)
    u = torch.rand(N * S, 2, generator=generator, dtype=L.dtype)
    flip = u.sum(1) > 1
    u = torch.where(flip[:, None], 1 - u, u)                                # fold the square onto the triangle
    y = a[tri] + u[:, :1] * (b[tri] - a[tri]) + u[:, 1:] * (c[tri] - a[tri])
    return y.view(N, S, 3), areas.sum()


def _unit_normal(L):
    area = _area_vector(L)
    return area / area.norm()


def _visibility(x, y, bvh, offset):
    """(N, S) 0/1: can x (N, 3) see y (N, S, 3) past the mesh of ``bvh``? Rays traced with the course's BVH."""
    N, S, _ = y.shape
    free = visible(x.detach().repeat_interleave(S, 0), y.detach().reshape(-1, 3), bvh, offset=offset)
    return free.view(N, S).to(x.dtype)


def _check_points(points, normals):
    X = as_tensor(points, name="points").double()
    Nrm = as_tensor(normals, name="normals").double()
    if X.dim() != 2 or X.shape[1] != 3 or Nrm.shape != X.shape:
        raise ValueError(f"points and normals must both have shape (N, 3), got {tuple(X.shape)} and "
                         f"{tuple(Nrm.shape)}")
    return X, Nrm / Nrm.norm(dim=1, keepdim=True)


def shadow_ray_form_factor(points, normals, light, occluders, samples: int = 64, *, seed: int = 0,
                           edge_samples: int = 0, offset: float = 1e-9) -> torch.Tensor:
    """(N,) the form factor estimated by ``samples`` shadow rays a point (module docstring), differentiable by
    autograd in the points, normals and light (the kernel and the samples' positions; not the visibility).
    With ``edge_samples`` > 0 the boundary term is added: its value is 0 (the estimate is unchanged) and its
    gradient is the sweep of the occluders' silhouettes over the light, with respect to the occluders'
    vertices and the points (the light held still). float64."""
    X, Nrm = _check_points(points, normals)
    L = check_light(light).double()
    if int(samples) < 1:
        raise ValueError(f"samples must be a positive integer, got {samples!r}")
    n_L = _unit_normal(L)
    g = torch.Generator().manual_seed(int(seed))
    y, area = _light_samples(L, X.shape[0], int(samples), g)
    k = _kernel(X[:, None], Nrm[:, None], y, n_L)
    if occluders is None:
        V = torch.ones_like(k)
    else:
        bvh = BVH(Mesh(occluders.verts.detach().double(), occluders.faces))
        V = _visibility(X, y, bvh, offset)
    F = area * (V * k).mean(1)
    if edge_samples and occluders is not None:
        F = F + _edge_term(X, Nrm, L, n_L, occluders, int(edge_samples), g, offset)
    return F


def _edge_term(X, Nrm, L, n_L, occluders, M, g, offset):
    """(N,) zero-valued, whose gradient is the boundary term (module docstring): for each receiver, M points
    on the occluders' edges projected onto the light, each weighted by k (V⁻ - V⁺) × (total length) / M times
    the normal velocity of its segment, which autograd takes from the projection."""
    verts = occluders.verts.double()
    faces = occluders.faces
    ends = torch.cat([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])   # every triangle's edges
    ends = torch.unique(torch.sort(ends, 1).values, dim=0)                  # (E, 2), a shared edge once
    a, b = verts[ends[:, 0]], verts[ends[:, 1]]                             # (E, 3)
    N, E = X.shape[0], a.shape[0]
    d_x = ((X - L[0]) @ n_L)[:, None]                                       # (N, 1) heights above the light
    h_a, h_b = (a - L[0]) @ n_L, (b - L[0]) @ n_L                           # (E,)
    between = ((h_a > 0) & (h_b > 0))[None] & (h_a[None] < d_x) & (h_b[None] < d_x)   # (N, E)
    den_a = torch.where(between, d_x - h_a[None], torch.ones_like(d_x - h_a[None]))
    den_b = torch.where(between, d_x - h_b[None], torch.ones_like(d_x - h_b[None]))
    qa = X[:, None] + (a[None] - X[:, None]) * (d_x / den_a)[..., None]     # (N, E, 3) on the light's plane
    qb = X[:, None] + (b[None] - X[:, None]) * (d_x / den_b)[..., None]
    # clip each segment qa + τ (qb - qa) to the light: τ in [lo, hi] inside every edge's half-plane
    lo = torch.zeros(N, E, dtype=X.dtype)
    hi = torch.where(between, torch.ones_like(lo), torch.zeros_like(lo))
    K = L.shape[0]
    for i in range(K):
        inward = torch.linalg.cross(n_L, L[(i + 1) % K] - L[i], dim=0)     # into the light
        s0 = ((qa.detach() - L[i]) * inward).sum(-1)
        s1 = ((qb.detach() - L[i]) * inward).sum(-1)
        ds = s1 - s0
        t = -s0 / torch.where(ds != 0, ds, torch.ones_like(ds))
        lo = torch.where(ds > 0, torch.maximum(lo, t), lo)
        hi = torch.where(ds < 0, torch.minimum(hi, t), hi)
        hi = torch.where((ds == 0) & (s0 < 0), torch.zeros_like(hi), hi)   # parallel and outside
    seg = (qb - qa).detach()
    length = (hi - lo).clamp_min(0) * seg.norm(dim=-1)                      # (N, E)
    total = length.sum(1)                                                   # (N,)
    has = total > 0
    weights = torch.where(has[:, None], length, torch.ones_like(length))
    pick = torch.multinomial(weights, M, replacement=True, generator=g)     # (N, M) which segment
    tau = lo.gather(1, pick) + torch.rand(N, M, generator=g, dtype=X.dtype) * (hi - lo).gather(1, pick)
    qa_s = qa.gather(1, pick[..., None].expand(N, M, 3))
    qb_s = qb.gather(1, pick[..., None].expand(N, M, 3))
    y = qa_s + tau[..., None] * (qb_s - qa_s)                               # (N, M, 3), moves with the occluder
    direction = (qb_s - qa_s).detach()
    normal = torch.linalg.cross(n_L.expand_as(direction), direction, dim=-1)
    normal = normal / normal.norm(dim=-1, keepdim=True).clamp_min(1e-300)   # in the plane, across the segment
    eps = 1e-7 * float((L - L.mean(0)).norm(dim=1).max())
    bvh = BVH(Mesh(verts.detach(), faces))
    y0 = y.detach()
    plus = _visibility(X, y0 + eps * normal, bvh, offset)
    minus = _visibility(X, y0 - eps * normal, bvh, offset)
    k = _kernel(X[:, None].detach(), Nrm[:, None].detach(), y0, n_L.detach())
    w = (k * (minus - plus) * (total / M)[:, None]).where(has[:, None], torch.zeros_like(k))
    surrogate = (w * (y * normal).sum(-1)).sum(1)                           # ∂/∂θ: Σ w v_n
    return surrogate - surrogate.detach()


def vsm_form_factor(points, normals, light, occluders, receiver: Mesh, *, grid: int = 3, resolution: int = 64,
                    blur: float = 1.0, sigma: float = 0.5) -> torch.Tensor:
    """(N,) the form factor with the light replaced by ``grid``² directional lights from the centres of a grid
    of cells on the light (module docstring), each one's shadow a variance shadow map (lecture 12's
    ``moment_map``) of the occluders and ``receiver`` (a map needs its receivers in it), and the kernel taken
    at each cell's centre: ``F ≈ A / grid² Σ p_j k(x, y_j)``. Differentiable in everything; biased."""
    X, Nrm = _check_points(points, normals)
    L = check_light(light).double()
    if L.shape[0] != 4:
        raise ValueError("vsm_form_factor takes a quadrilateral light (its grid of cells)")
    n_L = _unit_normal(L)
    verts = torch.cat([occluders.verts.double(), receiver.verts.double()])
    faces = torch.cat([occluders.faces, receiver.faces + occluders.verts.shape[0]])
    scene = Mesh(verts, faces)
    centre = occluders.verts.double().mean(0)                              # aimed through the occluders: their
                                                                            # shadow lands where this point's would
                                                                            # (the aim is part of the function:
                                                                            # differentiated with it)
    cells = (torch.arange(grid, dtype=torch.float64) + 0.5) / grid
    area = _area_vector(L).norm()
    F = X.new_zeros(X.shape[0])
    for u in cells:
        for v in cells:
            y = (1 - u) * (1 - v) * L[0] + u * (1 - v) * L[1] + u * v * L[2] + (1 - u) * v * L[3]
            direction = centre - y                                          # the way this light travels
            moments, to_ls = moment_map(scene, direction, resolution, sigma=sigma, blur=blur,
                                        region=occluders.verts)        # the texels spent on the occluders
            coords, depth = to_ls(X)
            p = variance_visibility(moments, coords, depth)
            F = F + p * _kernel(X, Nrm, y, n_L)
    return F * area / grid ** 2


def penumbra_gradient(scene: PenumbraScene, method: str = "exact", *, samples: int = 64, seed: int = 0,
                      step: float = 1e-3, edge_samples: int = 64, grid: int = 3, resolution: int = 64,
                      blur: float = 1.0) -> torch.Tensor:
    """The gradient of ``Σ weights · F(points)`` with respect to ``scene.occluders.verts`` (V, 3) by ``method``:
    ``exact`` (autograd through ``light_form_factor``), ``shadow_rays`` (``samples`` rays a point, autograd
    only: 0), ``edge_sampling`` (the same plus ``edge_samples`` boundary points a receiver), ``finite_differences``
    (central, step ``step``, the shadow-ray estimate with the same ``seed`` at both ends) or ``vsm``
    (``vsm_form_factor`` with ``grid``, ``resolution`` and ``blur``)."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    occ = scene.occluders
    if method == "finite_differences":
        base = occ.verts.detach().double()
        grad = torch.zeros_like(base)
        for i in range(base.shape[0]):
            for j in range(3):
                ends = []
                for sign in (1.0, -1.0):
                    moved = base.clone()
                    moved[i, j] += sign * step
                    F = shadow_ray_form_factor(scene.points, scene.normals, scene.light, Mesh(moved, occ.faces),
                                               samples, seed=seed)
                    ends.append(float((scene.weights * F).sum()))
                grad[i, j] = (ends[0] - ends[1]) / (2 * step)
        return grad
    verts = occ.verts.detach().double().clone().requires_grad_()
    mesh = Mesh(verts, occ.faces)
    if method == "exact":
        F = light_form_factor(scene.points, scene.normals, scene.light, mesh)
    elif method == "vsm":
        F = vsm_form_factor(scene.points, scene.normals, scene.light, mesh, scene.floor, grid=grid,
                            resolution=resolution, blur=blur)
    else:
        F = shadow_ray_form_factor(scene.points, scene.normals, scene.light, mesh, samples, seed=seed,
                                   edge_samples=edge_samples if method == "edge_sampling" else 0)
    if not F.requires_grad:
        return torch.zeros_like(verts.detach())                             # the occluders enter through V alone
    grad, = torch.autograd.grad((scene.weights * F).sum(), verts, allow_unused=True)
    return torch.zeros_like(verts.detach()) if grad is None else grad
