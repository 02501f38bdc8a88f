"""Lecture 10's graded tasks (course/grading/lecture10.py): the references agree with the package
(course.inverse.losses.silhouette_iou_loss and smoothness_loss), they score full marks, a solution written as a student
would scores full marks without calling them, typical mistakes lose points with the diagnosis a student can act
on, and calling the package (or the grader's references) scores 0."""
import pytest
import torch

from course import models
from course.inverse import losses
from course.grading import lecture10, run_check, tasks_for_lecture
from course.grading.lecture10 import silhouette_iou_loss_reference, smoothness_loss_reference
from grading_contract import contract

# the public references are forbidden to students; these call the same code under its private names
REFERENCES = {"10.1": lambda pred, target: lecture10._iou_loss(pred, target),
              "10.2": lambda verts, faces: lecture10._smoothness(verts, faces),
              "10.3": lambda render, target, pose0, steps: lecture10._fit(render, target, pose0, steps),
              "10.4": lambda loss_fn, start, stop, n: lecture10._staircase(loss_fn, start, stop, n)}


# ------------------------------------------------------------------------------ solutions, as students write

def iou_loss(pred, target, union_overlap=True, one=True, pooled=False, mean=False, guard=True):
    if pred.dim() == 2:
        pred, target = pred[None], target[None]
    dims = (0, 1, 2) if pooled else (1, 2)
    inter = (pred * target).sum(dims)
    union = (pred + target - (pred * target if union_overlap else 0)).sum(dims)
    if guard:
        safe = torch.where(union > 0, union, torch.ones_like(union))
        iou = torch.where(union > 0, inter / safe, torch.ones_like(union))
    else:
        iou = inter / union
    per_view = 1 - iou if one else iou
    return per_view.mean() if mean else per_view.sum()


def silhouette_iou_loss(pred, target):
    return iou_loss(pred, target)


def smooth(verts, faces, unit=True, sign=-1.0, square=True, twice=False):
    v0, v1, v2 = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    n = torch.linalg.cross(v1 - v0, v2 - v0, dim=-1)
    if unit:
        length = n.norm(dim=1, keepdim=True)
        n = n / length.clamp(min=1e-300)                                  # a zero-area face: 0 / tiny = 0
    owners = {}
    for f, (a, b, c) in enumerate(faces.tolist()):
        for i, j in ((a, b), (b, c), (c, a)):
            owners.setdefault((min(i, j), max(i, j)), []).append(f)
    pairs = [fs for fs in owners.values() if len(fs) == 2]
    if twice:
        pairs += [fs[::-1] for fs in pairs]
    total = verts.sum() * 0
    for f, g in pairs:
        term = 1 + sign * (n[f] @ n[g])
        total = total + (term ** 2 if square else term)
    return total


def smoothness_loss(verts, faces):
    return smooth(verts, faces)


def fit(render, target, pose0, steps, lr=0.05, zero=True, sign=1.0, renders=1, copy=True, move=True):
    """A student's loop: Adam at a constant learning rate on the mean squared difference."""
    pose = (pose0.detach().clone() if copy else pose0).requires_grad_(True)
    opt = torch.optim.Adam([pose], lr=lr)
    for _ in range(steps):
        if zero:
            opt.zero_grad()
        for _ in range(renders):
            image = render(pose)
        loss = sign * ((image - target) ** 2).mean()
        loss.backward()
        if move:
            opt.step()
    return pose.detach().clone()


def fit_pose(render, target, pose0, steps):
    return fit(render, target, pose0, steps)


def in_place(render, target, pose0, steps):
    """Optimises pose0 itself."""
    pose0.requires_grad_(True)
    opt = torch.optim.Adam([pose0], lr=0.05)
    for _ in range(steps):
        opt.zero_grad()
        ((render(pose0) - target) ** 2).mean().backward()
        opt.step()
    pose0.requires_grad_(False)
    return pose0.detach().clone()


def stairs(loss_fn, start, stop, n, runs_in_samples=False, in_units=True):
    xs = [start + (stop - start) * k / (n - 1) for k in range(n)]
    values = [float(loss_fn(torch.tensor(x, dtype=torch.float64))) for x in xs]
    jumps, longest, run = 0, 0, 0
    for a, b in zip(values, values[1:]):
        if a != b:
            jumps, run = jumps + 1, 0
        else:
            run += 1
            longest = max(longest, run)
    if runs_in_samples and longest:
        longest += 1
    return jumps, longest * (stop - start) / (n - 1) if in_units else longest


def staircase(loss_fn, start, stop, n):
    return stairs(loss_fn, start, stop, n)


SOLUTIONS = {"10.1": silhouette_iou_loss, "10.2": smoothness_loss, "10.3": fit_pose, "10.4": staircase}

MISTAKES = [
    ("10.1", lambda p, t: iou_loss(p, t, union_overlap=False), 0, ["counts the overlap twice"]),
    ("10.1", lambda p, t: iou_loss(p, t, one=False), 0, ["the IoU itself"]),
    ("10.1", lambda p, t: -iou_loss(p, t, one=False), 0, ["negative IoU"]),
    ("10.1", lambda p, t: iou_loss(p, t, pooled=True), 0, ["pooled"]),
    ("10.1", lambda p, t: iou_loss(p, t, mean=True), 0, ["mean over the views"]),
    ("10.1", lambda p, t: iou_loss(p, t, guard=False), 1, ["NaN", "perfect match"]),
    ("10.1", lambda p, t: iou_loss((p > 0.5).to(p.dtype), t), 0, ["thresholded"]),
    ("10.1", lambda p, t: iou_loss(p.detach(), t), 0, ["no gradient reaches pred"]),
    ("10.2", lambda v, f: smooth(v, f, sign=1.0), 0, ["sign is flipped"]),
    ("10.2", lambda v, f: smooth(v, f, unit=False), 0, ["not normalised"]),
    ("10.2", lambda v, f: smooth(v, f, square=False), 0, ["not squared"]),
    ("10.2", lambda v, f: smooth(v, f, twice=True), 0, ["counts twice"]),
    ("10.2", lambda v, f: lecture10._smoothness(v, f, pairs="consecutive"), 1, ["boundary edges"]),
    ("10.2", lambda v, f: lecture10._smoothness(v, f, reduce="mean"), 0, ["the mean over the edges"]),
    ("10.2", lambda v, f: smooth_nan(v, f), 2, ["zero-area face"]),
    ("10.3", lambda *a: fit(*a, sign=-1.0), 0, ["uphill", "against the gradient"]),
    ("10.3", lambda *a: fit(*a, zero=False), 0, ["down and up again", "clear them"]),
    ("10.3", lambda *a: fit(*a, lr=0.005), 0, ["not converged", "larger steps"]),
    ("10.3", lambda *a: fit(*a, move=False), 0, ["did not move"]),
    ("10.3", lambda *a: fit(*a, renders=2), 0, ["budget"]),
    ("10.3", in_place, 0, ["changed in place"]),
    ("10.4", lambda *a: stairs(*a, runs_in_samples=True), 1, ["spans k intervals"]),
    ("10.4", lambda *a: stairs(*a, in_units=False), 1, ["units"]),
    ("10.4", lambda *a: lecture10._staircase(*a, inclusive=False), 0, ["both ends included"]),
]


def smooth_nan(verts, faces):
    """Normalising with a plain division: a zero-area face gives 0 / 0."""
    v0, v1, v2 = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    n = torch.linalg.cross(v1 - v0, v2 - v0, dim=-1)
    n = n / n.norm(dim=1, keepdim=True)
    pairs = lecture10._face_pairs(torch.as_tensor(faces))
    return ((1 - (n[pairs[:, 0]] * n[pairs[:, 1]]).sum(-1)) ** 2).sum()


def test_lecture_10_has_four_tasks_with_points_by_difficulty():
    assert [(t.id, t.name, t.points) for t in tasks_for_lecture(10)] == [
        ("10.1", "silhouette_iou_loss", 2), ("10.2", "smoothness_loss", 3), ("10.3", "fit_pose", 5),
        ("10.4", "staircase", 2)]
    assert {task for task, *_ in MISTAKES} == set(REFERENCES)


(test_the_reference_scores_full_marks, test_a_students_solution_scores_full_marks,
 test_a_typical_mistake_loses_points_with_a_useful_message) = contract(REFERENCES, SOLUTIONS, MISTAKES)


# ------------------------------------------------------------------------- the references against the package

@pytest.mark.parametrize("shape, empty", [((1, 16, 16), ()), ((4, 12, 12), ()), ((3, 10, 10), (1,)), ((1, 8, 8), (0,))])
def test_the_iou_reference_is_the_package_loss_in_value_and_gradient(shape, empty):
    pred, target = lecture10._blobs(shape[0], shape[1], 7, empty=empty)
    for p, t in ((pred, target), (pred[0], target[0])):
        a = p.clone().requires_grad_(True)
        b = p.clone().requires_grad_(True)
        mine, theirs = silhouette_iou_loss_reference(a, t), losses.silhouette_iou_loss(b, t)
        assert torch.allclose(mine, theirs, atol=1e-12, rtol=0)
        mine.backward()
        theirs.backward()
        assert torch.isfinite(a.grad).all() and torch.allclose(a.grad, b.grad, atol=1e-12, rtol=0)


@pytest.mark.parametrize("mesh", ["bumpy", "grid", "seam", "degenerate", "teapot"])
def test_the_smoothness_reference_is_the_package_loss_in_value_and_gradient(mesh):
    """The teapot has uv seams (two copies of each seam vertex) and open rims: edges by index, as the package."""
    if mesh == "bumpy":
        verts, faces = lecture10._bumpy_sphere(3)
    elif mesh == "grid":
        verts, faces = lecture10._grid(5, 4)
    elif mesh == "seam":
        verts, faces = lecture10._grid(4, 5, seam=True)
    elif mesh == "degenerate":
        verts, faces = lecture10._degenerate()
    else:
        t = models.teapot(3, dtype=torch.float64)
        verts, faces = t.verts, t.faces
    a = verts.clone().requires_grad_(True)
    b = verts.clone().requires_grad_(True)
    mine, theirs = smoothness_loss_reference(a, faces), losses.smoothness_loss(b, faces)
    assert torch.allclose(mine, theirs, atol=1e-10, rtol=1e-12)
    mine.backward()
    theirs.backward()
    assert torch.isfinite(a.grad).all() and torch.allclose(a.grad, b.grad, atol=1e-10, rtol=1e-10)


def test_the_grids_seam_and_the_degenerate_face_change_the_loss():
    """The seam test is a test: welding the seam's copies by position would add interior edges; the zero-area
    face's three edges add exactly 1 each."""
    seam_v, seam_f = lecture10._grid(4, 5, seam=True)
    n = (4 + 1) ** 2
    welded = seam_f.clone()
    copies = torch.arange(n, seam_v.shape[0])
    originals = torch.arange(5) * 5 + 2
    for c, o in zip(copies.tolist(), originals.tolist()):
        welded[welded == c] = o
    assert len(lecture10._face_pairs(welded)) > len(lecture10._face_pairs(seam_f))
    verts, faces = lecture10._degenerate()
    n = lecture10._normals(verts, faces)
    assert float(n[2].abs().sum()) == 0.0
    pairs = lecture10._face_pairs(faces).tolist()
    assert sorted(sorted(p) for p in pairs if 2 in p) == [[0, 2], [1, 2], [2, 3]]


def test_the_fit_reference_converges_well_inside_the_tolerance_on_every_problem():
    for seed, n, dtype, steps in ((131, 2, torch.float64, 150), (132, 2, torch.float64, 150),
                                  (133, 3, torch.float64, 150), (134, 3, torch.float64, 150),
                                  (135, 3, torch.float64, 100), (136, 2, torch.float32, 150)):
        problem = lecture10._PoseProblem(seed, n, dtype, steps)
        angle, shift = problem.errors(lecture10._fit(problem.render, problem.target, problem.start, steps))
        assert shift < lecture10._SHIFT_TOL / 5 and (angle is None or angle < lecture10._ANGLE_TOL / 5)
        assert problem.calls == steps


def test_the_staircase_of_the_hard_loss_is_a_staircase_and_the_soft_loss_has_none():
    jumps, flat = lecture10._staircase(lecture10._Landscape((1.0, 0.0)), 0.0, 2.0, 201)
    assert 0 < jumps < 200 and flat > 0.02
    assert lecture10._staircase(lecture10._Landscape((1.0, 0.0), hard=False), 0.0, 1.0, 51) == (50, 0.0)


CALLING_THE_PACKAGE = {
    "10.1": lambda pred, target: losses.silhouette_iou_loss(pred, target),
    "10.2": lambda verts, faces: losses.smoothness_loss(verts, faces),
}


@pytest.mark.parametrize("task_id", sorted(CALLING_THE_PACKAGE))
def test_calling_the_package_scores_zero(task_id):
    result = run_check(task_id, CALLING_THE_PACKAGE[task_id])
    assert result.points == 0 and "calls course.inverse.losses" in result.message, result.message


def fit_via_grading(render, target, pose0, steps):
    from course.grading import lecture10
    return lecture10.fit_pose_reference(render, target, pose0, steps)


def test_calling_the_fit_reference_scores_zero():
    result = run_check("10.3", fit_via_grading)
    assert result.points == 0 and "fit_pose_reference" in result.message, result.message


def smoothness_via_grading(verts, faces):
    from course.grading import lecture10
    return lecture10.smoothness_loss_reference(verts, faces)


def test_calling_the_grading_reference_scores_zero():
    result = run_check("10.2", smoothness_via_grading)
    assert result.points == 0
    assert result.message.startswith("smoothness_loss calls course.grading.lecture10.smoothness_loss_reference")
