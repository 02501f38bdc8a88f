"""Lecture 13's graded tasks (course/grading/lecture13.py): the references agree with the package
(course.learning.data.voxel_iou and view_cameras, course.inverse.losses.silhouette_iou_loss; 13.5's views are the
data's), they score full marks, a
solution written as a student would scores full marks without calling them, typical mistakes lose points with
the diagnosis a student can act on, and calling the package scores 0."""
import math

import torch

from course.inverse import losses
from course.learning import data as shape_data, mvtn
from course.grading import lecture13, run_check, tasks_for_lecture
from grading_contract import contract

REFERENCES = {"13.1": lambda a, b: lecture13._voxel(a, b),
              "13.2": lambda p, t: lecture13._multiview(p, t),
              "13.3": lambda a, e, d: lecture13._eyes(a, e, d),
              "13.4": lambda m, o, x, y, f: lecture13._train(m, o, x, y, f),
              "13.5": lambda s, c, p: lecture13._hull(s, c, p)}


# ------------------------------------------------------------------------------ solutions, as students write

def voxel_iou(a, b):
    a, b = a.bool(), b.bool()
    if a.shape != b.shape:
        raise ValueError(f"shapes differ: {a.shape} and {b.shape}")
    union = (a | b).sum().item()
    if union == 0:
        return 1.0
    return (a & b).sum().item() / union


def multiview_iou_loss(pred, target):
    inter = (pred * target).sum(dim=(2, 3))
    union = (pred + target - pred * target).sum(dim=(2, 3))
    iou = torch.where(union > 0, inter / torch.clamp(union, min=1e-12), torch.ones_like(union))
    return (1 - iou).mean()


def view_eyes(azimuth, elevation, distance):
    x = torch.cos(elevation) * torch.sin(azimuth)
    y = torch.sin(elevation)
    z = torch.cos(elevation) * torch.cos(azimuth)
    return distance * torch.stack([x, y, z], dim=1)


def train_step(model, optimizer, inputs, targets, loss_fn):
    optimizer.zero_grad()
    loss = loss_fn(model(inputs), targets)
    loss.backward()
    optimizer.step()
    return loss.item()


def visual_hull(silhouettes, cameras, points):
    inside = torch.ones(len(points), dtype=torch.bool)
    for sil, camera in zip(silhouettes, cameras):
        xy, depth = camera.project(points)
        j, i = torch.floor(xy[:, 0]), torch.floor(xy[:, 1])
        # outside the image or behind the camera: outside this view's cone, so outside the hull
        ok = (depth > 0) & (j >= 0) & (j < camera.width) & (i >= 0) & (i < camera.height)
        seen = torch.zeros(len(points), dtype=torch.bool)
        seen[ok] = sil[i[ok].long(), j[ok].long()] > 0.5
        inside = inside & seen
    return inside


SOLUTIONS = {"13.1": voxel_iou, "13.2": multiview_iou_loss, "13.3": view_eyes, "13.4": train_step,
             "13.5": visual_hull}


# ------------------------------------------------------------------------------------- typical mistakes

def iou_no_empty(a, b):
    a, b = a.bool(), b.bool()
    return ((a & b).sum() / (a | b).sum()).item()


def iou_no_check(a, b):
    a, b = a.bool(), b.bool()
    n = int((a | b).sum())
    return 1.0 if n == 0 else int((a & b).sum()) / n


def eyes_floats(a, e, d):
    return torch.tensor([[d * math.cos(float(y)) * math.sin(float(x)), d * math.sin(float(y)),
                          d * math.cos(float(y)) * math.cos(float(x))] for x, y in zip(a, e)], dtype=torch.float64)


MISTAKES = [
    ("13.1", lambda a, b: lecture13._voxel(a, b, "dice"), 0, ["Dice"]),
    ("13.1", lambda a, b: lecture13._voxel(a, b, "recall"), 0, ["union"]),
    ("13.1", iou_no_empty, 1, ["1.0"]),
    ("13.1", iou_no_check, 1, ["ValueError"]),
    ("13.2", lambda p, t: lecture13._multiview(p, t, "pooled"), 0, ["whole batch"]),
    ("13.2", lambda p, t: lecture13._multiview(p, t, "per_shape"), 0, ["pooled"]),
    ("13.2", lambda p, t: lecture13._multiview(p, t, "sum"), 0, ["average"]),
    ("13.2", lambda p, t: lecture13._multiview(p, t).detach(), 2, ["no gradient"]),
    ("13.3", lambda a, e, d: lecture13._eyes(a, e, d, "degrees"), 0, ["radians"]),
    ("13.3", lambda a, e, d: lecture13._eyes(a, e, d, "x_first"), 0, ["+z at azimuth 0"]),
    ("13.3", lambda a, e, d: lecture13._eyes(a, e, d, "polar"), 0, ["above the horizon"]),
    ("13.3", eyes_floats, 1, ["no gradient"]),
    ("13.4", lambda m, o, x, y, f: lecture13._train(m, o, x, y, f, "no_zero"), 1, ["zero_grad"]),
    ("13.4", lambda m, o, x, y, f: lecture13._train(m, o, x, y, f, "no_step"), 0, ["optimizer.step()"]),
    ("13.4", lambda m, o, x, y, f: lecture13._train(m, o, x, y, f, "after"), 0, ["before"]),
    ("13.5", lambda s, c, p: lecture13._hull(s, c, p, "round"), 0, ["floor(x)"]),
    ("13.5", lambda s, c, p: lecture13._hull(s, c, p, "swap"), 0, ["swapped"]),
    ("13.5", lambda s, c, p: lecture13._hull(s, c, p, "union"), 2, ["*every* view"]),
    ("13.5", lambda s, c, p: lecture13._hull(s, c, p, "keep_outside"), 2, ["cannot place in its image"]),
    ("13.5", lambda s, c, p: lecture13._hull(s, c, p, "clamp"), 2, ["nearest border pixel"]),
    ("13.5", lambda s, c, p: lecture13._hull(s, c, p, "no_depth"), 3, ["behind a camera"]),
    ("13.5", lambda s, c, p: lecture13._hull(s, c, p).long(), 0, ["bool tensor"]),
]

(test_the_reference_scores_full_marks, test_a_students_solution_scores_full_marks,
 test_a_typical_mistake_loses_points_with_a_useful_message) = contract(REFERENCES, SOLUTIONS, MISTAKES)


def test_lecture_13_has_five_tasks_and_the_one_that_needs_thought_weighs_most():
    tasks = tasks_for_lecture(13)
    assert [t.id for t in tasks] == ["13.1", "13.2", "13.3", "13.4", "13.5"]
    assert tasks[-1].points > max(t.points for t in tasks[:-1])


def test_the_hull_checks_views_are_the_datas_and_the_hull_contains_the_balls():
    from course.learning.data import view_cameras
    cameras, silhouettes, grid = lecture13._hull_shapes()
    for mine, data in zip(cameras, view_cameras(8, size=32, dtype=torch.float64)):
        assert torch.allclose(mine.R, data.R, atol=1e-12) and torch.allclose(mine.t, data.t, atol=1e-12)
        assert torch.allclose(mine.K, data.K, atol=1e-12)
    hull = lecture13.visual_hull_reference(silhouettes["a ball"], cameras, grid)
    ball = ((grid - torch.tensor([0.1, 0.0, -0.05], dtype=torch.float64)).norm(dim=1) < 0.75)
    assert hull.sum() >= 0.9 * ball.sum() and hull.sum() < 1.6 * ball.sum()  # the hull: about the ball, a bit more
    assert not (hull & ((grid - torch.tensor([0.1, 0.0, -0.05], dtype=torch.float64)).norm(dim=1) > 1.2)).any()


def test_the_references_are_the_package():
    for seed in (1, 2, 3):
        a, b = lecture13._grids(seed)
        assert lecture13.voxel_iou_reference(a, b) == shape_data.voxel_iou(a, b)
    pred, target = lecture13._silhouettes(7)
    per_view = losses.silhouette_iou_loss(pred.flatten(0, 1), target.flatten(0, 1), reduction="mean")
    assert torch.allclose(lecture13.multiview_iou_loss_reference(pred, target), per_view, rtol=1e-14, atol=0)
    cams = shape_data.view_cameras(3, distance=3.2)                         # elevation 30°, golden-angle azimuths
    golden = math.pi * (3 - math.sqrt(5))
    azimuth = torch.tensor([k * golden for k in range(3)], dtype=torch.float64)
    eyes = lecture13.view_eyes_reference(azimuth, torch.full((3,), math.radians(30.0), dtype=torch.float64), 3.2)
    for cam, eye in zip(cams, eyes):
        assert torch.allclose(cam.eye.double(), eye, atol=1e-6)
    a, e = lecture13._angles(9)
    assert torch.allclose(lecture13.view_eyes_reference(a, e, 2.0),
                          2.0 * mvtn.view_directions(torch.rad2deg(a), torch.rad2deg(e)), rtol=0, atol=1e-14)


def test_the_train_step_check_leaves_the_global_generator_alone():
    state = torch.get_rng_state()
    run_check("13.4", train_step)
    assert torch.equal(state, torch.get_rng_state())


def test_calling_the_package_scores_zero():
    for task_id, impl in (("13.1", lambda a, b: shape_data.voxel_iou(a, b)),
                          ("13.2", lambda p, t: losses.silhouette_iou_loss(p.flatten(0, 1), t.flatten(0, 1),
                                                                           reduction="mean"))):
        result = run_check(task_id, impl)
        assert result.points == 0 and "course" in result.message, (task_id, result.message)
