"""Volume rendering: emission and absorption along camera rays through a voxel grid (lecture 15).

A ray ``o + s d`` (s in world units along a unit d) through a medium of density σ(x) (per unit length) and colour
c(x) collects

    C = ∫ T(s) σ(s) c(s) ds + T(far) · background,      T(s) = exp(-∫_0^s σ),

the light emitted at each point, dimmed by what lies in front of it. Two ways to evaluate it here:

* ``render_volume``: **NeRF's quadrature** (Mildenhall et al. 2020, after Max 1995): ``samples`` points per ray at
  the centres of equal steps δ through the grid's box, the fields looked up there (trilinear, or nearest), and
  ``C ≈ Σ_i T_i α_i c_i + T · background`` with ``α_i = 1 - exp(-σ_i δ)``, ``T_i = Π_{j<i} (1 - α_j)``: each step
  treated as a slab of constant density and colour. Differentiable in the grids and the camera.
* ``exact_volume``: the same integral **in closed form** where the fields are constant in each voxel (the
  ``nearest`` lookup): the ray is cut where it crosses the voxel walls, and in each piece of length ℓ with
  constant σ and c, the slab formula is exact: ``C = Σ_k T_k (1 - e^{-σ_k ℓ_k}) c_k``,
  ``T_k = exp(-Σ_{j<k} σ_j ℓ_j)``. The quadrature converges to it as the samples grow; lecture 15 measures how
  fast (about 1/samples: a step straddling a voxel wall takes one side's values for the whole step).

The grid: ``density`` (D, H, W) ≥ 0 and ``colors`` (D, H, W, 3) at the centres of D × H × W cells filling the box
``[lo, hi]`` (lo, hi (3,), world space; x along W, y along H, z along D); outside the box the medium is empty.
"""
from __future__ import annotations

import torch

from .tensors import _check_finite, as_tensor

__all__ = ["render_volume", "exact_volume", "ray_box", "sample_grid"]


def _check_grid(density, colors, lo, hi):
    sigma = as_tensor(density, name="density")
    if sigma.dim() != 3 or min(sigma.shape) < 1:
        raise ValueError(f"density must have shape (D, H, W), got {tuple(sigma.shape)}")
    c = as_tensor(colors, dtype=sigma.dtype, device=sigma.device, name="colors")
    if tuple(c.shape) != tuple(sigma.shape) + (3,):
        raise ValueError(f"colors must have shape {tuple(sigma.shape) + (3,)}, got {tuple(c.shape)}")
    _check_finite(sigma, "density")
    _check_finite(c, "colors")
    if bool((sigma.detach() < 0).any()):
        raise ValueError("density must be >= 0 (an absorption per unit length)")
    lo = as_tensor(lo, dtype=sigma.dtype, device=sigma.device, name="lo")
    hi = as_tensor(hi, dtype=sigma.dtype, device=sigma.device, name="hi")
    if lo.shape != (3,) or hi.shape != (3,) or not bool((hi > lo).all()):
        raise ValueError(f"the box must have lo < hi in every coordinate, got lo={lo.tolist()}, hi={hi.tolist()}")
    return sigma, c, lo, hi


def _rays(camera, dtype):
    origins, directions = camera.rays()
    origins, directions = origins.reshape(-1, 3).to(dtype), directions.reshape(-1, 3).to(dtype)
    return origins, directions / directions.norm(dim=1, keepdim=True)


def ray_box(origins, directions, lo, hi):
    """(s_in, s_out) (R,) where the rays enter and leave the box (the slab test; s_in >= 0, s_in >= s_out
    where a ray misses it)."""
    safe = torch.where(directions == 0, torch.full_like(directions, 1e-300), directions)
    a, b = (lo - origins) / safe, (hi - origins) / safe
    s_in = torch.minimum(a, b).amax(1).clamp_min(0)
    s_out = torch.maximum(a, b).amin(1)
    return s_in, s_out


def sample_grid(field, points, lo, hi, mode: str = "trilinear"):
    """The grid ``field`` (D, H, W, ...) at world ``points`` (P, 3): trilinear between cell centres (clamped at
    the box's faces) or the value of the cell the point lies in (``nearest``); 0 outside the box."""
    D, H, W = field.shape[:3]
    size = torch.tensor([W, H, D], dtype=points.dtype, device=points.device)
    u = (points - lo) / (hi - lo) * size                                      # cell coordinates, x y z
    inside = ((u >= 0) & (u <= size)).all(1)
    flat = field.reshape(D * H * W, -1)
    if mode == "nearest":
        cell = u.floor().long()
        cell = torch.minimum(cell.clamp_min(0), (size - 1).long())
        index = (cell[:, 2] * H + cell[:, 1]) * W + cell[:, 0]
        value = flat[index]
    elif mode == "trilinear":
        g = (u - 0.5).clamp_min(0)
        g = torch.minimum(g, size - 1)
        base = g.floor().long()
        base = torch.minimum(base, (size - 2).clamp_min(0).long())
        f = g - base
        value = 0
        for dz in (0, 1):
            for dy in (0, 1):
                for dx in (0, 1):
                    corner = base + torch.tensor([dx, dy, dz], device=points.device)
                    corner = torch.minimum(corner, (size - 1).long())
                    w = ((f[:, 0] if dx else 1 - f[:, 0]) * (f[:, 1] if dy else 1 - f[:, 1])
                         * (f[:, 2] if dz else 1 - f[:, 2]))
                    value = value + w[:, None] * flat[(corner[:, 2] * H + corner[:, 1]) * W + corner[:, 0]]
    else:
        raise ValueError(f"mode must be 'trilinear' or 'nearest', got {mode!r}")
    value = torch.where(inside[:, None], value, torch.zeros_like(value))
    return value.reshape((points.shape[0],) + field.shape[3:])


def render_volume(density, colors, lo, hi, camera, samples: int = 64, background=(0.0, 0.0, 0.0), *,
                  mode: str = "trilinear") -> torch.Tensor:
    """(H, W, 3) NeRF's quadrature of the emission-absorption integral (module docstring) along the camera's
    pixel-centre rays, ``samples`` equal steps through the box; the fields looked up ``trilinear`` or
    ``nearest``. Differentiable in density, colours, the box and the camera."""
    sigma, c, lo, hi = _check_grid(density, colors, lo, hi)
    n = int(samples)
    if n < 1:
        raise ValueError(f"samples must be a positive integer, got {samples!r}")
    o, d = _rays(camera, sigma.dtype)
    s_in, s_out = ray_box(o, d, lo, hi)
    length = (s_out - s_in).clamp_min(0)
    delta = length / n                                                        # (R,)
    mid = s_in[:, None] + (torch.arange(n, dtype=sigma.dtype) + 0.5)[None] * delta[:, None]   # (R, n)
    points = o[:, None] + mid[..., None] * d[:, None]
    s = sample_grid(sigma[..., None], points.reshape(-1, 3), lo, hi, mode).view(-1, n)
    col = sample_grid(c, points.reshape(-1, 3), lo, hi, mode).view(-1, n, 3)
    tau = s * delta[:, None]                                                  # each step's optical depth
    before = torch.exp(-torch.cumsum(torch.cat([torch.zeros_like(tau[:, :1]), tau[:, :-1]], 1), 1))
    image = ((before * -torch.expm1(-tau))[..., None] * col).sum(1)          # α = 1 - e^{-σδ}
    T = torch.exp(-tau.sum(1))
    bg = as_tensor(background, dtype=sigma.dtype, name="background")
    image = image + T[:, None] * bg
    return image.view(camera.height, camera.width, 3)


def exact_volume(density, colors, lo, hi, camera, background=(0.0, 0.0, 0.0)) -> torch.Tensor:
    """(H, W, 3) the emission-absorption integral in closed form for fields constant in each voxel (module
    docstring): each ray cut at every voxel wall it crosses, the slab formula exact in each piece."""
    sigma, c, lo, hi = _check_grid(density, colors, lo, hi)
    D, H, W = sigma.shape
    o, d = _rays(camera, sigma.dtype)
    s_in, s_out = ray_box(o, d, lo, hi)
    cuts = [s_in[:, None], s_out[:, None]]
    for axis, n in ((0, W), (1, H), (2, D)):                                  # every wall of every voxel
        walls = lo[axis] + (hi[axis] - lo[axis]) * torch.arange(n + 1, dtype=sigma.dtype) / n
        safe = torch.where(d[:, axis] == 0, torch.full_like(d[:, axis], 1e-300), d[:, axis])
        cuts.append((walls[None] - o[:, axis:axis + 1]) / safe[:, None])
    s = torch.cat(cuts, 1)
    s = torch.minimum(torch.maximum(s, s_in[:, None]), s_out[:, None].clamp_min(s_in[:, None]))
    s = s.sort(1).values                                                      # (R, K) the pieces' ends
    ell = s[:, 1:] - s[:, :-1]                                                # lengths (0 for repeated cuts)
    mid = 0.5 * (s[:, 1:] + s[:, :-1])
    points = o[:, None] + mid[..., None] * d[:, None]
    k = ell.shape[1]
    sig = sample_grid(sigma[..., None], points.reshape(-1, 3), lo, hi, "nearest").view(-1, k)
    col = sample_grid(c, points.reshape(-1, 3), lo, hi, "nearest").view(-1, k, 3)
    tau = sig * ell
    before = torch.exp(-torch.cumsum(torch.cat([torch.zeros_like(tau[:, :1]), tau[:, :-1]], 1), 1))
    image = ((before * (1 - torch.exp(-tau)))[..., None] * col).sum(1)
    T = torch.exp(-tau.sum(1))
    bg = as_tensor(background, dtype=sigma.dtype, name="background")
    image = image + T[:, None] * bg
    return image.view(camera.height, camera.width, 3)
