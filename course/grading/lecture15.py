"""The checks of lecture 15's graded tasks (points, Gaussians and volumes): 15.1 covariance_2d, 15.2 composite_pixel,
15.3 swap_jump, 15.4 ray_density.

Each check runs the student's function next to a reference on fixed, seeded-random and stress inputs and
says what to fix, recognising the typical mistakes of the task. ``import course.grading`` imports this
module, which registers its checks in ``course.grading.TASKS``.

* 15.1, a Gaussian's screen covariance (pixels²) from its camera-space mean (OpenCV: +z forward, x right, y down)
  and covariance: the perspective projection's Jacobian at the mean,
  ``J = K₂ [[1/z, 0, -x/z²], [0, 1/z, -y/z²]]`` (K₂ the upper-left 2 × 2 of K, skew included), and Kerbl et
  al.'s low-pass filter, ``Σ₂ = J Σ Jᵀ + 0.3 I``: ``course.splats.project_gaussians`` for a camera with R = I,
  t = 0.
* 15.2, one pixel composited by the rules of Kerbl et al.'s rasterizer (``course.splats``): the raw opacities
  ``a = o exp(-q/2)`` in front-to-back order, ``α = min(0.99, a)``, a Gaussian skipped where ``α < 1/255``,
  ``C += c α T``, ``T ← T (1 - α)``, stopping before the Gaussian that would take T below 1e-4 (neither it nor
  any after it is added), then ``C + T · background``.
* 15.3, the jump in a pixel's colour when two Gaussians (the only ones there) swap depth order:
  ``C(a in front) - C(b in front)``, ``C(x in front) = α_x c_x + (1 - α_x) α_y c_y + (1 - α_x)(1 - α_y) bg``,
  which is ``α_a α_b (c_a - c_b)``: the background cancels.
* 15.4, the analysis: the peak density κ of ``σ(x) = κ exp(-½ (x - μ)ᵀ Σ⁻¹ (x - μ))`` for which the ray
  ``o + s d`` has opacity ``1 - exp(-∫ σ ds)`` equal to the given one. With ``u = d / |d|`` (ds is length) and
  ``P = Σ⁻¹``, ``∫ exp(-½ q(o + s u)) ds = sqrt(2π / (uᵀ P u)) exp(-½ q_min)``,
  ``q_min = (o - μ)ᵀ P (o - μ) - ((o - μ)ᵀ P u)² / (uᵀ P u)`` the smallest q along the line, so
  ``κ = -ln(1 - opacity) / (sqrt(2π / (uᵀ P u)) exp(-½ q_min))`` (``course.splats.render_gaussians_volume`` on
  the ray through the mean, q_min = 0). The tolerance, ``rtol = 1e-8``, lets through a fine numerical quadrature
  of the line integral; every typical mistake is off by far more.

The references are written here, in float64; ``tests/test_grading_15.py`` checks that they agree with the
package (and 15.4 with a numerical quadrature). A graded function that calls them, or the package functions
doing the task's work, scores 0.
"""
from __future__ import annotations

import math
import numbers

import torch

from .helpers import _call, _close, _match, compare, grade_parts, require, summarize_exception, to_tensor
from .registry import forbidden_call, task

__all__ = ["covariance_2d_reference", "composite_pixel_reference", "swap_jump_reference", "ray_density_reference"]

ALPHA_MIN = 1.0 / 255.0  # the rules of course.splats (and of Kerbl et al.'s rasterizer)
ALPHA_MAX = 0.99
T_MIN = 1e-4
BLUR = 0.3

FORBIDDEN = [("course.splats", "project_gaussians"), ("course.splats", "render_gaussians"),
             ("course.splats", "_composite"), ("course.splats", "render_gaussians_volume"),
             ("course.splats", "volume_strength"),
             ("course.grading.lecture15", "covariance_2d_reference"),
             ("course.grading.lecture15", "composite_pixel_reference"),
             ("course.grading.lecture15", "swap_jump_reference"),
             ("course.grading.lecture15", "ray_density_reference")]


# ------------------------------------------------------------------------------------- the references

def covariance_2d_reference(mean_cam, cov_cam, K) -> torch.Tensor:
    """15.1: (2, 2) ``J cov_cam Jᵀ + 0.3 I`` in pixels², J the perspective Jacobian at ``mean_cam`` (3,) times
    K's upper-left 2 × 2."""
    return _cov2(mean_cam, cov_cam, K)


def composite_pixel_reference(alphas, colors, background) -> torch.Tensor:
    """15.2: (3,) the pixel's colour from raw opacities ``alphas`` (N,) front to back, ``colors`` (N, 3) and
    ``background`` (3,), by Kerbl et al.'s rules (clamp 0.99, skip below 1/255, stop before T < 1e-4)."""
    return _composite_pixel(alphas, colors, background)


def swap_jump_reference(alpha_a, color_a, alpha_b, color_b, background) -> torch.Tensor:
    """15.3: (3,) ``C(a in front) - C(b in front)`` for two Gaussians alone at a pixel."""
    return _swap(alpha_a, color_a, alpha_b, color_b, background)


def ray_density_reference(mean, cov, origin, direction, opacity) -> torch.Tensor:
    """15.4: the 0-dim κ for which the ray ``origin + s direction`` through ``κ exp(-½ (x - μ)ᵀ Σ⁻¹ (x - μ))``
    has the given opacity."""
    return _density(mean, cov, origin, direction, opacity)


def _f64(*tensors):
    return [torch.as_tensor(t).to(torch.float64) for t in tensors]


def _cov2(mean_cam, cov_cam, K, kind="course"):
    """``kind`` gives a typical mistake's answer instead: "no_blur" (0.3 I left out), "orthographic" (J without
    its -x/z², -y/z² column), "fx_only" (K₂ = fx I), "blur_everywhere" (0.3 added to every entry)."""
    dtype = torch.as_tensor(cov_cam).dtype
    m, S, Km = _f64(mean_cam, cov_cam, K)
    x, y, z = m.unbind()
    zero = torch.zeros((), dtype=torch.float64)
    if kind == "orthographic":
        P = torch.stack([torch.stack([1 / z, zero, zero]), torch.stack([zero, 1 / z, zero])])
    else:
        P = torch.stack([torch.stack([1 / z, zero, -x / z ** 2]), torch.stack([zero, 1 / z, -y / z ** 2])])
    K2 = Km[0, 0] * torch.eye(2, dtype=torch.float64) if kind == "fx_only" else Km[:2, :2]
    J = K2 @ P
    cov = J @ S @ J.T
    if kind == "blur_everywhere":
        cov = cov + BLUR
    elif kind != "no_blur":
        cov = cov + BLUR * torch.eye(2, dtype=torch.float64)
    return cov.to(dtype)


def _composite_pixel(alphas, colors, background, kind="course"):
    """``kind``: "no_clamp", "no_skip", "after" (the stopping Gaussian added, then stop), "never_stop",
    "continue" (the stopping Gaussian skipped, the ones after it still added), "reversed" (the list taken as
    back to front), "no_background"."""
    dtype = torch.as_tensor(alphas).dtype
    A, Cs, bg = _f64(alphas, colors, background)
    if kind == "reversed":
        A, Cs = A.flip(0), Cs.flip(0)
    C = torch.zeros(3, dtype=torch.float64)
    T = torch.ones((), dtype=torch.float64)
    for a, c in zip(A, Cs):
        alpha = a if kind == "no_clamp" else a.clamp(max=ALPHA_MAX)
        if kind != "no_skip" and bool(alpha < ALPHA_MIN):
            continue
        if kind != "never_stop" and bool(T * (1 - alpha) < T_MIN):
            if kind == "continue":
                continue
            if kind == "after":
                C, T = C + c * alpha * T, T * (1 - alpha)
            break
        C, T = C + c * alpha * T, T * (1 - alpha)
    if kind == "no_background":
        return C.to(dtype)
    return (C + T * bg).to(dtype)


def _swap(alpha_a, color_a, alpha_b, color_b, background, kind="course"):
    """``kind``: "sign" (b in front minus a in front), "no_transmittance" (α_a c_a - α_b c_b)."""
    dtype = torch.as_tensor(color_a).dtype
    aa, ca, ab, cb, bg = _f64(alpha_a, color_a, alpha_b, color_b, background)
    if kind == "no_transmittance":
        return (aa * ca - ab * cb).to(dtype)

    def front(ax, cx, ay, cy):
        return ax * cx + (1 - ax) * ay * cy + (1 - ax) * (1 - ay) * bg
    jump = front(aa, ca, ab, cb) - front(ab, cb, aa, ca)
    return (-jump if kind == "sign" else jump).to(dtype)


def _density(mean, cov, origin, direction, opacity, kind="course"):
    """κ as a 0-dim tensor. ``kind``: "unnormalised" (d used with its length), "no_qmin" (the ray taken through
    the mean), "inverted" (sqrt(2π uᵀ Σ⁻¹ u)), "opacity" (the opacity for the optical depth)."""
    dtype = torch.as_tensor(mean).dtype
    m, S, o, d, op = _f64(mean, cov, origin, direction, opacity)
    P = torch.linalg.inv(S)
    u = d if kind == "unnormalised" else d / d.norm()
    a = u @ P @ u
    r = o - m
    q_min = r @ P @ r - (r @ P @ u) ** 2 / a
    if kind == "no_qmin":
        q_min = torch.zeros_like(q_min)
    line = (torch.sqrt(2 * math.pi * a) if kind == "inverted" else torch.sqrt(2 * math.pi / a)) * torch.exp(-q_min / 2)
    tau = op if kind == "opacity" else -torch.log1p(-op)
    return (tau / line).to(dtype)


def _telling(variants, expected, tol=1e-6):
    """The ``(alternative, explanation)`` pairs whose alternative differs from the expected result: only those
    can tell a mistake."""
    return [(a, why) for a, why in variants if a is not None and not _close(a, expected, tol)]


def _no_gradient(fn, what):
    return (f"{fn}: the value is right but no gradient reaches {what}: compute with tensor operations (no .item(), "
            "float(), .tolist() or numpy) and return the tensor")


def _tol(dtype):
    return dict(atol=1e-5, rtol=1e-4) if dtype == torch.float32 else dict(atol=1e-12, rtol=1e-10)


def _gradient(impl, fn, label, args, wrt, names, reference, symmetric=()):
    """The gradient of ``Σ w ⊙ impl(*args)`` (fixed weights) with respect to ``args[i]`` for i in ``wrt``,
    against autograd through ``reference``; a gradient named in ``symmetric`` is compared symmetrised (the
    function may read either triangle of a symmetric matrix)."""
    leaves = [a.clone().requires_grad_(i in wrt) if isinstance(a, torch.Tensor) else a for i, a in enumerate(args)]
    out = impl(*leaves)
    listed = [names[i] for i in wrt]
    what = listed[0] if len(listed) == 1 else ", ".join(listed[:-1]) + " and " + listed[-1]
    if not (isinstance(out, torch.Tensor) and out.requires_grad):
        return _no_gradient(f"{fn}({label})", what)
    refs = [a.clone().requires_grad_(i in wrt) if isinstance(a, torch.Tensor) else a for i, a in enumerate(args)]
    expected = reference(*refs)
    weights = torch.linspace(-1.0, 2.0, expected.numel(), dtype=torch.float64).view(expected.shape)
    if out.shape != expected.shape:
        return f"{fn}({label}): shape {tuple(expected.shape)} expected, got {tuple(out.shape)}"
    got = torch.autograd.grad((out * weights.to(out.dtype)).sum(), [leaves[i] for i in wrt], allow_unused=True)
    want = torch.autograd.grad((expected * weights).sum(), [refs[i] for i in wrt])
    for g, w, i in zip(got, want, wrt):
        if g is None:
            return _no_gradient(f"{fn}({label})", names[i])
        if names[i] in symmetric:
            g, w = (g + g.T) / 2, (w + w.T) / 2
        bad = compare(g, w, name=f"{fn}({label}): the gradient w.r.t. {names[i]}", check_dtype=False,
                      atol=1e-10, rtol=1e-8)
        if bad:
            return bad
    return None


def _rotation(seed):
    """A seeded random rotation (float64)."""
    g = torch.Generator().manual_seed(seed)
    Q, R = torch.linalg.qr(torch.randn(3, 3, generator=g, dtype=torch.float64))
    Q = Q * torch.sign(torch.diagonal(R))
    return Q if float(torch.linalg.det(Q)) > 0 else -Q


def _covariance(scales, seed):
    """``R S Sᵀ Rᵀ`` for a seeded random rotation R and S = diag(scales)."""
    M = _rotation(seed) * torch.tensor(scales, dtype=torch.float64)
    return M @ M.T


# ---------------------------------------------------------------------------------- 15.1 covariance_2d

def _cov_cases():
    """(ahead, off_axis) lists of (label, mean_cam, cov_cam, K)."""
    f64 = lambda v: torch.tensor(v, dtype=torch.float64)                   # noqa: E731
    K = f64([[500.0, 0.0, 320.0], [0.0, 450.0, 240.0], [0.0, 0.0, 1.0]])    # fx != fy
    skewed = f64([[520.0, 15.0, 300.0], [0.0, 470.0, 250.0], [0.0, 0.0, 1.0]])
    ahead = [("a Gaussian straight ahead at z = 4, fx = 500, fy = 450", f64([0.0, 0.0, 4.0]),
              _covariance([0.3, 0.1, 0.2], 151), K),
             ("a Gaussian straight ahead at z = 2.5, a skewed K", f64([0.0, 0.0, 2.5]),
              _covariance([0.05, 0.2, 0.15], 152), skewed)]
    off_axis = [("a Gaussian at (0.8, -0.5, 3), fx = 500, fy = 450", f64([0.8, -0.5, 3.0]),
                 _covariance([0.3, 0.1, 0.2], 153), K),
                ("a Gaussian at (-1.2, 0.9, 5.5), a skewed K", f64([-1.2, 0.9, 5.5]),
                 _covariance([0.4, 0.25, 0.1], 154), skewed),
                ("a Gaussian far off-axis at (2, 1.5, 2.2), a skewed K", f64([2.0, 1.5, 2.2]),
                 _covariance([0.1, 0.3, 0.05], 155), skewed)]
    return ahead, off_axis


def _cov_problem(impl, label, mean_cam, cov_cam, K):
    name = f"covariance_2d({label})"
    try:
        out = _call(impl, mean_cam, cov_cam, K)
    except RuntimeError as exc:                                               # the student's code
        text = str(exc)
        if "cannot be multiplied" in text or "size mismatch" in text or "shape" in text:
            return (f"{name}: the matrix shapes do not fit ({summarize_exception(exc)}): J is 2 × 3 (two pixel "
                    "coordinates by three camera coordinates), so Σ₂ = J Σ Jᵀ, (2 × 3)(3 × 3)(3 × 2) = 2 × 2, not "
                    "Jᵀ Σ J")
        raise
    got = to_tensor(out, name)
    expected = _cov2(mean_cam, cov_cam, K)
    if tuple(got.shape) == (3, 3):
        return (f"{name}: shape (2, 2) expected, got (3, 3): J is 2 × 3 (two pixel coordinates by three camera "
                "coordinates), so Σ₂ = J Σ Jᵀ is 2 × 2; Jᵀ (...) J is 3 × 3")
    message = compare(got, expected, name=name, check_dtype=True, **_tol(cov_cam.dtype))
    if message is None or "dtype" in message or "shape" in message:
        return message
    explanation = _match(got, _telling([
        (_cov2(mean_cam, cov_cam, K, "no_blur"), "the low-pass filter is missing: Kerbl et al. add 0.3 px² to the "
                                                 "diagonal, Σ₂ = J Σ Jᵀ + 0.3 I, so no splat is thinner than a "
                                                 "pixel"),
        (_cov2(mean_cam, cov_cam, K, "blur_everywhere"), "0.3 was added to every entry: the low-pass filter is "
                                                         "0.3 I, on the diagonal only (an isotropic blur adds no "
                                                         "correlation between x and y)"),
        (_cov2(mean_cam, cov_cam, K, "orthographic"), "J lacks its third column: the pixel position x/z, y/z also "
                                                      "moves with z, so ∂(x/z)/∂z = -x/z² and ∂(y/z)/∂z = -y/z², "
                                                      "J = K₂ [[1/z, 0, -x/z²], [0, 1/z, -y/z²]]"),
        (_cov2(mean_cam, cov_cam, K, "fx_only"), "only fx was used: the pixel position is K₂ (x/z, y/z) + (cx, cy), "
                                                 "so J is K's upper-left 2 × 2 (fx, skew; 0, fy) times the "
                                                 "projection's Jacobian"),
    ], expected))
    return f"{name}: {explanation}" if explanation else message


@task("15.1", "covariance_2d", points=3, reference=("course.splats", "project_gaussians"))
def _check_covariance(impl):
    forbidden = forbidden_call(impl, "covariance_2d", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    ahead, off_axis = _cov_cases()

    def straight():
        for case in ahead:
            require(_cov_problem(impl, *case))

    def off():
        for case in off_axis:
            require(_cov_problem(impl, *case))

    def stress():
        for label, m, S, K in (ahead[0], off_axis[1]):
            require(_cov_problem(impl, label + ", float32", m.float(), S.float(), K.float()))
        label, m, S, K = off_axis[1]
        require(_gradient(impl, "covariance_2d", label, (m, S, K), (0, 1), ("mean_cam", "cov_cam", "K"), _cov2,
                          symmetric=("cov_cam",)))
    return grade_parts((1, "a Gaussian straight ahead", straight), (1, "off-axis Gaussians, a skewed K", off),
                       (1, "float32, the gradient", stress))


# --------------------------------------------------------------------------------- 15.2 composite_pixel

def _composite_cases():
    """(basic, cut, stop): lists of (label, alphas, colors, background)."""
    f64 = lambda v: torch.tensor(v, dtype=torch.float64)                   # noqa: E731
    g = torch.Generator().manual_seed(152)
    colors = lambda n: torch.rand(n, 3, generator=g, dtype=torch.float64)  # noqa: E731
    grey = f64([0.2, 0.3, 0.4])
    basic = [("three Gaussians, a grey background", f64([0.6, 0.3, 0.45]), colors(3), grey),
             ("five Gaussians, a white background", f64([0.15, 0.7, 0.25, 0.5, 0.35]), colors(5),
              f64([1.0, 1.0, 1.0]))]
    cut = [("a faint one (a = 0.002 < 1/255) between two others", f64([0.5, 0.002, 0.7]), colors(3), grey),
           ("a = 1 (clamped to 0.99) behind a = 0.4", f64([0.4, 1.0, 0.8]), colors(3), grey),
           ("a = 0.996 (clamped to 0.99) in front, a faint a = 0.003 behind it", f64([0.996, 0.003, 0.6]),
            colors(3), f64([0.9, 0.1, 0.5]))]
    stop = [("six Gaussians, the fourth would take T below 1e-4", f64([0.8, 0.9, 0.97, 0.9, 0.02, 0.6]),
             colors(6), grey)]
    return basic, cut, stop


def _composite_problem(impl, label, alphas, colors, background):
    name = f"composite_pixel({label})"
    got = to_tensor(_call(impl, alphas, colors, background), name)
    expected = _composite_pixel(alphas, colors, background)
    message = compare(got, expected, name=name, check_dtype=True, **_tol(alphas.dtype))
    if message is None or "dtype" in message or "shape" in message:
        return message
    stop = ("stop before the Gaussian that would take T below 1e-4: when T (1 - α) < 1e-4 that Gaussian is not "
            "added, and neither is any after it")

    def wrong(kind):
        return _composite_pixel(alphas, colors, background, kind)
    explanation = _match(got, _telling([
        (wrong("no_background"), "the background is missing: what the Gaussians let through, T, shows the "
                                 "background, so return C + T · background"),
        (wrong("reversed"), "composited in the wrong order: the Gaussians come front to back, alphas[0] the "
                            "nearest, which is seen with T = 1"),
        (wrong("no_clamp"), "α was not clamped: α = min(0.99, a), so no Gaussian is fully opaque"),
        (wrong("no_skip"), "a faint Gaussian was added: skip a Gaussian whose α < 1/255 (it leaves C and T as "
                           "they are)"),
        (wrong("after"), "the Gaussian that takes T below 1e-4 was added: " + stop),
        (wrong("never_stop"), "compositing never stopped: " + stop),
        (wrong("continue"), "Gaussians after the stopping one were added: " + stop),
    ], expected))
    return f"{name}: {explanation}" if explanation else message


@task("15.2", "composite_pixel", points=3, reference=("course.splats", "_composite"))
def _check_composite(impl):
    forbidden = forbidden_call(impl, "composite_pixel", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    basic, cut, stop = _composite_cases()

    def few():
        for case in basic:
            require(_composite_problem(impl, *case))

    def cut_offs():
        for case in cut:
            require(_composite_problem(impl, *case))

    def stress():
        for case in stop:
            require(_composite_problem(impl, *case))
        label, a, c, bg = basic[1]
        require(_composite_problem(impl, label + ", float32", a.float(), c.float(), bg.float()))
        label, a, c, bg = basic[0]
        require(_gradient(impl, "composite_pixel", label, (a, c, bg), (0, 1), ("alphas", "colors", "background"),
                          _composite_pixel))
    return grade_parts((1, "a few Gaussians", few), (1, "a faint one skipped, the 0.99 clamp", cut_offs),
                       (1, "the early stop, float32, the gradient", stress))


# ---------------------------------------------------------------------------------------- 15.3 swap_jump

def _swap_cases():
    """(random, special): lists of (label, alpha_a, color_a, alpha_b, color_b, background)."""
    g = torch.Generator().manual_seed(153)
    f64 = lambda v: torch.tensor(v, dtype=torch.float64)                   # noqa: E731

    def rand(*shape):
        return torch.rand(*shape, generator=g, dtype=torch.float64)
    random = [(f"random alphas and colours ({k + 1})", 0.1 + 0.8 * rand(()), rand(3), 0.1 + 0.8 * rand(()), rand(3),
               rand(3)) for k in range(3)]
    same = rand(3)
    special = [("equal colours", f64(0.7), same, f64(0.4), same.clone(), rand(3)),
               ("equal alphas 0.5", f64(0.5), rand(3), f64(0.5), rand(3), rand(3))]
    return random, special


def _swap_problem(impl, label, aa, ca, ab, cb, bg):
    name = f"swap_jump({label})"
    got = to_tensor(_call(impl, aa, ca, ab, cb, bg), name)
    expected = _swap(aa, ca, ab, cb, bg)
    message = compare(got, expected, name=name, check_dtype=True, **_tol(ca.dtype))
    if message is None or "dtype" in message or "shape" in message:
        return message
    explanation = _match(got, _telling([
        (_swap(aa, ca, ab, cb, bg, "sign"), "the sign: the jump is C(a in front) - C(b in front), not the other way "
                                            "round"),
        (_swap(aa, ca, ab, cb, bg, "no_transmittance"), "the one behind is seen through the one in front: "
                                                        "C(a in front) = α_a c_a + (1 - α_a) α_b c_b + "
                                                        "(1 - α_a)(1 - α_b) bg; the (1 - α) factor is missing"),
    ], expected))
    return f"{name}: {explanation}" if explanation else message


@task("15.3", "swap_jump", points=2, reference=("course.grading.lecture15", "swap_jump_reference"))
def _check_swap(impl):
    forbidden = forbidden_call(impl, "swap_jump", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    random, special = _swap_cases()

    def values():
        for case in random:
            require(_swap_problem(impl, *case))

    def stress():
        for case in special:
            require(_swap_problem(impl, *case))
        label, aa, ca, ab, cb, bg = random[0]
        require(_swap_problem(impl, label + ", float32", aa.float(), ca.float(), ab.float(), cb.float(), bg.float()))
        require(_gradient(impl, "swap_jump", label, random[0][1:], (0, 1, 2, 3),
                          ("alpha_a", "color_a", "alpha_b", "color_b", "background"), _swap))
    return grade_parts((1, "random alphas and colours", values),
                       (1, "equal colours, equal alphas, float32, the gradient", stress))


# -------------------------------------------------------------------------- 15.4 ray_density (an analysis)

RTOL_DENSITY, ATOL_DENSITY = 1e-8, 1e-12


def _density_cases():
    """(through, offset, rotated, transparent): lists of (label, mean, cov, origin, direction, opacity)."""
    f64 = lambda v: torch.tensor(v, dtype=torch.float64)                   # noqa: E731
    zero = f64([0.0, 0.0, 0.0])
    mu = f64([0.3, -0.2, 4.0])
    iso = 0.25 * torch.eye(3, dtype=torch.float64)
    to_mu = (mu - zero) / (mu - zero).norm()
    side = f64([1.0, 1.0, 0.0])
    through = [("the ray from the origin through the mean, Σ = 0.25 I, a unit direction, opacity 0.6", mu, iso, zero,
                to_mu, f64(0.6)),
               ("the same ray, the direction 3.7 long, opacity 0.3", mu, iso, zero, 3.7 * to_mu, f64(0.3)),
               ("a ray through the mean from (1, 1, 0), the direction 0.5 long, opacity 0.9", mu, iso, side,
                0.5 * (mu - side) / (mu - side).norm(), f64(0.9))]
    axes = torch.diag(f64([0.09, 0.16, 0.25]))
    offset = [("a ray along z passing (0.3, 0.2) off the mean, Σ = diag(0.09, 0.16, 0.25), a unit direction, "
               "opacity 0.5", f64([0.0, 0.0, 3.0]), axes, f64([0.3, 0.2, 0.0]), f64([0.0, 0.0, 1.0]), f64(0.5)),
              ("an oblique ray off the mean, Σ = diag(0.09, 0.16, 0.25), a unit direction, opacity 0.8",
               f64([0.5, -0.3, 2.0]), axes, f64([-0.2, 0.1, 0.0]), f64([0.6, -0.5, 2.0]) / f64([0.6, -0.5, 2.0]).norm(),
               f64(0.8))]
    rot = _covariance([0.6, 0.2, 0.35], 154)
    m2 = f64([-0.4, 0.6, 3.5])
    rotated = [("a rotated anisotropic Σ, the ray through the mean, the direction 2.5 long, opacity 0.7", m2, rot,
                zero, 2.5 * (m2 / m2.norm()), f64(0.7)),
               ("a rotated anisotropic Σ, an offset oblique ray, the direction 0.4 long, opacity 0.95", m2, rot,
                f64([0.1, 0.3, 0.2]), f64([-0.2, 0.12, 0.4]), f64(0.95))]
    transparent = [("opacity 0, the ray through the mean", mu, iso, zero, 3.7 * to_mu, f64(0.0)),
                   ("opacity 0, a rotated Σ, an offset ray", m2, rot, f64([0.1, 0.3, 0.2]), f64([-0.2, 0.12, 0.4]),
                    f64(0.0))]
    return through, offset, rotated, transparent


def _density_problem(impl, label, mean, cov, origin, direction, opacity):
    name = f"ray_density({label})"
    out = _call(impl, mean, cov, origin, direction, opacity)
    if isinstance(out, numbers.Real) and not isinstance(out, bool):          # float, int, numpy scalars
        got = torch.tensor(float(out), dtype=torch.float64)
    else:
        got = to_tensor(out, name)
        if got.numel() != 1:
            return f"{name}: one number expected, got shape {tuple(got.shape)}"
        got = got.reshape(()).to(torch.float64)
    expected = _density(mean, cov, origin, direction, opacity)
    message = compare(got, expected, name=name, check_dtype=False, atol=ATOL_DENSITY, rtol=RTOL_DENSITY)
    if message is None:
        return None
    if float(opacity) == 0.0:
        return f"{name}: a transparent ray (opacity 0) needs no density: 0 expected, got {float(got):.6g}"
    args = (mean, cov, origin, direction, opacity)
    explanation = _match(got, _telling([
        (_density(*args, "unnormalised"), "the result depends on the direction's length: ∫ σ ds is along the ray's "
                                          "length, so integrate along the unit direction u = d / |d| (along "
                                          "o + s d, a unit of s covers |d| of length)"),
        (_density(*args, "no_qmin"), "this ray misses the mean: along it the exponent never reaches 0 but only its "
                                     "smallest value q_min, so the line integral is "
                                     "sqrt(2π / (uᵀ Σ⁻¹ u)) exp(-½ q_min); complete the square in s"),
        (_density(*args, "inverted"), "the Gaussian integral is inverted: ∫ exp(-½ a s²) ds = sqrt(2π / a), "
                                      "a = uᵀ Σ⁻¹ u, not sqrt(2π a)"),
        (_density(*args, "opacity"), "the opacity is not the optical depth: the ray's opacity is 1 - exp(-∫ σ ds), "
                                     "so ∫ σ ds must be -ln(1 - opacity)"),
    ], expected, tol=1e-9), tol=1e-9)
    return f"{name}: {explanation}" if explanation else message


@task("15.4", "ray_density", points=4, reference=("course.grading.lecture15", "ray_density_reference"))
def _check_density(impl):
    forbidden = forbidden_call(impl, "ray_density", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    through, offset, rotated, transparent = _density_cases()

    def run(cases):
        def part():
            for case in cases:
                require(_density_problem(impl, *case))
        return part
    return grade_parts((1, "rays through the mean, directions of any length", run(through)),
                       (1, "rays that miss the mean", run(offset)),
                       (1, "a rotated anisotropic Σ", run(rotated)),
                       (1, "opacity 0", run(transparent)))
