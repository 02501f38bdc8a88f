"""Reparameterizing the discontinuities: the third cure for the visibility term (lecture 09).

A pixel's value is ``I(π) = ∫_A f(x, π) dx`` over its unit square A, and f jumps where one face meets another
or the background; the jumps move with π, so the derivative cannot be taken under the integral. Change the
variable: ``x = T(y, π)`` with T the identity at the current π and moving the points of A along with the
jumps. Then ``f(T(y, π), π)`` jumps at fixed y, and

    I(π) = ∫_A f(T(y, π), π) |det ∂T/∂y| dy,   dI/dπ = ∫_A ∂f/∂π + ∇f · V + f ∇·V dy = ∫_A ∂f/∂π + ∇·(f V) dy,

with ``V = ∂T/∂π``, the warp's velocity field: differentiated under the integral, by Monte Carlo samples y and
autograd. Two conditions make T a change of variables of A that removes the motion of the jumps:

* on every curve where f jumps, V's normal part is the curve's normal speed v_n;
* on the pixel's border (its own, fixed, discontinuity: the box filter) V has no normal part, so A maps onto A
  (sliding along the border is allowed).

In between V must be continuous (its divergence is then an ordinary function, integrable). Given such a V,
the estimator is unbiased: over a region of one colour c, ``∫ c ∇·V = c ∮ V · n`` (divergence theorem), which on
the jumps is ``c v_n`` and on the pixel's border 0; summed over the regions this is the Reynolds boundary term.

The warp here (``warp="bounded"``, the default) asks V to meet every constraint as strongly as the point is
near it: the least-squares solution of

    V · n_k = v_k  with weight ω_k = 1/d_k²,   k over the pieces of jump curve in the pixel and its 4 sides,

(n_k the piece's unit normal, v_k the normal speed of its point nearest y, 0 on a side), plus ``ω_0 |V|²``
(ω_0 = 1/kernel²): a 2 × 2 system ``M V = b`` per point, solved in closed form, and ∇·V from its derivative.
On a curve or a side its own constraint holds (ω → 1/ε², ε = 2^-14 px: the misfit integrated along the curves
and sides is below 1e-6 of ∫ |v_n|, see ``bounded_warp_field``). Where a curve meets a side, or an occluding
edge meets the one it hides, two constraints with different normals meet: one V satisfies both, so V is
continuous there and ∇·V stays bounded (V - V* = O(r²)). That is what makes its variance finite: a bounded
integrand. It is still steep where a jump runs a hair from a pixel's side (V must go from v_n to 0 across the
gap), and undefined where a jump lies along the side (the kink the exact gradient has there too).

``warp="harmonic"`` (Bangaru, Li and Durand's warped-area sampling, SIGGRAPH Asia 2020, in its simplest form)
blends what each piece of jump curve does, the whole velocity vector, by inverse-distance weights,

    V(y) = Σ_j ω_j(y) δ_j(y) / (Σ_j ω_j(y) + Σ_sides ω_s(y) + ω_0),   ω = 1 / distance²,  ω_0 = 1 / kernel²,

with δ_j(y) the velocity of the point of piece j nearest y (on a face edge: the edge's ends' velocities
interpolated, so two edges meeting at a vertex agree there; on an intersection line: v_n along its normal).
It is unbiased too, but where a jump curve meets the pixel's border (V = δ_j on the curve, 0 on the side, and
δ_j is not tangent to the side) or two curves that move differently meet, V jumps at the point, ∇·V grows like
1/r there and the estimator's second moment diverges (logarithmically). The error of one run at 256 samples a
pixel on ``tests/test_warp.py``'s three scenes (a sphere's silhouette, the camera's translation, vertex colours;
the mean of 4 seeds), both warps with the control variate below: 0.28, 0.27, 0.25 of the gradient for this
warp, 0.08, 0.11, 0.08 for the bounded one (without the control variate: 0.34, 0.86, 1.25 against 0.11, 0.26,
0.48). ``python -m course bench gradients`` sets the time against error of both beside the other methods.

``warp="nearest"`` follows only the nearest piece (δ of the one nearest piece, same weights): the one
"dominant discontinuity" of Loubet, Holzschuch and Jakob's estimator (SIGGRAPH Asia 2019), on the image
plane. Where two pieces share a pixel, V jumps along the line halfway between them, ∇·V misses that jump, and
the estimate is biased; the bias shrinks with ``kernel`` (each piece's warp dies out within it). It is here
to measure that bias.

Why not a per-sample translation: the box filter's border is a discontinuity of the integrand that never
moves, so the warp's normal part must vanish there; a translation of a kernel around each sample (Loubet et
al.'s construction) does not, and is biased near every pixel border, whatever its kernel size.

The control variate: ``∫_A c ∇·V = 0`` for any constant c, so each pixel's integrand is ``(f - c_A) ∇·V`` with
c_A the pixel's mean colour on a fixed 4 × 4 grid (``_pixel_level``, at π, no gradient): unbiased, and |f - c_A|
is about half the jump where ``f - background`` can be a whole colour (bounded warp, 256 samples a pixel, on the
three scenes above: a run's error 0.11, 0.26, 0.48 of the gradient relative to the background, 0.08, 0.11, 0.08
relative to c_A).

Samples (``samples`` per pixel, stratified: ``_stratified``, seeded): flat colours are constant inside a face, so
``∂f/∂π = ∇f = 0`` and only ``f ∇·V`` remains, 0 in a pixel with no jump: only pixels that hold a piece of
jump curve are sampled. With screen-affine vertex colours (``model="affine"``) every pixel is sampled (the
colour also changes under fixed pieces). ``f`` is taken relative to the pixel's mean colour (above). The derivative w.r.t. the colours is linear and exact
(as for the boundary methods). Everything is computed in float64, as ``boundary_gradient``.
"""
from __future__ import annotations

import math

import torch

from .boundary import _visible_at, boundary_pieces, normal_shift
from .coverage_affine import _Field

__all__ = ["warp_gradient", "warp_field", "bounded_warp_field", "WARPS"]

WARPS = ("bounded", "harmonic", "nearest")
TINY = 1e-12             # pixels: distances are clamped here (a sample exactly on a curve or a side)
SOFT = 2.0 ** -14         # pixels (6.1e-5): the bounded warp's weights are 1 / (d² + SOFT²) (see bounded_warp_field)


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


def _pairs(pixel, piece_pixel):
    """The (point, piece) pairs of one pixel: point (M,) indices into the points, j (M,) into the pieces."""
    order = torch.argsort(piece_pixel, stable=True)
    keys = piece_pixel[order]
    first = torch.searchsorted(keys, pixel)
    count = torch.searchsorted(keys, pixel, right=True) - first
    point = torch.repeat_interleave(torch.arange(pixel.numel(), device=pixel.device), count)
    offset = torch.arange(point.numel(), device=pixel.device) - torch.repeat_interleave(torch.cumsum(count, 0) - count,
                                                                                          count)
    return point, order[first[point] + offset]


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
    point, j = _pairs(pixel, piece_pixel)                                  # the (point, piece) pairs of a pixel
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


def bounded_warp_field(y, pixel, width, a, b, s0, s1, piece_pixel, velocity, kernel=1.0):
    """The bounded warp V at points y (N, 2) of pixels ``pixel`` (N,) and its divergence ∇·V: (N, 2), (N,).

    V is what the constraints ask of it, each as strongly as the point is near it (module docstring): the
    least-squares solution of ``V · n_k = v_k`` with weights ω_k = 1/(d_k² + ε²), over the pieces of jump curve in
    the pixel (n_k the piece's line's unit normal, v_k the normal speed of its point nearest y) and the pixel's
    four sides (``V · n_s = 0``), plus ``ω_0 |V|²`` (ω_0 = 1/kernel²):

        M(y) V = b(y),   M = Σ_k ω_k n_k n_kᵀ + ω_0 I,   b = Σ_k ω_k v_k n_k.

    ∇·V = tr(M⁻¹ (∂b/∂y - ∂M/∂y V)) in closed form: ∂ω_k/∂y = -2 r_k / (d_k² + ε²)² (r_k from the nearest point
    to y), ∂v_k/∂y = (dv_k/ds) ∇s, the normal speed being affine along a piece. ``velocity(j, s)`` gives the
    velocity (M, 2) of the points at fractions s (M,) of pieces j (M,) (autograd carries it).

    ε = ``SOFT`` (2^-14 px) is numerical: with ω = 1/d² a sample 1e-8 px from a curve gives ω ~ 1e16, and the
    2 × 2 determinant, where two terms of order ω² cancel, keeps no correct digit (one such sample made a run
    3x the gradient off). Softened, ω ≤ 2.7e8, and the constraints hold to ε² times the other weights: on random
    pieces, V · n - v_n integrated along the curves and V · n on the sides come to 4e-7 and 6e-7 of ∫ |v_n|
    (``tests/test_warp.py``), the only bias, far below the noise of any run."""
    N = y.shape[0]
    corner = torch.stack([pixel % width, torch.div(pixel, width, rounding_mode="floor")], 1).to(y.dtype)
    u = y - corner
    # the sides: V · x̂ = 0 on the left and right (weights 1/u², 1/(1-u)²), V · ŷ = 0 on the top and bottom
    lo, hi = u * u + SOFT ** 2, (1 - u) ** 2 + SOFT ** 2                  # left/top, right/bottom: d² + ε²
    side = 1 / lo + 1 / hi                                                  # (N, 2): x̂x̂ᵀ and ŷŷᵀ weights
    dside = -2 * u / lo ** 2 + 2 * (1 - u) / hi ** 2                       # (N, 2): d/du_x of the first, d/du_y
    w0 = 0.0 if kernel is None else kernel ** -2
    M = torch.zeros(N, 2, 2, dtype=y.dtype, device=y.device)
    M[:, 0, 0] = side[:, 0] + w0
    M[:, 1, 1] = side[:, 1] + w0
    dM = torch.zeros(N, 2, 2, 2, dtype=y.dtype, device=y.device)          # dM[:, i] = ∂M/∂y_i
    dM[:, 0, 0, 0] = dside[:, 0]
    dM[:, 1, 1, 1] = dside[:, 1]
    point, j = _pairs(pixel, piece_pixel)
    ab = b[j] - a[j]
    length2 = (ab * ab).sum(1)
    n = torch.stack([-ab[:, 1], ab[:, 0]], 1) / length2.sqrt()[:, None]    # (M, 2) the line's unit normal
    t = ((y[point] - a[j]) * ab).sum(1) / length2
    s = torch.minimum(torch.maximum(t, s0[j]), s1[j])
    r = y[point] - (a[j] + s[:, None] * ab)                                 # from the nearest point to y
    dist2 = (r * r).sum(1) + SOFT ** 2
    w = 1 / dist2                                                           # 1 / (d² + ε²)
    dw = -2 * r / dist2[:, None] ** 2                                       # its gradient
    inside = ((t > s0[j]) & (t < s1[j]))[:, None]
    grad_s = torch.where(inside, ab / length2[:, None], 0.0)               # ∇s: 0 where s is clamped at an end
    nn = n[:, :, None] * n[:, None, :]                                      # (M, 2, 2)
    M = M.index_add(0, point, w[:, None, None] * nn)
    dM = dM.index_add(0, point, dw[:, :, None, None] * nn[:, None])
    v = (velocity(j, s) * n).sum(1)                                         # (M,) normal speeds (autograd)
    dv = ((velocity(j, torch.ones_like(s)) - velocity(j, torch.zeros_like(s))) * n).sum(1)   # dv/ds
    rhs = y.new_zeros(N, 2).index_add(0, point, (w * v)[:, None] * n)
    # ∂b/∂y_i = Σ (∂ω/∂y_i v + ω dv/ds ∂s/∂y_i) n: (N, i, 2)
    coef = dw * v[:, None] + (w * dv)[:, None] * grad_s                    # (M, 2) over i
    drhs = y.new_zeros(N, 2, 2).index_add(0, point, coef[:, :, None] * n[:, None, :])
    Minv = torch.linalg.inv(M.detach())                                     # (N, 2, 2): geometry only
    V = (Minv @ rhs[:, :, None])[:, :, 0]
    dV = drhs - (dM.detach() @ V[:, None, :, None])[..., 0]                # (N, i, 2): ∂b/∂y_i - ∂M/∂y_i V
    div = (Minv[:, 0, :] * dV[:, 0, :]).sum(1) + (Minv[:, 1, :] * dV[:, 1, :]).sum(1)   # Σ_i (M⁻¹ ∂_i)_i
    return V, div


LEVEL_GRID = 4           # the control variate: each pixel's mean colour on a LEVEL_GRID² grid of points


def _pixel_level(prob, p, pixels, culled, colors, background):
    """(P, 3) a constant per pixel to take from f: the mean colour on a fixed ``LEVEL_GRID``² grid in the pixel
    (at π, no gradient). ``∫_A c ∇·V = 0`` for any constant c (the warp holds the pixel's border), so the mean
    is unchanged and the variance is that of ``(f - c) ∇·V``: with c between the colours that meet in the pixel,
    |f - c| is about half the jump, where ``f - background`` can be the whole colour."""
    W = prob.camera0.width
    k = LEVEL_GRID
    x = (torch.arange(k, dtype=torch.float64, device=pixels.device) + 0.5) / k
    grid = torch.stack(torch.meshgrid(x, x, indexing="xy"), -1).reshape(-1, 2)   # (k², 2)
    pix = pixels.repeat_interleave(k * k)
    corner = torch.stack([pix % W, torch.div(pix, W, rounding_mode="floor")], 1).double()
    offset = grid.repeat(pixels.numel(), 1)
    with torch.no_grad():
        mesh, cam = prob.mesh({n: v.detach() for n, v in p.items()}), prob.camera({n: v.detach() for n, v in p.items()})
        face = _visible_at(mesh, cam, corner + offset, culled)
        seen = face >= 0
        c = background.expand(face.numel(), -1).clone()
        if prob.model == "flat":
            c[seen] = colors[face[seen]]
        elif seen.any():
            field = _Field(mesh.verts, prob.faces, cam)
            c[seen] = field.colors(face[seen], pix[seen], offset[seen], colors)
    return c.view(pixels.numel(), k * k, -1).mean(1)


def warp_gradient(prob, names, *, samples=16, kernel=1.0, warp="bounded", generator=None):
    """dL/dπ for ``names`` (not "colors") by warped-area sampling (module docstring): ``samples`` points per
    pixel, stratified (``_stratified``), from ``generator``; the surrogate ``Σ w (f(y + D(y, π); π) - c_A) (1 + ∇·D(y, π)) / samples``
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

    if e.numel() and warp == "bounded":
        D, div = bounded_warp_field(y, point_pixel, W, ad[e], bd[e], s0, s1, pix, velocity, kernel)
    elif e.numel():
        D, div = warp_field(y, point_pixel, W, ad[e], bd[e], s0, s1, pix, velocity, divergence, kernel, warp)
    else:
        D, div = y.new_zeros(y.shape), y.new_zeros(y.shape[0])
    seen = face >= 0
    w = weights[point_pixel]
    background = prob.background.double()
    colors = p["colors"].detach()
    level = _pixel_level(prob, p, pixels, edges.culled, colors, background)   # (P, 3): a control variate
    level = level.repeat_interleave(samples, 0)
    if prob.model == "flat":
        f = torch.where(seen[:, None], colors[face.clamp(min=0)], background) - level
        surrogate = (w * f).sum(1) * div
    else:
        field = _Field(mesh.verts, prob.faces, cam)
        field.check(torch.unique(face[seen]), "image_gradient")
        k = seen.nonzero().squeeze(1)
        f = field.colors(face[k], point_pixel[k], u[k] + D[k], colors) - level[k]
        rest = (~seen).nonzero().squeeze(1)                                 # the background, shifted too
        surrogate = torch.cat([(w[k] * f).sum(1) * (1 + div[k]), (w[rest] * (background - level[rest])).sum(1) * div[rest]])
    surrogate = surrogate.sum() / samples
    grads = torch.autograd.grad(surrogate, targets, allow_unused=True) if surrogate.requires_grad else \
        (None,) * len(targets)
    return prob.gradients(grads, targets, names)
