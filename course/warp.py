"""Reparameterizing the discontinuities: the third cure for the visibility term (lecture 09).

A pixel's value is ``I(π) = ∫_A f(x, π) dx`` over its unit square A, and f jumps where one face meets another
or the background; the jumps move with π, so the derivative cannot be taken under the integral. Change the
variable: ``x = T(y, π)`` with T the identity at the current π and moving the points of A along with the
jumps. Then ``f(T(y, π), π)`` jumps at fixed y, and

    I(π) = ∫_A f(T(y, π), π) |det ∂T/∂y| dy,   dI/dπ = ∫_A ∂f/∂π + ∇f · V + f ∇·V dy = ∫_A ∂f/∂π + ∇·(f V) dy,

with ``V = ∂T/∂π``, the warp's velocity field: differentiated under the integral, by Monte Carlo samples y and
autograd. Two conditions make T a change of variables of A that removes the motion of the jumps:

* on every curve where f jumps, V's normal part is the curve's normal speed v_n;
* on the pixel's border (its own, fixed, discontinuity: the box filter) V is 0, so A maps onto A.

In between V must be continuous (its divergence is then an ordinary function, integrable). Given such a V,
the estimator is unbiased: over a region of one colour c, ``∫ c ∇·V = c ∮ V · n`` (divergence theorem), which on
the jumps is ``c v_n`` and on the pixel's border 0; summed over the regions this is the Reynolds boundary term.

The warp here (``warp="harmonic"``, Bangaru, Li and Durand's warped-area sampling, SIGGRAPH Asia 2020, in
its simplest form): inside a pixel, V is an inverse-distance blend of what each piece of jump curve j in
that pixel does,

    V(y) = Σ_j ω_j(y) δ_j(y) / (Σ_j ω_j(y) + Σ_sides ω_s(y) + ω_0),   ω = 1 / distance²,  ω_0 = 1 / kernel²,

with δ_j(y) the velocity of the point of piece j nearest y (on a face edge: the edge's ends' velocities
interpolated, so two edges meeting at a vertex agree there; on an intersection line: v_n along its normal),
the four sides of the pixel held still (V = 0 on them), and ``kernel`` (pixels) how far from the jumps the
warp reaches before the constant ω_0 takes over. Every choice of ``kernel`` gives the same mean; it moves
the variance. V is discontinuous only at isolated points (where a jump curve meets the pixel's border, or
two curves that move differently meet: an occluding edge over an occluded one), where ∇·V grows like 1/r:
integrable, and the variance of the estimator lives there.

``warp="nearest"`` follows only the nearest piece (δ of the one nearest piece, same weights): the one
"dominant discontinuity" of Loubet, Holzschuch and Jakob's estimator (SIGGRAPH Asia 2019), on the image
plane. Where two pieces share a pixel, V jumps along the line halfway between them, ∇·V misses that jump, and
the estimate is biased; the bias shrinks with ``kernel`` (each piece's warp dies out within it). It is here
to measure that bias; the harmonic warp is the method.

Why the harmonic warp and not a per-sample translation: the box filter's border is a discontinuity of the
integrand that never moves, so the warp must vanish there; a translation of a kernel around each sample
(Loubet et al.'s construction) does not, and is biased near every pixel border, whatever its kernel size;
the blend above vanishes on the border by construction and is continuous elsewhere, so it is unbiased and
can be tested against the exact gradient with a derived statistical tolerance (``tests/test_warp.py``).

Samples (``samples`` per pixel, stratified: ``_stratified``, seeded): flat colours are constant inside a face, so
``∂f/∂π = ∇f = 0`` and only ``f ∇·V`` remains, 0 in a pixel with no jump: only pixels that hold a piece of
jump curve are sampled. With screen-affine vertex colours (``model="affine"``) every pixel is sampled (the
colour also changes under fixed pieces). ``f`` is taken relative to the background (``∫_A ∇·V = 0``, so a
constant shift changes nothing but the variance). The derivative w.r.t. the colours is linear and exact
(as for the boundary methods). Everything is computed in float64, as ``boundary_gradient``.
"""
from __future__ import annotations

import math

import torch

from .boundary import _visible_at, boundary_pieces, normal_shift
from .coverage_affine import _Field

__all__ = ["warp_gradient", "warp_field", "WARPS"]

WARPS = ("harmonic", "nearest")
TINY = 1e-12             # pixels: distances are clamped here (a sample exactly on a curve or a side)


def _sides(u):
    """Weights ω = 1/d² of the pixel's four sides at points u (N, 2) relative to its corner, and their
    gradients: (N,), (N, 2)."""
    d = torch.cat([u, 1 - u], 1).clamp_min(TINY)                           # left, top, right, bottom
    w = d ** -2
    dw = -2 * d ** -3 * torch.tensor([1.0, 1.0, -1.0, -1.0], dtype=u.dtype, device=u.device)   # d/du of each
    return w.sum(1), torch.stack([dw[:, 0] + dw[:, 2], dw[:, 1] + dw[:, 3]], 1)


def _stratified(pixels, samples, generator):
    """(pixels × samples, 2) points in the unit square, each pixel's ``samples`` in distinct cells of a k × k
    grid (k = ⌈√samples⌉, the cells drawn at random), uniform in its cell: each point is uniform on the
    square (unbiased), and together they spread out (less variance than independent points)."""
    k = math.isqrt(samples - 1) + 1
    cells = torch.rand(pixels, k * k, generator=generator, dtype=torch.float64).argsort(1)[:, :samples].reshape(-1)
    cell = torch.stack([cells % k, torch.div(cells, k, rounding_mode="floor")], 1).double()
    return (cell + torch.rand(cells.numel(), 2, dtype=torch.float64, generator=generator)) / k


def warp_field(y, pixel, width, a, b, s0, s1, piece_pixel, velocity, divergence, kernel=1.0, warp="harmonic"):
    """The warp V at points y (N, 2) of pixels ``pixel`` (N,) and its divergence ∇·V, (N, 2) and (N,).

    The pieces of jump curve: segments of the lines a → b (P, 2) between the fractions s0 and s1 (P,), in
    pixels ``piece_pixel`` (P,). ``velocity(j, s)`` gives the velocity (M, 2) of the points at fractions s (M,) of
    pieces j (M,); ``divergence(j, grad_s)`` the divergence of that velocity field, given ∇s (M, 2) (the nearest
    point's fraction moves with y). Autograd flows through them: V is what they make it (module docstring)."""
    N = y.shape[0]
    corner = torch.stack([pixel % width, torch.div(pixel, width, rounding_mode="floor")], 1).to(y.dtype)
    wsum, dwsum = _sides(y - corner)
    if kernel is not None:
        wsum = wsum + kernel ** -2
    # the pairs (point, piece) of one pixel
    order = torch.argsort(piece_pixel, stable=True)
    keys = piece_pixel[order]
    first = torch.searchsorted(keys, pixel)
    count = torch.searchsorted(keys, pixel, right=True) - first
    point = torch.repeat_interleave(torch.arange(N, device=y.device), count)
    offset = torch.arange(point.numel(), device=y.device) - torch.repeat_interleave(torch.cumsum(count, 0) - count,
                                                                                      count)
    j = order[first[point] + offset]
    ab = b[j] - a[j]
    length2 = (ab * ab).sum(1)
    t = ((y[point] - a[j]) * ab).sum(1) / length2
    s = torch.minimum(torch.maximum(t, s0[j]), s1[j])
    r = y[point] - (a[j] + s[:, None] * ab)                                 # from the nearest point to y
    d = r.norm(dim=1).clamp_min(TINY)
    w = d ** -2
    dw = -2 * d[:, None] ** -4 * r                                          # ∇(1/d²) = -2 r / d⁴
    if warp == "nearest":                                                   # only the nearest piece counts
        best = torch.full((N,), math.inf, dtype=d.dtype, device=d.device).scatter_reduce(0, point, d, "amin")
        idx = torch.arange(d.numel(), device=d.device)
        pick = torch.where(d == best[point], idx, d.numel())                # ties (a shared end): the first
        first_pick = torch.full((N,), d.numel(), device=d.device).scatter_reduce(0, point, pick, "amin")
        one = idx == first_pick[point]
        w, dw = torch.where(one, w, 0.0), torch.where(one[:, None], dw, 0.0)
    total = wsum.index_add(0, point, w)                                     # Σ ω over the sides and pieces
    dtotal = dwsum.index_add(0, point, dw)
    inside = ((t > s0[j]) & (t < s1[j]))[:, None]
    grad_s = torch.where(inside, ab / length2[:, None], 0.0)               # ∇s: 0 where s is clamped at an end
    v = velocity(j, s)                                                      # (M, 2)
    share = w / total[point]                                                # ω_j / Ω
    dshare = dw / total[point, None] - (w / total[point] ** 2)[:, None] * dtotal[point]
    V = y.new_zeros(N, 2).index_add(0, point, share[:, None] * v)
    div = y.new_zeros(N).index_add(0, point, (dshare * v).sum(1) + share * divergence(j, grad_s))
    return V, div


def warp_gradient(prob, names, *, samples=16, kernel=1.0, warp="harmonic", generator=None):
    """dL/dπ for ``names`` (not "colors") by warped-area sampling (module docstring): ``samples`` points per
    pixel, stratified (``_stratified``), from ``generator``; the surrogate ``Σ w (f(y + D(y, π); π) - bg) (1 + ∇·D(y, π)) / samples``
    with D the warp's displacement (0 at π, its derivative V), differentiated by autograd."""
    p = prob.leaves(names)
    targets = prob.targets(p, names)
    p = {k: v.double() for k, v in p.items()}
    edges, e, s0, s1, pix, _ = boundary_pieces(prob, p)
    W, H = prob.camera0.width, prob.camera0.height
    weights = prob.weights.double().reshape(-1, 3)
    if prob.model == "flat":                                                # where something jumps
        pixels = torch.unique(pix)
    else:                                                                   # the colour moves everywhere
        pixels = torch.arange(W * H, device=pix.device)
    pixels = pixels[weights[pixels].abs().sum(1) > 0]
    if pixels.numel() == 0:
        return prob.gradients((None,) * len(names), targets, names)
    point_pixel = pixels.repeat_interleave(samples)
    u = _stratified(pixels.numel(), samples, generator).to(pix.device)
    corner = torch.stack([point_pixel % W, torch.div(point_pixel, W, rounding_mode="floor")], 1).double()
    y = corner + u
    mesh, cam = prob.mesh(p), prob.camera(p)
    with torch.no_grad():
        face = _visible_at(mesh, cam, y, edges.culled)                      # what each sample sees, at π
    a, b = edges.a, edges.b
    ad, bd = a.detach(), b.detach()
    curve = e                                                               # the pieces' curves

    def velocity(j, s):
        """Displacement (0 at π, derivative = velocity) of the points at fractions s of pieces j."""
        c = curve[j]
        m = c < edges.n_edges
        x = ad[c] + s[:, None] * (bd[c] - ad[c])
        moved = a[c] + s[:, None] * (b[c] - a[c])
        out = torch.where(m[:, None], moved - moved.detach(), 0.0)         # face edges: the point itself
        if (~m).any():                                                      # intersection lines: along n
            line = (~m).nonzero().squeeze(1)
            shift = normal_shift(prob, p, edges, c[line], s[line], x[line])
            out = out.index_add(0, line, edges.n[c[line]] * shift[:, None])
        return out

    def divergence(j, grad_s):
        """∇·δ: on a face edge δ = (1 - s) Δa + s Δb, so ∇·δ = ∇s · (Δb - Δa); 0 on an intersection line."""
        c = curve[j]
        m = (c < edges.n_edges)[:, None]
        ends = (b[c] - b[c].detach()) - (a[c] - a[c].detach())
        return (torch.where(m, grad_s, 0.0) * ends).sum(1)

    if e.numel():
        D, div = warp_field(y, point_pixel, W, ad[e], bd[e], s0, s1, pix, velocity, divergence, kernel, warp)
    else:
        D, div = y.new_zeros(y.shape), y.new_zeros(y.shape[0])
    seen = face >= 0
    w = weights[point_pixel]
    background = prob.background.double()
    colors = p["colors"].detach()
    if prob.model == "flat":
        f = torch.where(seen[:, None], colors[face.clamp(min=0)] - background, 0.0)
        surrogate = (w * f).sum(1) * div
    else:
        field = _Field(mesh.verts, prob.faces, cam)
        field.check(torch.unique(face[seen]), "image_gradient")
        k = seen.nonzero().squeeze(1)
        f = field.colors(face[k], point_pixel[k], u[k] + D[k], colors) - background
        surrogate = (w[k] * f).sum(1) * (1 + div[k])
    surrogate = surrogate.sum() / samples
    grads = torch.autograd.grad(surrogate, targets, allow_unused=True) if surrogate.requires_grad else \
        (None,) * len(targets)
    return prob.gradients(grads, targets, names)
