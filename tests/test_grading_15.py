"""Lecture 15's graded tasks (course/grading/lecture15.py): the references agree with the package
(course.splats.project_gaussians for 15.1 with R = I, t = 0; render_gaussians on a one-pixel scene for 15.2; the
difference of the two orders composited for 15.3; for 15.4 a numerical quadrature of the line integral and
render_gaussians_volume's κ on the central ray), they score full marks, solutions written as students would (a
loop, cumulative products, the closed form of the jump, a quadrature of the line integral) score full marks
without calling them, typical mistakes lose points with the diagnosis a student can act on, and calling the
package scores 0."""
import math

import numpy as np
import pytest
import torch

from course import splats
from course.camera import Camera
from course.grading import lecture15, run_check, tasks_for_lecture
from grading_contract import contract

REFERENCES = {"15.1": lambda m, S, K: lecture15._cov2(m, S, K),
              "15.2": lambda a, c, bg: lecture15._composite_pixel(a, c, bg),
              "15.3": lambda aa, ca, ab, cb, bg: lecture15._swap(aa, ca, ab, cb, bg),
              "15.4": lambda m, S, o, d, op: lecture15._density(m, S, o, d, op)}


# ------------------------------------------------------------------------------ solutions, as students write

def covariance_2d(mean_cam, cov_cam, K):
    x, y, z = mean_cam[0], mean_cam[1], mean_cam[2]
    zero = torch.zeros_like(z)
    P = torch.stack([torch.stack([1 / z, zero, -x / z**2]), torch.stack([zero, 1 / z, -y / z**2])])
    J = K[:2, :2] @ P
    return J @ cov_cam @ J.T + 0.3 * torch.eye(2, dtype=cov_cam.dtype)


def composite_pixel(alphas, colors, background):
    C = torch.zeros(3, dtype=alphas.dtype)
    T = 1.0
    for a, c in zip(alphas, colors):
        alpha = torch.clamp(a, max=0.99)
        if alpha < 1 / 255:
            continue
        if T * (1 - alpha) < 1e-4:
            break
        C = C + c * alpha * T
        T = T * (1 - alpha)
    return C + T * background


def swap_jump(alpha_a, color_a, alpha_b, color_b, background):
    a_front = alpha_a * color_a + (1 - alpha_a) * alpha_b * color_b + (1 - alpha_a) * (1 - alpha_b) * background
    b_front = alpha_b * color_b + (1 - alpha_b) * alpha_a * color_a + (1 - alpha_b) * (1 - alpha_a) * background
    return a_front - b_front


def ray_density(mean, cov, origin, direction, opacity):
    u = direction / torch.linalg.norm(direction)
    P = torch.linalg.inv(cov)
    r = origin - mean
    a = u @ P @ u
    q_min = r @ P @ r - (r @ P @ u) ** 2 / a
    line_integral = torch.sqrt(2 * torch.pi / a) * torch.exp(-0.5 * q_min)
    return -torch.log(1 - opacity) / line_integral


SOLUTIONS = {"15.1": covariance_2d, "15.2": composite_pixel, "15.3": swap_jump, "15.4": ray_density}


def covariance_2d_with_solve(mean_cam, cov_cam, K):
    """J written entry by entry, the covariance symmetrised."""
    x, y, z = mean_cam.unbind()
    fx, s, fy = K[0, 0], K[0, 1], K[1, 1]
    J = torch.stack([torch.stack([fx / z, s / z, -(fx * x + s * y) / z**2]),
                     torch.stack([torch.zeros_like(z), fy / z, -fy * y / z**2])])
    S = (cov_cam + cov_cam.T) / 2
    return torch.einsum("ij,jk,lk->il", J, S, J) + torch.diag(torch.full((2,), 0.3, dtype=cov_cam.dtype))


def composite_vectorised(alphas, colors, background):
    alpha = alphas.clamp(max=0.99)
    alpha = torch.where(alpha >= 1 / 255, alpha, torch.zeros_like(alpha))
    before = torch.cumprod(torch.cat([torch.ones_like(alpha[:1]), 1 - alpha[:-1]]), 0)
    done = torch.cummax(((before * (1 - alpha)) < 1e-4).to(torch.int8), 0).values.bool()
    w = torch.where(done, torch.zeros_like(alpha), alpha * before)
    T = torch.where(done, torch.ones_like(alpha), 1 - alpha).prod()
    return w @ colors + T * background


def swap_jump_closed_form(alpha_a, color_a, alpha_b, color_b, background):
    return alpha_a * alpha_b * (color_a - color_b)


def ray_density_by_quadrature(mean, cov, origin, direction, opacity):
    """The line integral by the trapezoid rule over ±12 standard deviations about the closest point."""
    u = direction / direction.norm()
    P = torch.linalg.inv(cov)
    r = origin - mean
    a = u @ P @ u
    s_star = -(r @ P @ u) / a
    s = s_star + torch.linspace(-12.0, 12.0, 4001, dtype=mean.dtype) / a.sqrt()
    x = origin + s[:, None] * u - mean
    f = torch.exp(-0.5 * torch.einsum("ni,ij,nj->n", x, P, x))
    integral = torch.trapezoid(f, s)
    return -torch.log1p(-opacity) / integral


@pytest.mark.parametrize("task_id, impl", [("15.1", covariance_2d_with_solve), ("15.2", composite_vectorised),
                                           ("15.3", swap_jump_closed_form), ("15.4", ray_density_by_quadrature)],
                         ids=lambda v: v if isinstance(v, str) else v.__name__)
def test_other_correct_solutions_score_full_marks(task_id, impl):
    result = run_check(task_id, impl)
    assert (result.points, result.message) == (result.max_points, "")


# ------------------------------------------------------------------------------------- typical mistakes

def cov_transposed(mean_cam, cov_cam, K):
    x, y, z = mean_cam.unbind()
    zero = torch.zeros_like(z)
    J = K[:2, :2] @ torch.stack([torch.stack([1 / z, zero, -x / z**2]), torch.stack([zero, 1 / z, -y / z**2])])
    return J.T @ cov_cam @ J + 0.3 * torch.eye(2, dtype=cov_cam.dtype)


def composite_floats(alphas, colors, background):
    """T from Python floats: no gradient reaches alphas."""
    C, T = torch.zeros(3, dtype=alphas.dtype), 1.0
    for a, c in zip(alphas.tolist(), colors):
        alpha = min(a, 0.99)
        if alpha < 1 / 255:
            continue
        if T * (1 - alpha) < 1e-4:
            break
        C, T = C + c * alpha * T, T * (1 - alpha)
    return C + T * background


def cov(kind):
    return lambda m, S, K: lecture15._cov2(m, S, K, kind)


def comp(kind):
    return lambda a, c, bg: lecture15._composite_pixel(a, c, bg, kind)


def swap(kind):
    return lambda aa, ca, ab, cb, bg: lecture15._swap(aa, ca, ab, cb, bg, kind)


def density(kind):
    return lambda m, S, o, d, op: lecture15._density(m, S, o, d, op, kind)


MISTAKES = [
    ("15.1", cov("no_blur"), 0, ["low-pass filter is missing", "0.3 I"]),
    ("15.1", cov("blur_everywhere"), 0, ["every entry", "diagonal"]),
    ("15.1", cov("orthographic"), 1, ["third column", "-x/z²"]),
    ("15.1", cov("fx_only"), 0, ["only fx", "skew"]),
    ("15.1", cov_transposed, 0, ["shapes do not fit", "J Σ Jᵀ"]),
    ("15.1", lambda m, S, K: lecture15._cov2(m, S, K).double(), 2, ["dtype float32 in, float64 out"]),
    ("15.1", lambda m, S, K: lecture15._cov2(m, S, K).detach(), 2, ["no gradient"]),
    ("15.2", comp("no_clamp"), 2, ["not clamped", "min(0.99, a)"]),
    ("15.2", comp("no_skip"), 2, ["faint Gaussian was added", "1/255"]),
    ("15.2", comp("after"), 2, ["takes T below 1e-4 was added"]),
    ("15.2", comp("never_stop"), 2, ["never stopped"]),
    ("15.2", comp("continue"), 2, ["after the stopping one were added"]),
    ("15.2", comp("reversed"), 0, ["wrong order", "front to back"]),
    ("15.2", comp("no_background"), 0, ["background is missing", "C + T · background"]),
    ("15.2", composite_floats, 2, ["no gradient reaches alphas"]),
    ("15.3", swap("sign"), 0, ["the sign"]),
    ("15.3", swap("no_transmittance"), 0, ["(1 - α) factor is missing"]),
    ("15.3", lambda *args: lecture15._swap(*args).detach(), 1, ["no gradient"]),
    ("15.4", density("unnormalised"), 2, ["direction's length", "u = d / |d|"]),
    ("15.4", density("no_qmin"), 2, ["misses the mean", "q_min"]),
    ("15.4", density("inverted"), 1, ["inverted", "sqrt(2π / a)"]),
    ("15.4", density("opacity"), 1, ["optical depth", "-ln(1 - opacity)"]),
]

(test_the_reference_scores_full_marks, test_a_students_solution_scores_full_marks,
 test_a_typical_mistake_loses_points_with_a_useful_message) = contract(REFERENCES, SOLUTIONS, MISTAKES)


def test_lecture_15_has_four_tasks_and_the_one_that_needs_thought_weighs_most():
    tasks = tasks_for_lecture(15)
    assert [(t.id, t.name, t.points) for t in tasks] == [
        ("15.1", "covariance_2d", 3), ("15.2", "composite_pixel", 3), ("15.3", "swap_jump", 2),
        ("15.4", "ray_density", 4)]
    assert tasks[-1].points > max(t.points for t in tasks[:-1])
    assert (lecture15.ALPHA_MIN, lecture15.ALPHA_MAX, lecture15.T_MIN, lecture15.BLUR) == (
        splats.ALPHA_MIN, splats.ALPHA_MAX, splats.T_MIN, splats.BLUR)


# ------------------------------------------------------------------------------ the references are the package

def _one_pixel_camera(K=None):
    K = torch.tensor([[1.0, 0.0, 0.5], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]], dtype=torch.float64) if K is None else K
    return Camera(K, torch.eye(3, dtype=torch.float64), torch.zeros(3, dtype=torch.float64), 1, 1)


def _unit_quaternions(n, seed):
    q = torch.randn(n, 4, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    return q / q.norm(dim=1, keepdim=True)


def test_the_screen_covariance_is_project_gaussians_for_a_camera_at_the_origin():
    ahead, off_axis = lecture15._cov_cases()
    for K in {id(case[3]): case[3] for case in ahead + off_axis}.values():
        camera = Camera(K, torch.eye(3, dtype=torch.float64), torch.zeros(3, dtype=torch.float64), 640, 480)
        g = torch.Generator().manual_seed(15)
        means = torch.randn(8, 3, generator=g, dtype=torch.float64) + torch.tensor([0.0, 0.0, 5.0], dtype=torch.float64)
        scales = torch.rand(8, 3, generator=g, dtype=torch.float64) * 0.4 + 0.05
        rotations = _unit_quaternions(8, 151)
        _, cov2, _ = splats.project_gaussians(means, scales, rotations, camera)
        cov3 = splats.covariance_3d(scales, rotations)
        for m, S, want in zip(means, cov3, cov2):
            assert torch.allclose(lecture15.covariance_2d_reference(m, S, K), want, rtol=1e-12, atol=1e-12)
    for label, m, S, K in ahead + off_axis:                                 # the mistakes can be told apart
        want = lecture15._cov2(m, S, K)
        for kind in ("no_blur", "blur_everywhere", "fx_only"):
            assert not torch.allclose(lecture15._cov2(m, S, K, kind), want, rtol=1e-4, atol=1e-4), (label, kind)
        told = not torch.allclose(lecture15._cov2(m, S, K, "orthographic"), want, rtol=1e-4, atol=1e-4)
        assert told == (label in [c[0] for c in off_axis]), label


def _one_pixel_scene():
    """Six Gaussians on the pixel's ray (one far to the side: faint), in depth order: one clamped (o = 1 at the
    centre), one faint, the fifth stops the compositing."""
    f64 = lambda v: torch.tensor(v, dtype=torch.float64)                   # noqa: E731
    means = f64([[0.0, 0.0, 2.0], [5.0, 0.0, 2.5], [0.0, 0.0, 3.0], [0.01, -0.02, 3.5], [0.0, 0.0, 4.0],
                 [0.0, 0.0, 4.5]])
    scales = f64([[0.3, 0.2, 0.25]] * 6)
    rotations = _unit_quaternions(6, 152)
    opacities = f64([0.8, 0.9, 1.0, 0.9, 0.7, 0.5])
    colors = torch.rand(6, 3, generator=torch.Generator().manual_seed(152), dtype=torch.float64)
    return means, scales, rotations, opacities, colors


def test_one_pixel_composited_is_render_gaussians_one_pixel():
    means, scales, rotations, opacities, colors = _one_pixel_scene()
    camera = _one_pixel_camera()
    background = torch.tensor([0.2, 0.5, 0.9], dtype=torch.float64)
    image = splats.render_gaussians(means, scales, rotations, opacities, colors, camera, background)
    mean2, cov2, z = splats.project_gaussians(means, scales, rotations, camera)
    order = torch.argsort(z)
    d = torch.tensor([0.5, 0.5], dtype=torch.float64) - mean2[order]
    q = torch.einsum("ni,nij,nj->n", d, torch.linalg.inv(cov2[order]), d)
    raw = opacities[order] * torch.exp(-q / 2)
    assert float(raw.max()) > 0.99 and float(raw.min()) < 1 / 255                 # a clamp and a skip
    got = lecture15.composite_pixel_reference(raw, colors[order], background)
    assert torch.allclose(got, image[0, 0], rtol=1e-13, atol=1e-14)
    for kind in ("no_clamp", "no_skip", "after", "never_stop", "continue", "reversed", "no_background"):
        wrong = lecture15._composite_pixel(raw, colors[order], background, kind)
        assert not torch.allclose(wrong, got, atol=1e-6), kind
    for label, a, c, bg in sum(lecture15._composite_cases(), []):               # the graded cases are composited
        assert torch.equal(lecture15._composite_pixel(a, c, bg), composite_vectorised(a, c, bg)), label   # as the
                                                                                # package does


def test_the_swap_jump_is_the_difference_of_the_two_orders():
    random, special = lecture15._swap_cases()
    for label, aa, ca, ab, cb, bg in random + special:
        jump = lecture15.swap_jump_reference(aa, ca, ab, cb, bg)
        both = lecture15.composite_pixel_reference(torch.stack([aa, ab]), torch.stack([ca, cb]), bg) - \
            lecture15.composite_pixel_reference(torch.stack([ab, aa]), torch.stack([cb, ca]), bg)
        assert torch.allclose(jump, both, rtol=0, atol=1e-15), label
        assert torch.allclose(jump, aa * ab * (ca - cb), rtol=0, atol=1e-15), label   # the background cancels
    assert torch.equal(lecture15.swap_jump_reference(*special[0][1:]), torch.zeros(3, dtype=torch.float64))


def _optical_depth(mean, cov, origin, direction, kappa):
    """∫ κ exp(-½ q) ds along the line by the trapezoid rule, ±14 standard deviations about the closest point."""
    m, S, o, d = (np.asarray(t, dtype=np.float64) for t in (mean, cov, origin, direction))
    u = d / np.linalg.norm(d)
    P = np.linalg.inv(S)
    a = u @ P @ u
    s = -((o - m) @ P @ u) / a + np.linspace(-14.0, 14.0, 20001) / math.sqrt(a)
    x = o + s[:, None] * u - m
    return float(kappa) * np.trapezoid(np.exp(-0.5 * np.einsum("ni,ij,nj->n", x, P, x)), s)


def test_the_density_gives_the_opacity_by_quadrature_of_the_line_integral():
    through, offset, rotated, transparent = lecture15._density_cases()
    for label, m, S, o, d, op in through + offset + rotated:
        kappa = lecture15.ray_density_reference(m, S, o, d, op)
        tau = _optical_depth(m, S, o, d, kappa)
        assert abs(1 - math.exp(-tau) - float(op)) < 1e-12, label
        assert abs(float(lecture15._density(m, S, o, d * 2.3, op)) - float(kappa)) < 1e-12 * float(kappa), label
        for kind in ("unnormalised", "no_qmin", "inverted", "opacity"):         # far outside the tolerance,
            wrong = float(lecture15._density(m, S, o, d, op, kind))            # where the case can tell them
            if kind == "unnormalised" and abs(float(d.norm()) - 1) < 1e-12:
                continue
            if kind == "no_qmin" and label in [c[0] for c in through] + [rotated[0][0]]:
                continue
            assert abs(wrong - float(kappa)) > 1e-3 * float(kappa), (label, kind)
    for label, m, S, o, d, op in transparent:
        assert float(lecture15.ray_density_reference(m, S, o, d, op)) == 0.0, label


def test_the_density_on_the_central_ray_is_render_gaussians_volumes():
    mean = torch.tensor([[0.0, 0.0, 4.0]], dtype=torch.float64)               # on the pixel centre's ray
    scales = torch.tensor([[0.3, 0.5, 0.4]], dtype=torch.float64)
    rotations = _unit_quaternions(1, 154)
    opacity = torch.tensor([0.6], dtype=torch.float64)
    white = torch.ones(1, 3, dtype=torch.float64)
    image = splats.render_gaussians_volume(mean, scales, rotations, opacity, white, _one_pixel_camera(),
                                           samples=512)
    assert abs(float(image[0, 0, 0]) - 0.6) < 1e-9                            # the package's κ gives opacity 0.6
    cov = splats.covariance_3d(scales, rotations)[0]
    eye = torch.zeros(3, dtype=torch.float64)
    kappa = lecture15.ray_density_reference(mean[0], cov, eye, mean[0] - eye, opacity[0])
    assert abs(1 - math.exp(-_optical_depth(mean[0], cov, eye, mean[0], kappa)) - 0.6) < 1e-12
    strength = getattr(splats, "volume_strength", None)                       # the package's κ, where exposed
    if strength is not None:
        means = torch.tensor([[0.0, 0.0, 4.0], [0.7, -0.4, 3.0]], dtype=torch.float64)
        s2, q2, o2 = scales.repeat(2, 1), _unit_quaternions(2, 155), torch.tensor([0.6, 0.9], dtype=torch.float64)
        eye = torch.tensor([0.1, 0.2, -0.5], dtype=torch.float64)
        want = strength(means, s2, q2, o2, eye)
        for m, S, o, k in zip(means, splats.covariance_3d(s2, q2), o2, want):
            assert torch.allclose(lecture15.ray_density_reference(m, S, eye, m - eye, o), k, rtol=1e-12, atol=0)


# --------------------------------------------------------------------------------- calling the package

def cov_from_the_package(mean_cam, cov_cam, K):
    camera = Camera(K, torch.eye(3, dtype=K.dtype), torch.zeros(3, dtype=K.dtype), 640, 480)
    return splats.project_gaussians(mean_cam[None], torch.ones(1, 3), torch.tensor([[1.0, 0, 0, 0]]), camera)[1][0]


def composite_from_the_package(alphas, colors, background):
    camera = Camera(torch.eye(3), torch.eye(3), torch.zeros(3), 1, 1)
    return splats.render_gaussians(torch.zeros(len(alphas), 3), torch.ones(len(alphas), 3),
                                   torch.tensor([[1.0, 0, 0, 0]]).repeat(len(alphas), 1), alphas, colors, camera,
                                   background)[0, 0]


def density_from_the_package(mean, cov, origin, direction, opacity):
    return splats.volume_strength(mean[None], torch.ones(1, 3), torch.tensor([[1.0, 0, 0, 0]]), opacity[None],
                                  origin)[0]


def test_calling_the_package_scores_zero():
    for task_id, impl in (("15.1", cov_from_the_package),
                          ("15.1", lambda m, S, K: lecture15.covariance_2d_reference(m, S, K)),
                          ("15.2", composite_from_the_package),
                          ("15.2", lambda a, c, bg: lecture15.composite_pixel_reference(a, c, bg)),
                          ("15.3", lambda *args: lecture15.swap_jump_reference(*args)),
                          ("15.4", density_from_the_package),
                          ("15.4", lambda m, S, o, d, op: splats.render_gaussians_volume(m[None], S, o, d, op, None)),
                          ("15.4", lambda m, S, o, d, op: lecture15.ray_density_reference(m, S, o, d, op))):
        result = run_check(task_id, impl)
        assert result.points == 0 and "course" in result.message, (task_id, result.message)
