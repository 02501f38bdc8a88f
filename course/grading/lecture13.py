"""The checks of lecture 13's graded tasks (learning through the renderer): 13.1 voxel_iou,
13.2 multiview_iou_loss, 13.3 view_eyes, 13.4 train_step, 13.5 visual_hull.

Each check runs the student's function next to a reference on fixed, seeded-random and stress inputs and
says what to fix, recognising the typical mistakes of the task. ``import course.grading`` imports this
module, which registers its checks in ``course.grading.TASKS``.

* 13.1, the voxel IoU of two occupancy grids (Kato et al.'s Table 1 metric): ``|a ∩ b| / |a ∪ b|``, 1.0 when
  both are empty, a ValueError for grids of different shapes (``course.learning.data.voxel_iou``).
* 13.2, the silhouette IoU loss of a batch of shapes seen from several views: soft silhouettes (B, V, H, W),
  ``1 - Σ ŝ s / Σ (ŝ + s - ŝ s)`` per shape and view, averaged over both (an empty pair counts 0).
* 13.3, cameras on a sphere, differentiable in their angles: eyes ``d (cos e sin a, sin e, cos e cos a)`` (+z at
  azimuth 0, +x at 90°, y up; the course's convention, ``course.learning.data.view_cameras``), with autograd
  reaching the azimuths and elevations (what lets a network learn where to look; ``course.learning.mvtn.view_directions``
  in degrees, times the distance).
* 13.4, one training step: clear the gradients, forward, loss, backward, step; return the loss before the step
  as a float.
* 13.5, the visual hull of a shape's views (what silhouette supervision can pin down at best): a point is in it
  when every view sees it inside the silhouette. The student decides, and the check tests, which pixel a
  projected point falls in (floor, the course's pixel convention) and what a point is that a view cannot place
  in its image or that lies behind its camera (outside that view's cone: outside the hull).

The references are written here, in float64; ``tests/test_grading_13.py`` checks that they agree with the
package. A graded function that calls them, or the package functions doing the task's work, scores 0.
"""
from __future__ import annotations

import math
from functools import cache

import torch

from .helpers import _call, _match, compare, generator, grade_parts, require, to_tensor
from .registry import forbidden_call, task

__all__ = ["voxel_iou_reference", "multiview_iou_loss_reference", "view_eyes_reference", "train_step_reference",
           "visual_hull_reference"]

FORBIDDEN = [("course.learning.data", "voxel_iou"), ("course.inverse.losses", "silhouette_iou_loss"),
             ("course.learning.mvtn", "view_directions"),
             ("course.grading.lecture13", "voxel_iou_reference"),
             ("course.grading.lecture13", "multiview_iou_loss_reference"),
             ("course.grading.lecture13", "view_eyes_reference"),
             ("course.grading.lecture13", "train_step_reference"),
             ("course.grading.lecture13", "visual_hull_reference")]


# ------------------------------------------------------------------------------------- the references

def voxel_iou_reference(a, b) -> float:
    """13.1: ``|a ∩ b| / |a ∪ b|`` of two bool grids of one shape; 1.0 when both are empty."""
    return _voxel(a, b)


def multiview_iou_loss_reference(pred, target) -> torch.Tensor:
    """13.2: the mean over shapes and views of ``1 - Σ ŝ s / Σ (ŝ + s - ŝ s)``; (B, V, H, W) in, a scalar out."""
    return _multiview(pred, target)


def view_eyes_reference(azimuth, elevation, distance) -> torch.Tensor:
    """13.3: (N, 3) ``distance (cos e sin a, sin e, cos e cos a)``, radians."""
    return _eyes(azimuth, elevation, distance)


def train_step_reference(model, optimizer, inputs, targets, loss_fn) -> float:
    """13.4: one step; the loss before it, as a float."""
    return _train(model, optimizer, inputs, targets, loss_fn)


def _voxel(a, b, kind="iou"):
    a, b = torch.as_tensor(a).bool(), torch.as_tensor(b).bool()
    if a.shape != b.shape:
        raise ValueError(f"the grids must have the same shape, got {tuple(a.shape)} and {tuple(b.shape)}")
    inter, union = int((a & b).sum()), int((a | b).sum())
    if kind == "dice":
        total = int(a.sum()) + int(b.sum())
        return 1.0 if total == 0 else 2 * inter / total
    if kind == "recall":
        n = int(b.sum())
        return 1.0 if n == 0 else inter / n
    return 1.0 if union == 0 else inter / union


def _multiview(pred, target, kind="per_view"):
    inter = (pred * target).flatten(2).sum(-1)                              # (B, V)
    union = (pred + target - pred * target).flatten(2).sum(-1)
    tiny = torch.finfo(pred.dtype).tiny ** 0.5
    loss = torch.where(union > tiny, 1 - inter / union.clamp_min(tiny), torch.zeros_like(union))
    if kind == "pooled":                                                    # one IoU for the whole batch
        return 1 - inter.sum() / union.sum()
    if kind == "per_shape":                                                 # views pooled, then shapes averaged
        return (1 - inter.sum(1) / union.sum(1)).mean()
    if kind == "sum":
        return loss.sum()
    return loss.mean()


def _eyes(azimuth, elevation, distance, kind="course"):
    a, e = azimuth, elevation
    if kind == "degrees":
        a, e = torch.deg2rad(a), torch.deg2rad(e)
    if kind == "x_first":                                                   # +x at azimuth 0
        return distance * torch.stack([torch.cos(e) * torch.cos(a), torch.sin(e), torch.cos(e) * torch.sin(a)], -1)
    if kind == "polar":                                                     # elevation taken from the pole
        return distance * torch.stack([torch.sin(e) * torch.sin(a), torch.cos(e), torch.sin(e) * torch.cos(a)], -1)
    return distance * torch.stack([torch.cos(e) * torch.sin(a), torch.sin(e), torch.cos(e) * torch.cos(a)], -1)


def _train(model, optimizer, inputs, targets, loss_fn, kind="full"):
    if kind != "no_zero":
        optimizer.zero_grad()
    loss = loss_fn(model(inputs), targets)
    loss.backward()
    if kind != "no_step":
        optimizer.step()
    if kind == "after":
        with torch.no_grad():
            return float(loss_fn(model(inputs), targets))
    return float(loss.detach())


# ------------------------------------------------------------------------------------ 13.1 voxel_iou

def _grids(seed, shape=(8, 8, 8), fill=0.4):
    g = generator(seed)
    return torch.rand(shape, generator=g) < fill, torch.rand(shape, generator=g) < fill


def _as_number(out, name):
    if isinstance(out, (int, float)) and not isinstance(out, bool):
        return float(out)
    t = to_tensor(out, name)
    if t.numel() != 1:
        require(f"{name}: one number expected, got shape {tuple(t.shape)}")
    return float(t.reshape(()))


def _voxel_problem(impl, label, a, b):
    name = f"voxel_iou({label})"
    got = _as_number(_call(impl, a, b), name)
    want = _voxel(a, b)
    if abs(got - want) <= 1e-6:                                             # a float32 division is fine
        return None
    for kind, explanation in (("dice", "that is the Dice score 2|a ∩ b| / (|a| + |b|): divide |a ∩ b| by the "
                                       "union |a ∪ b|"),
                              ("recall", "that is |a ∩ b| / |b|: divide by the union |a ∪ b|")):
        if abs(got - _voxel(a, b, kind)) <= 1e-6:
            return f"{name}: {explanation}"
    swapped = _voxel(b, a, "recall")
    if abs(got - swapped) <= 1e-6:
        return f"{name}: that is |a ∩ b| / |a|: divide by the union |a ∪ b|"
    return f"{name}: {want:.6g} expected, got {got:.6g}"


@task("13.1", "voxel_iou", points=2, reference=("course.learning.data", "voxel_iou"))
def _check_voxel(impl):
    forbidden = forbidden_call(impl, "voxel_iou", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def basic():
        a, b = _grids(1311)
        require(_voxel_problem(impl, "two random 8³ grids", a, b))
        a, b = _grids(1312, (16, 16, 16), 0.2)
        require(_voxel_problem(impl, "two random 16³ grids", a, b))
        require(_voxel_problem(impl, "a grid and itself", a, a.clone()))

    def edges():
        empty = torch.zeros(4, 4, 4, dtype=torch.bool)
        name = "voxel_iou(two empty grids)"
        got = _as_number(_call(impl, empty, empty.clone()), name)
        if got != 1.0:
            require(f"{name}: two empty shapes agree perfectly: return 1.0 (not 0 / 0), got {got:.6g}")
        full = torch.ones(4, 4, 4, dtype=torch.bool)
        require(_voxel_problem(impl, "an empty and a full grid", empty, full))
        a, b = _grids(1313)
        require(_voxel_problem(impl, "0 / 1 integer grids", a.to(torch.int64), b.to(torch.int64)))
        try:
            impl(torch.zeros(4, 4, 4, dtype=torch.bool), torch.zeros(4, 4, 5, dtype=torch.bool))
        except ValueError:
            return
        except Exception as err:                                            # noqa: BLE001   the student's code
            require(f"voxel_iou(grids of shapes (4, 4, 4) and (4, 4, 5)): raise a ValueError naming the shapes, "
                    f"not {type(err).__name__}")
        require("voxel_iou(grids of shapes (4, 4, 4) and (4, 4, 5)): grids of different shapes cannot be compared "
                "voxel by voxel: raise a ValueError naming the shapes")
    return grade_parts((1, "random grids", basic), (1, "empty grids, integer grids, shapes that differ", edges))


# --------------------------------------------------------------------------- 13.2 multiview_iou_loss

def _silhouettes(seed, B=3, V=2, H=6, W=5, dtype=torch.float64):
    g = generator(seed)
    pred = torch.rand(B, V, H, W, generator=g, dtype=torch.float64)
    target = (torch.rand(B, V, H, W, generator=g, dtype=torch.float64) < 0.4).double()
    target[0, 0] = 0                                                        # one small view, for uneven unions
    target[0, 0, :2, :2] = 1
    return pred.to(dtype), target.to(dtype)


def _multiview_problem(impl, label, pred, target):
    name = f"multiview_iou_loss({label})"
    got = to_tensor(_call(impl, pred, target), name)
    expected = _multiview(pred, target)
    low = pred.dtype == torch.float32
    message = compare(got.reshape(()) if got.numel() == 1 else got, expected, name=name, check_dtype=True,
                      **(dict(atol=1e-6, rtol=1e-5) if low else dict(atol=1e-12, rtol=1e-10)))
    if message is None or "dtype" in message:
        return message
    explanation = _match(got.reshape(()) if got.numel() == 1 else got, [
        (_multiview(pred, target, "pooled"), "one IoU over the whole batch: take the IoU of every shape in every "
                                             "view (sum over H and W only), then average"),
        (_multiview(pred, target, "per_shape"), "the views of a shape were pooled into one IoU: every view is its "
                                                "own IoU, then average over shapes and views"),
        (_multiview(pred, target, "sum"), "summed over shapes and views: average them, so the loss does not grow "
                                          "with the batch"),
    ])
    return f"{name}: {explanation}" if explanation else message


def _multiview_gradient(impl):
    pred, target = _silhouettes(1321)
    leaf = pred.clone().requires_grad_(True)
    out = impl(leaf, target.clone())
    if not (isinstance(out, torch.Tensor) and out.requires_grad):
        return ("multiview_iou_loss: the value is right but no gradient reaches the silhouettes: compute with "
                "tensor operations (no .item(), float() or numpy) and return the tensor")
    got, = torch.autograd.grad(out, leaf)
    ref = pred.clone().requires_grad_(True)
    want, = torch.autograd.grad(_multiview(ref, target), ref)
    return compare(got, want, name="d loss / d pred", atol=1e-12, rtol=1e-9)


@task("13.2", "multiview_iou_loss", points=3,
      reference=("course.grading.lecture13", "multiview_iou_loss_reference"))
def _check_multiview(impl):
    forbidden = forbidden_call(impl, "multiview_iou_loss", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def basic():
        require(_multiview_problem(impl, "3 shapes, 2 views, float64", *_silhouettes(1322)))
        require(_multiview_problem(impl, "1 shape, 4 views", *_silhouettes(1323, B=1, V=4)))

    def empty():
        pred, target = _silhouettes(1324)
        pred[1, 1], target[1, 1] = 0, 0
        require(_multiview_problem(impl, "a view where both silhouettes are empty (it counts 0)", pred, target))

    def stress():
        require(_multiview_problem(impl, "float32", *_silhouettes(1325, dtype=torch.float32)))
        require(_multiview_gradient(impl))
    return grade_parts((1, "per view, averaged", basic), (1, "an empty view", empty),
                       (1, "float32, the gradient", stress))


# ------------------------------------------------------------------------------------ 13.3 view_eyes

def _angles(seed, n=7):
    g = generator(seed)
    a = (torch.rand(n, generator=g, dtype=torch.float64) * 2 - 1) * 3.1
    e = (torch.rand(n, generator=g, dtype=torch.float64) * 2 - 1) * 1.4
    return a, e


def _eyes_problem(impl, label, a, e, d):
    name = f"view_eyes({label})"
    got = to_tensor(_call(impl, a, e, d), name)
    expected = _eyes(a, e, d)
    message = compare(got, expected, name=name, check_dtype=True, atol=1e-12, rtol=1e-10)
    if message is None or "dtype" in message or "shape" in message:
        return message
    explanation = _match(got, [
        (_eyes(a, e, d, "degrees"), "the angles were converted from degrees: they are radians already"),
        (_eyes(a, e, d, "x_first"), "+x lies at azimuth 0 here: the course puts +z at azimuth 0 and +x at 90° "
                                    "(x = cos e sin a, z = cos e cos a)"),
        (_eyes(a, e, d, "polar"), "the elevation was taken from the pole: it is the angle above the horizon "
                                  "(y = d sin e)"),
    ])
    return f"{name}: {explanation}" if explanation else message


def _eyes_gradient(impl):
    a, e = _angles(1331, 4)
    la, le = a.clone().requires_grad_(True), e.clone().requires_grad_(True)
    out = impl(la, le, 2.5)
    if not (isinstance(out, torch.Tensor) and out.requires_grad):
        return ("view_eyes: the positions are right but no gradient reaches the angles: use torch.sin / torch.cos "
                "on the tensors (not math.sin or float()), so that a network can learn where to look")
    w = torch.arange(12, dtype=torch.float64).view(4, 3)
    got = torch.autograd.grad((out * w).sum(), [la, le], allow_unused=True)
    ra, re = a.clone().requires_grad_(True), e.clone().requires_grad_(True)
    want = torch.autograd.grad((_eyes(ra, re, 2.5) * w).sum(), [ra, re])
    for g, h, what in zip(got, want, ("azimuths", "elevations")):
        if g is None:
            return f"view_eyes: no gradient reaches the {what}"
        bad = compare(g, h, name=f"d eyes / d {what}", atol=1e-12, rtol=1e-9)
        if bad:
            return bad
    return None


@task("13.3", "view_eyes", points=2, reference=("course.grading.lecture13", "view_eyes_reference"))
def _check_eyes(impl):
    forbidden = forbidden_call(impl, "view_eyes", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def basic():
        four = torch.tensor([0.0, 0.5, 1.0, 1.5], dtype=torch.float64) * torch.pi
        require(_eyes_problem(impl, "a circle at the horizon, distance 3", four, torch.zeros(4, dtype=torch.float64),
                              3.0))
        require(_eyes_problem(impl, "random angles, distance 2.5", *_angles(1332), 2.5))

    def gradient():
        require(_eyes_gradient(impl))
    return grade_parts((1, "positions", basic), (1, "differentiable in the angles", gradient))


# ----------------------------------------------------------------------------------- 13.4 train_step

def _model(seed):
    with torch.random.fork_rng():                                          # nn.Linear's init draws from the global
        model = torch.nn.Sequential(torch.nn.Linear(4, 6), torch.nn.Tanh(),  # generator: leave the student's as
                                    torch.nn.Linear(6, 2)).double()           # it was (overwritten below)
    g = generator(seed)
    with torch.no_grad():
        for p in model.parameters():
            p.copy_(torch.randn(p.shape, generator=g, dtype=torch.float64) * 0.5)
    return model


def _batch(seed):
    g = generator(seed)
    return torch.randn(8, 4, generator=g, dtype=torch.float64), torch.randn(8, 2, generator=g, dtype=torch.float64)


def _run_steps(fn, opt_name, steps, seed=1341, kind=None):
    model = _model(seed)
    opt = (torch.optim.SGD(model.parameters(), lr=0.1) if opt_name == "sgd"
           else torch.optim.Adam(model.parameters(), lr=0.05))
    x, y = _batch(seed + 1)
    mse = torch.nn.functional.mse_loss
    losses = []
    for _ in range(steps):
        losses.append(fn(model, opt, x, y, mse) if kind is None else _train(model, opt, x, y, mse, kind))
    return losses, [p.detach().clone() for p in model.parameters()]


def _train_problem(impl, opt_name, steps):
    label = f"{steps} step(s) of {'SGD' if opt_name == 'sgd' else 'Adam'} on a small network"
    name = f"train_step({label})"
    got_losses, got_params = _run_steps(impl, opt_name, steps)
    want_losses, want_params = _run_steps(_train, opt_name, steps)
    for value in got_losses:
        if not isinstance(value, float):
            return f"{name}: return the loss as a Python float (float(loss)), got {type(value).__name__}"
    same = all(torch.allclose(a, b, rtol=1e-10, atol=1e-12) for a, b in zip(got_params, want_params))
    if not same:
        for kind, explanation in (("no_zero", "the gradients were not cleared before backward: call "
                                              "optimizer.zero_grad() first, or they add up from step to step"),
                                  ("no_step", "the parameters did not move: call optimizer.step() after backward")):
            _, params = _run_steps(None, opt_name, steps, kind=kind)
            if all(torch.allclose(a, b, rtol=1e-10, atol=1e-12) for a, b in zip(got_params, params)):
                return f"{name}: {explanation}"
        return f"{name}: the parameters after the step(s) differ from one step of the optimizer on the loss"
    if not all(abs(a - b) <= 1e-12 * max(1.0, abs(b)) for a, b in zip(got_losses, want_losses)):
        after, _ = _run_steps(None, opt_name, steps, kind="after")
        if all(abs(a - b) <= 1e-12 * max(1.0, abs(b)) for a, b in zip(got_losses, after)):
            return f"{name}: that is the loss after the step: return the loss computed before it"
        return f"{name}: the losses {[round(v, 6) for v in want_losses]} expected, got {[round(v, 6) for v in got_losses]}"
    return None


@task("13.4", "train_step", points=2, reference=("course.grading.lecture13", "train_step_reference"))
def _check_train(impl):
    forbidden = forbidden_call(impl, "train_step", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def one():
        require(_train_problem(impl, "sgd", 1))

    def several():
        require(_train_problem(impl, "sgd", 3))
        require(_train_problem(impl, "adam", 3))
    return grade_parts((1, "one step", one), (1, "several steps, SGD and Adam", several))


# ----------------------------------------------------------------------------------- 13.5 visual_hull

def visual_hull_reference(silhouettes, cameras, points) -> torch.Tensor:
    """13.5: (N,) bool, True where a point falls inside the silhouette in every view: the pixel it falls in is
    (row floor(y), column floor(x)) of its projection; a point outside a view's image or behind its camera
    (depth <= 0) is outside that view's cone, so outside the hull."""
    return _hull(silhouettes, cameras, points)


def _hull(silhouettes, cameras, points, kind="course"):
    return _hulls(silhouettes, cameras, points, (kind,))[kind]


def _hulls(silhouettes, cameras, points, kinds):
    """{kind: (N,) bool} the hull, and the typical mistakes' answers (``_HULL_MISTAKES``), projecting once a view."""
    sil = torch.as_tensor(silhouettes)
    points = torch.as_tensor(points)
    N = points.shape[0]
    inside = {k: torch.zeros(N, dtype=torch.bool) if k == "union" else torch.ones(N, dtype=torch.bool) for k in kinds}
    for view, camera in enumerate(cameras):
        xy, depth = camera.project(points.to(camera.K.dtype))
        H, W = int(camera.height), int(camera.width)
        mask = sil[view] if sil.dtype == torch.bool else sil[view] > 0.5
        front = depth > 0
        for kind in kinds:
            pick = torch.round if kind == "round" else torch.floor         # round: the nearest integer, not the pixel
            col, row = pick(xy[:, 0]), pick(xy[:, 1])
            finite = torch.isfinite(col) & torch.isfinite(row)
            col = torch.where(finite, col, torch.full_like(col, -1)).clamp(-1, max(H, W) + 1).long()
            row = torch.where(finite, row, torch.full_like(row, -1)).clamp(-1, max(H, W) + 1).long()
            if kind == "swap":
                row, col = col, row
            frame = (col >= 0) & (col < W) & (row >= 0) & (row < H)
            if kind == "clamp":                                             # off the frame: the border pixel
                col, row = col.clamp(0, W - 1), row.clamp(0, H - 1)
            seen = (frame | (kind == "clamp")) & (front | (kind == "no_depth"))
            in_view = torch.zeros(N, dtype=torch.bool)
            in_view[seen] = mask[row[seen], col[seen]]
            if kind == "keep_outside":                                      # a view that can't place it: kept
                in_view = in_view | ~frame
            inside[kind] = inside[kind] | in_view if kind == "union" else inside[kind] & in_view
    return inside


_HULL_MISTAKES = [
    ("round", "a point falls in the pixel that contains it: pixel (row i, column j) covers [j, j+1) × [i, i+1), "
              "so take floor(x) and floor(y); rounding picks a pixel half a pixel off"),
    ("swap", "rows and columns are swapped: the projection gives (x, y) = (column, row), and the silhouette is "
             "indexed [row, column], i.e. [floor(y), floor(x)]"),
    ("union", "a point is in the hull when *every* view sees it inside the silhouette (an intersection of "
              "cones); yours keeps a point that *any* view sees inside"),
    ("keep_outside", "a point outside a view's image was kept: the views frame the whole shape, so a point a view "
                     "cannot place in its image is outside that view's cone, and outside the hull"),
    ("clamp", "a point outside a view's image was read at the nearest border pixel: it is outside that view's "
              "cone, so outside the hull, whatever the border pixel says"),
    ("no_depth", "points behind a camera (depth <= 0) were projected anyway: dividing by a negative depth flips "
                 "them into the image, but a camera sees nothing behind it: such a point is outside its cone"),
]


def _look(eye, size=(16, 16), fov=40.0, dtype=torch.float64):
    from course.camera import Camera
    return Camera.look_at(eye, (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), fov_y=fov, width=size[1], height=size[0],
                          dtype=dtype)


def _hull_problem(impl, label, silhouettes, cameras, points):
    name = f"visual_hull({label})"
    out = _call(impl, silhouettes, list(cameras), points)
    got = to_tensor(out, name)
    expected = _hull(silhouettes, cameras, points)
    if tuple(got.shape) != tuple(expected.shape):
        return f"{name}: shape ({expected.shape[0]},) expected, one answer per point, got {tuple(got.shape)}"
    if got.dtype != torch.bool:
        return f"{name}: return a bool tensor (True inside the hull), got {str(got.dtype).replace('torch.', '')}"
    if torch.equal(got, expected):
        return None
    answers = _hulls(silhouettes, cameras, points, tuple(kind for kind, _ in _HULL_MISTAKES))
    variants = [(kind, answers[kind], why) for kind, why in _HULL_MISTAKES]
    telling = [(v, why) for kind, v, why in variants
               if not torch.equal(v, expected) and sum(torch.equal(v, w) for _, w, _ in variants) == 1]
    for v, why in telling:
        if torch.equal(got, v):
            return f"{name}: {why}"
    wrong = int((got != expected).sum())
    first = int((got != expected).nonzero()[0, 0])
    return (f"{name}: {wrong} of {expected.numel()} points wrong (first: point {first}, got {bool(got[first])}, "
            f"expected {bool(expected[first])})")


def _random_points(seed, n, low, high, dtype=torch.float64):
    g = generator(seed)
    low, high = torch.tensor(low, dtype=dtype), torch.tensor(high, dtype=dtype)
    return low + (high - low) * torch.rand(n, 3, generator=g, dtype=dtype)


def _random_mask(seed, shape, fill):
    return (torch.rand(shape, generator=generator(seed)) < fill).to(torch.float64)


def _balls_silhouettes(cameras, balls):
    """(V, H, W) float64: 1 where the ray through a pixel centre meets one of ``balls`` ((centre, radius) pairs)."""
    sils = []
    for camera in cameras:
        origins, directions = camera.rays()                                 # (H, W, 3) each, unit directions
        hit = torch.zeros(origins.shape[:2], dtype=torch.bool)
        for centre, radius in balls:
            oc = origins - torch.tensor(centre, dtype=origins.dtype)
            b = (oc * directions).sum(-1)
            hit |= (b * b - (oc * oc).sum(-1) + radius ** 2 >= 0) & (b <= 0)   # in front of the camera
        sils.append(hit.to(torch.float64))
    return torch.stack(sils)


@cache
def _hull_shapes():
    """The course's 8 data views (``learning.data.view_cameras(8)``: 30° up, 3.2 away, 32 px), the silhouettes of a ball and of two
    balls seen through them (exact, ray by ray), and a 10³ grid of points over [-1, 1]³."""
    golden = 180.0 * (3 - 5 ** 0.5)                                         # the golden angle, degrees
    cameras = [_look(_eyes(torch.tensor(math.radians(k * golden), dtype=torch.float64),
                           torch.tensor(math.radians(30.0), dtype=torch.float64), 3.2).tolist(),
                     size=(32, 32)) for k in range(8)]                      # as learning.data.view_cameras(8)
    shapes = {"a ball": [((0.1, 0.0, -0.05), 0.75)],
              "two balls": [((-0.45, 0.1, 0.0), 0.45), ((0.4, -0.2, 0.2), 0.5)]}
    c = -1 + (torch.arange(10, dtype=torch.float64) + 0.5) * (2 / 10)
    grid = torch.stack(torch.meshgrid(c, c, c, indexing="ij"), -1).reshape(-1, 3)
    return cameras, {name: _balls_silhouettes(cameras, balls) for name, balls in shapes.items()}, grid


@task("13.5", "visual_hull", points=4, reference=("course.grading.lecture13", "visual_hull_reference"))
def _check_hull(impl):
    forbidden = forbidden_call(impl, "visual_hull", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def one_view():
        camera = _look((0.0, 0.0, 3.0))
        points = _random_points(1351, 300, (-0.9, -0.9, -0.5), (0.9, 0.9, 0.5))
        require(_hull_problem(impl, "one view of a random 16 × 16 silhouette", _random_mask(1352, (1, 16, 16), 0.5),
                              [camera], points))

    def several():
        cameras = [_look((0.0, 0.0, 3.0)), _look((3.0, 0.0, 0.0)), _look((0.0, 3.0, 0.01))]
        points = _random_points(1353, 400, (-0.9, -0.9, -0.9), (0.9, 0.9, 0.9))
        require(_hull_problem(impl, "three views of random silhouettes", _random_mask(1354, (3, 16, 16), 0.7),
                              cameras, points))

    def unseen():
        wide = _random_points(1355, 400, (-2.5, -2.5, -2.5), (2.5, 2.5, 2.5))
        full = torch.ones(1, 12, 16, dtype=torch.float64)
        require(_hull_problem(impl, "points outside a 12 × 16 image, a silhouette that fills it", full,
                              [_look((0.0, 0.3, 3.0), size=(12, 16), fov=30.0)], wide))
        border = torch.zeros(1, 12, 16, dtype=torch.float64)
        border[:, 0], border[:, -1], border[:, :, 0], border[:, :, -1] = 1, 1, 1, 1
        require(_hull_problem(impl, "points outside the image, a silhouette on its border", border,
                              [_look((0.0, 0.3, 3.0), size=(12, 16), fov=30.0)], wide))
        require(_hull_problem(impl, "a camera among the points (some behind it)", full,
                              [_look((0.0, 0.2, 1.2), size=(12, 16), fov=90.0)], wide))

    def shapes():
        cameras, silhouettes, grid = _hull_shapes()
        for name, sils in silhouettes.items():
            require(_hull_problem(impl, f"{name} seen by the course's 8 views at 32 px", sils, cameras, grid))
        sils = silhouettes["two balls"]
        require(_hull_problem(impl, "bool silhouettes", sils.bool(), cameras, grid))
        require(_hull_problem(impl, "float32 points", sils, cameras, grid.float()))
        require(_hull_problem(impl, "no points", sils, cameras, torch.zeros(0, 3, dtype=torch.float64)))
    return grade_parts((1, "one view: which pixel", one_view), (1, "several views: all of them", several),
                       (1, "points a view cannot place", unseen), (1, "the course's views, bool, no points", shapes))
