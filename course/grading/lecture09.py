"""The checks of lecture 9's graded tasks (visibility gradients): 9.1 best_step, 9.2 boundary_term,
9.3 triangle_term, 9.4 edge_sample.

Each check runs the student's function next to a reference on fixed, seeded-random and stress inputs and
says what to fix, recognising the typical mistakes of the task. ``import course.grading`` imports this
module, which registers its checks in ``course.grading.TASKS``.

9.1 is an analysis: the central difference (f(x + h e_i) − f(x − h e_i)) / 2h of a function the grader
chooses, evaluated in a given dtype at each of a list of steps, its relative error ‖g − grad‖ / ‖grad‖ to the
exact gradient, and the step where that error is smallest, with its error. The answer depends on the
function (its size |f| sets the round-off, its third derivative the truncation) and on the dtype, so the
check runs the student's function on functions, points and dtypes of its own.

9.2 to 9.4 live on one pixel and straight edges, the example lecture 09 works by hand. An edge runs
p0 → p1 (pixels, x right, y down); its points move, p(s) = p0 + s (p1 − p0) at the velocity
v(s) = (1 − s) v0 + s v1 (s in [0, 1]); the region on the edge's right as drawn on screen, the side its normal
n = (e_y, −e_x) / |e| (e = p1 − p0) points *away* from, has colour c_in, the other side c_out, and
jump = c_in − c_out. The Reynolds transport theorem (Zhang et al. 2019, 2020) gives the rate of change of
the pixel's box-filtered value (the integral of the colour over its unit square):

    d value / dt = ∫_{edge ∩ pixel} jump (v · n) ds,

and since v · n is linear along the edge, the integral is ``|e| (s1 − s0) jump (v(s_mid) · n)`` with
[s0, s1] the part of the edge inside the square and s_mid its middle (9.2). A flat triangle of colour c over a
background b (9.3) is the sum of its three edges' terms, each edge oriented so that its normal leaves the
triangle (jump = c − b): the orientation follows the triangle's winding, which the check varies. Edge sampling
(Li et al. 2018) estimates 9.2's integral from N uniform points on the whole edge:
``|e| / N Σ_k [p(s_k) in pixel] jump (v(s_k) · n)`` (9.4).

The references are written here from these formulas, in float64; ``tests/test_grading_09.py`` checks that
they agree with autograd through ``course.coverage.halfplane_pixel_area`` and with
``course.visibility.image_gradient(method="exact")`` on a one-triangle scene. They are public so that those
tests (and a curious student) can read them; a graded function that calls them, or the package functions
doing the task's work, scores 0.
"""
from __future__ import annotations

import math

import torch

from .helpers import (Fail, _call, _close, _frames, _not_attempted, compare, generator, grade_parts, require,
                      to_tensor)
from .registry import forbidden_call, task

__all__ = ["best_step_reference", "boundary_term_reference", "triangle_term_reference", "edge_sample_reference"]

FORBIDDEN = [("course.visibility", "image_gradient"), ("course.visibility", "fd_gradient"),
             ("course.boundary", "boundary_gradient"), ("course.boundary", "boundary_points"),
             ("course.coverage", "halfplane_pixel_area"),
             ("course.grading.lecture09", "best_step_reference"),
             ("course.grading.lecture09", "boundary_term_reference"),
             ("course.grading.lecture09", "triangle_term_reference"),
             ("course.grading.lecture09", "edge_sample_reference")]


# ------------------------------------------------------------------------------------- the references

def best_step_reference(f, x, grad, steps, dtype) -> tuple[float, float]:
    """9.1: ``(h, error)``, the step of ``steps`` whose central difference of f at x, computed in ``dtype``, has
    the smallest relative error ‖g − grad‖ / ‖grad‖ (computed in float64), and that error."""
    return _best(f, x, grad, steps, dtype)


def boundary_term_reference(p0, p1, v0, v1, jump, col: int, row: int) -> torch.Tensor:
    """9.2: ``∫_{edge ∩ pixel} jump (v · n) ds`` (C,) in jump's dtype (computed in float64): see the module."""
    return _boundary(p0, p1, v0, v1, jump, col, row).to(jump.dtype)


def triangle_term_reference(tri, vel, color, background, col: int, row: int) -> torch.Tensor:
    """9.3: d(pixel value)/dt (C,) of a flat triangle ``tri`` (3, 2) of colour ``color`` (C,) over ``background``
    (C,) whose vertices move at ``vel`` (3, 2): its three edges' boundary terms, each edge's normal out of the
    triangle; in color's dtype (computed in float64)."""
    return _triangle(tri, vel, color, background, col, row).to(color.dtype)


def edge_sample_reference(p0, p1, v0, v1, jump, col: int, row: int, samples: int, gen) -> torch.Tensor:
    """9.4: the edge-sampling estimate (C,) of 9.2's integral from ``samples`` uniform points on the edge,
    s = ``torch.rand(samples, generator=gen)``, in jump's dtype (computed in float64)."""
    s = torch.rand(samples, generator=gen, dtype=torch.float64)
    return _estimate(p0, p1, v0, v1, jump, col, row, s).to(jump.dtype)


def _central(f, x, h, forward=False, denominator=2.0) -> torch.Tensor:
    """(N,) central (or forward) differences of f at x, one coordinate at a time, in x's dtype."""
    out = []
    for i in range(x.shape[0]):
        e = torch.zeros_like(x)
        e[i] = h
        lo = f(x) if forward else f(x - e)
        out.append((torch.as_tensor(f(x + e)) - torch.as_tensor(lo)) / (h if forward else denominator * h))
    return torch.stack(out).to(x.dtype)


def _step_errors(f, x, grad, steps, dtype, *, forward=False, cast=True, relative=True) -> list[float]:
    """The error of the central difference at each step, and the typical mistakes as switches: ``forward``
    (the forward difference), ``cast`` (evaluate in ``dtype``; else in x's own dtype), ``relative`` (divide by
    ‖grad‖; else the absolute error)."""
    x = x.to(dtype) if cast else x
    grad = torch.as_tensor(grad).to(torch.float64)
    errors = []
    for h in steps:
        err = (_central(f, x, h, forward=forward).to(torch.float64) - grad).norm()
        errors.append(float(err / grad.norm() if relative else err))
    return errors


def _best(f, x, grad, steps, dtype, worst=False, **mistake) -> tuple[float, float]:
    errors = _step_errors(f, x, grad, steps, dtype, **mistake)
    k = (max if worst else min)(range(len(steps)), key=errors.__getitem__)
    return float(steps[k]), errors[k]


def _f64(*xs):
    return [torch.as_tensor(x).to(torch.float64) for x in xs]


def _clip(p0, p1, col, row, clip=True):
    """[s0, s1] (floats), the part of p0 + s (p1 − p0), s in [0, 1], inside [col, col+1] × [row, row+1]
    (Liang–Barsky); s1 <= s0 when the edge misses the square. ``clip=False``: the whole edge [0, 1]."""
    if not clip:
        return 0.0, 1.0
    s0, s1 = 0.0, 1.0
    for k, lo in ((0, float(col)), (1, float(row))):
        a, d = float(p0[k]), float(p1[k] - p0[k])
        if d == 0.0:
            if not lo <= a <= lo + 1.0:
                return 0.0, 0.0
            continue
        t0, t1 = sorted(((lo - a) / d, (lo + 1.0 - a) / d))
        s0, s1 = max(s0, t0), min(s1, t1)
    return s0, s1


def _boundary(p0, p1, v0, v1, jump, col, row, *, clip=True, length=True, sign=1.0, unit=True,
              normal=True, middle="piece") -> torch.Tensor:
    """9.2 (C,) float64, and the typical mistakes as switches: ``clip`` (to the pixel), ``length`` (times the
    piece's length), ``sign`` (of the normal), ``unit`` (normal normalised), ``normal`` (v · n, else |v|),
    ``middle`` ("piece": the speed at the clipped piece's middle; "edge": at the whole edge's middle)."""
    p0, p1, v0, v1, jump = _f64(p0, p1, v0, v1, jump)
    e = p1 - p0
    L = float(e.norm())
    s0, s1 = _clip(p0, p1, col, row, clip)
    if L == 0.0 or s1 <= s0:
        return torch.zeros_like(jump)
    n = sign * torch.stack([e[1], -e[0]]) / (L if unit else 1.0)         # outward: away from the c_in side
    sm = 0.5 * (s0 + s1) if middle == "piece" else 0.5
    v = (1.0 - sm) * v0 + sm * v1                                         # linear along the edge
    speed = (v * n).sum() if normal else v.norm()
    return jump * speed * ((s1 - s0) * (L if length else 1.0))


def _estimate(p0, p1, v0, v1, jump, col, row, s, *, length=True, per_hit=False) -> torch.Tensor:
    """9.4 (C,) float64 at the points s (N,) of the edge; mistakes: no length weight, dividing by the hits."""
    p0, p1, v0, v1, jump = _f64(p0, p1, v0, v1, jump)
    e = p1 - p0
    L = float(e.norm())
    if L == 0.0:
        return torch.zeros_like(jump)
    p = p0 + s[:, None] * e                                               # (N, 2) points on the edge
    v = (1.0 - s[:, None]) * v0 + s[:, None] * v1                         # (N, 2) their velocities
    n = torch.stack([e[1], -e[0]]) / L
    inside = ((p[:, 0] >= col) & (p[:, 0] < col + 1) & (p[:, 1] >= row) & (p[:, 1] < row + 1)).to(s.dtype)
    total = (inside * (v * n).sum(1)).sum()
    count = max(float(inside.sum()), 1.0) if per_hit else float(s.shape[0])
    return jump * total * ((L if length else 1.0) / count)


def _match(got, variants, tol=1e-6):
    """The explanation of the first ``(alternative, explanation)`` that ``got`` matches, else None."""
    for alternative, explanation in variants:
        if alternative is not None and _close(got, alternative, tol):
            return explanation
    return None



# ------------------------------------------------------------------------------------- 9.1 the best step

def _smooth(x):
    """A smooth test function of (N,) → scalar, of order one near 0, in x's dtype."""
    w = torch.arange(1, x.shape[0] + 1, dtype=x.dtype)
    return (w * torch.exp(0.5 * x)).sum() + x[0] * x[1] ** 2


def _far(x):
    """The same function lifted by 1000: the same derivatives, a thousand times the round-off."""
    return _smooth(x) + 1000.0


def _pair(out, name) -> tuple[float, float]:
    """A student's ``(h, error)`` as two floats, or ``Fail`` saying what was expected."""
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        raise Fail(f"{name}: return a pair (h, error), got {type(out).__name__}"
                   + (f" of {len(out)}" if isinstance(out, (tuple, list)) else ""))
    values = []
    for value, what in zip(out, ("h", "error")):
        if isinstance(value, torch.Tensor) and value.numel() == 1:
            value = value.item()
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            raise Fail(f"{name}: {what} should be a number, got {type(value).__name__}")
        values.append(float(value))
    return values[0], values[1]


def _step_problem(impl, f, x, steps, dtype, label) -> str | None:
    name = f"best_step({label})"
    xg = x.clone().requires_grad_(True)
    f(xg).backward()                                                        # the exact gradient, float64
    grad = xg.grad.detach()
    h, err = _pair(_call(impl, f, x, grad, list(steps), dtype), name)
    want_h, want_err = _best(f, x, grad, steps, dtype)
    rtol = 2e-2 if dtype == torch.float32 else 1e-3
    if math.isclose(h, want_h, rel_tol=1e-9) and math.isclose(err, want_err, rel_tol=rtol):
        return None

    def near(pair):
        return math.isclose(h, pair[0], rel_tol=1e-9) and math.isclose(err, pair[1], rel_tol=rtol)
    for pair, explanation in (
            (_best(f, x, grad, steps, dtype, cast=False),
             f"the differences were evaluated in {str(x.dtype)[6:]}, not in {str(dtype)[6:]}: cast x to dtype "
             "first, so that f computes in it (its round-off, about ε |f| / h, decides where the best step is)"),
            (_best(f, x, grad, steps, dtype, forward=True),
             "that is the forward difference (f(x + h e_i) − f(x)) / h, error O(h): step both ways, "
             "(f(x + h e_i) − f(x − h e_i)) / 2h"),
            (_best(f, x, grad, steps, dtype, relative=False),
             "the error is absolute: the relative error is ‖g − grad‖ / ‖grad‖"),
            (_best(f, x, grad, steps, dtype, worst=True), "that is the largest error: return the step whose error "
                                                          "is the smallest, and that error")):
        if near(pair):
            return f"{name}: {explanation}"
    if h in range(len(steps)) and not any(math.isclose(h, s, rel_tol=1e-9) for s in steps):
        return f"{name}: h = {h:g} is an index: return the step itself, steps[k]"
    if not math.isclose(h, want_h, rel_tol=1e-9):
        return f"{name}: h = {h:g} expected {want_h:g} (its relative error {want_err:.3g}; you return {err:.3g})"
    return f"{name}: the error at h = {h:g} is {want_err:.4g}, you return {err:.4g}"


@task("9.1", "best_step", points=3, reference=("course.visibility", "fd_gradient"))
def _check_best_step(impl):
    forbidden = forbidden_call(impl, "best_step", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    x = torch.tensor([0.3, -0.7, 1.1], dtype=torch.float64)
    steps = [10.0 ** -k for k in range(1, 9)]

    def f64():
        require(_step_problem(impl, _smooth, x, steps, torch.float64, "a smooth function, float64"))

    def f32():
        require(_step_problem(impl, _smooth, x, steps, torch.float32, "a smooth function, float32"))

    def far():
        mixed = [1e-3, 1e-1, 1e-5, 1e-2, 1e-4, 1e-6]                        # not sorted
        y = torch.tensor([0.9, 0.2, -0.4, 0.6], dtype=torch.float64)
        require(_step_problem(impl, _far, y, mixed, torch.float32, "the function + 1000, float32"))
        require(_step_problem(impl, _far, y, mixed, torch.float64, "the function + 1000, float64"))
    return grade_parts((1, "float64", f64), (1, "float32", f32),
                       (1, "a function far from 0, steps in any order", far))


# ------------------------------------------------------------------------------ 9.2 the boundary term

def _boundary_problem(impl, args, label) -> str | None:
    name = f"boundary_term({label})"
    p0, p1, v0, v1, jump, col, row = args
    got = to_tensor(_call(impl, *args), name)
    expected = _boundary(*args).to(jump.dtype)
    low = jump.dtype == torch.float32
    message = compare(got, expected, name=name, check_dtype=True,
                      **({} if low else dict(atol=1e-12, rtol=1e-9)))
    if message is None or "shape" in message or "dtype" in message:
        return message
    if not bool(torch.isfinite(got).all()):
        return (f"{name}: NaN or inf: a zero-length edge has no normal (0 / 0); it sweeps no area, so its "
                "term is 0")
    ref = lambda **kw: _boundary(*args, **kw)                            # noqa: E731
    explanation = _match(got, [
        (ref(sign=-1.0), "the sign of the normal is flipped: n = (e_y, −e_x) / |e| points away from the "
                         "c_in side, and the term is positive when the c_in region grows (v · n > 0)"),
        (ref(length=False), "the length of the edge inside the pixel is missing: the term is an integral "
                            "along the edge, |e| (s1 − s0) × jump × (v · n)"),
        (ref(unit=False), "the normal is not normalised: n = (e_y, −e_x) / |e|, so the edge's length "
                          "counts once, not twice"),
        (ref(clip=False), "the whole edge is counted: clip it to the pixel's square [col, col+1] × "
                          "[row, row+1] and integrate only over the part inside"),
        (ref(middle="edge"), "the speed is taken at the middle of the whole edge: v · n is linear along the "
                             "edge, so take it at the middle of the part inside the pixel"),
        (ref(normal=False), "the speed is |v|: only the normal component v · n moves the boundary (sliding "
                            "along the edge changes nothing)"),
    ])
    return f"{name}: {explanation}" if explanation else message


def _edge_args(p0, p1, v0, v1, jump, col, row, dtype=torch.float64):
    t = lambda x: torch.tensor(x, dtype=dtype)                            # noqa: E731
    return t(p0), t(p1), t(v0), t(v1), t(jump), col, row


@task("9.2", "boundary_term", points=4, reference=("course.boundary", "boundary_gradient"))
def _check_boundary_term(impl):
    forbidden = forbidden_call(impl, "boundary_term", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def translation():
        args = _edge_args([3.2, 1.4], [6.9, 5.1], [0.6, -0.2], [0.6, -0.2], [0.8, -0.3, 0.25], 4, 2)
        require(_boundary_problem(impl, args, "an edge across pixel (2, 4), moved rigidly, float64"))
        args = _edge_args([5.7, 4.6], [2.1, 1.8], [-0.3, 0.9], [-0.3, 0.9], [0.5, 0.5, -1.0], 3, 2)
        require(_boundary_problem(impl, args, "the reverse direction, float64"))

    def rotation():
        args = _edge_args([1.3, 2.2], [7.6, 3.9], [0.0, 1.0], [0.4, -0.7], [0.9, 0.2, 0.4], 4, 2)
        require(_boundary_problem(impl, args, "endpoints moving differently (a rotation), float64"))
        args = _edge_args([4.5, 2.6], [9.0, 6.1], [1.0, 0.0], [0.0, 0.0], [0.7, -0.1, 0.3], 4, 2)
        require(_boundary_problem(impl, args, "an edge starting inside pixel (2, 4), one endpoint moving, float64"))
        g = generator(92)
        for k in range(3):
            p = torch.rand(2, 2, generator=g, dtype=torch.float64) * 4.0 + 1.0
            v = torch.randn(2, 2, generator=g, dtype=torch.float64)
            c = torch.rand(3, generator=g, dtype=torch.float64) - 0.5
            require(_boundary_problem(impl, (p[0], p[1], v[0], v[1], c, 2, 2), f"random edge {k}, float64"))

    def stress():
        args = _edge_args([0.5, 0.5], [2.5, 0.5], [0.0, 1.0], [0.0, 1.0], [1.0, 0.5, 0.2], 4, 2)
        require(_boundary_problem(impl, args, "an edge that misses the pixel, float64"))
        args = _edge_args([4.3, 2.6], [4.3, 2.6], [0.5, 0.5], [0.5, 0.5], [1.0, 0.5, 0.2], 4, 2)
        require(_boundary_problem(impl, args, "a zero-length edge, float64"))
        args = _edge_args([2.0, 2.5], [7.0, 2.5], [0.2, 0.6], [0.2, 0.6], [1.0, -1.0, 0.5], 4, 2)
        require(_boundary_problem(impl, args, "a horizontal edge, float64"))
        args = _edge_args([3.2, 1.4], [6.9, 5.1], [0.6, -0.2], [0.1, 0.4], [0.8, -0.3, 0.25], 4, 2, torch.float32)
        require(_boundary_problem(impl, args, "float32"))
    return grade_parts((1, "an edge moved rigidly", translation),
                       (2, "endpoints moving differently, clipped pieces", rotation),
                       (1, "missing the pixel, zero length, axis-aligned, float32", stress))



# ----------------------------------------------------------------------------- 9.3 a triangle's edges

def _triangle(tri, vel, color, background, col, row, *, orient="out", background_counts=True) -> torch.Tensor:
    """9.3 (C,) float64, and the typical mistakes as switches: ``orient`` "out" (each edge's normal leaves the
    triangle), "given" (the edges k → k+1 as the vertices come: right for one winding only), "in" (every normal
    into the triangle); ``background_counts`` (jump = colour − background, else the colour alone)."""
    tri, vel, color, background = _f64(tri, vel, color, background)
    jump = color - background if background_counts else color
    total = torch.zeros_like(color)
    for k in range(3):
        a, b, va, vb = tri[k], tri[(k + 1) % 3], vel[k], vel[(k + 1) % 3]
        e = b - a
        inward = float(torch.stack([e[1], -e[0]]) @ (tri[(k + 2) % 3] - a)) > 0   # the normal points at the third
        if (orient == "out" and inward) or (orient == "in" and not inward):       # vertex: into the triangle
            a, b, va, vb = b, a, vb, va
        total = total + _boundary(a, b, va, vb, jump, col, row)
    return total


def _triangle_problem(impl, args, label) -> str | None:
    name = f"triangle_term({label})"
    color = args[2]
    try:
        got = to_tensor(_call(impl, *args), name)
    except NotImplementedError as exc:                                    # boundary_term not written yet?
        frames = _frames(exc)
        if frames and frames[-1][2] != getattr(impl, "__name__", None) and _not_attempted(exc):
            raise Fail(f"{name}: {frames[-1][2]}, which it calls, is not written yet: write it first "
                       "(task 9.2)") from None
        raise
    expected = _triangle(*args).to(color.dtype)
    low = color.dtype == torch.float32
    message = compare(got, expected, name=name, check_dtype=True, **({} if low else dict(atol=1e-12, rtol=1e-9)))
    if message is None or "shape" in message or "dtype" in message:
        return message
    ref = lambda **kw: _triangle(*args, **kw)                            # noqa: E731
    explanation = _match(got, [
        (ref(orient="given"), "the edges run as the vertices come: that is right for one winding only; decide for "
                              "each edge which side the triangle is on (where its third vertex lies) and orient the "
                              "edge so that its normal leaves the triangle"),
        (ref(orient="in"), "the sign is flipped: with jump = colour − background the normal must leave the "
                           "triangle, not point into it"),
        (ref(background_counts=False), "the background is missing: the jump across the edge is colour − "
                                       "background"),
    ])
    return f"{name}: {explanation}" if explanation else message


def _tri_args(tri, vel, color, background, col, row, dtype=torch.float64):
    t = lambda x: torch.tensor(x, dtype=dtype)                            # noqa: E731
    return t(tri), t(vel), t(color), t(background), col, row


@task("9.3", "triangle_term", points=2, reference=("course.boundary", "boundary_gradient"))
def _check_triangle_term(impl):
    forbidden = forbidden_call(impl, "triangle_term", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    tri = [[2.3, 1.6], [8.7, 3.2], [4.1, 6.9]]
    push = [[1.0, 0.0], [0.0, 0.0], [0.0, 0.0]]

    def windings():
        for order, winding in (([0, 1, 2], "one winding"), ([0, 2, 1], "the other winding")):
            t, v = [tri[k] for k in order], [push[k] for k in order]
            args = _tri_args(t, v, [0.9, 0.4, 0.2], [0.0, 0.0, 0.0], 2, 3)
            require(_triangle_problem(impl, args, f"vertex 0 pushed along x, pixel (3, 2), {winding}"))
            args = _tri_args(t, v, [0.9, 0.4, 0.2], [0.0, 0.0, 0.0], 5, 2)
            require(_triangle_problem(impl, args, f"vertex 0 pushed along x, pixel (2, 5), {winding}"))

    def random():
        g = generator(95)
        for k in range(4):
            t = torch.rand(3, 2, generator=g, dtype=torch.float64) * 5.0 + 0.5
            v = torch.randn(3, 2, generator=g, dtype=torch.float64)
            c, b = torch.rand(3, generator=g, dtype=torch.float64), torch.rand(3, generator=g, dtype=torch.float64)
            require(_triangle_problem(impl, (t, v, c, b, 2, 2), f"random triangle {k} over a grey background, "
                                                               "every vertex moving, float64"))
        args = _tri_args([[4.5, 1.2], [1.3, 5.8], [6.2, 4.9]], [[0.3, -0.2], [0.1, 0.5], [-0.4, 0.2]],
                         [0.2, 0.7, 0.5], [0.3, 0.3, 0.3], 3, 3, torch.float32)
        require(_triangle_problem(impl, args, "float32"))
    return grade_parts((1, "both windings", windings), (1, "random triangles, a background, float32", random))


# ------------------------------------------------------------------------------- 9.4 edge sampling

# The estimator's spread: with N points the estimate's standard deviation is σ_1 / √N, σ_1 the spread of one
# sample, |e| jump (v · n)(s) [p(s) in pixel] with s uniform. A correct estimator lands within Z standard
# deviations of the exact value on each fixed-seed case (Z = 5: a two-sided miss has probability 6e-7), and a
# mistake that is off by far more than that is recognised.
Z = 5.0


def _spread(args, s_fine) -> torch.Tensor:
    """σ_1 (C,) of one sample, from a fine, even grid of s (a deterministic quadrature of the variance)."""
    one = torch.stack([_estimate(*args, s_fine[k:k + 1]) for k in range(s_fine.shape[0])])   # (M, C)
    return one.std(0)


def _sampling_problem(impl, args, samples, seed, label) -> str | None:
    name = f"edge_sample({label}, N = {samples})"
    jump = args[4]
    got = to_tensor(_call(impl, *args, samples, generator(seed)), name)
    exact = _boundary(*args)
    message = compare(got, exact.to(jump.dtype), name=name, check_dtype=True, atol=math.inf, rtol=0.0)
    if message is not None:                                               # shape or dtype only
        return message
    if not bool(torch.isfinite(got).all()):
        return f"{name}: NaN or inf"
    sigma = _spread(args, (torch.arange(2000, dtype=torch.float64) + 0.5) / 2000) / math.sqrt(samples)
    err = (got.to(torch.float64) - exact).abs()
    if bool((err <= Z * sigma + 1e-12).all()):
        return None
    g = generator(seed)
    s = torch.rand(samples, generator=g, dtype=torch.float64)
    tol = float(Z * sigma.max() / exact.abs().max().clamp_min(1e-12)) + 1e-6
    explanation = _match(got, [
        (_estimate(*args, s, length=False), "the length weight is missing: each point stands for |e| / N of "
                                             "the edge, so the weight is length / N, not 1 / N"),
        (_estimate(*args, s, per_hit=True), "dividing by the number of points inside the pixel is biased: "
                                             "divide by N, all the points drawn (those outside count 0)"),
        (exact / max(_clip(args[0], args[1], args[5], args[6])[1] - _clip(args[0], args[1], args[5], args[6])[0],
                     1e-12) if float(exact.abs().max()) > 0 else None,
         "dividing by the number of points inside the pixel is biased: divide by N, all the points drawn"),
        (-exact, "the sign of the normal is flipped: n = (e_y, −e_x) / |e|"),
    ], tol=tol)
    if explanation:
        return f"{name}: {explanation}"
    return (f"{name}: {_fmt_vec(got)} is {float((err / sigma.clamp_min(1e-300)).max()):.1f} standard deviations "
            f"from the exact value {_fmt_vec(exact)}: an unbiased estimator lands within {Z:g}; draw s uniform in "
            "[0, 1) on the whole edge (torch.rand with the generator), weight each point |e| / N")


def _fmt_vec(x):
    return "[" + ", ".join(f"{float(v):.4g}" for v in x) + "]"


def _sampling_rate(impl, args) -> str | None:
    """The error over 24 seeds at N = 64 and N = 1024: an unbiased Monte Carlo estimator's RMS error falls
    16 ^ 1/2 = 4 times; a deterministic one (no randomness) or one that ignores N does not."""
    exact = _boundary(*args)
    rms = []
    for samples in (64, 1024):
        runs = torch.stack([to_tensor(_call(impl, *args, samples, generator(900 + k)), "edge_sample")
                            .to(torch.float64) for k in range(24)])
        if samples == 64 and bool((runs == runs[0]).all()):
            return ("edge_sample(24 seeds, N = 64): the same result for every generator: draw the points with "
                    "torch.rand(samples, generator=generator), the estimate must be random")
        rms.append(float(((runs - exact) ** 2).mean().sqrt()))
    ratio = rms[0] / max(rms[1], 1e-300)
    if not 2.0 <= ratio <= 8.0:                                            # 4 expected; RMS of 24 runs: ±30 %
        return (f"edge_sample: the RMS error fell {ratio:.2g} times from N = 64 to N = 1024 (24 seeds each), "
                "expected about 4 (1 / √N): use all N points, each weighted |e| / N")
    return None


@task("9.4", "edge_sample", points=3, reference=("course.boundary", "boundary_gradient"))
def _check_edge_sample(impl):
    forbidden = forbidden_call(impl, "edge_sample", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    across = _edge_args([3.2, 1.4], [6.9, 5.1], [0.6, -0.2], [0.1, 0.4], [0.8, -0.3, 0.25], 4, 2)

    def estimates():
        require(_sampling_problem(impl, across, 4000, 93, "an edge across pixel (2, 4), float64"))
        inside = _edge_args([4.2, 2.3], [4.9, 2.8], [0.0, 1.0], [0.5, 0.5], [1.0, 0.5, -0.5], 4, 2)
        require(_sampling_problem(impl, inside, 1000, 94, "an edge inside the pixel, float64"))
        corner = _edge_args([1.0, 0.2], [9.0, 5.9], [0.3, -0.6], [0.3, -0.6], [0.2, 0.9, 0.4], 4, 2)
        require(_sampling_problem(impl, corner, 4000, 95, "a long edge that crosses a corner of the pixel, float64"))

    def rate():
        require(_sampling_rate(impl, across))

    def stress():
        miss = _edge_args([0.5, 0.5], [2.5, 0.5], [0.0, 1.0], [0.0, 1.0], [1.0, 0.5, 0.2], 4, 2)
        require(_sampling_problem(impl, miss, 500, 96, "an edge that misses the pixel, float64"))
        dot = _edge_args([4.3, 2.6], [4.3, 2.6], [0.5, 0.5], [0.5, 0.5], [1.0, 0.5, 0.2], 4, 2)
        require(_sampling_problem(impl, dot, 100, 97, "a zero-length edge, float64"))
        low = _edge_args([3.2, 1.4], [6.9, 5.1], [0.6, -0.2], [0.1, 0.4], [0.8, -0.3, 0.25], 4, 2, torch.float32)
        require(_sampling_problem(impl, low, 4000, 98, "float32"))
    return grade_parts((1, "close to the exact term with many samples", estimates),
                       (1, "the error falls like 1 / √N", rate),
                       (1, "missing the pixel, zero length, float32", stress))
