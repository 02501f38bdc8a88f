"""Lecture 09's graded tasks (course/grading/lecture09.py): the references agree with the package (autograd
through course.coverage.halfplane_pixel_area, course.visibility.image_gradient on a one-triangle scene), they
score full marks, a solution written as a student would scores full marks without calling them, typical
mistakes lose points with the diagnosis a student can act on, and calling the package scores 0."""
import math

import pytest
import torch

from course.camera import Camera
from course.coverage import halfplane_pixel_area
from course.grading import run_check, tasks_for_lecture
from grading_contract import contract
from course.grading import lecture09
from course.grading.lecture09 import (best_step_reference, boundary_term_reference, edge_sample_reference,
                                      triangle_term_reference)
from course.mesh import Mesh
from course.visibility import image_gradient

# the public references are forbidden to students; these call the same code under its private names
REFERENCES = {"9.1": lambda f, x, grad, steps, dtype: lecture09._best(f, x, grad, steps, dtype),
              "9.2": lambda *a: lecture09._boundary(*a).to(a[4].dtype),
              "9.3": lambda *a: lecture09._triangle(*a).to(a[2].dtype),
              "9.4": lambda p0, p1, v0, v1, jump, col, row, n, gen: lecture09._estimate(
                  p0, p1, v0, v1, jump, col, row, torch.rand(n, generator=gen, dtype=torch.float64)).to(jump.dtype)}


# ------------------------------------------------------------------------------ solutions, as students write

def central_difference(f, x, h, forward=False):
    grads = torch.zeros_like(x)
    for i in range(x.shape[0]):
        step = torch.zeros_like(x)
        step[i] = h
        low = f(x) if forward else f(x - step)
        grads[i] = (f(x + step) - low) / (h if forward else 2 * h)
    return grads


def steps_analysis(f, x, grad, steps, dtype, forward=False, cast=True, relative=True, worst=False, index=False):
    x = x.to(dtype) if cast else x
    errors = []
    for h in steps:
        diff = central_difference(f, x, h, forward).double() - grad
        errors.append(float(diff.norm() / grad.norm() if relative else diff.norm()))
    k = errors.index(max(errors) if worst else min(errors))
    return (k if index else steps[k]), errors[k]


def best_step(f, x, grad, steps, dtype):
    return steps_analysis(f, x, grad, steps, dtype)


def clip_to_pixel(p0, p1, col, row):
    s0, s1 = 0.0, 1.0
    for k, lo in ((0, col), (1, row)):
        d = float(p1[k] - p0[k])
        if d == 0:
            if not lo <= float(p0[k]) <= lo + 1:
                return 0.0, 0.0
            continue
        a, b = (lo - float(p0[k])) / d, (lo + 1 - float(p0[k])) / d
        s0, s1 = max(s0, min(a, b)), min(s1, max(a, b))
    return s0, s1


def term(p0, p1, v0, v1, jump, col, row, sign=1.0, length=True, clip=True, unit=True, guard=True):
    e = p1 - p0
    L = e.norm()
    if guard and L == 0:
        return torch.zeros_like(jump)
    s0, s1 = clip_to_pixel(p0, p1, col, row) if clip else (0.0, 1.0)
    if s1 <= s0:
        return torch.zeros_like(jump)
    n = sign * torch.stack([e[1], -e[0]]) / (L if unit else 1.0)
    s = 0.5 * (s0 + s1)
    v = (1 - s) * v0 + s * v1
    return jump * (v @ n) * (s1 - s0) * (L if length else 1.0)


def boundary_term(p0, p1, v0, v1, jump, col, row):
    return term(p0, p1, v0, v1, jump, col, row)


def sample(p0, p1, v0, v1, jump, col, row, samples, generator, length=True, per_hit=False, fixed=False,
           count=None):
    e = p1 - p0
    L = e.norm()
    if L == 0:
        return torch.zeros_like(jump)
    n = count or samples
    s = (torch.arange(n, dtype=p0.dtype) + 0.5) / n if fixed else torch.rand(n, generator=generator, dtype=p0.dtype)
    p = p0 + s[:, None] * e
    v = (1 - s[:, None]) * v0 + s[:, None] * v1
    normal = torch.stack([e[1], -e[0]]) / L
    inside = (p[:, 0] >= col) & (p[:, 0] < col + 1) & (p[:, 1] >= row) & (p[:, 1] < row + 1)
    total = ((v @ normal) * inside).sum()
    hits = max(int(inside.sum()), 1) if per_hit else n
    return jump * total * (L if length else 1.0) / hits


def edge_sample(p0, p1, v0, v1, jump, col, row, samples, generator):
    return sample(p0, p1, v0, v1, jump, col, row, samples, generator)


def triangle(tri, vel, color, background, col, row, orient="out", jump=None):
    total = torch.zeros_like(color)
    for k in range(3):
        a, b, va, vb = tri[k], tri[(k + 1) % 3], vel[k], vel[(k + 1) % 3]
        e = b - a
        inward = float(torch.stack([e[1], -e[0]]) @ (tri[(k + 2) % 3] - a)) > 0
        if (orient == "out" and inward) or (orient == "in" and not inward):
            a, b, va, vb = b, a, vb, va
        total = total + boundary_term(a, b, va, vb, color - background if jump is None else jump(color, background),
                                      col, row)
    return total


def triangle_term(tri, vel, color, background, col, row):
    return triangle(tri, vel, color, background, col, row)


def counter_clockwise_only(tri, vel, color, background, col, row):
    """Keeps the edges as the vertices come: right for one winding, the wrong way round for the other."""
    return triangle(tri, vel, color, background, col, row, orient="given")


def boundary_term_unwritten(p0, p1, v0, v1, jump, col, row):
    raise NotImplementedError()


def triangle_on_an_unwritten_boundary_term(tri, vel, color, background, col, row):
    return sum(boundary_term_unwritten(tri[k], tri[(k + 1) % 3], vel[k], vel[(k + 1) % 3], color - background,
                                       col, row) for k in range(3))


SOLUTIONS = {"9.1": best_step, "9.2": boundary_term, "9.3": triangle_term, "9.4": edge_sample}

MISTAKES = [
    ("9.1", lambda *a: steps_analysis(*a, cast=False), 1, ["not in float32", "cast x to dtype"]),
    ("9.1", lambda *a: steps_analysis(*a, forward=True), 0, ["forward difference"]),
    ("9.1", lambda *a: steps_analysis(*a, relative=False), 0, ["the error is absolute"]),
    ("9.1", lambda *a: steps_analysis(*a, worst=True), 0, ["largest error"]),
    ("9.1", lambda *a: steps_analysis(*a, index=True), 0, ["is an index"]),
    ("9.1", lambda f, x, grad, steps, dtype: (1e-5, 2.1e-11), 0, ["h = 1e-05 expected 0.1"]),
    ("9.1", lambda *a: list(steps_analysis(*a)) + [0.0], 0, ["return a pair (h, error)"]),
    ("9.2", lambda *a: term(*a, sign=-1.0), 0, ["sign of the normal"]),
    ("9.2", lambda *a: term(*a, length=False), 0, ["length of the edge inside the pixel is missing"]),
    ("9.2", lambda *a: term(*a, unit=False), 0, ["not normalised"]),
    ("9.2", lambda *a: term(*a, clip=False), 0, ["clip it to the pixel"]),
    ("9.2", lambda *a: term(*a, guard=False), 3, ["zero-length edge"]),
    ("9.3", counter_clockwise_only, 0, ["right for one winding only"]),
    ("9.3", lambda *a: triangle(*a, orient="in"), 0, ["the sign is flipped"]),
    ("9.3", lambda *a: triangle(*a, jump=lambda c, b: c), 1, ["the background is missing"]),
    ("9.3", lambda *a: triangle(*a, jump=lambda c, b: b - c), 0, ["the sign is flipped"]),
    ("9.3", triangle_on_an_unwritten_boundary_term, 0, ["boundary_term_unwritten, which it calls, is not written"]),
    ("9.4", lambda *a: sample(*a, length=False), 0, ["length weight is missing"]),
    ("9.4", lambda *a: sample(*a, per_hit=True), 0, ["biased"]),
    ("9.4", lambda *a: sample(*a, fixed=True), 2, ["the same result for every generator"]),
    ("9.4", lambda *a: sample(*a, count=64), 1, ["standard deviations", "expected about 4"]),
]


def test_lecture_09_has_four_tasks_with_points_by_difficulty():
    assert [(t.id, t.name, t.points) for t in tasks_for_lecture(9)] == [
        ("9.1", "best_step", 3), ("9.2", "boundary_term", 4), ("9.3", "triangle_term", 2), ("9.4", "edge_sample", 3)]
    assert {task for task, *_ in MISTAKES} == set(REFERENCES)


(test_the_reference_scores_full_marks, test_a_students_solution_scores_full_marks,
 test_a_typical_mistake_loses_points_with_a_useful_message) = contract(REFERENCES, SOLUTIONS, MISTAKES)


# ------------------------------------------------------------------------- the references against the package

def test_the_best_step_reference_finds_the_bottom_of_the_step_size_curve():
    """On the coverage of a pixel by a half-plane, as a function of (a, b, c): the central difference at the
    float64 best step agrees with autograd to 1e-9; float32's best step is larger and its error far larger
    (round-off lifts the left branch), while at the largest step both precisions make the same truncation
    error (1 %)."""
    line = torch.tensor([0.6, -0.8, 0.8 * 3.4 - 0.6 * 5.3], dtype=torch.float64, requires_grad=True)
    area = lambda l: halfplane_pixel_area(l, 5, 3)                        # noqa: E731
    area(line).backward()
    steps = [10.0 ** -k for k in range(1, 9)]
    h64, e64 = best_step_reference(area, line.detach(), line.grad, steps, torch.float64)
    h32, e32 = best_step_reference(area, line.detach(), line.grad, steps, torch.float32)
    fd = lecture09._central(area, line.detach(), h64)
    assert torch.allclose(fd, line.grad, atol=1e-9, rtol=0) and e64 < 1e-9
    assert h32 > h64 and e32 > 1e3 * e64
    big = [lecture09._step_errors(area, line.detach(), line.grad, steps[:1], dtype)[0]
           for dtype in (torch.float64, torch.float32)]
    assert math.isclose(big[0], big[1], rel_tol=1e-2)


@pytest.mark.parametrize("p, q", [((5.3, 3.4), (4.1, 1.2)), ((3.7, 2.2), (7.4, 4.9)), ((4.9, 2.1), (4.2, 3.8))])
def test_the_boundary_term_of_a_translated_line_is_the_derivative_of_the_covered_area(p, q):
    """The half-plane a x + b y + c >= 0 with the line through p, q (long enough to cross the whole pixel):
    moving it by t v changes c at rate −(a, b) · v; autograd through halfplane_pixel_area gives d area / dt.
    The edge runs so that its outward normal (e_y, −e_x) / |e| points out of the half-plane (to a x + b y + c
    < 0); float64 sums of a few terms: 1e-12."""
    p, q = torch.tensor(p, dtype=torch.float64), torch.tensor(q, dtype=torch.float64)
    d = (q - p) / (q - p).norm()
    p0, p1 = p - 10 * d, q + 10 * d                                       # well beyond the pixel (row 2, col 4)
    e = p1 - p0
    ab = torch.stack([-e[1], e[0]])                                       # inside: opposite the outward normal
    v = torch.tensor([0.37, -0.81], dtype=torch.float64)
    t = torch.zeros((), dtype=torch.float64, requires_grad=True)
    c = -(ab @ p0) - t * (ab @ v)                                         # the line through p0 + t v
    halfplane_pixel_area(torch.cat([ab, c[None]]), 4, 2).backward()
    jump = torch.tensor([1.0, 0.5, -2.0], dtype=torch.float64)
    expected = float(t.grad) * jump
    assert abs(float(t.grad)) > 1e-3
    assert torch.allclose(boundary_term_reference(p0, p1, v, v, jump, 4, 2), expected, atol=1e-12, rtol=1e-12)


@pytest.mark.parametrize("order", [(0, 1, 2), (0, 2, 1)], ids=["one winding", "the other winding"])
def test_the_triangle_term_is_the_derivative_of_image_gradient(order):
    """One flat triangle in front of a black background, a screen-aligned orthographic camera (pixel = world
    x, y), its vertices moving at random screen velocities: d pixel / dt = Σ_k dL/dvert_k · vel_k from
    image_gradient("exact") and "reynolds", for every pixel the triangle touches, whichever order its vertices
    come in: float64, 1e-10."""
    H, W = 8, 10
    cam = Camera(torch.eye(3, dtype=torch.float64), torch.eye(3, dtype=torch.float64),
                 torch.zeros(3, dtype=torch.float64), width=W, height=H, near=0.0, far=10.0, orthographic=True)
    tri = torch.tensor([[2.3, 1.6], [8.7, 3.2], [4.1, 6.9]], dtype=torch.float64)
    mesh = Mesh(torch.cat([tri, torch.full((3, 1), 2.0, dtype=torch.float64)], 1), torch.tensor([[0, 1, 2]]))
    color = torch.tensor([[0.9, 0.4, 0.2]], dtype=torch.float64)
    vel = torch.randn(3, 2, generator=torch.Generator().manual_seed(9), dtype=torch.float64)
    o = list(order)
    checked = 0
    for row in range(H):
        for col in range(W):
            ours = triangle_term_reference(tri[o], vel[o], color[0], torch.zeros(3, dtype=torch.float64), col, row)
            weights = torch.zeros(H, W, 3, dtype=torch.float64)
            weights[row, col, 0] = 1.0
            for method in ("exact", "reynolds"):
                g = image_gradient(mesh, cam, color, weights, method=method)
                rate = float((g[:, :2] * vel).sum())
                assert abs(rate - float(ours[0])) < 1e-10, (row, col, method, rate, float(ours[0]))
            checked += bool(ours.abs().sum() > 0)
    assert checked >= 10


def test_the_edge_sampling_reference_is_unbiased_and_its_error_falls_like_one_over_sqrt_n():
    """Over 400 seeds at N = 50 the mean estimate is within 5 standard errors of the boundary term (the spread
    measured on the same runs), and the RMS error over 100 seeds falls 4 ± 1.2 times from N = 64 to 1024."""
    args = lecture09._edge_args([3.2, 1.4], [6.9, 5.1], [0.6, -0.2], [0.1, 0.4], [0.8, -0.3, 0.25], 4, 2)
    exact = boundary_term_reference(*args)
    runs = torch.stack([edge_sample_reference(*args, 50, torch.Generator().manual_seed(k)) for k in range(400)])
    assert ((runs.mean(0) - exact).abs() <= 5 * runs.std(0) / math.sqrt(400)).all()
    rms = [float(((torch.stack([edge_sample_reference(*args, n, torch.Generator().manual_seed(k))
                               for k in range(100)]) - exact) ** 2).mean().sqrt()) for n in (64, 1024)]
    assert 2.8 < rms[0] / rms[1] < 5.2


CALLING_THE_PACKAGE = {
    "9.1": lambda f, x, grad, steps, dtype: image_gradient(None, None, None, None, method="finite_differences"),
    "9.2": lambda p0, p1, v0, v1, jump, col, row: halfplane_pixel_area(None, col, row),
    "9.3": lambda *a: image_gradient(None, None, None, None, method="reynolds"),
    "9.4": lambda *a: image_gradient(None, None, None, None, method="edge_sampling"),
}


@pytest.mark.parametrize("task_id", sorted(CALLING_THE_PACKAGE))
def test_calling_the_package_scores_zero(task_id):
    result = run_check(task_id, CALLING_THE_PACKAGE[task_id])
    assert result.points == 0 and "which does this task's work for you" in result.message, result.message


def boundary_via_grading(p0, p1, v0, v1, jump, col, row):
    from course.grading import lecture09
    return lecture09.boundary_term_reference(p0, p1, v0, v1, jump, col, row)


def test_calling_the_grading_reference_scores_zero():
    result = run_check("9.2", boundary_via_grading)
    assert result.points == 0
    assert result.message.startswith("boundary_term calls course.grading.lecture09.boundary_term_reference")
