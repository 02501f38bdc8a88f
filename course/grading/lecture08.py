"""The checks of lecture 8's graded tasks (differentiable rasterization): 8.1 nmr_edge_gradients (NMR's
approximate gradient along a row, both edges, the sign rule), 8.2 soft_coverage, 8.3 soft_blend, 8.4
sigma_for_blur (an analysis: the σ that blurs an edge over a given width).

Each check runs the student's function next to a reference on fixed, seeded-random and stress inputs and
says what to fix, recognising the typical mistakes of the task. ``import course.grading`` imports this
module, which registers its checks in ``course.grading.TASKS``.

``course.soft.soft_rasterize`` computes 8.2 and 8.3 inline, on (pixel, face) pairs and from logits, and
``course.nmr`` computes 8.1 per vertex over a whole image, so the references are written here from the
formulas of Kato et al. 2018 and Liu et al. 2019 (as ``course/nmr.py`` and ``course/soft.py`` state them), on
dense tensors and in float64; ``tests/test_grading_08.py`` checks that they agree with ``nmr_rasterize`` and
``soft_rasterize`` on small scenes. They are public so that those tests (and a curious student) can read
them; a graded function that calls them, or the package functions doing the task's work, scores 0.
"""
from __future__ import annotations

import math

import torch

from .helpers import Fail, _call, _close, compare, generator, grade_parts, require, to_tensor
from .registry import forbidden_call, task

__all__ = ["nmr_edge_gradients_reference", "soft_coverage_reference", "soft_blend_reference",
           "sigma_for_blur_reference"]

FORBIDDEN = [("course.soft", "soft_rasterize"), ("course.soft", "_pair_terms"),
             ("course.soft", "_silhouette_terms"), ("course.soft", "_color_terms"),
             ("course.grading.lecture08", "nmr_edge_gradients_reference"),
             ("course.grading.lecture08", "soft_coverage_reference"),
             ("course.grading.lecture08", "soft_blend_reference"),
             ("course.grading.lecture08", "sigma_for_blur_reference")]
FORBIDDEN_NMR = FORBIDDEN + [("course.nmr", "nmr_rasterize"), ("course.nmr", "nmr_image"),
                             ("course.nmr", "_nmr_backward"), ("course.nmr", "_nmr_scan"),
                             ("course.nmr", "_nmr_pixels")]


# ------------------------------------------------------------------------------------- the references

def _signed_d2(tri, height, width, segments=True, winding=0):
    """δ d² in pixels² (H, W) of the pixel centres to the triangle tri (3, 2) pixels, float64: d the distance
    to the triangle (to its edge lines if not ``segments``), δ = +1 strictly inside, -1 outside; 0 on an
    edge. ``winding`` 0: either winding is inside (the task); +1 / -1: only where all three edge functions
    have that sign (a typical mistake)."""
    tri = tri.to(torch.float64)
    y, x = torch.meshgrid(torch.arange(height, dtype=torch.float64) + 0.5,
                          torch.arange(width, dtype=torch.float64) + 0.5, indexing="ij")
    d2, cross = [], []
    for k in range(3):
        a, b = tri[k], tri[(k + 1) % 3]
        ex, ey, wx, wy = b[0] - a[0], b[1] - a[1], x - a[0], y - a[1]
        ee = ex * ex + ey * ey
        t = (wx * ex + wy * ey) / ee if ee > 0 else torch.zeros_like(x)
        t = t.clamp(0, 1) if segments else t                              # the closest point of the edge
        d2.append((wx - t * ex) ** 2 + (wy - t * ey) ** 2)
        cross.append(ex * wy - ey * wx)                                   # the edge function
    area = cross[0] + cross[1] + cross[2]
    sign = area if winding == 0 else torch.full_like(area, float(winding))
    inside = (cross[0] * sign > 0) & (cross[1] * sign > 0) & (cross[2] * sign > 0)
    d2 = torch.stack(d2).amin(0)
    return torch.where(inside, d2, -d2)


def nmr_edge_gradients_reference(row, grad, x_left: float, x_right: float, color, background,
                                 min_step: float) -> torch.Tensor:
    """8.1, in row's dtype (computed in float64): see ``_nmr_row``."""
    return _nmr_row(row, grad, x_left, x_right, color, background, min_step).to(row.dtype)


def sigma_for_blur_reference(width_px: float, image_width: int, level: float) -> float:
    """8.4: see ``_sigma_for_blur``."""
    return _sigma_for_blur(width_px, image_width, level)


def soft_coverage_reference(tri, height: int, width: int, sigma: float) -> torch.Tensor:
    """8.2, in tri's dtype (computed in float64): see ``_coverage``."""
    return _coverage(tri, height, width, sigma).to(tri.dtype)


def soft_blend_reference(D, z, colors, background, gamma: float, eps: float) -> torch.Tensor:
    """8.3, in D's dtype (computed in float64): see ``_blend``."""
    return _blend(D, z, colors, background, gamma, eps).to(D.dtype)


def _coverage(tri, height: int, width: int, sigma: float) -> torch.Tensor:
    """8.2: ``D = sigmoid(δ d² / σ)`` (H, W) float64 at the pixel centres (j + 0.5, i + 0.5), for the
    triangle tri (3, 2) in pixels; d in normalised device coordinates, ``d_ndc = 2 d_px / width``."""
    return torch.sigmoid(_signed_d2(tri, height, width) * (4.0 / (width * width)) / sigma)


def _blend(D, z, colors, background, gamma: float, eps: float) -> torch.Tensor:
    """8.3: the depth softmax (H, W, C) float64 of Liu et al.: ``(Σ_j w_j C_j + w_b C_b) / (Σ_j w_j + w_b)``
    with ``w_j = D_j exp(z_j / γ)``, ``w_b = exp(ε / γ)``; D, z (F, H, W), colors (F, C), background (C,).
    Written with log-weights and the largest one (the background's included) subtracted before ``exp``."""
    D, z, colors, background = (v.to(torch.float64) for v in (D, z, colors, background))
    log_w = torch.log(D) + z / gamma                                      # (F, H, W), -inf where D = 0
    log_b = torch.full_like(log_w[0], eps / gamma)                        # (H, W)
    top = torch.maximum(log_w.amax(0), log_b)
    w, w_b = torch.exp(log_w - top), torch.exp(log_b - top)               # each <= 1
    num = torch.einsum("fhw,fc->hwc", w, colors) + w_b[..., None] * background
    return num / (w.sum(0) + w_b)[..., None]


def _nmr_row(row, grad, x_left, x_right, color, background, min_step, *, rule="lower", both=True, floor=True,
             across=True, centre=0.5, direction="move"):
    """8.1: NMR's approximate gradient (2,) float64 ``[∂L/∂x_left, ∂L/∂x_right]`` of one image row (W, C)
    w.r.t. where a face's left and right edges cross the row, for ∂L/∂I ``grad`` (W, C) (Kato et al. 2018).

    The face covers the pixel centres u = j + 0.5 with x_left <= u <= x_right and is in front of everything.
    A pixel left of the span is covered by moving the left edge left by |δ| (δ = u - x_left), one right of it by
    moving the right edge right; δI = color - row[j]. A pixel inside is uncovered by moving the left edge
    right past it (δ = u - x_left) *and* by moving the right edge left past it (δ = u - x_right): two terms,
    δI = the colour across that edge (the row's pixel just outside the span, ``background`` beyond the border)
    - row[j]. Each term is ``grad[j] · δI / δx`` with δx = ± max(|δ|, min_step), the sign of the move, and is
    kept only where ``grad[j] · δI < 0`` (the sign rule). The keywords give the typical mistakes: ``rule``
    "all" / "raise" (no sign rule / the opposite one), ``both`` False (inside: the nearer edge only), ``floor``
    False, ``across`` False (uncovering shows the background), ``centre`` 0 (centres at j), ``direction``
    "sign" (the sign of δ: 0, and an infinite term, on a centre), "abs" (|δx|, no sign) or "clamp" (δ clamped
    below at min_step)."""
    row, grad, color, background = (v.to(torch.float64) for v in (row, grad, color, background))
    W = row.shape[0]
    u = torch.arange(W, dtype=torch.float64) + centre                     # (W,) pixel centres
    inside = (u >= x_left) & (u <= x_right)
    jl, jr = math.ceil(x_left - centre) - 1, math.floor(x_right - centre) + 1   # just outside the span
    behind_l = row[jl] if across and 0 <= jl < W else background          # (C,) across the left edge
    behind_r = row[jr] if across and 0 <= jr < W else background
    nearer_left = (u - x_left) <= (x_right - u)
    terms = [(0, u < x_left, u - x_left, -1.0, color - row),              # left edge moves left: covers
             (1, u > x_right, u - x_right, 1.0, color - row),             # right edge moves right: covers
             (0, inside & (both | nearer_left), u - x_left, 1.0, behind_l - row),       # moves right: uncovers
             (1, inside & (both | ~nearer_left), u - x_right, -1.0, behind_r - row)]    # moves left: uncovers
    out = torch.zeros(2, dtype=torch.float64)
    for edge, mask, delta, move, dI in terms:
        dot = (grad * dI).sum(-1)                                         # (W,) δᴾ · δI
        keep = mask & {"lower": dot < 0, "all": torch.ones_like(mask), "raise": dot > 0}[rule]
        step = delta.abs().clamp(min=min_step) if floor else delta.abs()
        dx = {"move": move * step, "sign": torch.sign(delta) * step, "abs": step,
              "clamp": delta.clamp(min=min_step)}[direction]
        out[edge] += torch.where(keep, dot / dx, torch.zeros_like(dot)).sum()
    return out


def _sigma_for_blur(width_px, image_width, level, *, ndc=True, half=True, logit=True, square=True):
    """8.4: the σ (NDC) at which D = sigmoid(δ d² / σ) rises from ``level`` to ``1 - level`` across
    ``width_px`` pixels: D = level at d = width / 2 outside, so σ_px = (width / 2)² / ln((1 - level) / level),
    and σ = σ_px · 4 / image_width². The keywords give the typical mistakes."""
    d = width_px / 2 if half else width_px
    x = math.log((1 - level) / level) if logit else math.log(1 / level)
    sigma_px = (d * d if square else d) / x
    return sigma_px * 4 / image_width ** 2 if ndc else sigma_px


def _match(got, variants):
    """The explanation of the first ``(alternative, explanation)`` that ``got`` matches, else None."""
    for alternative, explanation in variants:
        if alternative is not None and _close(got, alternative, 1e-4):
            return explanation
    return None


# ---------------------------------------------------------------------- 8.1 NMR's gradient along a row

def _nmr_problem(impl, row, grad, x_left, x_right, color, background, min_step, label) -> str | None:
    name = f"nmr_edge_gradients({label})"
    expected = _nmr_row(row, grad, x_left, x_right, color, background, min_step)
    got = to_tensor(_call(impl, row, grad, x_left, x_right, color, background, min_step), name)
    message = compare(got, expected.to(row.dtype), name=name, check_dtype=True, atol=1e-9, rtol=1e-9)
    if message is None or "shape" in message or "dtype" in message:
        return message
    if not bool(torch.isfinite(got).all()):
        return (f"{name}: not finite: a pixel centre on an edge has δ = 0; floor |δ| at min_step, and take the "
                "direction of the move from the edge and the side (cover or uncover), not from the sign of δ")
    ref = lambda **kw: _nmr_row(row, grad, x_left, x_right, color, background, min_step, **kw)  # noqa: E731
    explanation = _match(got, [
        (ref(rule="all"), "the sign rule is missing: keep a term only where ∂L/∂I · δI < 0 (moving the edge that "
                          "way would lower the loss)"),
        (ref(rule="raise"), "the sign rule is the wrong way round: keep the terms with ∂L/∂I · δI < 0, those "
                            "whose move lowers the loss"),
        (ref(both=False), "a pixel inside the span can be uncovered by either edge: add both terms (the left edge "
                          "moving right past it and the right edge moving left past it), not only the nearer one"),
        (ref(across=False), "uncovering a pixel shows what lies across the edge (the row's pixel just outside "
                            "the span), not the background, unless the span reaches the border"),
        (ref(direction="abs"), "δx has a sign: the left edge moves left (−) to cover and right (+) to uncover, "
                               "the right edge the opposite way; divide by the signed move"),
        (ref(direction="clamp"), "the floor must keep the move's sign: δx = ± max(|δ|, min_step), not "
                                 "max(δ, min_step)"),
        (ref(centre=0.0), "the pixel centres are at j + 0.5, not j"),
    ])
    if explanation is None and _close(got, ref(floor=False)):
        explanation = "|δx| must be floored at min_step: use max(|δ|, min_step)"
    return f"{name}: {explanation}" if explanation else message


def _nmr_inputs(seed, W, C, x_left, x_right, inside_value=None):
    """A row (W, C) with the face's colour over its span and other surfaces elsewhere, the face's colour
    (C,), a background (C,) and a random ∂L/∂I (W, C) of both signs, float64."""
    g = generator(seed)
    r = lambda *s: torch.rand(*s, generator=g, dtype=torch.float64)     # noqa: E731
    color, background = r(C), r(C)
    row = r(W, C)                                                          # other surfaces
    u = torch.arange(W, dtype=torch.float64) + 0.5
    span = (u >= x_left) & (u <= x_right)
    row[span] = color if inside_value is None else inside_value
    grad = torch.randn(W, C, generator=g, dtype=torch.float64)
    return row, grad, color, background


@task("8.1", "nmr_edge_gradients", points=5, reference=("course.nmr", "nmr_image"))
def _check_nmr_edge_gradients(impl):
    forbidden = forbidden_call(impl, "nmr_edge_gradients", FORBIDDEN_NMR)
    if forbidden:
        return 0, forbidden

    def silhouette():
        for seed, (xl, xr) in ((91, (5.3, 13.8)), (92, (2.7, 9.1))):
            row, grad, _, _ = _nmr_inputs(seed, 16, 1, xl, xr)
            row = ((torch.arange(16) + 0.5 >= xl) & (torch.arange(16) + 0.5 <= xr)).double()[:, None]
            one, zero = torch.ones(1, dtype=torch.float64), torch.zeros(1, dtype=torch.float64)
            require(_nmr_problem(impl, row, grad, xl, xr, one, zero, 0.1,
                                 f"a silhouette row, span [{xl}, {xr}], W = 16, min_step = 0.1"))

    def colours():
        row, grad, color, bg = _nmr_inputs(93, 20, 3, 6.4, 15.2)
        require(_nmr_problem(impl, row, grad, 6.4, 15.2, color, bg, 0.1,
                             "colours, span [6.4, 15.2], W = 20, min_step = 0.1"))
        row, grad, color, bg = _nmr_inputs(94, 12, 3, 0.2, 7.7, inside_value=None)
        require(_nmr_problem(impl, row, grad, 0.2, 7.7, color, bg, 0.1,
                             "colours, span [0.2, 7.7] from the image's left border, W = 12, min_step = 0.1"))
        row, grad, color, bg = _nmr_inputs(95, 12, 2, 4.6, 11.9)
        require(_nmr_problem(impl, row, grad, 4.6, 11.9, color, bg, 0.1,
                             "two channels, span [4.6, 11.9] to the right border, W = 12, min_step = 0.1"))

    def near_centres():
        row, grad, color, bg = _nmr_inputs(96, 16, 3, 4.5, 10.3)
        grad[4] = row[4] - row[3]                  # pixel 4's centre is on the left edge: uncovering it helps
        require(_nmr_problem(impl, row, grad, 4.5, 10.3, color, bg, 0.5,
                             "the left edge on a pixel centre, the right edge 0.2 from one, min_step = 0.5"))
        row, grad, color, bg = _nmr_inputs(97, 16, 3, 3.9, 12.5)
        grad[12] = row[12] - row[13]               # pixel 12's centre is on the right edge
        require(_nmr_problem(impl, row, grad, 3.9, 12.5, color, bg, 1.5, "min_step = 1.5, the right edge on a "
                                                                          "pixel centre"))
    return grade_parts((2, "a silhouette row: covering and uncovering", silhouette),
                       (2, "colours, other surfaces across the edges, the image border", colours),
                       (1, "edges on and near pixel centres: the floor and the direction", near_centres))


# ------------------------------------------------------------------------------------ 8.2 soft coverage

def _coverage_problem(impl, tri, height, width, sigma, label) -> str | None:
    name = f"soft_coverage({label})"
    expected = _coverage(tri, height, width, sigma)
    got = to_tensor(_call(impl, tri, height, width, sigma), name)
    if tuple(got.shape) == (width, height) and width != height:
        return f"{name}: shape {(height, width)} expected (rows = height, columns = width), got {tuple(got.shape)}"
    low = tri.dtype == torch.float32
    message = compare(got, expected.to(tri.dtype), name=name, check_dtype=True,
                      **({} if low else dict(atol=1e-9, rtol=1e-7)))
    if message is None or "shape" in message or "dtype" in message:
        return message
    if not bool(torch.isfinite(got).all()):
        return (f"{name}: NaN: a zero-length edge (two equal corners) gives t = 0 / 0 for the closest point; "
                "guard e · e = 0 (the closest point is then the corner)")
    s = _signed_d2(tri, height, width)
    px = 4.0 / (width * width)
    one_winding = ("the triangle's inside is missed for one winding: a pixel is inside when its three edge "
                   "functions have the sign of the area, whichever way the corners go")
    corner = _signed_d2(tri + 0.5, height, width)                        # centres at (j, i): tri shifted by +0.5
    explanation = _match(got, [
        (torch.sigmoid(s / sigma),
         "d is in pixels: measure it in normalised device coordinates, d_ndc = 2 d_px / width (so d² gets 4 / width²)"),
        (torch.sigmoid(s * 4.0 / (height * height) / sigma),
         "d_ndc is scaled by the height: the image is 2 wide in NDC, so d_ndc = 2 d_px / width"),
        (torch.sigmoid(s.sign() * s.abs().sqrt() * (2.0 / width) / sigma),
         "that is sigmoid(δ d / σ): square the distance, D = sigmoid(δ d² / σ)"),
        (torch.sigmoid(-s * px / sigma), "inside and outside are swapped: δ = +1 inside (D > 1/2), −1 outside"),
        (torch.sigmoid(_signed_d2(tri, height, width, segments=False) * px / sigma),
         "outside a corner, d is the distance to an edge's infinite line: clamp the closest point to the segment "
         "(t in [0, 1])"),
        (torch.sigmoid(corner * px / sigma), "the pixel centres are at (j + 0.5, i + 0.5), not (j, i)"),
        (torch.sigmoid(_signed_d2(tri, height, width, winding=1) * px / sigma), one_winding),
        (torch.sigmoid(_signed_d2(tri, height, width, winding=-1) * px / sigma), one_winding),
    ])
    return f"{name}: {explanation}" if explanation else message


def _random_triangle(seed, width, height, dtype):
    g = generator(seed)
    tri = torch.rand(3, 2, generator=g, dtype=torch.float64) * torch.tensor([width, height]) * 1.2 - 0.1 * torch.tensor(
        [width, height])
    return tri.to(dtype)


@task("8.2", "soft_coverage", points=3, reference=("course.soft", "soft_rasterize"))
def _check_soft_coverage(impl):
    forbidden = forbidden_call(impl, "soft_coverage", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def random():
        for seed, sigma in ((81, 1e-2), (82, 3e-3)):
            tri = _random_triangle(seed, 20, 12, torch.float32)
            require(_coverage_problem(impl, tri, 12, 20, sigma, f"a random triangle, 12 × 20, σ = {sigma:g}, float32"))

    def windings():
        tri = torch.tensor([[2.3, 1.7], [13.6, 4.2], [5.1, 10.4]], dtype=torch.float64)   # clockwise on screen
        require(_coverage_problem(impl, tri, 12, 16, 1e-2, "a clockwise triangle, float64"))
        require(_coverage_problem(impl, tri.flip(0), 12, 16, 1e-2, "a counter-clockwise triangle, float64"))
        thin = torch.tensor([[1.2, 2.0], [14.0, 2.5], [7.0, 2.25]], dtype=torch.float64)   # a sliver
        require(_coverage_problem(impl, thin, 6, 16, 2e-2, "a sliver, float64"))

    def stress():
        tri = torch.tensor([[3.5, 3.5], [40.5, 8.5], [12.5, 30.5]], dtype=torch.float64)  # corners on centres
        require(_coverage_problem(impl, tri, 32, 48, 1e-7, "σ = 1e-7 and vertices on pixel centres, float64"))
        require(_coverage_problem(impl, tri, 32, 48, 1.0, "σ = 1, float64"))
        require(_coverage_problem(impl, torch.tensor([[2.0, 2.0], [9.0, 6.0], [2.0, 2.0]], dtype=torch.float64),
                                  8, 12, 1e-2, "a degenerate triangle (two equal corners), float64"))
    return grade_parts((1, "random triangles, float32", random),
                       (1, "both windings and a sliver", windings),
                       (1, "tiny and large σ, a degenerate triangle", stress))


# ------------------------------------------------------------------------------ 8.3 softmax blending

def _blend_problem(impl, D, z, colors, background, gamma, eps, label) -> str | None:
    name = f"soft_blend({label})"
    expected = _blend(D, z, colors, background, gamma, eps)
    got = to_tensor(_call(impl, D, z, colors, background, gamma, eps), name)
    low = D.dtype == torch.float32
    message = compare(got, expected.to(D.dtype), name=name, check_dtype=True,
                      **({} if low else dict(atol=1e-8, rtol=1e-8)))
    if message is None or "shape" in message or "dtype" in message:
        return message
    if not bool(torch.isfinite(got).all()):
        return (f"{name}: NaN or inf: at small γ exp(z / γ) overflows (z / γ reaches 1e5 at γ = 1e-5); work "
                "with log-weights log D_j + z_j / γ and ε / γ, subtract their largest (the background's included) "
                "before exp")
    d, zz, c, bg = (v.to(torch.float64) for v in (D, z, colors, background))
    ref = lambda **kw: _blend_variant(d, zz, c, bg, gamma, eps, **kw)     # noqa: E731
    explanation = _match(got, [
        (ref(bg_term=False), "the background is missing: it is one more term of the softmax, weight exp(ε / γ) "
                             "and colour `background`"),
        (ref(bg_log=0.0), "the background's weight is exp(ε / γ), not 1: it sits at normalised depth ε"),
        (ref(sign=-1.0), "exp(−z / γ) favours the far faces: z is the normalised *inverse* depth (1 near, "
                         "0 far), so the weight is D exp(+z / γ)"),
        (ref(use_D=False), "the coverage is missing: each face's weight is D_j exp(z_j / γ), not exp(z_j / γ)"),
        (ref(use_z=False), "the depth is missing: each face's weight is D_j exp(z_j / γ), not D_j"),
    ])
    return f"{name}: {explanation}" if explanation else message


def _blend_variant(D, z, colors, bg, gamma, eps, bg_term=True, bg_log=None, sign=1.0, use_D=True, use_z=True):
    log_w = (torch.log(D) if use_D else torch.zeros_like(D)) + (sign * z / gamma if use_z else 0.0)
    top = log_w.amax(0)
    if bg_term:
        log_b = torch.full_like(top, eps / gamma if bg_log is None else bg_log)
        top = torch.maximum(top, log_b)
    w = torch.exp(log_w - top)
    num, den = torch.einsum("fhw,fc->hwc", w, colors), w.sum(0)
    if bg_term:
        w_b = torch.exp(log_b - top)
        num, den = num + w_b[..., None] * bg, den + w_b
    return num / den[..., None]


def _blend_inputs(seed, F, H, W, C, dtype, far=False):
    g = generator(seed)
    r = lambda *s: torch.rand(*s, generator=g, dtype=torch.float64)     # noqa: E731
    D = torch.sigmoid(r(F, H, W) * 16 - 10)                               # mostly outside, some inside
    if far:
        D = 10 ** (-30 * r(F, H, W))                                       # faces far outside every pixel
    z = 0.1 + 0.8 * r(F, 1, 1) + 0.05 * r(F, H, W)                        # each face near a depth
    return D.to(dtype), z.to(dtype), r(F, C).to(dtype), r(C).to(dtype)


@task("8.3", "soft_blend", points=3, reference=("course.soft", "soft_rasterize"))
def _check_soft_blend(impl):
    forbidden = forbidden_call(impl, "soft_blend", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def moderate():
        D, z, c, bg = _blend_inputs(86, 4, 5, 6, 3, torch.float32)
        require(_blend_problem(impl, D, z, c, bg, 0.1, 1e-3, "4 faces, γ = 0.1, float32"))
        D, z, c, bg = _blend_inputs(87, 3, 4, 4, 2, torch.float64)
        require(_blend_problem(impl, D, z, c, bg, 0.03, 0.05, "3 faces, γ = 0.03, ε = 0.05, float64"))

    def tiny():
        D, z, c, bg = _blend_inputs(88, 4, 5, 6, 3, torch.float64)
        require(_blend_problem(impl, D, z, c, bg, 1e-5, 1e-3, "γ = 1e-5, float64"))
        D, z, c, bg = _blend_inputs(89, 3, 4, 5, 3, torch.float64, far=True)
        require(_blend_problem(impl, D, z, c, bg, 1e-4, 1e-3, "faces far outside the pixels, γ = 1e-4, float64"))

    def limits():
        D, z, c, bg = _blend_inputs(90, 3, 4, 5, 3, torch.float64)
        D[:, :, :2] = 0.0                                                  # no face at all: the background
        require(_blend_problem(impl, D, z, c, bg, 1e-3, 1e-3, "D = 0 in some pixels, float64"))
        require(_blend_problem(impl, D, z, c, bg, 10.0, 1e-3, "γ = 10 (a plain average), float64"))
    return grade_parts((1, "moderate γ", moderate),
                       (1, "tiny γ: overflow of exp(z / γ)", tiny),
                       (1, "pixels no face covers, large γ", limits))


# ---------------------------------------------------------------------- 8.4 analysis: σ for a blur width

def _as_number(x, name) -> float:
    if isinstance(x, (int, float)) and not isinstance(x, bool):
        return float(x)
    t = to_tensor(x, name)
    if t.numel() != 1:
        raise Fail(f"{name}: expected one number, got shape {tuple(t.shape)}")
    return float(t.reshape(()))


def _sigma_problem(impl, width_px, image_width, level) -> str | None:
    name = f"sigma_for_blur({width_px}, {image_width}, {level})"
    expected = _sigma_for_blur(width_px, image_width, level)
    got = _as_number(_call(impl, width_px, image_width, level), name)
    if math.isclose(got, expected, rel_tol=1e-6):
        return None
    for kw, explanation in (
            (dict(ndc=False), "that is σ_px, in pixels²: σ is in NDC, where the image is 2 wide: "
                              "σ = σ_px · 4 / W²"),
            (dict(half=False), "the blur spans both sides of the edge: D = level at a distance of width / 2 "
                               "outside, and 1 − level at width / 2 inside"),
            (dict(logit=False), "D = sigmoid(−d² / σ_px) = level gives d² / σ_px = ln((1 − level) / level), "
                                "not ln(1 / level)"),
            (dict(square=False), "σ divides d², not d: σ_px = d² / ln((1 − level) / level)"),
            (dict(ndc=False, half=False), "the width spans both sides of the edge (d = width / 2), and σ is in "
                                          "NDC (σ = σ_px · 4 / W²)")):
        if math.isclose(got, _sigma_for_blur(width_px, image_width, level, **kw), rel_tol=1e-6):
            return f"{name}: {explanation}"
    return f"{name}: got {got:.6g}, expected {expected:.6g}"


@task("8.4", "sigma_for_blur", points=2, reference=("course.soft", "soft_rasterize"))
def _check_sigma_for_blur(impl):
    forbidden = forbidden_call(impl, "sigma_for_blur", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def paper():
        for width in (2.0, 4.4):
            require(_sigma_problem(impl, width, 256, 0.05))

    def others():
        for args in ((1.0, 64, 0.01), (3.0, 100, 0.25), (10.0, 512, 1e-3), (0.5, 32, 0.1)):
            require(_sigma_problem(impl, *args))
    return grade_parts((1, "a 256-pixel image, 5 % to 95 %", paper),
                       (1, "other widths, image sizes and levels", others))
