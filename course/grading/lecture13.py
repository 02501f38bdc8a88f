"""The checks of lecture 13's graded tasks (learning through the renderer): 13.1 voxel_iou,
13.2 multiview_iou_loss, 13.3 view_eyes, 13.4 train_step.

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

The references are written here, in float64; ``tests/test_grading_13.py`` checks that they agree with the
package. A graded function that calls them, or the package functions doing the task's work, scores 0.
"""
from __future__ import annotations

import torch

from .helpers import _call, _match, compare, generator, grade_parts, require, to_tensor
from .registry import forbidden_call, task

__all__ = ["voxel_iou_reference", "multiview_iou_loss_reference", "view_eyes_reference", "train_step_reference"]

FORBIDDEN = [("course.learning.data", "voxel_iou"), ("course.inverse.losses", "silhouette_iou_loss"),
             ("course.learning.mvtn", "view_directions"),
             ("course.grading.lecture13", "voxel_iou_reference"),
             ("course.grading.lecture13", "multiview_iou_loss_reference"),
             ("course.grading.lecture13", "view_eyes_reference"),
             ("course.grading.lecture13", "train_step_reference")]


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
