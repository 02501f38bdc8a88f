"""The checks of lecture 14's graded tasks (soft shadows and the light's boundary): 14.1 lambert_form_factor,
14.2 project_from_point, 14.3 clip_polygon, 14.4 edge_derivative.

Each check runs the student's function next to a reference on fixed, seeded-random and stress inputs and
says what to fix, recognising the typical mistakes of the task. ``import course.grading`` imports this
module, which registers its checks in ``course.grading.TASKS``.

* 14.1, the form factor from a point x with unit normal n to a convex polygon light, by Lambert's contour
  formula: with ``r_i = q_i - x``, ``c_i = r_i × r_{i+1}`` and ``γ_i`` the angle between r_i and r_{i+1},
  ``F = -(1/2π) Σ_i γ_i n · c_i / |c_i|`` (positive for a polygon wound counter-clockwise about its normal, that
  normal facing x; ``course.shadows.area.polygon_form_factor``). γ from acos is the same angle: it passes. The
  gradient with respect to n is compared across n only (the part a unit normal can move along), so a function
  that normalises n itself passes too.
* 14.2, the central projection from x onto a plane (an occluder's shadow on the light, seen from x): with
  ``d(p) = (p - plane_point) · plane_normal``, ``q = x + (v - x) d(x) / (d(x) - d(v))``, whatever the normal's
  length; a vertex at x's level (``d(v) == d(x)``) has no projection: a ValueError.
* 14.3, Sutherland–Hodgman against one plane: the part of a convex polygon where a linear function's
  ``values`` are >= 0, crossings ``p_i + t (p_{i+1} - p_i)``, ``t = values[i] / (values[i] - values[i+1])`` on the
  edges strictly across, a vertex with value 0 kept once and no edge through it cut, an empty (0, 3) tensor when
  fewer than 3 vertices remain (``course.shadows.gradients._clip`` with no tolerance). Polygons are compared up
  to the vertex the walk starts from, not up to their winding.
* 14.4, the analysis: how fast the form factor of a square light ``[-half, half]²`` at ``z = height`` (emitting
  down) changes when an occluder's edge, whose shadow on the light runs along ``y = s``, moves: x sees the strip
  ``y >= s``, and by Leibniz's rule (Reynolds transport in one dimension)
  ``dF/ds = -(1/π) ∫_{-half}^{half} k(u, s) du``, ``k = cos θ_x cos θ_L / r² = (n · r)(height - x_z) / |r|⁴``,
  ``r = (u, s, height) - x``; 0 for s outside ``(-half, half)``. The reference is the integral's antiderivative
  (exact); ``tests/test_grading_14.py`` checks it against Gauss–Legendre quadrature and against converged central
  differences of the package's form factor of the visible rectangle. The tolerance, ``rtol = 1e-6`` (and
  ``atol = 1e-10``), lets through a 100-point Gauss–Legendre rule (the receiver nearest the light is 0.2 below it,
  under a light 2 wide: such a rule reaches rounding there, 1e-15) and a central difference of the student's own form
  factor with a step from 1e-6 to 1e-4; every typical mistake is off by far more.

The references are written here, in float64; ``tests/test_grading_14.py`` checks that they agree with the
package. A graded function that calls them, or the package functions doing the task's work, scores 0.
"""
from __future__ import annotations

import math
import numbers

import torch

from .helpers import _call, _close, _match, compare, grade_parts, require, to_tensor
from .registry import forbidden_call, task

__all__ = ["lambert_form_factor_reference", "project_from_point_reference", "clip_polygon_reference",
           "edge_derivative_reference"]

FORBIDDEN = [("course.shadows", "polygon_form_factor"), ("course.shadows.area", "polygon_form_factor"),
             ("course.shadows", "light_form_factor"), ("course.shadows.area", "light_form_factor"),
             ("course.shadows.gradients", "_clip"),
             ("course.grading.lecture14", "lambert_form_factor_reference"),
             ("course.grading.lecture14", "project_from_point_reference"),
             ("course.grading.lecture14", "clip_polygon_reference"),
             ("course.grading.lecture14", "edge_derivative_reference")]


# ------------------------------------------------------------------------------------- the references

def lambert_form_factor_reference(x, n, poly) -> torch.Tensor:
    """14.1: the form factor from x (3,) with unit normal n (3,) to the convex polygon ``poly`` (K, 3), wound
    counter-clockwise about its normal, which faces x: ``-(1/2π) Σ γ_i n · c_i / |c_i|``; a scalar tensor."""
    return _lambert(x, n, poly)


def project_from_point_reference(x, verts, plane_point, plane_normal) -> torch.Tensor:
    """14.2: (M, 3) the points ``verts`` (M, 3) projected from x (3,) onto the plane through ``plane_point`` with
    normal ``plane_normal`` (any length); ValueError for a vertex at x's level."""
    return _project(x, verts, plane_point, plane_normal)


def clip_polygon_reference(poly, values) -> torch.Tensor:
    """14.3: the part of the convex polygon ``poly`` (K, 3) where ``values`` (K,) >= 0, (M, 3) in its winding,
    or an empty (0, 3) tensor."""
    return _clip_polygon(poly, values)


def edge_derivative_reference(x, n, half, height, s) -> float:
    """14.4: dF/ds for the square light ``[-half, half]²`` at ``z = height`` seen from x (3,) with unit normal n
    (3,) over the strip ``y >= s``; 0 when s is outside ``(-half, half)``."""
    return float(_edge(x, n, half, height, s))


def _f64(*tensors):
    return [torch.as_tensor(t).to(torch.float64) for t in tensors]


def _lambert(x, n, poly, kind="course"):
    """``kind`` gives a typical mistake's answer instead: "pi" (divided by π), "sign" (not negated),
    "unnormalised" (γ n · c), "poly_normal" / "poly_normal_back" (the light's normal, either way, for n)."""
    dtype = torch.as_tensor(poly).dtype
    X, N, P = _f64(x, n, poly)
    r = P - X
    r_next = r.roll(-1, 0)
    c = torch.linalg.cross(r, r_next, dim=1)
    length = c.norm(dim=1)
    gamma = torch.atan2(length, (r * r_next).sum(1))                        # the angle at x of each edge
    if kind in ("poly_normal", "poly_normal_back"):
        area = torch.linalg.cross(P, P.roll(-1, 0), dim=1).sum(0)
        N = area / area.norm() * (1.0 if kind == "poly_normal" else -1.0)
    safe = torch.where(length > 0, length, torch.ones_like(length))         # an edge in line with x: no angle
    total = (gamma * (c @ N)).sum() if kind == "unnormalised" else (gamma * (c @ N) / safe).sum()
    if kind == "pi":
        return (-total / math.pi).to(dtype)
    if kind == "sign":
        return (total / (2 * math.pi)).to(dtype)
    return (-total / (2 * math.pi)).to(dtype)


def _project(x, verts, plane_point, plane_normal, kind="course"):
    """``kind``: "orthogonal" (dropped onto the plane along its normal), "t_dv" (t = d(v) / (d(x) - d(v))),
    "t_flip" (t = d(x) / (d(v) - d(x))), "mixed_up" / "mixed_down" (d(x) over |n| in the numerator only, or in
    the denominator only: t scaled by 1/|n| or |n|)."""
    dtype = torch.as_tensor(verts).dtype
    X, V, p, m = _f64(x, verts, plane_point, plane_normal)
    d_x = (X - p) @ m
    d_v = (V - p) @ m
    if kind == "orthogonal":
        return (V - (d_v / (m @ m))[:, None] * m).to(dtype)
    if kind == "course":
        level = (d_v == d_x).nonzero().flatten().tolist()
        if level:
            raise ValueError(f"vertex {level[0]} lies at x's level (d(v) == d(x)): the line from x through it is "
                             "parallel to the plane and never meets it")
    t = d_x / (d_x - d_v)
    if kind == "t_dv":
        t = d_v / (d_x - d_v)
    elif kind == "t_flip":
        t = d_x / (d_v - d_x)
    elif kind == "mixed_up":
        t = t / m.norm()
    elif kind == "mixed_down":
        t = t * m.norm()
    return (X + (V - X) * t[:, None]).to(dtype)


def _clip_polygon(poly, values, kind="course"):
    """``kind``: "wrong_end" / "wrong_end_out" (t = v_j / (v_j - v_i), or v_j / (v_i - v_j)), "leaving" /
    "entering" (only the crossing where the walk leaves, or comes back into, the kept side), "duplicate" (cut
    where (v_i >= 0) != (v_j >= 0): a vertex with value 0 comes twice), "short" (fewer than 3 vertices returned
    as they are)."""
    dtype = torch.as_tensor(poly).dtype
    P, s = _f64(poly, values)
    side = [1 if v > 0 else (-1 if v < 0 else 0) for v in s.tolist()]
    K = len(side)
    out = []
    for i in range(K):
        j = (i + 1) % K
        if side[i] >= 0:
            out.append(P[i])
        across = side[i] * side[j] < 0                                      # strictly across: cut the edge
        if kind == "leaving":
            across = side[i] > 0 > side[j]
        elif kind == "entering":
            across = side[i] < 0 < side[j]
        elif kind == "duplicate":
            across = (side[i] >= 0) != (side[j] >= 0)
        if across:
            t = s[i] / (s[i] - s[j])
            if kind == "wrong_end":
                t = s[j] / (s[j] - s[i])
            elif kind == "wrong_end_out":
                t = s[j] / (s[i] - s[j])
            out.append(P[i] + t * (P[j] - P[i]))
    if len(out) >= 3 or (kind == "short" and out):
        return torch.stack(out).to(dtype)
    return P[:0].to(dtype)


def _edge(x, n, half, height, s, kind="course"):
    """dF/ds as a 0-dim float64 tensor, by the antiderivative in u of the kernel along y = s. ``kind``: "sign",
    "no_pi", "plain" (1/r² alone), "no_cos_light" (cos θ_x / r²), "no_cos_receiver" (cos θ_L / r²), "outside"
    (the integral also for s outside the light)."""
    X, N = _f64(x, n)
    half, height, s = float(half), float(height), float(s)
    if not -half < s < half and kind != "outside":
        return torch.zeros((), dtype=torch.float64)
    H = height - X[2]                                                       # the light's height above x
    b = s - X[1]
    B = b * b + H * H                                                       # |r|² = w² + B, w = u - x_x
    C = N[1] * b + N[2] * H                                                 # n · r = n_x w + C
    w = torch.stack([-half - X[0], half - X[0]])
    q = w * w + B
    if kind == "plain":                                                     # ∫ 1 / (w² + B)
        prim = torch.atan(w / B.sqrt()) / B.sqrt()
    elif kind == "no_cos_light":                                            # ∫ (n_x w + C) / (w² + B)^(3/2)
        prim = -N[0] / q.sqrt() + C * w / (B * q.sqrt())
    elif kind == "no_cos_receiver":                                         # ∫ H / (w² + B)^(3/2)
        prim = H * w / (B * q.sqrt())
    else:                                                                   # ∫ H (n_x w + C) / (w² + B)²
        prim = H * (-N[0] / (2 * q) + C * (w / (2 * B * q) + torch.atan(w / B.sqrt()) / (2 * B * B.sqrt())))
    integral = prim[1] - prim[0]
    if kind == "sign":
        return integral / math.pi
    if kind == "no_pi":
        return -integral
    return -integral / math.pi


def _unit(v):
    v = torch.as_tensor(v, dtype=torch.float64)
    return v / v.norm()


def _scalar(out, name):
    """A student's scalar result as a 0-dim tensor (one element of any shape is taken as that number)."""
    got = to_tensor(out, name)
    return got.reshape(()) if got.numel() == 1 else got


def _telling(variants, expected, tol=1e-6):
    """The ``(alternative, explanation)`` pairs whose alternative differs from the expected result: only those
    can tell a mistake."""
    return [(a, why) for a, why in variants if a is not None and not _close(a, expected, tol)]


def _no_gradient(fn, what):
    return (f"{fn}: the value is right but no gradient reaches {what}: compute with tensor operations (no .item(), "
            "float(), .tolist() or numpy) and return the tensor")


# ---------------------------------------------------------------------------- 14.1 lambert_form_factor

def _frame(normal):
    """(n̂, u, v): a right-handed orthonormal frame, u × v = n̂."""
    n = _unit(normal)
    helper = torch.tensor([1.0, 0.0, 0.0] if abs(float(n[0])) < 0.9 else [0.0, 1.0, 0.0], dtype=torch.float64)
    u = torch.linalg.cross(helper, n, dim=0)
    u = u / u.norm()
    return n, u, torch.linalg.cross(n, u, dim=0)


def _polygon(angles, centre, normal, radius):
    """A convex polygon on the circle of ``radius`` about ``centre`` in the plane normal to ``normal``, its
    vertices at ``angles`` (increasing): counter-clockwise about ``normal``."""
    _, u, v = _frame(normal)
    a = torch.as_tensor(angles, dtype=torch.float64)[:, None]
    return torch.as_tensor(centre, dtype=torch.float64) + radius * (a.cos() * u + a.sin() * v)


def _regular(K, centre, normal, radius, phase=0.3):
    return _polygon(phase + 2 * math.pi * torch.arange(K, dtype=torch.float64) / K, centre, normal, radius)


def _square_above(half, height):
    """The square ``[-half, half]²`` at ``z = height``, emitting down: counter-clockwise about -z."""
    h = half
    return torch.tensor([[-h, -h, height], [-h, h, height], [h, h, height], [h, -h, height]], dtype=torch.float64)


def _form_factor_cases():
    """(label, x, n, poly): squares straight above, then tilted polygons seen from tilted receivers; every
    polygon faces its receiver and lies in front of the receiver's tangent plane (``tests/test_grading_14.py``)."""
    zero, up = torch.zeros(3, dtype=torch.float64), torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    above = [("a square of side 1 at height 1 straight above, n up", zero, up, _square_above(0.5, 1.0)),
             ("a square of side 1 at height 0.25 straight above, n up", zero, up, _square_above(0.5, 0.25)),
             ("a square of side 1 at height 1, the receiver off-centre at (0.3, -0.2, 0)",
              torch.tensor([0.3, -0.2, 0.0], dtype=torch.float64), up, _square_above(0.5, 1.0))]
    g = torch.Generator().manual_seed(1411)
    angles = torch.sort(torch.rand(4, generator=g, dtype=torch.float64)).values * 1.3 + \
        torch.arange(4, dtype=torch.float64) * (math.pi / 2)               # a quadrilateral, no two corners close
    tilted = [("a regular pentagon tilted, a tilted normal",
               zero, _unit([0.25, 0.1, 1.0]), _regular(5, [0.2, 0.1, 1.5], [0.3, -0.2, -1.0], 0.6)),
              ("a regular hexagon on a steep plane, a tilted normal",
               torch.tensor([0.1, -0.3, 0.2], dtype=torch.float64), _unit([-0.2, 0.8, 1.0]),
               _regular(6, [-0.4, 0.8, 0.9], [0.4, -1.0, -0.8], 0.35, phase=1.1)),
              ("an irregular quadrilateral close to the receiver, a tilted normal",
               torch.tensor([0.5, 0.5, -0.5], dtype=torch.float64), _unit([0.3, -0.4, 1.0]),
               _polygon(angles, [0.7, 0.3, 0.1], [-0.1, 0.2, -1.0], 0.7))]
    return above, tilted


def _lambert_problem(impl, label, x, n, poly):
    name = f"lambert_form_factor({label})"
    got = _scalar(_call(impl, x, n, poly), name)
    expected = _lambert(x, n, poly)
    low = poly.dtype == torch.float32
    message = compare(got, expected, name=name, check_dtype=True,
                      **(dict(atol=1e-5, rtol=1e-4) if low else dict(atol=1e-12, rtol=1e-10)))
    if message is None or "dtype" in message or "shape" in message:
        return message
    own_normal = ("the polygon's normal was used: the cosine at the receiver is taken with the receiver's normal n, "
                  "F = -(1/2π) Σ γ_i n · c_i / |c_i|")
    explanation = _match(got, _telling([
        (_lambert(x, n, poly, "pi"), "divided by π: Lambert's formula divides the sum by 2π, "
                                     "F = -(1/2π) Σ γ_i n · c_i / |c_i|; yours is twice the form factor"),
        (_lambert(x, n, poly, "sign"), "the form factor came out negative: the polygon is wound counter-clockwise "
                                       "about its normal, which points back at x, so each c_i = r_i × r_{i+1} "
                                       "points against n and the sum Σ γ_i n · c_i / |c_i| is negative; negate "
                                       "it, F = -(1/2π) Σ ..."),
        (_lambert(x, n, poly, "unnormalised"), "c_i = r_i × r_{i+1} was not normalised: each edge adds "
                                               "γ_i n · c_i / |c_i| (the unit normal of the plane through x and "
                                               "the edge), not γ_i n · c_i"),
        (_lambert(x, n, poly, "poly_normal"), own_normal),
        (_lambert(x, n, poly, "poly_normal_back"), own_normal),
    ], expected))
    return f"{name}: {explanation}" if explanation else message


def _lambert_gradient(impl, label, x, n, poly):
    """The gradient of F with respect to x, n (across n only) and the polygon's vertices, against autograd
    through the reference."""
    leaves = [t.clone().requires_grad_(True) for t in (x, n, poly)]
    out = impl(*leaves)
    if not (isinstance(out, torch.Tensor) and out.requires_grad):
        return _no_gradient(f"lambert_form_factor({label})", "x, n and poly")
    got = torch.autograd.grad(out.sum(), leaves, allow_unused=True)
    refs = [t.clone().requires_grad_(True) for t in (x, n, poly)]
    want = torch.autograd.grad(_lambert(*refs), refs)
    n_hat = _unit(n)
    for g, w, what in zip(got, want, ("x", "n", "poly")):
        if g is None:
            return _no_gradient(f"lambert_form_factor({label})", what)
        if what == "n":                                                     # along n: a unit normal can't move
            g, w = g - (g @ n_hat) * n_hat, w - (w @ n_hat) * n_hat
        bad = compare(g, w, name=f"lambert_form_factor({label}): dF/d{what}", check_dtype=False,
                      atol=1e-10, rtol=1e-8)
        if bad:
            return bad
    return None


@task("14.1", "lambert_form_factor", points=3, reference=("course.shadows.area", "polygon_form_factor"))
def _check_lambert(impl):
    forbidden = forbidden_call(impl, "lambert_form_factor", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    above, tilted = _form_factor_cases()

    def square():
        for case in above:
            require(_lambert_problem(impl, *case))

    def general():
        for case in tilted:
            require(_lambert_problem(impl, *case))

    def stress():
        for label, x, n, poly in (above[0], tilted[1]):
            require(_lambert_problem(impl, label + ", float32", x.float(), n.float(), poly.float()))
        require(_lambert_gradient(impl, *tilted[0]))
    return grade_parts((1, "a square straight above", square), (1, "tilted polygons and normals", general),
                       (1, "float32, the gradient", stress))


# ----------------------------------------------------------------------------- 14.2 project_from_point

def _projection_cases():
    """(label, x, verts, plane_point, plane_normal): a light's plane above x and points between them (a unit
    normal), then a tilted plane with a normal of length 3, points beyond the plane and behind x. A point is put
    at a fraction k of the way from x to a point Q of the plane (its projection is Q: between for 0 < k < 1,
    beyond the plane for k > 1, behind x for k < 0)."""
    g = torch.Generator().manual_seed(1421)
    f64 = lambda v: torch.tensor(v, dtype=torch.float64)                   # noqa: E731
    x = f64([0.1, -0.2, 0.0])
    between = torch.rand(6, 3, generator=g, dtype=torch.float64) * 2 + f64([-1.0, -1.0, 0.5])
    flat = ("the plane z = 3 (normal (0, 0, -1)), 6 points between x and it", x, between, f64([0.0, 0.0, 3.0]),
            f64([0.0, 0.0, -1.0]))
    m, p = f64([1.0, 2.0, -2.0]), f64([0.5, 0.5, 2.5])                      # |m| = 3
    _, u, v = _frame(m)
    x2 = f64([-0.3, 0.2, 0.1])

    def towards(fractions):
        ab = torch.randn(len(fractions), 2, generator=g, dtype=torch.float64)
        Q = p + ab[:, :1] * u + ab[:, 1:] * v                               # points of the plane
        return x2 + f64(fractions)[:, None] * (Q - x2)
    tilted = ("a tilted plane with normal (1, 2, -2) of length 3, 4 points between x and it", x2,
              towards([0.2, 0.45, 0.7, 0.9]), p, m)
    far = ("the tilted plane, points beyond it and behind x", x2, towards([1.4, 2.5, -0.6, -2.0]), p, m)
    return flat, tilted, far


def _project_problem(impl, label, x, verts, p, m):
    name = f"project_from_point({label})"
    got = to_tensor(_call(impl, x, verts, p, m), name)
    expected = _project(x, verts, p, m)
    low = verts.dtype == torch.float32
    message = compare(got, expected, name=name, check_dtype=True,
                      **(dict(atol=1e-5, rtol=1e-4) if low else dict(atol=1e-12, rtol=1e-10)))
    if message is None or "dtype" in message or "shape" in message:
        return message
    wrong_t = ("the point on the line from x through v is at the wrong t: along x + (v - x) t the signed distance "
               "is d(x) + t (d(v) - d(x)), which is 0 at t = d(x) / (d(x) - d(v))")
    mixed = ("the result depends on the normal's length: use the same normal in d(x) and in d(x) - d(v) (unit in "
             "both or in neither); its length then cancels in t = d(x) / (d(x) - d(v))")
    explanation = _match(got, _telling([
        (_project(x, verts, p, m, "orthogonal"), "that is the orthogonal projection onto the plane: project along "
                                                 "the line from x through v, q = x + (v - x) d(x) / (d(x) - d(v))"),
        (_project(x, verts, p, m, "t_dv"), wrong_t),
        (_project(x, verts, p, m, "t_flip"), wrong_t),
        (_project(x, verts, p, m, "mixed_up"), mixed),
        (_project(x, verts, p, m, "mixed_down"), mixed),
    ], expected))
    if explanation:
        return f"{name}: {explanation}"
    P = got.to(torch.float64)
    off = ((P - p) @ m).abs().max() / m.norm()
    if bool(torch.isfinite(off)) and float(off) > 1e-6:
        return f"{message} (the results are not on the plane: they lie up to {float(off):.3g} off it)"
    return message


def _project_level(impl):
    """A vertex at x's level (d(v) == d(x) exactly): a ValueError."""
    f64 = lambda v: torch.tensor(v, dtype=torch.float64)                   # noqa: E731
    x, p, m = f64([0.0, 0.0, 1.0]), f64([0.0, 0.0, 3.0]), f64([0.0, 0.0, -2.0])
    verts = f64([[0.2, 0.1, 2.0], [0.5, 0.25, 1.0], [-0.3, 0.4, 1.5]])    # the second at x's level
    name = "project_from_point(a vertex at x's level, normal (0, 0, -2))"
    try:
        impl(x.clone(), verts.clone(), p.clone(), m.clone())
    except ValueError:
        return None
    except Exception as err:                                                # noqa: BLE001   the student's code
        return f"{name}: raise a ValueError naming the vertex, not {type(err).__name__}"
    return (f"{name}: the line from x through a vertex at x's level (d(v) == d(x)) is parallel to the plane and "
            "never meets it: raise a ValueError naming that vertex")


def _project_gradient(impl, label, x, verts, p, m):
    leaves = [x.clone().requires_grad_(True), verts.clone().requires_grad_(True)]
    out = impl(leaves[0], leaves[1], p.clone(), m.clone())
    if not (isinstance(out, torch.Tensor) and out.requires_grad):
        return _no_gradient(f"project_from_point({label})", "x and verts")
    weights = torch.linspace(-1.0, 2.0, verts.numel(), dtype=torch.float64).view(verts.shape)
    got = torch.autograd.grad((out * weights).sum(), leaves, allow_unused=True)
    refs = [x.clone().requires_grad_(True), verts.clone().requires_grad_(True)]
    want = torch.autograd.grad((_project(refs[0], refs[1], p, m) * weights).sum(), refs)
    for g, w, what in zip(got, want, ("x", "verts")):
        if g is None:
            return _no_gradient(f"project_from_point({label})", what)
        bad = compare(g, w, name=f"project_from_point({label}): the gradient w.r.t. {what}", check_dtype=False,
                      atol=1e-10, rtol=1e-8)
        if bad:
            return bad
    return None


@task("14.2", "project_from_point", points=2,
      reference=("course.grading.lecture14", "project_from_point_reference"))
def _check_project(impl):
    forbidden = forbidden_call(impl, "project_from_point", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    flat, tilted, far = _projection_cases()

    def between():
        require(_project_problem(impl, *flat))

    def stress():
        require(_project_problem(impl, *tilted))
        require(_project_problem(impl, *far))
        label, x, verts, p, m = tilted
        require(_project_problem(impl, label + ", float32", x.float(), verts.float(), p.float(), m.float()))
        require(_project_level(impl))
        require(_project_gradient(impl, *tilted))
    return grade_parts((1, "points between x and the plane", between),
                       (1, "a normal of length 3, points beyond the plane, a vertex at x's level, float32, the "
                           "gradient", stress))


# ---------------------------------------------------------------------------------- 14.3 clip_polygon

def _same_cyclic(got, want, tol) -> int | None:
    """The shift k with ``got.roll(-k, 0)`` equal to ``want`` within ``tol`` (of the polygon's size), else None."""
    if got.shape != want.shape:
        return None
    if want.shape[0] == 0:
        return 0
    g, w = got.to(torch.float64), want.to(torch.float64)
    scale = tol * (1 + float(w.abs().max()))
    for k in range(g.shape[0]):
        if float((g.roll(-k, 0) - w).abs().max()) <= scale:
            return k
    return None


def _plane_values(poly, point, normal):
    """(K,) the signed distances (times |normal|) of the polygon's vertices to a plane."""
    return (poly - torch.as_tensor(point, dtype=torch.float64)) @ torch.as_tensor(normal, dtype=torch.float64)


def _clip_cases():
    """(cut, special) lists of (label, poly, values): planes through two edges; then all kept, none kept, vertices
    exactly on the plane (values exactly 0, from integer coordinates)."""
    f64 = lambda v: torch.tensor(v, dtype=torch.float64)                   # noqa: E731
    square = f64([[0.0, 0.0, 1.0], [2.0, 0.0, 1.0], [2.0, 2.0, 1.0], [0.0, 2.0, 1.0]])
    pentagon = _regular(5, [0.2, -0.1, 0.4], [0.3, 1.0, -0.2], 1.2, phase=0.2)
    hexagon = _regular(6, [1.0, 2.0, 3.0], [-1.0, 0.5, 0.7], 0.8, phase=0.9)
    cut = [("a square cut through two edges, x >= 0.6", square, square[:, 0] - 0.6),
           ("a tilted pentagon, a plane through its middle", pentagon,
            _plane_values(pentagon, pentagon.mean(0) + 0.2, [1.0, -0.5, 0.3])),
           ("a hexagon, most of it cut away", hexagon, _plane_values(hexagon, hexagon[2] * 0.7 + hexagon[3] * 0.3,
                                                                     [0.2, 1.0, -0.6]))]
    y = [0.0, 1.0, 0.0]
    special = [("a pentagon all on the kept side", pentagon, _plane_values(pentagon, [0.0, -5.0, 0.0], y)),
               ("a pentagon all on the other side", pentagon, _plane_values(pentagon, [0.0, 5.0, 0.0], y)),
               ("a square, the plane through a corner and across the opposite edges, x + y >= 2", square,
                square[:, 0] + square[:, 1] - 2.0),
               ("a square, the plane through corner 0 and across edge 1 → 2, 4y - x >= 0", square,
                4 * square[:, 1] - square[:, 0]),
               ("a square, the plane through corner 0 and across edge 1 → 2, x - 4y >= 0", square,
                square[:, 0] - 4 * square[:, 1]),
               ("a square, an edge on the plane, the rest kept, y >= 0", square, square[:, 1]),
               ("a square touching the plane at one corner, the rest cut away, x + y <= 0", square,
                -(square[:, 0] + square[:, 1])),
               ("a square with an edge on the plane, the rest cut away, y <= 0", square, -square[:, 1])]
    return cut, special


def _clip_problem(impl, label, poly, values):
    name = f"clip_polygon({label})"
    got = to_tensor(_call(impl, poly, values), name)
    expected = _clip_polygon(poly, values)
    if got.dim() != 2 or got.shape[-1] != 3:
        if got.numel() == 0 and expected.shape[0] == 0:
            return f"{name}: nothing is kept: return an empty (0, 3) tensor, got shape {tuple(got.shape)}"
        return f"{name}: return the kept polygon as an (M, 3) tensor of vertices, got shape {tuple(got.shape)}"
    if got.dtype != expected.dtype:
        return compare(got, expected, name=name, check_dtype=True)
    if not bool(torch.isfinite(got).all()):
        return (f"{name}: NaN or inf among the vertices: cut an edge only when one end's value is > 0 and the "
                "other's < 0, so values[i] - values[i+1] is never 0")
    tol = 1e-5 if poly.dtype == torch.float32 else 1e-12
    if _same_cyclic(got, expected, tol) is not None:
        return None
    if expected.shape[0] == 0 and 0 < got.shape[0] < 3:
        left = "only 1 vertex remains" if got.shape[0] == 1 else "only 2 vertices remain"
        return (f"{name}: {left}, which is no polygon: when fewer than 3 vertices remain, return an empty (0, 3) "
                "tensor")
    across = ("a crossing is missing: every edge whose ends lie strictly on opposite sides (one value > 0, the "
              "other < 0) adds the point where it meets the plane, where the walk leaves the kept side and where it "
              "comes back")
    wrong_end = ("the crossing is measured from the wrong end: on the edge p_i → p_{i+1} it lies at "
                 "p_i + t (p_{i+1} - p_i), t = values[i] / (values[i] - values[i+1]), the fraction of the way from "
                 "p_i where the value reaches 0")
    for alternative, why in (
            (_clip_polygon(poly, -values), "you kept the wrong side: keep the part where values >= 0"),
            (_clip_polygon(poly, values, "wrong_end"), wrong_end),
            (_clip_polygon(poly, values, "wrong_end_out"), wrong_end),
            (_clip_polygon(poly, values, "leaving"), across),
            (_clip_polygon(poly, values, "entering"), across),
            (_clip_polygon(poly, values, "duplicate"), "a vertex on the plane (value 0) came out twice: keep it once "
                                                        "and cut no edge through it (cut only where one end's value "
                                                        "is > 0 and the other's < 0)"),
            (expected.flip(0), "the polygon runs the other way round: keep the input's winding")):
        if _same_cyclic(alternative, expected, 1e-9) is None and _same_cyclic(got, alternative, 1e-6) is not None:
            return f"{name}: {why}"
    if got.shape[0] != expected.shape[0]:
        return (f"{name}: {expected.shape[0]} vertices expected (those with values >= 0 and one crossing on each "
                f"edge strictly across), got {got.shape[0]}")
    shifts = [got.roll(-k, 0) for k in range(got.shape[0])]
    best = min(shifts, key=lambda r: float((r.to(torch.float64) - expected.to(torch.float64)).abs().max()))
    return compare(best, expected, name=name + " (from its best-matching start vertex)", check_dtype=False,
                   **(dict(atol=1e-5, rtol=1e-5) if poly.dtype == torch.float32 else dict(atol=1e-12, rtol=1e-10)))


def _clip_gradient(impl, label, poly, values):
    """The gradient of the kept vertices (matched from the student's start vertex) w.r.t. poly and values."""
    leaves = [poly.clone().requires_grad_(True), values.clone().requires_grad_(True)]
    out = impl(*leaves)
    if not (isinstance(out, torch.Tensor) and out.requires_grad):
        return _no_gradient(f"clip_polygon({label})", "poly and values")
    refs = [poly.clone().requires_grad_(True), values.clone().requires_grad_(True)]
    expected = _clip_polygon(*refs)
    k = _same_cyclic(out.detach(), expected.detach(), 1e-12)
    if k is None:
        return f"clip_polygon({label}): the polygon differs from the expected one"
    weights = torch.linspace(-1.0, 2.0, expected.numel(), dtype=torch.float64).view(expected.shape)
    got = torch.autograd.grad((out.roll(-k, 0) * weights).sum(), leaves, allow_unused=True)
    want = torch.autograd.grad((expected * weights).sum(), refs)
    for g, w, what in zip(got, want, ("poly", "values")):
        if g is None:
            if what == "values":
                return (f"clip_polygon({label}): no gradient reaches values: the crossings move with them, through "
                        "t = values[i] / (values[i] - values[i+1]); compute t from the tensor, not from floats "
                        "(.item(), float(), .tolist())")
            return _no_gradient(f"clip_polygon({label})", what)
        bad = compare(g, w, name=f"clip_polygon({label}): the gradient w.r.t. {what}", check_dtype=False,
                      atol=1e-10, rtol=1e-8)
        if bad:
            return bad
    return None


@task("14.3", "clip_polygon", points=3, reference=("course.shadows.gradients", "_clip"))
def _check_clip(impl):
    forbidden = forbidden_call(impl, "clip_polygon", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    cut, special = _clip_cases()

    def through():
        for case in cut:
            require(_clip_problem(impl, *case))

    def edges():
        for case in special:
            require(_clip_problem(impl, *case))

    def stress():
        for label, poly, values in cut[:2]:
            require(_clip_problem(impl, label + ", float32", poly.float(), values.float()))
        require(_clip_gradient(impl, *cut[1]))
    return grade_parts((1, "planes through two edges", through),
                       (1, "all kept, none kept, vertices on the plane", edges),
                       (1, "float32, the gradient through t", stress))


# -------------------------------------------------------------- 14.4 the moving edge's derivative (an analysis)

RTOL_EDGE, ATOL_EDGE = 1e-6, 1e-10      # see the module docstring: quadrature and central differences pass


def _edge_cases():
    """(label, x, n, half, height, s) by part: below the centre; off-centre with a tilted normal; near the light
    (a peaked kernel); s outside the light. Every light lies in front of its receiver's tangent plane."""
    f64 = lambda v: torch.tensor(v, dtype=torch.float64)                   # noqa: E731
    zero, up = f64([0.0, 0.0, 0.0]), f64([0.0, 0.0, 1.0])
    centre = [(f"x below the centre of a light of side 1 at height 1, n up, s = {s}", zero, up, 0.5, 1.0, s)
              for s in (0.0, 0.3, -0.45)]
    x, n = f64([0.3, -0.2, 0.1]), _unit([0.2, -0.3, 1.0])
    tilted = [(f"x at (0.3, -0.2, 0.1), n tilted, a light of side 1 at height 1.2, s = {s}", x, n, 0.5, 1.2, s)
              for s in (-0.1, 0.25)]
    x, n = f64([0.1, 0.2, 0.0]), _unit([0.1, 0.05, 1.0])
    near = [(f"x 0.2 below a light of side 2, n tilted, s = {s}", x, n, 1.0, 0.2, s) for s in (0.0, 0.6, -0.9)]
    outside = [(f"x below the centre, s = {s}, outside the light [-0.5, 0.5]", zero, up, 0.5, 1.0, s)
               for s in (-0.75, 0.6)] + [("x off-centre, n tilted, s = 3", f64([0.3, -0.2, 0.1]),
                                          _unit([0.2, -0.3, 1.0]), 0.5, 1.2, 3.0)]
    return centre, tilted, near, outside


def _edge_problem(impl, label, x, n, half, height, s):
    name = f"edge_derivative({label})"
    out = _call(impl, x, n, half, height, s)
    if isinstance(out, numbers.Real) and not isinstance(out, bool):          # float, int, numpy scalars
        got = torch.tensor(float(out), dtype=torch.float64)
    else:
        got = _scalar(out, name)
        if got.numel() != 1:
            return f"{name}: one number expected, got shape {tuple(got.shape)}"
        got = got.to(torch.float64)
    expected = _edge(x, n, half, height, s)
    message = compare(got, expected, name=name, check_dtype=False, atol=ATOL_EDGE, rtol=RTOL_EDGE)
    if message is None:
        return None
    if float(expected) == 0.0:
        if _close(got, _edge(x, n, half, height, s, "outside"), 1e-6):
            return (f"{name}: s lies outside the light: the line y = s does not cross it, so no part of the light "
                    "moves into or out of view as s moves: dF/ds = 0")
        return f"{name}: s lies outside the light, where F does not change: 0 expected, got {float(got):.6g}"
    one_cosine = _edge(x, n, half, height, s, "no_cos_light")
    if _close(one_cosine, _edge(x, n, half, height, s, "no_cos_receiver"), 1e-9):   # n · r = height - x_z: which
        one_cosine = (one_cosine, "a cosine is missing: the kernel is k = cos θ_x cos θ_L / r² = "   # one can't tell
                                  "(n · r)(height - x_z) / |r|⁴, the receiver's cosine n · r / |r| times the "
                                  "light's (height - x_z) / |r|")
    else:
        one_cosine = (None, "")
    explanation = _match(got, _telling([
        one_cosine,
        (_edge(x, n, half, height, s, "sign"), "the sign: the visible strip y >= s shrinks as s grows, so F "
                                               "decreases, dF/ds = -(1/π) ∫ k(u, s) du"),
        (_edge(x, n, half, height, s, "no_pi"), "the 1/π is missing: F = (1/π) ∫∫ cos θ_x cos θ_L / r² dA, so "
                                                "dF/ds = -(1/π) ∫ k(u, s) du"),
        (_edge(x, n, half, height, s, "plain"), "the kernel is 1/r² alone: the form factor weighs it with both "
                                                "cosines, k = cos θ_x cos θ_L / r² "
                                                "= (n · r)(height - x_z) / |r|⁴"),
        (_edge(x, n, half, height, s, "no_cos_light"), "cos θ_L is missing: the light's own cosine, "
                                                       "(height - x_z) / |r| (its normal is -z), weighs the kernel "
                                                       "too, k = (n · r)(height - x_z) / |r|⁴"),
        (_edge(x, n, half, height, s, "no_cos_receiver"), "cos θ_x is missing: the receiver's cosine n · r / |r| "
                                                          "weighs the kernel too, k = (n · r)(height - x_z) / |r|⁴"),
    ], expected))
    return f"{name}: {explanation}" if explanation else message


@task("14.4", "edge_derivative", points=4, reference=("course.grading.lecture14", "edge_derivative_reference"))
def _check_edge(impl):
    forbidden = forbidden_call(impl, "edge_derivative", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    centre, tilted, near, outside = _edge_cases()

    def run(cases):
        def part():
            for case in cases:
                require(_edge_problem(impl, *case))
        return part
    return grade_parts((1, "below the centre, n up", run(centre)), (1, "off-centre, a tilted normal", run(tilted)),
                       (1, "a receiver near the light", run(near)), (1, "s outside the light", run(outside)))
