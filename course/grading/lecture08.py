"""The checks of lecture 8's graded tasks (differentiable rasterization): 8.1 soft_coverage, 8.2
soft_silhouette, 8.3 soft_blend.

Each check runs the student's function next to a reference on fixed, seeded-random and stress inputs and
says what to fix, recognising the typical mistakes of the task. ``import course.grading`` imports this
module, which registers its checks in ``course.grading.TASKS``.

``course.soft.soft_rasterize`` computes all three inline, on (pixel, face) pairs and from logits, so the
references are written here from the formulas of Liu et al. 2019 (as ``course/soft.py`` states them), on
dense (F, H, W) tensors and in float64; ``tests/test_grading_08.py`` checks that they agree with
``soft_rasterize`` on small scenes. They are public so that those tests (and a curious student) can read
them; a graded function that calls them, or the package functions doing the task's work, scores 0.
"""
from __future__ import annotations

import torch

from .helpers import _call, _close, compare, generator, grade_parts, require, to_tensor
from .registry import forbidden_call, task

__all__ = ["soft_coverage_reference", "soft_silhouette_reference", "soft_blend_reference"]

FORBIDDEN = [("course.soft", "soft_rasterize"), ("course.soft", "_pair_terms"),
             ("course.soft", "_silhouette_terms"), ("course.soft", "_color_terms"),
             ("course.grading.lecture08", "soft_coverage_reference"),
             ("course.grading.lecture08", "soft_silhouette_reference"),
             ("course.grading.lecture08", "soft_blend_reference")]


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


def soft_coverage_reference(tri, height: int, width: int, sigma: float) -> torch.Tensor:
    """8.1, in tri's dtype (computed in float64): see ``_coverage``."""
    return _coverage(tri, height, width, sigma).to(tri.dtype)


def soft_silhouette_reference(D) -> torch.Tensor:
    """8.2, in D's dtype (computed in float64): see ``_silhouette``."""
    return _silhouette(D).to(D.dtype)


def soft_blend_reference(D, z, colors, background, gamma: float, eps: float) -> torch.Tensor:
    """8.3, in D's dtype (computed in float64): see ``_blend``."""
    return _blend(D, z, colors, background, gamma, eps).to(D.dtype)


def _coverage(tri, height: int, width: int, sigma: float) -> torch.Tensor:
    """8.1: ``D = sigmoid(δ d² / σ)`` (H, W) float64 at the pixel centres (j + 0.5, i + 0.5), for the
    triangle tri (3, 2) in pixels; d in normalised device coordinates, ``d_ndc = 2 d_px / width``."""
    return torch.sigmoid(_signed_d2(tri, height, width) * (4.0 / (width * width)) / sigma)


def _silhouette(D) -> torch.Tensor:
    """8.2: the probabilistic OR ``1 - Π_j (1 - D_j)`` (H, W) of D (F, H, W), float64, as
    ``-expm1(Σ_j log1p(-D_j))`` so that faint coverage (D ~ 1e-9) is not rounded away."""
    return -torch.expm1(torch.log1p(-D.to(torch.float64)).sum(0))


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


def _match(got, variants):
    """The explanation of the first ``(alternative, explanation)`` that ``got`` matches, else None."""
    for alternative, explanation in variants:
        if alternative is not None and _close(got, alternative, 1e-4):
            return explanation
    return None


# ------------------------------------------------------------------------------------ 8.1 soft coverage

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


@task("8.1", "soft_coverage", points=3, reference=("course.soft", "soft_rasterize"))
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


# ------------------------------------------------------------------------------- 8.2 probabilistic OR

def _silhouette_problem(impl, D, label, faint=False) -> str | None:
    name = f"soft_silhouette({label})"
    expected = _silhouette(D)
    got = to_tensor(_call(impl, D), name)
    tol = dict(atol=1e-30, rtol=1e-4) if faint else ({} if D.dtype == torch.float32 else dict(atol=1e-12, rtol=1e-9))
    message = compare(got, expected.to(D.dtype), name=name, check_dtype=True, **tol)
    if message is None or "shape" in message or "dtype" in message:
        return message
    if faint and float((got.to(torch.float64) - expected).abs().max()) <= 4 * D.shape[0] * torch.finfo(D.dtype).eps:
        # right to within the rounding of numbers near 1, not to the relative precision of the faint values
        return (f"{name}: 1 − Π(1 − D) loses faint coverage: 1 − D rounds to 1 once D is below the "
                "dtype's precision (6e-8 in float32, 1e-16 in float64); sum log1p(−D_j) and return −expm1 of the sum")
    d = D.to(torch.float64)
    explanation = _match(got, [
        (torch.prod(1 - d, 0), "that is Π(1 − D_j), the probability that *no* face covers the pixel: "
                               "return 1 minus it"),
        (d.sum(0).clamp(max=1), "the sum of the D_j (clamped) is not a probability: combine them as "
                                "1 − Π(1 − D_j) (a pixel is empty only if every face misses it)"),
        (d.amax(0), "the largest D_j ignores the other faces: combine them as 1 − Π(1 − D_j)"),
        (torch.prod(d, 0), "Π D_j is the probability that *every* face covers the pixel: the silhouette is "
                           "1 − Π(1 − D_j)"),
        (d.mean(0), "the mean of the D_j is not the probabilistic OR: 1 − Π(1 − D_j)"),
    ])
    return f"{name}: {explanation}" if explanation else message


@task("8.2", "soft_silhouette", points=3, reference=("course.soft", "soft_rasterize"))
def _check_soft_silhouette(impl):
    forbidden = forbidden_call(impl, "soft_silhouette", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def random():
        D = torch.rand(5, 6, 7, generator=generator(83), dtype=torch.float64) ** 3
        require(_silhouette_problem(impl, D.float(), "5 faces, 6 × 7, float32"))
        require(_silhouette_problem(impl, D, "5 faces, 6 × 7, float64"))

    def saturated():
        D = torch.rand(4, 5, 5, generator=generator(84), dtype=torch.float64)
        D[0, :2] = 1.0                                                     # surely covered
        D[:, 4] = 0.0                                                      # surely empty
        D[1:, 2] = torch.tensor([1e-3, 1 - 1e-9, 0.5])[:, None]
        require(_silhouette_problem(impl, D.float(), "D exactly 0 and 1, float32"))
        require(_silhouette_problem(impl, D, "D exactly 0 and 1, float64"))
        require(_silhouette_problem(impl, D[:1], "a single face, float64"))

    def faint():
        g = generator(85)
        D = 10 ** (-7 - 5 * torch.rand(6, 4, 8, generator=g, dtype=torch.float64))   # 1e-12 .. 1e-7
        require(_silhouette_problem(impl, D.float(), "faint coverage D ~ 1e-12 .. 1e-7, float32", faint=True))
        require(_silhouette_problem(impl, D * 1e-8, "faint coverage D ~ 1e-20 .. 1e-15, float64", faint=True))
    return grade_parts((1, "random coverages", random),
                       (1, "coverage exactly 0 and 1, one face", saturated),
                       (1, "faint coverage far from every face (precision)", faint))


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
