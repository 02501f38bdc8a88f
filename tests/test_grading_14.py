"""Lecture 14's graded tasks (course/grading/lecture14.py): the references agree with the package
(course.shadows.area.polygon_form_factor for 14.1, the package's projection onto the light for 14.2,
course.shadows.gradients._clip for 14.3, and for 14.4 converged central differences of the package's form factor
of the visible part of the light), they score full marks, solutions written as students would (acos for the
angle, a walk from another start vertex, quadrature, a closed form, central differences of their own form factor)
score full marks without calling them, typical mistakes lose points with the diagnosis a student can act on,
and calling the package scores 0."""
import math

import numpy as np
import pytest
import torch

from course.grading import lecture14, run_check, tasks_for_lecture
from course.shadows import area, gradients
from grading_contract import contract

REFERENCES = {"14.1": lambda x, n, poly: lecture14._lambert(x, n, poly),
              "14.2": lambda x, v, p, m: lecture14._project(x, v, p, m),
              "14.3": lambda poly, values: lecture14._clip_polygon(poly, values),
              "14.4": lambda x, n, half, height, s: lecture14._edge(x, n, half, height, s)}


# ------------------------------------------------------------------------------ solutions, as students write

def lambert_form_factor(x, n, poly):
    total = 0.0
    K = poly.shape[0]
    for i in range(K):
        a = poly[i] - x
        b = poly[(i + 1) % K] - x
        c = torch.linalg.cross(a, b)
        gamma = torch.acos(torch.dot(a, b) / (torch.linalg.norm(a) * torch.linalg.norm(b)))   # acos is fine
        total = total + gamma * torch.dot(n, c) / torch.linalg.norm(c)
    return -total / (2 * math.pi)


def project_from_point(x, verts, plane_point, plane_normal):
    n = plane_normal / torch.linalg.norm(plane_normal)                  # normalised: its length cancels anyway
    dx = torch.dot(x - plane_point, n)
    dv = (verts - plane_point) @ n
    level = torch.nonzero(dv == dx).flatten()
    if len(level) > 0:
        raise ValueError(f"vertex {int(level[0])} is at the level of x: its ray never meets the plane")
    t = dx / (dx - dv)
    return x + (verts - x) * t.unsqueeze(1)


def clip_polygon(poly, values):
    out = []
    K = len(poly)
    for i in range(K):
        j = (i + 1) % K
        if values[i] >= 0:
            out.append(poly[i])
        if (values[i] > 0 and values[j] < 0) or (values[i] < 0 and values[j] > 0):
            t = values[i] / (values[i] - values[j])
            out.append(poly[i] + t * (poly[j] - poly[i]))
    if len(out) < 3:
        return torch.zeros((0, 3), dtype=poly.dtype)
    return torch.stack(out)


def edge_derivative(x, n, half, height, s):
    if s <= -half or s >= half:
        return 0.0
    u, w = np.polynomial.legendre.leggauss(100)                          # 100-point Gauss–Legendre
    u, w = torch.tensor(u * half), torch.tensor(w * half)
    r = torch.stack([u - x[0], s - x[1] + 0 * u, height - x[2] + 0 * u], dim=1)
    k = (r @ n) * (height - x[2]) / (r * r).sum(1) ** 2
    return float(-(w * k).sum() / math.pi)


SOLUTIONS = {"14.1": lambert_form_factor, "14.2": project_from_point, "14.3": clip_polygon, "14.4": edge_derivative}


def lambert_vectorised(x, n, poly):
    r = poly - x
    c = torch.cross(r, torch.roll(r, -1, 0), dim=1)
    gamma = torch.atan2(c.norm(dim=1), (r * torch.roll(r, -1, 0)).sum(1))
    return -(gamma * (c @ n) / c.norm(dim=1)).sum() / (2 * torch.pi)


def lambert_normalising_n(x, n, poly):
    return lambert_vectorised(x, n / n.norm(), poly)                     # dF/dn then has no part along n


def clip_from_the_last_edge(poly, values):
    """The textbook loop: edges (i - 1, i), the crossing before the vertex: the same polygon from another start."""
    out = []
    for i in range(len(poly)):
        prev, cur = poly[i - 1], poly[i]
        vp, vc = values[i - 1], values[i]
        if vp * vc < 0:
            out.append(prev + vp / (vp - vc) * (cur - prev))
        if vc >= 0:
            out.append(cur)
    return torch.stack(out) if len(out) >= 3 else poly[:0]


def edge_derivative_by_differences(x, n, half, height, s):
    """Central differences of the student's own form factor of the visible rectangle y >= s."""
    if not -half < s < half:
        return 0.0

    def F(y):
        rect = torch.tensor([[-half, y, height], [-half, half, height], [half, half, height], [half, y, height]],
                            dtype=torch.float64)
        return lambert_vectorised(x, n, rect)
    eps = 1e-5
    return float((F(s + eps) - F(s - eps)) / (2 * eps))


def edge_derivative_exact(x, n, half, height, s):
    """The antiderivative in u, written out."""
    if s <= -half or s >= half:
        return 0.0
    H, b = height - float(x[2]), s - float(x[1])
    B = b * b + H * H
    C = float(n[1]) * b + float(n[2]) * H

    def prim(u):
        w = u - float(x[0])
        q = w * w + B
        return H * (-float(n[0]) / (2 * q) + C * (w / (2 * B * q) + math.atan(w / math.sqrt(B)) / (2 * B ** 1.5)))
    return -(prim(half) - prim(-half)) / math.pi


@pytest.mark.parametrize("task_id, impl", [("14.1", lambert_vectorised), ("14.1", lambert_normalising_n),
                                           ("14.3", clip_from_the_last_edge), ("14.4", edge_derivative_exact),
                                           ("14.4", edge_derivative_by_differences)],
                         ids=lambda v: v if isinstance(v, str) else v.__name__)
def test_other_correct_solutions_score_full_marks(task_id, impl):
    result = run_check(task_id, impl)
    assert (result.points, result.message) == (result.max_points, "")


# ------------------------------------------------------------------------------------- typical mistakes

def project_no_error(x, verts, plane_point, plane_normal):
    dx = (x - plane_point) @ plane_normal
    dv = (verts - plane_point) @ plane_normal
    return x + (verts - x) * (dx / (dx - dv))[:, None]


def clip_floats(poly, values):
    """t from Python floats: the crossings do not move with the values in autograd."""
    v = values.tolist()
    out = []
    for i in range(len(v)):
        j = (i + 1) % len(v)
        if v[i] >= 0:
            out.append(poly[i])
        if v[i] * v[j] < 0:
            out.append(poly[i] + v[i] / (v[i] - v[j]) * (poly[j] - poly[i]))
    return torch.stack(out) if len(out) >= 3 else poly[:0]


def edge(kind):
    return lambda x, n, half, height, s: float(lecture14._edge(x, n, half, height, s, kind))


MISTAKES = [
    ("14.1", lambda x, n, p: lecture14._lambert(x, n, p, "pi"), 0, ["2π", "twice"]),
    ("14.1", lambda x, n, p: lecture14._lambert(x, n, p, "sign"), 0, ["negative", "negate"]),
    ("14.1", lambda x, n, p: lecture14._lambert(x, n, p, "unnormalised"), 0, ["not normalised"]),
    ("14.1", lambda x, n, p: lecture14._lambert(x, n, p, "poly_normal_back"), 1, ["polygon's normal"]),
    ("14.1", lambda x, n, p: lecture14._lambert(x, n, p, "poly_normal"), 0, ["negate", "polygon's normal"]),
    ("14.1", lambda x, n, p: lecture14._lambert(x, n, p).double(), 2, ["dtype float32 in, float64 out"]),
    ("14.1", lambda x, n, p: lecture14._lambert(x, n, p).detach(), 2, ["no gradient"]),
    ("14.2", lambda x, v, p, m: lecture14._project(x, v, p, m, "orthogonal"), 0, ["orthogonal projection"]),
    ("14.2", lambda x, v, p, m: lecture14._project(x, v, p, m, "t_dv"), 0, ["wrong t"]),
    ("14.2", lambda x, v, p, m: lecture14._project(x, v, p, m, "t_flip"), 0, ["wrong t"]),
    ("14.2", lambda x, v, p, m: lecture14._project(x, v, p, m, "mixed_up"), 1, ["normal's length"]),
    ("14.2", lambda x, v, p, m: lecture14._project(x, v, p, m, "mixed_down"), 1, ["normal's length"]),
    ("14.2", project_no_error, 1, ["ValueError"]),
    ("14.3", lambda poly, values: lecture14._clip_polygon(poly, -values), 0, ["wrong side"]),
    ("14.3", lambda poly, values: lecture14._clip_polygon(poly, values, "wrong_end"), 0, ["wrong end"]),
    ("14.3", lambda poly, values: lecture14._clip_polygon(poly, values, "wrong_end_out"), 0, ["wrong end"]),
    ("14.3", lambda poly, values: lecture14._clip_polygon(poly, values, "leaving"), 0, ["crossing is missing"]),
    ("14.3", lambda poly, values: lecture14._clip_polygon(poly, values, "entering"), 0, ["crossing is missing"]),
    ("14.3", lambda poly, values: lecture14._clip_polygon(poly, values, "duplicate"), 2, ["came out twice"]),
    ("14.3", lambda poly, values: lecture14._clip_polygon(poly, values, "short"), 2, ["empty (0, 3)"]),
    ("14.3", lambda poly, values: lecture14._clip_polygon(poly, values).flip(0), 0, ["other way round"]),
    ("14.3", clip_floats, 2, ["no gradient reaches values"]),
    ("14.4", edge("sign"), 1, ["shrinks as s grows"]),
    ("14.4", edge("no_pi"), 1, ["1/π is missing"]),
    ("14.4", edge("plain"), 1, ["1/r² alone"]),
    ("14.4", edge("no_cos_light"), 1, ["a cosine is missing", "cos θ_L is missing"]),
    ("14.4", edge("no_cos_receiver"), 1, ["a cosine is missing", "cos θ_x is missing"]),
    ("14.4", edge("outside"), 3, ["outside the light", "dF/ds = 0"]),
]

(test_the_reference_scores_full_marks, test_a_students_solution_scores_full_marks,
 test_a_typical_mistake_loses_points_with_a_useful_message) = contract(REFERENCES, SOLUTIONS, MISTAKES)


def test_lecture_14_has_four_tasks_and_the_one_that_needs_thought_weighs_most():
    tasks = tasks_for_lecture(14)
    assert [(t.id, t.name, t.points) for t in tasks] == [
        ("14.1", "lambert_form_factor", 3), ("14.2", "project_from_point", 2), ("14.3", "clip_polygon", 3),
        ("14.4", "edge_derivative", 4)]
    assert tasks[-1].points > max(t.points for t in tasks[:-1])


# ------------------------------------------------------------------------------ the references are the package

def test_the_form_factor_is_the_packages_and_the_squares_closed_form():
    above, tilted = lecture14._form_factor_cases()
    for label, x, n, poly in above + tilted:
        area_vector = torch.linalg.cross(poly, poly.roll(-1, 0), dim=1).sum(0)
        assert float((x - poly[0]) @ area_vector) > 0, label                 # the polygon faces x,
        assert bool(((poly - x) @ n > 0).all()), label                     # in front of x's tangent plane,
        turn = torch.linalg.cross(poly.roll(-1, 0) - poly, poly.roll(-2, 0) - poly.roll(-1, 0), dim=1) @ area_vector
        assert bool((turn > 0).all()), label                               # convex, counter-clockwise
        assert abs(float(n.norm()) - 1) < 1e-15
        ref = lecture14.lambert_form_factor_reference(x, n, poly)
        assert torch.allclose(ref, area.polygon_form_factor(x, n, poly), rtol=1e-14, atol=0), label
        assert 0 < float(ref) < 1
    for height in (1.0, 0.25):                                              # a square of half-side a at height h
        X = 0.5 / height                                                    # straight above: the four corners'
        closed = 4 / math.pi * X / math.sqrt(1 + X * X) * math.atan(X / math.sqrt(1 + X * X))   # rectangles
        x, n = torch.zeros(3, dtype=torch.float64), torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
        got = float(lecture14.lambert_form_factor_reference(x, n, lecture14._square_above(0.5, height)))
        assert abs(got - closed) < 1e-14


def test_the_projection_lands_on_the_plane_on_the_line_from_x_as_the_packages_shadow_does():
    for label, x, verts, p, m in lecture14._projection_cases():
        q = lecture14.project_from_point_reference(x, verts, p, m)
        assert ((q - p) @ m).abs().max() < 1e-13 * float(m.norm()), label   # on the plane
        along = torch.linalg.cross(q - x, verts - x, dim=1).norm(dim=1)
        assert along.max() < 1e-12, label                                   # on the line from x through v
        # the package's point-light shadow: v + (v - x) h / (h_x - h), h the heights above the plane
        n_hat = m / m.norm()
        h, h_x = (verts - p) @ n_hat, (x - p) @ n_hat
        assert torch.allclose(q, verts + (verts - x) * (h / (h_x - h))[:, None], rtol=0, atol=1e-12), label
    _, (label, x, verts, p, m), _ = lecture14._projection_cases()
    n_hat = m / m.norm()
    tri = verts[:3]
    D = gradients._shadow_polygon(tri, p, n_hat, gradients._Light(None, x), cos=(x - p) @ n_hat, tol=1e-12)
    q = lecture14.project_from_point_reference(x, tri, p, m)
    assert any(torch.allclose(D, q.roll(k, 0), atol=1e-12) or torch.allclose(D, q.flip(0).roll(k, 0), atol=1e-12)
               for k in range(3))
    with pytest.raises(ValueError, match="vertex 1"):
        lecture14.project_from_point_reference(torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64),
                                               torch.tensor([[0.0, 0.0, 2.0], [1.0, 1.0, 1.0]], dtype=torch.float64),
                                               torch.tensor([0.0, 0.0, 3.0], dtype=torch.float64),
                                               torch.tensor([0.0, 0.0, -2.0], dtype=torch.float64))


def test_the_clip_is_the_packages_on_the_checks_and_on_random_inputs():
    cut, special = lecture14._clip_cases()
    for label, poly, values in cut + special:
        assert torch.equal(lecture14.clip_polygon_reference(poly, values), gradients._clip(poly, values, 0.0)), label
    g = torch.Generator().manual_seed(14)
    for k in range(20):
        K = 3 + k % 5
        angles = torch.sort(torch.rand(K, generator=g, dtype=torch.float64) * 2 * math.pi).values
        poly = lecture14._polygon(angles, torch.randn(3, generator=g, dtype=torch.float64),
                                  torch.randn(3, generator=g, dtype=torch.float64), 1.0)
        values = (poly - poly.mean(0) - 0.3 * torch.randn(3, generator=g, dtype=torch.float64)) @ \
            torch.randn(3, generator=g, dtype=torch.float64)
        assert torch.equal(lecture14.clip_polygon_reference(poly, values), gradients._clip(poly, values, 0.0))


def _visible_form_factor(x, n, half, height, s):
    """The package's form factor of the part y >= s of the square light (counter-clockwise about -z)."""
    rect = torch.tensor([[-half, s, height], [-half, half, height], [half, half, height], [half, s, height]],
                        dtype=torch.float64)
    return float(area.polygon_form_factor(x, n, rect))


def test_the_edge_derivative_is_the_converged_central_difference_of_the_form_factor():
    for part in lecture14._edge_cases()[:3]:
        for label, x, n, half, height, s in part:
            want = lecture14.edge_derivative_reference(x, n, half, height, s)
            assert want < 0, label                                           # less of the light as s grows
            corners = torch.tensor([[a, b, height] for a in (-half, half) for b in (-half, half)], dtype=torch.float64)
            assert bool(((corners - x) @ n > 0).all()), label               # the light is in front of x
            assert _visible_form_factor(x, n, half, height, -half) > 0       # the winding: F > 0
            fd = [(_visible_form_factor(x, n, half, height, s + e) - _visible_form_factor(x, n, half, height, s - e))
                  / (2 * e) for e in (1e-4, 1e-5)]
            assert abs(fd[0] - fd[1]) < 2e-7 * abs(want), label              # converged: two steps agree
            assert abs(fd[1] - want) < 1e-8 * abs(want), label
            u, w = np.polynomial.legendre.leggauss(200)                      # and quadrature to rounding
            u, w = torch.tensor(u * half), torch.tensor(w * half)
            r = torch.stack([u - x[0], s - x[1] + 0 * u, height - x[2] + 0 * u], 1)
            quad = float(-(w * (r @ n) * (height - x[2]) / (r * r).sum(1) ** 2).sum() / math.pi)
            assert abs(quad - want) < 1e-13 * abs(want), label
    for label, x, n, half, height, s in lecture14._edge_cases()[3]:
        assert lecture14.edge_derivative_reference(x, n, half, height, s) == 0.0, label
        assert lecture14._edge(x, n, half, height, s, "outside") != 0, label   # the mistake is told apart


def test_the_mistakes_of_the_edge_derivative_are_far_outside_the_tolerance():
    for part in lecture14._edge_cases()[:3]:
        for label, x, n, half, height, s in part:
            want = float(lecture14._edge(x, n, half, height, s))
            for kind in ("sign", "no_pi", "plain", "no_cos_light", "no_cos_receiver"):
                wrong = float(lecture14._edge(x, n, half, height, s, kind))
                assert abs(wrong - want) > 1e-3 * abs(want), (label, kind)


# --------------------------------------------------------------------------------- calling the package

def edge_from_the_packages_form_factor(x, n, half, height, s):
    if not -half < s < half:
        return 0.0
    return (_visible_form_factor(x, n, half, height, s + 1e-5)
            - _visible_form_factor(x, n, half, height, s - 1e-5)) / 2e-5


def test_calling_the_package_scores_zero():
    for task_id, impl in (("14.1", lambda x, n, poly: area.polygon_form_factor(x, n, poly)),
                          ("14.1", lambda x, n, poly: area.light_form_factor(x[None], n[None], poly)[0]),
                          ("14.2", lambda x, v, p, m: lecture14.project_from_point_reference(x, v, p, m)),
                          ("14.3", lambda poly, values: gradients._clip(poly, values, 0.0)),
                          ("14.3", lambda poly, values: lecture14.clip_polygon_reference(poly, values)),
                          ("14.4", edge_from_the_packages_form_factor),
                          ("14.4", lambda x, n, half, height, s: lecture14.edge_derivative_reference(x, n, half,
                                                                                                   height, s))):
        result = run_check(task_id, impl)
        assert result.points == 0 and "course" in result.message, (task_id, result.message)
