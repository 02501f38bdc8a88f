"""Lecture 08's graded tasks (course/grading/lecture08.py): the references agree with course.nmr.nmr_rasterize
and course.soft.soft_rasterize, they score full marks, a solution written as a student would scores full marks
without calling them, typical mistakes lose points with the diagnosis a student can act on, and calling the
package scores 0."""
import math

import pytest
import torch

from course import nmr, soft
from course.camera import Camera
from course.grading import run_check, tasks_for_lecture
from grading_contract import contract
from course.grading import lecture08
from course.grading.lecture08 import (nmr_edge_gradients_reference, sigma_for_blur_reference, soft_blend_reference,
                                      soft_coverage_reference)
from course.mesh import Mesh

# the public references are forbidden to students; these call the same code under its private names
REFERENCES = {"8.1": lambda row, *a: lecture08._nmr_row(row, *a).to(row.dtype),
              "8.2": lambda tri, *a: lecture08._coverage(tri, *a).to(tri.dtype),
              "8.3": lambda D, *a: lecture08._blend(D, *a).to(D.dtype),
              "8.4": lambda *a: lecture08._sigma_for_blur(*a)}


# ------------------------------------------------------------------------------ solutions, as students write

def edge_gradients(row, grad, x_left, x_right, color, background, min_step, rule=-1, both=True, floor=True,
                   across=True, direction="move"):
    """NMR along one row, a pixel at a time, as a student writes it; the keywords make the typical mistakes."""
    W = row.shape[0]
    first, last = math.ceil(x_left - 0.5), math.floor(x_right - 0.5)      # the span's first and last pixels
    left_colour = row[first - 1] if first >= 1 else background
    right_colour = row[last + 1] if last + 1 < W else background
    if not across:
        left_colour = right_colour = background
    d_left, d_right = torch.zeros((), dtype=row.dtype), torch.zeros((), dtype=row.dtype)

    def term(j, delta, move, dI):
        dot = (grad[j] * dI).sum()
        if (rule == -1 and dot >= 0) or (rule == 1 and dot <= 0):
            return 0.0
        step = max(abs(delta), min_step) if floor else abs(delta)
        if direction == "abs":
            return dot / step
        if direction == "clamp":
            return dot / max(delta, min_step)
        return dot / (move * step)
    for j in range(W):
        u = j + 0.5
        if u < x_left:
            d_left = d_left + term(j, u - x_left, -1, color - row[j])
        elif u > x_right:
            d_right = d_right + term(j, u - x_right, 1, color - row[j])
        else:
            near_left = u - x_left <= x_right - u
            if both or near_left:
                d_left = d_left + term(j, u - x_left, 1, left_colour - row[j])
            if both or not near_left:
                d_right = d_right + term(j, u - x_right, -1, right_colour - row[j])
    return torch.stack([d_left, d_right])


def nmr_edge_gradients(row, grad, x_left, x_right, color, background, min_step):
    return edge_gradients(row, grad, x_left, x_right, color, background, min_step)


def blur_sigma(width_px, image_width, level, ndc=True, half=True, logit=True):
    d = width_px / 2 if half else width_px
    sigma_px = d ** 2 / (math.log((1 - level) / level) if logit else -math.log(level))
    return 4 * sigma_px / image_width ** 2 if ndc else sigma_px


def sigma_for_blur(width_px, image_width, level):
    return blur_sigma(width_px, image_width, level)


def coverage(tri, height, width, sigma, ndc=True, square=True, segments=True, centre=0.5, flip=False,
             winding=0, guard=True):
    y, x = torch.meshgrid(torch.arange(height, dtype=tri.dtype) + centre,
                          torch.arange(width, dtype=tri.dtype) + centre, indexing="ij")
    d2, cross = [], []
    for k in range(3):
        a, b = tri[k], tri[(k + 1) % 3]
        e, wx, wy = b - a, x - a[0], y - a[1]
        ee = (e * e).sum()
        if guard:
            ee = torch.where(ee > 0, ee, torch.ones_like(ee))
        t = (wx * e[0] + wy * e[1]) / ee
        if segments:
            t = t.clamp(0, 1)
        d2.append((wx - t * e[0]) ** 2 + (wy - t * e[1]) ** 2)
        cross.append(e[0] * wy - e[1] * wx)
    d2 = torch.stack(d2).amin(0)
    area = sum(cross) if winding == 0 else torch.full_like(x, float(winding))
    inside = (cross[0] * area > 0) & (cross[1] * area > 0) & (cross[2] * area > 0)
    d = d2 if square else d2.sqrt()
    if ndc:
        d = d * (4.0 / width ** 2 if square else 2.0 / width)
    return torch.sigmoid(torch.where(inside != flip, d, -d) / sigma)


def soft_coverage(tri, height, width, sigma):
    return coverage(tri, height, width, sigma)


def soft_blend(D, z, colors, background, gamma, eps):
    log_w = torch.log(D) + z / gamma                                      # (F, H, W)
    log_b = torch.full_like(log_w[0], eps / gamma)
    top = torch.maximum(log_w.amax(0), log_b)
    w, w_b = torch.exp(log_w - top), torch.exp(log_b - top)
    num = (w[..., None] * colors[:, None, None, :]).sum(0) + w_b[..., None] * background
    return num / (w.sum(0) + w_b)[..., None]


SOLUTIONS = {"8.1": nmr_edge_gradients, "8.2": soft_coverage, "8.3": soft_blend, "8.4": sigma_for_blur}


# ------------------------------------------------------------------------------------------ mistakes

def naive_blend(D, z, colors, background, gamma, eps):
    w, w_b = D * torch.exp(z / gamma), torch.exp(torch.tensor(eps / gamma, dtype=D.dtype))
    return ((w[..., None] * colors[:, None, None, :]).sum(0) + w_b * background) / (w.sum(0) + w_b)[..., None]


def blend_with(bg_term=True, bg_one=False, sign=1.0, use_D=True, use_z=True, bg_in_max=True):
    def soft_blend(D, z, colors, background, gamma, eps):
        log_w = (torch.log(D) if use_D else torch.zeros_like(D)) + (sign * z / gamma if use_z else 0.0)
        log_b = torch.full_like(log_w[0], 0.0 if bg_one else eps / gamma)
        top = torch.maximum(log_w.amax(0), log_b) if bg_in_max and bg_term else log_w.amax(0)
        w, w_b = torch.exp(log_w - top), torch.exp(log_b - top)
        num, den = (w[..., None] * colors[:, None, None, :]).sum(0), w.sum(0)
        if bg_term:
            num, den = num + w_b[..., None] * background, den + w_b
        return num / den[..., None]
    return soft_blend


def nmr_with(**kw):
    return lambda *a: edge_gradients(*a, **kw)


MISTAKES = [
    ("8.1", nmr_with(rule=0), 0, ["sign rule is missing"]),
    ("8.1", nmr_with(rule=1), 0, ["wrong way round"]),
    ("8.1", nmr_with(both=False), 0, ["either edge"]),
    ("8.1", nmr_with(across=False), 2, ["across the edge"]),
    ("8.1", nmr_with(direction="abs"), 0, ["δx has a sign"]),
    ("8.1", nmr_with(direction="clamp"), 0, ["keep the move's sign"]),
    ("8.1", nmr_with(floor=False), 4, ["floor |δ| at min_step"]),
    ("8.1", lambda *a: lecture08._nmr_row(*a, direction="sign"), 4, ["direction of the move"]),
    ("8.1", lambda *a: lecture08._nmr_row(*a, centre=0.0), 0, ["j + 0.5"]),
    ("8.4", lambda *a: blur_sigma(*a, ndc=False), 0, ["σ_px", "NDC"]),
    ("8.4", lambda *a: blur_sigma(*a, half=False), 0, ["both sides of the edge"]),
    ("8.4", lambda *a: blur_sigma(*a, logit=False), 0, ["ln((1 − level) / level)"]),
    ("8.4", lambda *a: 2.07e-5, 0, ["expected"]),
    ("8.2", lambda t, h, w, s: coverage(t, h, w, s, ndc=False), 0, ["normalised device coordinates"]),
    ("8.2", lambda t, h, w, s: coverage(t, h, w, s, square=False), 0, ["square the distance"]),
    ("8.2", lambda t, h, w, s: coverage(t, h, w, s, flip=True), 0, ["swapped"]),
    ("8.2", lambda t, h, w, s: coverage(t, h, w, s, segments=False), 0, ["infinite line"]),
    ("8.2", lambda t, h, w, s: coverage(t, h, w, s, centre=0.0), 0, ["(j + 0.5, i + 0.5)"]),
    ("8.2", lambda t, h, w, s: coverage(t, h, w, s, winding=1), 1, ["one winding"]),
    ("8.2", lambda t, h, w, s: coverage(t, h, w, s, guard=False), 2, ["zero-length edge"]),
    ("8.2", lambda t, h, w, s: coverage(t, h, w, s).T, 0, ["shape (12, 20) expected"]),
    ("8.2", lambda t, h, w, s: coverage(t.double(), h, w, s), 2, ["keep the input's dtype"]),
    ("8.3", naive_blend, 2, ["overflows", "log-weights"]),
    ("8.3", blend_with(bg_in_max=False), 2, ["background's included"]),
    ("8.3", blend_with(bg_term=False), 1, ["background is missing"]),
    ("8.3", blend_with(bg_one=True), 1, ["exp(ε / γ), not 1"]),
    ("8.3", blend_with(sign=-1.0), 0, ["*inverse* depth"]),
    ("8.3", blend_with(use_D=False), 1, ["coverage is missing"]),
    ("8.3", blend_with(use_z=False), 0, ["depth is missing"]),
]


def test_lecture_08_has_four_tasks_with_points_by_difficulty():
    assert [(t.id, t.name, t.points) for t in tasks_for_lecture(8)] == [
        ("8.1", "nmr_edge_gradients", 5), ("8.2", "soft_coverage", 3), ("8.3", "soft_blend", 3),
        ("8.4", "sigma_for_blur", 2)]
    assert {task for task, *_ in MISTAKES} == set(REFERENCES)


(test_the_reference_scores_full_marks, test_a_students_solution_scores_full_marks,
 test_a_typical_mistake_loses_points_with_a_useful_message) = contract(REFERENCES, SOLUTIONS, MISTAKES)


def one_triangle_scene():
    """A screen-aligned orthographic camera (pixel = world x, y) and triangles parallel to the image."""
    camera = Camera(torch.eye(3, dtype=torch.float64), torch.eye(3, dtype=torch.float64),
                    torch.zeros(3, dtype=torch.float64), width=20, height=14, near=0.0, far=10.0, orthographic=True)
    tris = torch.tensor([[[3.2, 2.1], [16.4, 5.3], [6.8, 12.2]], [[9.5, 1.0], [18.0, 9.0], [12.0, 13.0]]],
                        dtype=torch.float64)
    return camera, tris


@pytest.mark.parametrize("sigma", [1e-2, 1e-3])
def test_the_coverage_and_silhouette_references_agree_with_soft_rasterize(sigma):
    camera, tris = one_triangle_scene()
    depth = torch.tensor([[2.0] * 3, [4.0] * 3], dtype=torch.float64)
    verts = torch.cat([tris, depth[..., None]], -1).reshape(-1, 3)
    mesh = Mesh(verts, torch.arange(6).view(2, 3))
    one = Mesh(verts[:3], torch.arange(3).view(1, 3))
    thr = 1e-12                                                            # soft_rasterize skips D < thr
    image = soft.soft_rasterize(one, camera, sigma=sigma, threshold=thr, cull_backfaces=False)
    D = torch.stack([soft_coverage_reference(t, 14, 20, sigma) for t in tris])
    assert torch.allclose(image, D[0], atol=2 * thr, rtol=1e-12)
    image = soft.soft_rasterize(mesh, camera, sigma=sigma, threshold=thr, cull_backfaces=False)
    assert torch.allclose(image, -torch.expm1(torch.log1p(-D).sum(0)), atol=4 * thr, rtol=1e-12)   # the OR
    assert 0.2 < float(image.mean()) < 0.8


@pytest.mark.parametrize("gamma", [1e-1, 1e-4])
def test_the_blend_reference_agrees_with_soft_rasterize(gamma):
    camera, tris = one_triangle_scene()
    depth = torch.tensor([[2.0] * 3, [4.0] * 3], dtype=torch.float64)
    verts = torch.cat([tris, depth[..., None]], -1).reshape(-1, 3)
    mesh = Mesh(verts, torch.arange(6).view(2, 3))
    colors = torch.tensor([[0.9, 0.2, 0.1], [0.1, 0.3, 0.8]], dtype=torch.float64)
    bg = torch.tensor([1.0, 1.0, 0.5], dtype=torch.float64)
    sigma, eps, thr = 1e-2, 1e-3, 1e-12
    image = soft.soft_rasterize(mesh, camera, mode="color", sigma=sigma, gamma=gamma, face_colors=colors,
                                background=bg, threshold=thr, eps=eps, cull_backfaces=False)
    D = torch.stack([soft_coverage_reference(t, 14, 20, sigma) for t in tris])
    z = ((camera.far - depth[:, :1, None]) / (camera.far - camera.near)).expand(2, 14, 20)   # orthographic
    expected = soft_blend_reference(D, z, colors, bg, gamma, eps)
    assert torch.allclose(image, expected, atol=1e-9, rtol=1e-9)


@pytest.mark.parametrize("x_left, x_right", [(3.0, 11.0), (0.0, 7.0), (5.0, 16.0)])
def test_the_nmr_reference_agrees_with_nmr_rasterize(x_left, x_right):
    """One image row: a triangle whose left edge a→b is vertical at x_left and whose edge c→a crosses the row at
    x_right, c far above. Moving the whole triangle moves both crossings
    (∂L/∂tx = ∂L/∂x_left + ∂L/∂x_right); moving c alone moves the right crossing by c's weight there. Crossings on whole numbers keep every pixel
    centre at least min_step = 0.5 from them, where the package's floor per vertex is the task's per crossing."""
    f64 = torch.float64
    W = 16
    camera = Camera(torch.eye(3, dtype=f64), torch.eye(3, dtype=f64), torch.zeros(3, dtype=f64), width=W, height=1,
                    near=0.0, far=10.0, orthographic=True)
    w_c = 50.5 / 200                                                      # c's weight on the row y = 0.5
    verts = torch.tensor([[x_left, -50.0, 2.0], [x_left, 50.0, 2.0], [x_left + (x_right - x_left) / w_c, 150.0, 2.0]],
                         dtype=f64, requires_grad=True)
    colour, bg = torch.tensor([[0.9, 0.2, 0.4]], dtype=f64), torch.tensor([0.1, 0.5, 0.3], dtype=f64)
    grad = torch.randn(1, W, 3, generator=torch.Generator().manual_seed(int(x_left)), dtype=f64)
    image = nmr.nmr_rasterize(Mesh(verts, torch.tensor([[0, 1, 2]])), camera, face_colors=colour, background=bg,
                              cull_backfaces=False)
    (image * grad).sum().backward()
    expected = nmr_edge_gradients_reference(image[0].detach(), grad[0], x_left, x_right, colour[0], bg, 0.5)
    assert expected.abs().min() > 1e-3                                     # both edges get a gradient
    assert torch.allclose(verts.grad[:, 0].sum(), expected.sum(), atol=1e-12)
    assert torch.allclose(verts.grad[2, 0] / w_c, expected[1], atol=1e-12)


def test_the_blur_reference_gives_the_width_it_was_asked_for():
    """The σ of 8.4, put into the soft coverage of a half-plane (a huge triangle), gives D = 95 % and 5 % at
    width / 2 inside and outside the edge."""
    sigma = sigma_for_blur_reference(4.0, 64, 0.05)
    tri = torch.tensor([[30.5, -1e4], [30.5, 1e4], [-2e4, 0.0]], dtype=torch.float64)   # inside: x < 30.5
    D = soft_coverage_reference(tri, 1, 64, sigma)[0]                     # centres 28.5 and 32.5: 2 px away
    assert math.isclose(float(D[28]), 0.95, rel_tol=1e-9) and math.isclose(float(D[32]), 0.05, rel_tol=1e-9)


CALLING_THE_PACKAGE = {
    "8.1": lambda row, grad, xl, xr, c, b, m: nmr.nmr_image(row, None, None, None),
    "8.2": lambda tri, h, w, s: soft.soft_rasterize(None, None, sigma=s),
    "8.4": lambda width, size, level: soft.soft_rasterize(None, None, sigma=width),
}


@pytest.mark.parametrize("task_id", sorted(CALLING_THE_PACKAGE))
def test_calling_the_reference_scores_zero(task_id):
    result = run_check(task_id, CALLING_THE_PACKAGE[task_id])
    assert result.points == 0 and "the package function this task re-implements" in result.message


def blend_via_grading(D, z, colors, background, gamma, eps):
    from course.grading import lecture08
    return lecture08.soft_blend_reference(D, z, colors, background, gamma, eps)


def test_calling_the_grading_reference_scores_zero():
    result = run_check("8.3", blend_via_grading)
    assert result.points == 0
    assert result.message.startswith("soft_blend calls course.grading.lecture08.soft_blend_reference")
