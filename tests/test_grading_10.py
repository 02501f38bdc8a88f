"""Lecture 10's graded tasks (course/grading/lecture10.py): the references agree with the package
(course.losses.silhouette_iou_loss and smoothness_loss, torch.optim.SGD), they score full marks, a solution
written as a student would scores full marks without calling them, typical mistakes lose points with the
diagnosis a student can act on, and calling the package (or torch.optim) scores 0."""
import pytest
import torch

from course import losses, models
from course.grading import lecture10, run_check, tasks_for_lecture
from course.grading.lecture10 import (gradient_step_reference, silhouette_iou_loss_reference,
                                      smoothness_loss_reference)
from grading_contract import contract

# the public references are forbidden to students; these call the same code under its private names
REFERENCES = {"10.1": lambda pred, target: lecture10._iou_loss(pred, target),
              "10.2": lambda verts, faces: lecture10._smoothness(verts, faces),
              "10.3": lambda params, loss_fn, lr: lecture10._step(params, loss_fn, lr)}


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


def step(params, loss_fn, lr, zero=True, sign=-1.0, no_grad=True, rebind=False, after=False, keep_graph=False):
    if zero:
        for p in params:
            if p.grad is not None:
                p.grad.zero_()
    loss = loss_fn()
    loss.backward()
    if rebind:
        for k, p in enumerate(params):
            params[k] = p + sign * lr * p.grad
        return loss.detach()
    if no_grad:
        with torch.no_grad():
            for p in params:
                p += sign * lr * p.grad
    else:
        for p in params:
            p += sign * lr * p.grad
    if after:
        return loss_fn().detach()
    return loss if keep_graph else loss.item()


def gradient_step(params, loss_fn, lr):
    return step(params, loss_fn, lr)


SOLUTIONS = {"10.1": silhouette_iou_loss, "10.2": smoothness_loss, "10.3": gradient_step}

MISTAKES = [
    ("10.1", lambda p, t: iou_loss(p, t, union_overlap=False), 0, ["counts the overlap twice"]),
    ("10.1", lambda p, t: iou_loss(p, t, one=False), 0, ["the IoU itself"]),
    ("10.1", lambda p, t: -iou_loss(p, t, one=False), 0, ["negative IoU"]),
    ("10.1", lambda p, t: iou_loss(p, t, pooled=True), 1, ["pooled"]),
    ("10.1", lambda p, t: iou_loss(p, t, mean=True), 1, ["mean over the views"]),
    ("10.1", lambda p, t: iou_loss(p, t, guard=False), 2, ["NaN", "perfect match"]),
    ("10.1", lambda p, t: iou_loss((p > 0.5).to(p.dtype), t), 0, ["thresholded"]),
    ("10.1", lambda p, t: iou_loss(p.detach(), t), 0, ["no gradient reaches pred"]),
    ("10.2", lambda v, f: smooth(v, f, sign=1.0), 0, ["sign is flipped"]),
    ("10.2", lambda v, f: smooth(v, f, unit=False), 0, ["not normalised"]),
    ("10.2", lambda v, f: smooth(v, f, square=False), 0, ["not squared"]),
    ("10.2", lambda v, f: smooth(v, f, twice=True), 0, ["counts twice"]),
    ("10.2", lambda v, f: lecture10._smoothness(v, f, pairs="consecutive"), 1, ["boundary edges"]),
    ("10.2", lambda v, f: lecture10._smoothness(v, f, reduce="mean"), 0, ["the mean over the edges"]),
    ("10.2", lambda v, f: smooth_nan(v, f), 2, ["zero-area face"]),
    ("10.3", lambda ps, fn, lr: step(ps, fn, lr, sign=1.0), 0, ["uphill"]),
    ("10.3", lambda ps, fn, lr: step(ps, fn, lr, zero=False), 1, ["not cleared"]),
    ("10.3", lambda ps, fn, lr: step(ps, fn, lr, no_grad=False), 0, ["torch.no_grad()"]),
    ("10.3", lambda ps, fn, lr: step(ps, fn, lr, rebind=True), 0, ["replaced by a new tensor"]),
    ("10.3", lambda ps, fn, lr: step(ps, fn, lr, after=True), 0, ["after the step"]),
    ("10.3", lambda ps, fn, lr: step(ps, fn, lr, keep_graph=True), 0, ["still holds the graph"]),
]


def smooth_nan(verts, faces):
    """Normalising with a plain division: a zero-area face gives 0 / 0."""
    v0, v1, v2 = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    n = torch.linalg.cross(v1 - v0, v2 - v0, dim=-1)
    n = n / n.norm(dim=1, keepdim=True)
    pairs = lecture10._face_pairs(torch.as_tensor(faces))
    return ((1 - (n[pairs[:, 0]] * n[pairs[:, 1]]).sum(-1)) ** 2).sum()


def test_lecture_10_has_three_tasks_of_three_points_each():
    assert [(t.id, t.name, t.points) for t in tasks_for_lecture(10)] == [
        ("10.1", "silhouette_iou_loss", 3), ("10.2", "smoothness_loss", 3), ("10.3", "gradient_step", 3)]
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


def test_the_step_reference_is_torch_optim_sgd():
    f, starts = lecture10._layer(9)
    mine = [s.clone().requires_grad_(True) for s in starts]
    theirs = [s.clone().requires_grad_(True) for s in starts]
    sgd = torch.optim.SGD(theirs, lr=0.1)
    for _ in range(5):
        loss = gradient_step_reference(mine, lambda: f(*mine), 0.1)
        sgd.zero_grad()
        want = f(*theirs)
        want.backward()
        sgd.step()
        assert float(loss) == pytest.approx(float(want.detach()), rel=1e-12)
    for p, q in zip(mine, theirs):
        assert p.is_leaf and torch.allclose(p, q, atol=1e-14, rtol=0)


CALLING_THE_PACKAGE = {
    "10.1": lambda pred, target: losses.silhouette_iou_loss(pred, target),
    "10.2": lambda verts, faces: losses.smoothness_loss(verts, faces),
}


@pytest.mark.parametrize("task_id", sorted(CALLING_THE_PACKAGE))
def test_calling_the_package_scores_zero(task_id):
    result = run_check(task_id, CALLING_THE_PACKAGE[task_id])
    assert result.points == 0 and "calls course.losses" in result.message, result.message


def step_with_sgd(params, loss_fn, lr):
    opt = torch.optim.SGD(params, lr=lr)
    opt.zero_grad()
    loss = loss_fn()
    loss.backward()
    opt.step()
    return loss.detach()


def test_an_optimiser_from_torch_scores_zero():
    result = run_check("10.3", step_with_sgd)
    assert result.points == 0 and "torch.optim" in result.message, result.message
    result = run_check("10.3", torch.optim.SGD)                           # the reference itself, passed as is
    assert result.points == 0 and result.message.startswith("gradient_step calls torch.optim.sgd.SGD"), result.message


def smoothness_via_grading(verts, faces):
    from course.grading import lecture10
    return lecture10.smoothness_loss_reference(verts, faces)


def test_calling_the_grading_reference_scores_zero():
    result = run_check("10.2", smoothness_via_grading)
    assert result.points == 0
    assert result.message.startswith("smoothness_loss calls course.grading.lecture10.smoothness_loss_reference")
