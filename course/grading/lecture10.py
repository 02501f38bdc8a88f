"""The checks of lecture 10's graded tasks (inverse rendering): 10.1 silhouette_iou_loss, 10.2 smoothness_loss,
10.3 fit_pose, 10.4 staircase.

Each check runs the student's function next to a reference on fixed, seeded-random and stress inputs and
says what to fix, recognising the typical mistakes of the task. ``import course.grading`` imports this
module, which registers its checks in ``course.grading.TASKS``.

The tasks are the pieces of every fit in lecture 10 (Kato, Ushiku and Harada, CVPR 2018), and one measurement:

* 10.1, the silhouette loss: per view, ``1 - |ŝ ⊙ s|₁ / |ŝ + s - ŝ ⊙ s|₁`` (one minus the soft IoU of the
  rendered silhouette ŝ and the target s), summed over the views; a view whose union is empty is a perfect
  match and scores 0 (never 0 / 0).
* 10.2, the smoothness loss: ``Σ (1 - n₁·n₂)²`` over the interior edges (shared by exactly two faces, found by
  vertex index), n₁, n₂ the unit normals of the edge's two faces (a zero-area face has the normal 0).
* 10.3, a fitting loop that must converge: from a start pose, minimise the mean squared difference between a
  given differentiable render and a target within a step budget (one render per step); graded by the error
  the returned pose has on the grader's own problems (a soft 2D triangle shifted, or turned and shifted: radians
  beside pixels), so the loop must pick its optimiser and step sizes well.
* 10.4, an analysis: sample a loss of one parameter on a fine grid and measure its staircase, the number of
  intervals where it jumps and the widest flat run; graded on the grader's hard and soft losses.

The references are written here from these formulas, in float64; ``tests/test_grading_10.py`` checks that
they agree with ``course.inverse.losses.silhouette_iou_loss`` and ``course.inverse.losses.smoothness_loss``. They are public so that those tests (and a curious student) can read them; a graded
function that calls them, or the package functions doing the task's work, scores 0.
"""
from __future__ import annotations

import math

import torch

from .helpers import _close, compare, generator, grade_parts, require, to_tensor
from .registry import forbidden_call, task

__all__ = ["silhouette_iou_loss_reference", "smoothness_loss_reference", "fit_pose_reference", "staircase_reference"]

FORBIDDEN = [("course.inverse.losses", "silhouette_iou_loss"), ("course.inverse.losses", "smoothness_loss"),
             ("course.inverse.losses", "interior_edges"), ("course.inverse.silhouettes", "fit_silhouettes"),
             ("course.grading.lecture10", "silhouette_iou_loss_reference"),
             ("course.grading.lecture10", "smoothness_loss_reference"),
             ("course.grading.lecture10", "fit_pose_reference"), ("course.inverse.pose", "fit_camera"),
             ("course.grading.lecture10", "staircase_reference")]


# ------------------------------------------------------------------------------------- the references

def silhouette_iou_loss_reference(pred, target) -> torch.Tensor:
    """10.1: ``Σ_views 1 - |ŝ ⊙ s|₁ / |ŝ + s - ŝ ⊙ s|₁``, a scalar in pred's dtype; pred, target (H, W) or
    (N, H, W) in [0, 1]; an empty union gives 0. Differentiable in pred."""
    return _iou_loss(pred, target)


def smoothness_loss_reference(verts, faces) -> torch.Tensor:
    """10.2: ``Σ (1 - n₁·n₂)²`` over the interior edges of the mesh, a scalar in verts' dtype; verts (V, 3),
    faces (F, 3) int64. Differentiable in verts."""
    return _smoothness(verts, faces)


# ----------------------------------------------------------------------------- 10.1 the silhouette loss

def _iou_loss(pred, target, *, union="exact", one=True, per_view=True, reduce="sum", guard=True):
    """10.1 and its typical mistakes as switches: ``union`` ("exact": ŝ + s - ŝ s, "sum": ŝ + s, the overlap
    counted twice), ``one`` (1 - IoU, else the IoU itself), ``per_view`` (else one ratio over all views),
    ``reduce`` ("sum" or "mean" over views), ``guard`` (an empty union gives 0, else 0 / 0)."""
    views = pred.dim() == 3
    dims = (-2, -1) if per_view else tuple(range(pred.dim()))
    inter = (pred * target).sum(dims)
    total = pred + target - (pred * target if union == "exact" else 0)
    uni = total.sum(dims)
    if guard:
        empty = uni <= torch.finfo(uni.dtype).tiny ** 0.5
        ratio = inter / torch.where(empty, torch.ones_like(uni), uni)
        loss = torch.where(empty, torch.zeros_like(ratio), (1 - ratio) if one else ratio)
    else:
        ratio = inter / uni
        loss = (1 - ratio) if one else ratio
    if views and per_view:
        loss = loss.sum() if reduce == "sum" else loss.mean()
    return loss


def _blobs(n, size, seed, dtype=torch.float64, empty=()):
    """(n, size, size) soft silhouettes in [0, 1]: blurred discs at random places, and matching targets that are
    hard discs a little off; views listed in ``empty`` are empty in both."""
    g = generator(seed)
    y, x = torch.meshgrid(torch.arange(size, dtype=torch.float64) + 0.5, torch.arange(size, dtype=torch.float64) + 0.5,
                          indexing="ij")
    preds, targets = [], []
    for k in range(n):
        c = torch.rand(2, generator=g, dtype=torch.float64) * size * 0.5 + size * 0.25
        r = float(torch.rand((), generator=g, dtype=torch.float64)) * size * 0.2 + size * 0.15
        d = torch.rand(2, generator=g, dtype=torch.float64) * 4 - 2
        dist = ((x - c[0]) ** 2 + (y - c[1]) ** 2).sqrt()
        pred = torch.sigmoid((r - dist) * 1.5)
        target = (((x - c[0] - d[0]) ** 2 + (y - c[1] - d[1]) ** 2).sqrt() < r * 0.9).to(torch.float64)
        if k in empty:
            pred, target = torch.zeros_like(pred), torch.zeros_like(target)
        preds.append(pred)
        targets.append(target)
    return torch.stack(preds).to(dtype), torch.stack(targets).to(dtype)


def _loss_and_grad(impl, pred, target, name):
    """The student's loss (a detached tensor) and its gradient with respect to pred (None if none reaches it)."""
    p = pred.clone().requires_grad_(True)
    out = impl(p, target.clone())
    got = to_tensor(out, name)
    grad = None
    if isinstance(out, torch.Tensor) and out.requires_grad and out.dim() == 0:
        (grad,) = torch.autograd.grad(out, p, allow_unused=True)
    return got, grad, isinstance(out, torch.Tensor) and out.requires_grad


def _iou_problem(impl, pred, target, label) -> str | None:
    name = f"silhouette_iou_loss({label})"
    got, grad, tracked = _loss_and_grad(impl, pred, target, name)
    expected = _iou_loss(pred, target)
    low = pred.dtype == torch.float32
    message = compare(got, expected, name=name, check_dtype=True, **({} if low else dict(atol=1e-10, rtol=1e-10)))
    if message is not None and "shape" not in message and "dtype" not in message:
        if not bool(torch.isfinite(got).all()):
            return (f"{name}: NaN or inf: a view whose silhouettes are both empty has union 0 and 0 / 0 = NaN; "
                    "such a view is a perfect match: give it the loss 0")
        f = lambda **kw: _iou_loss(pred, target, **kw)                    # noqa: E731
        explanation = _match(got, [
            (f(union="sum"), "the union counts the overlap twice: it is |ŝ + s - ŝ ⊙ s|₁ (a pixel covered by "
                             "both counts once), not |ŝ + s|₁"),
            (f(one=False), "that is the IoU itself, 1 for a perfect fit: the loss is 1 - IoU, which is 0 for a "
                           "perfect fit and falls as the silhouettes overlap more"),
            (-f(one=False), "that is -IoU (Kato et al.'s negative IoU): add 1 per view, so that a perfect fit "
                            "scores 0"),
            (f(per_view=False), "one ratio over all the views pooled: compute the IoU of each view (sums over H "
                                "and W only), then sum the per-view losses"),
            (f(reduce="mean"), "the mean over the views: sum the per-view losses (Kato et al.)"),
            (_iou_loss((pred > 0.5).to(pred.dtype), target), "that is the IoU of thresholded masks: use the soft "
                                                            "values ŝ themselves, so the loss has a gradient"),
        ])
        return f"{name}: {explanation}" if explanation else message
    if message is not None:
        return message
    # the value is right: now the gradient, which is what the fit uses
    p = pred.clone().requires_grad_(True)
    (want,) = torch.autograd.grad(_iou_loss(p, target), p)
    if not tracked or grad is None:
        return (f"{name}: the value is right but no gradient reaches pred: compute it with tensor operations on "
                "pred (no .item(), float(), numpy or thresholds), and return the tensor")
    bad = compare(grad, want, name=f"d {name} / d pred", check_dtype=False,
                  **({} if low else dict(atol=1e-9, rtol=1e-9)))
    if bad is not None:
        return f"{bad} (the value is right; is part of the expression detached?)"
    return None


def _match(got, variants, tol=1e-6):
    """The explanation of the first ``(alternative, explanation)`` that ``got`` matches, else None."""
    for alternative, explanation in variants:
        if alternative is not None and _close(got, alternative, tol):
            return explanation
    return None


@task("10.1", "silhouette_iou_loss", points=2, reference=("course.inverse.losses", "silhouette_iou_loss"))
def _check_silhouette_iou_loss(impl):
    forbidden = forbidden_call(impl, "silhouette_iou_loss", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def one_view():
        pred, target = _blobs(1, 16, 101)
        require(_iou_problem(impl, pred[0], target[0], "one 16 x 16 view, float64"))
        pred, target = _blobs(1, 12, 102)
        require(_iou_problem(impl, pred[0], pred[0], "a perfect fit, float64"))

    def views():
        pred, target = _blobs(4, 16, 103)
        require(_iou_problem(impl, pred, target, "4 views of 16 x 16, float64"))
        pred, target = _blobs(3, 10, 104)
        target[1] = 1.0 - target[1]                                       # a poor match in one view
        require(_iou_problem(impl, pred, target, "3 views, one poorly matched, float64"))

    def stress():
        pred, target = _blobs(3, 12, 105, empty=(1,))
        require(_iou_problem(impl, pred, target, "3 views, the middle one empty in both, float64"))
        pred, target = _blobs(1, 8, 106, empty=(0,))
        require(_iou_problem(impl, pred[0], target[0], "one view, both silhouettes empty, float64"))
        pred, target = _blobs(2, 12, 107, dtype=torch.float32)
        require(_iou_problem(impl, pred, target, "2 views, float32"))
    def views_and_one():
        one_view()
        views()
    return grade_parts((1, "one view and several views", views_and_one),
                       (1, "empty views, float32", stress))


# ---------------------------------------------------------------------------- 10.2 the smoothness loss

def _normals(verts, faces, unit=True):
    """(F, 3) face normals (v1 - v0) × (v2 - v0), normalised (zero for a zero-area face) if ``unit``."""
    v0, v1, v2 = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    n = torch.linalg.cross(v1 - v0, v2 - v0, dim=-1)
    if not unit:
        return n
    length = n.norm(dim=-1, keepdim=True)
    return torch.where(length > 0, n / torch.where(length > 0, length, torch.ones_like(length)), torch.zeros_like(n))


def _face_pairs(faces, mode="interior"):
    """(E, 2) the two faces of every interior edge (by vertex index). ``mode``: "interior" (edges of exactly two
    faces), "twice" (each interior edge once from each of its faces: every pair twice), "consecutive" (all the
    face sides sorted by edge, paired blindly two by two, as if every edge had two faces)."""
    F = faces.shape[0]
    sides = torch.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], 1).reshape(-1, 2)
    sides = sides.sort(dim=1).values                                      # (3F, 2) smaller index first
    face_of = torch.arange(F).repeat_interleave(3)                        # (3F,)
    key = sides[:, 0] * (int(faces.max()) + 1) + sides[:, 1]
    order = torch.argsort(key, stable=True)
    key, face_of = key[order], face_of[order]
    if mode == "consecutive":
        m = key.shape[0] // 2 * 2
        return face_of[:m].view(-1, 2)
    pairs = []
    start = 0
    while start < key.shape[0]:
        end = start
        while end < key.shape[0] and key[end] == key[start]:
            end += 1
        if end - start == 2:
            a, b = int(face_of[start]), int(face_of[start + 1])
            pairs.append((a, b))
            if mode == "twice":
                pairs.append((b, a))
        start = end
    return torch.tensor(pairs, dtype=torch.int64).view(-1, 2)


def _smoothness(verts, faces, *, unit=True, sign=-1.0, power=2, pairs="interior", reduce="sum"):
    """10.2 and its typical mistakes: ``unit`` (normalised normals), ``sign`` (-1: 1 - n₁·n₂; +1: 1 + n₁·n₂, the
    cosine's sign flipped), ``power`` (2, or 1: not squared), ``pairs`` (see ``_face_pairs``), ``reduce``."""
    faces = torch.as_tensor(faces, dtype=torch.int64)
    n = _normals(verts, faces, unit)
    p = _face_pairs(faces, pairs)
    cos = (n[p[:, 0]] * n[p[:, 1]]).sum(-1)
    terms = (1 + sign * cos) ** power
    if terms.numel() == 0:
        return verts.sum() * 0
    return terms.sum() if reduce == "sum" else terms.mean()


def _bumpy_sphere(seed, dtype=torch.float64):
    """An icosphere (2 subdivisions, 320 faces: closed) with its vertices moved radially at random."""
    verts, faces = _icosphere(2)
    g = generator(seed)
    scale = 1 + 0.15 * (torch.rand(verts.shape[0], 1, generator=g, dtype=torch.float64) - 0.5)
    return (verts * scale).to(dtype), faces


def _icosphere(subdivisions):
    t = (1 + 5 ** 0.5) / 2
    verts = torch.tensor([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t],
                          [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], dtype=torch.float64)
    faces = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
             [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11],
             [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    verts = list(verts / verts.norm(dim=1, keepdim=True))
    for _ in range(subdivisions):
        mid, out = {}, []

        def middle(a, b):
            key = (min(a, b), max(a, b))
            if key not in mid:
                m = verts[a] + verts[b]
                verts.append(m / m.norm())
                mid[key] = len(verts) - 1
            return mid[key]
        for a, b, c in faces:
            ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
            out += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        faces = out
    return torch.stack(verts), torch.tensor(faces, dtype=torch.int64)


def _grid(n, seed, dtype=torch.float64, seam=False):
    """An open n x n grid of squares (2 n² faces: boundary edges all round) with random heights; ``seam``: the
    middle column of vertices duplicated for the right half (two copies at one position, like a uv seam), so
    the edges along it are boundaries by index."""
    g = generator(seed)
    y, x = torch.meshgrid(torch.arange(n + 1, dtype=torch.float64), torch.arange(n + 1, dtype=torch.float64),
                          indexing="ij")
    z = 0.4 * torch.rand(n + 1, n + 1, generator=g, dtype=torch.float64)
    verts = torch.stack([x, y, z], -1).reshape(-1, 3) / n
    idx = torch.arange((n + 1) ** 2).view(n + 1, n + 1)
    if seam:
        copies = verts[idx[:, n // 2]]                                    # (n + 1, 3) the seam's second copies
        extra = torch.arange(verts.shape[0], verts.shape[0] + n + 1)
        verts = torch.cat([verts, copies])
    faces = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = int(idx[i, j]), int(idx[i, j + 1]), int(idx[i + 1, j]), int(idx[i + 1, j + 1])
            if seam and j == n // 2:                                      # the right half uses the copies
                a, c = int(extra[i]), int(extra[i + 1])
            faces += [[a, b, d], [a, d, c]]
    return verts.to(dtype), torch.tensor(faces, dtype=torch.int64)


def _degenerate():
    """Five vertices, four faces: (0, 1, 2) has zero area (vertex 2 is the middle of 0 - 1) and shares its three
    edges with the three other faces."""
    verts = torch.tensor([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.2], [1.0, -1.0, 0.3]],
                         dtype=torch.float64)
    faces = torch.tensor([[0, 2, 3], [2, 1, 3], [0, 1, 2], [1, 0, 4]], dtype=torch.int64)
    return verts, faces


def _smoothness_problem(impl, verts, faces, label, gradient=True) -> str | None:
    name = f"smoothness_loss({label})"
    v = verts.clone().requires_grad_(True)
    out = impl(v, faces.clone())
    got = to_tensor(out, name)
    expected = _smoothness(verts, faces)
    low = verts.dtype == torch.float32
    message = compare(got, expected, name=name, check_dtype=True, **({} if low else dict(atol=1e-9, rtol=1e-9)))
    if message is not None and "shape" not in message and "dtype" not in message:
        if not bool(torch.isfinite(got).all()):
            return (f"{name}: NaN or inf: a zero-area face has no direction, its cross product is 0 and 0 / 0 is "
                    "NaN; give it the normal 0 (divide only where the length is > 0)")
        f = lambda **kw: _smoothness(verts, faces, **kw)                  # noqa: E731
        explanation = _match(got, [
            (f(sign=1.0), "the cosine's sign is flipped: with unit normals n₁·n₂ = -cos θ (θ the dihedral "
                          "angle, 180° when flat), so the term is (1 - n₁·n₂)², 0 on a flat surface"),
            (f(unit=False), "the normals are not normalised: n₁·n₂ must be the cosine of the angle between "
                            "the faces, so divide each cross product by its length"),
            (f(power=1), "the terms are not squared: Σ (1 - n₁·n₂)²"),
            (f(pairs="twice"), "every interior edge counts twice (once from each of its faces): count each "
                               "edge once"),
            (f(pairs="consecutive"), "the faces were paired two by two after sorting the sides, as if every "
                                     "edge had two faces: boundary edges (one face) shift the pairing; keep "
                                     "only the edges shared by exactly two faces"),
            (f(reduce="mean"), "the mean over the edges: the loss is the sum"),
        ])
        return f"{name}: {explanation}" if explanation else message
    if message is not None or not gradient:                               # a zero-area face: no gradient to
        return message                                                    # compare (its normal's is undefined)
    v2 = verts.clone().requires_grad_(True)
    (want,) = torch.autograd.grad(_smoothness(v2, faces), v2)
    if not (isinstance(out, torch.Tensor) and out.requires_grad):
        return (f"{name}: the value is right but no gradient reaches verts: compute it with tensor operations "
                "on verts and return the tensor")
    (grad,) = torch.autograd.grad(out, v, allow_unused=True)
    if grad is None:
        return f"{name}: the value is right but no gradient reaches verts"
    bad = compare(grad, want, name=f"d {name} / d verts", check_dtype=False,
                  **({} if low else dict(atol=1e-8, rtol=1e-8)))
    return None if bad is None else f"{bad} (the value is right; is part of the expression detached?)"


@task("10.2", "smoothness_loss", points=3, reference=("course.inverse.losses", "smoothness_loss"))
def _check_smoothness_loss(impl):
    forbidden = forbidden_call(impl, "smoothness_loss", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def closed():
        verts, faces = _bumpy_sphere(111)
        require(_smoothness_problem(impl, verts, faces, "a bumpy icosphere, 320 faces, float64"))
        verts, faces = _icosphere(1)
        require(_smoothness_problem(impl, verts, faces, "a round icosphere, 80 faces, float64"))

    def open_mesh():
        verts, faces = _grid(4, 112)
        require(_smoothness_problem(impl, verts, faces, "an open 4 x 4 grid with random heights, float64"))
        verts, faces = _grid(4, 113, seam=True)
        require(_smoothness_problem(impl, verts, faces, "a grid with a seam (duplicated vertices), float64"))

    def stress():
        verts, faces = _degenerate()
        require(_smoothness_problem(impl, verts, faces, "a zero-area face, float64", gradient=False))
        verts, faces = _bumpy_sphere(114, torch.float32)
        require(_smoothness_problem(impl, verts, faces, "a bumpy icosphere, float32"))
        verts = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], dtype=torch.float64)
        require(_smoothness_problem(impl, verts, torch.tensor([[0, 1, 2]]), "one triangle (no interior edge)"))
    return grade_parts((1, "closed meshes", closed),
                       (1, "open meshes: boundary edges and seams", open_mesh),
                       (1, "a zero-area face, float32, no interior edge", stress))


# ------------------------------------------------------------------------------- 10.3 a fitting loop

_TRIANGLE = torch.tensor([[6.0, 5.0], [19.0, 9.0], [9.0, 19.0]], dtype=torch.float64)   # pixels, asymmetric


def _posed(verts, pose):
    """verts (3, 2) moved by pose: (2,) a shift in pixels, or (3,) a turn (radians, about the centroid) then a
    shift."""
    if pose.shape[0] == 2:
        return verts + pose
    c = verts.mean(0)
    cos, sin = torch.cos(pose[0]), torch.sin(pose[0])
    rot = torch.stack([torch.stack([cos, -sin]), torch.stack([sin, cos])])
    return c + (verts - c) @ rot.T + pose[1:]


def _triangle_image(pose, size=24, width=0.7, hard=False):
    """(size, size) coverage of the posed triangle at the pixel centres: soft (a product of sigmoids of the signed
    distances to the three edges, ``width`` pixels wide) or hard (the centre inside or not)."""
    v = _posed(_TRIANGLE.to(pose.dtype), pose)
    y, x = torch.meshgrid(torch.arange(size, dtype=pose.dtype) + 0.5, torch.arange(size, dtype=pose.dtype) + 0.5,
                          indexing="ij")
    e0, e1 = v[1] - v[0], v[2] - v[0]
    orientation = torch.sign(e0[0] * e1[1] - e0[1] * e1[0])
    cover = torch.ones(size, size, dtype=pose.dtype)
    for k in range(3):
        a, e = v[k], v[(k + 1) % 3] - v[k]
        d = orientation * (e[0] * (y - a[1]) - e[1] * (x - a[0])) / e.norm()   # > 0 inside
        cover = cover * ((d > 0).to(pose.dtype) if hard else torch.sigmoid(d / width))
    return cover


class _PoseProblem:
    """One fit the grader asks for: a render function that counts its calls and records the poses it sees, the
    target (the render at the true pose), a start, a step budget, and tolerances (radians, pixels)."""

    def __init__(self, seed, n, dtype=torch.float64, steps=150):
        g = generator(seed)
        spread = torch.tensor([0.2, 1.5, 1.5], dtype=torch.float64)[-n:]
        offset = torch.tensor([0.3, 3.0, 3.0], dtype=torch.float64)[-n:]
        self.true = torch.randn(n, generator=g, dtype=torch.float64) * spread
        self.start = (self.true + (torch.rand(n, generator=g, dtype=torch.float64) * 2 - 1) * offset).to(dtype)
        self.target = _triangle_image(self.true.to(dtype))
        self.steps, self.dtype, self.calls, self.seen = steps, dtype, 0, []

    def render(self, pose):
        self.calls += 1
        pose = torch.as_tensor(pose)
        self.seen.append(pose.detach().to(torch.float64).clone())
        return _triangle_image(pose)

    def errors(self, pose):
        """(angle error in degrees or None, shift error in pixels)."""
        d = (torch.as_tensor(pose).detach().to(torch.float64) - self.true).abs()
        return (math.degrees(float(d[0])) if d.shape[0] == 3 else None), float(d[-2:].norm())

    def loss(self, pose):
        with torch.no_grad():
            return float(((_triangle_image(pose.to(self.dtype)) - self.target) ** 2).mean())


_ANGLE_TOL, _SHIFT_TOL = 0.5, 0.05                                        # degrees, pixels


def _fit(render, target, pose0, steps, *, lr=0.1, decay=0.1, zero=True, maximize=False):
    """10.3: Adam on the mean squared difference, the learning rate decaying to ``decay`` times itself; the
    switches are the typical mistakes (``zero``: clear the gradients each step; ``maximize``: uphill)."""
    pose = pose0.detach().clone().requires_grad_(True)
    opt = torch.optim.Adam([pose], lr=lr, maximize=maximize)
    schedule = torch.optim.lr_scheduler.ExponentialLR(opt, decay ** (1 / max(steps, 1)))
    for _ in range(steps):
        if zero:
            opt.zero_grad()
        loss = ((render(pose) - target) ** 2).mean()
        loss.backward()
        opt.step()
        schedule.step()
    return pose.detach()


def fit_pose_reference(render, target, pose0, steps):
    """10.3: the pose (a detached tensor like pose0) minimising mean (render(pose) - target)², found in ``steps``
    optimiser steps (one render each) from pose0."""
    return _fit(render, target, pose0, steps)


def _error_text(angle, shift):
    return (f"{angle:.3g}° and " if angle is not None else "") + f"{shift:.3g} px"


def _fit_problem(impl, problem, label) -> str | None:
    name = f"fit_pose({label})"
    pose0 = problem.start.clone()
    out = impl(problem.render, problem.target.clone(), pose0, problem.steps)
    if not torch.equal(pose0, problem.start):
        return f"{name}: pose0 was changed in place: copy it (pose0.detach().clone()) and optimise the copy"
    got = to_tensor(out, name)
    if got.shape != problem.start.shape:
        return f"{name}: return the pose, shape {tuple(problem.start.shape)}, got {tuple(got.shape)}"
    if problem.calls > problem.steps + 1:
        return (f"{name}: render was called {problem.calls} times for a budget of {problem.steps} steps: render "
                "once per step (and reuse that image for the loss)")
    if not bool(torch.isfinite(got).all()):
        return f"{name}: the pose came back NaN or inf: the steps are far too large"
    start_angle, start_shift = problem.errors(problem.start)
    angle, shift = problem.errors(got)
    if torch.equal(got.to(problem.start.dtype), problem.start):
        return (f"{name}: the pose did not move: the optimiser must hold the tensor you render with "
                "(requires_grad=True, not detached), and step it after each backward()")
    if (angle is None or angle <= _ANGLE_TOL) and shift <= _SHIFT_TOL:
        return None
    start_loss, end_loss = problem.loss(problem.start), problem.loss(got)
    before = _error_text(start_angle, start_shift)
    after = _error_text(angle, shift)
    need = (f"{_ANGLE_TOL:g}° and " if angle is not None else "") + f"{_SHIFT_TOL:g} px"
    if end_loss > start_loss:
        return (f"{name}: the fit went uphill: the error grew from {before} to {after}; step against the "
                "gradient (minimise the loss)")
    seen = [problem.loss(p) for p in problem.seen]
    if seen and min(seen) < 0.25 * seen[-1]:
        return (f"{name}: the error went from {before} to {after}, above the {need} needed, and the loss went down "
                "and up again: the steps are too large near the answer, or the gradients pile up (clear them "
                "before each backward()); let the step size shrink as the fit settles")
    return (f"{name}: not converged: the error fell from {before} to {after}, above the {need} needed, in "
            f"{problem.steps} steps: take larger steps (an optimiser that adapts to each parameter's scale copes "
            "with an angle in radians beside a shift in pixels)")


@task("10.3", "fit_pose", points=5, reference=("course.grading.lecture10", "fit_pose_reference"))
def _check_fit_pose(impl):
    forbidden = forbidden_call(impl, "fit_pose", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def shift():
        require(_fit_problem(impl, _PoseProblem(131, 2), "a shift of 2 parameters, float64"))
        require(_fit_problem(impl, _PoseProblem(132, 2), "another shift, float64"))

    def turn():
        require(_fit_problem(impl, _PoseProblem(133, 3), "a turn and a shift: radians beside pixels, float64"))
        require(_fit_problem(impl, _PoseProblem(134, 3), "another turn and shift, float64"))

    def budget():
        require(_fit_problem(impl, _PoseProblem(135, 3, steps=100), "a budget of 100 steps, float64"))
        require(_fit_problem(impl, _PoseProblem(136, 2, dtype=torch.float32), "a shift, float32"))
    return grade_parts((2, "a shift", shift),
                       (2, "a turn and a shift", turn),
                       (1, "a smaller budget, float32", budget))


# ---------------------------------------------------------------------- 10.4 the staircase, measured

def _staircase(loss_fn, start, stop, n, *, runs="intervals", units=True, inclusive=True):
    """10.4 and its typical mistakes: ``runs`` ("intervals": a flat run of k equal neighbours spans k intervals;
    "samples": counted as k + 1 samples), ``units`` (the run in the parameter's units, else in samples),
    ``inclusive`` (n samples from start to stop inclusive, else stop excluded)."""
    if inclusive:
        xs = torch.linspace(start, stop, n, dtype=torch.float64)
    else:
        xs = start + (stop - start) * torch.arange(n, dtype=torch.float64) / n
    values = torch.tensor([float(loss_fn(x)) for x in xs], dtype=torch.float64)
    same = (values[1:] == values[:-1]).tolist()
    longest = run = 0
    for s in same:
        run = run + 1 if s else 0
        longest = max(longest, run)
    if runs == "samples" and longest > 0:
        longest += 1
    spacing = float(xs[1] - xs[0]) if n > 1 else 0.0
    return len(same) - sum(same), longest * spacing if units else float(longest)


def staircase_reference(loss_fn, start, stop, n):
    """10.4: (jumps, longest_flat) of ``loss_fn`` sampled at n evenly spaced values from start to stop inclusive:
    how many of the n - 1 intervals change the value, and the widest run of intervals over which it stays
    exactly the same, in the parameter's units."""
    return _staircase(loss_fn, start, stop, n)


class _Landscape:
    """A loss of one number, a shift in pixels along ``direction``: the mean squared difference between the
    (hard or soft) triangle shifted and the hard triangle in place. Counts its calls."""

    def __init__(self, direction, hard=True):
        self.direction = torch.tensor(direction, dtype=torch.float64)
        self.hard, self.calls = hard, 0
        self.target = _triangle_image(torch.zeros(2, dtype=torch.float64), hard=True)

    def __call__(self, x):
        self.calls += 1
        pose = torch.as_tensor(x, dtype=torch.float64).reshape(()) * self.direction
        return ((_triangle_image(pose, hard=self.hard) - self.target) ** 2).mean()


def _staircase_problem(impl, loss_fn, start, stop, n, label, which) -> str | None:
    name = f"staircase({label})"
    out = impl(loss_fn, start, stop, n)
    if not (isinstance(out, (tuple, list)) and len(out) == 2):
        return f"{name}: return two numbers, (jumps, longest_flat)"
    if loss_fn.calls > n + 1:
        return f"{name}: the loss was evaluated {loss_fn.calls} times for {n} samples: evaluate it once per sample"
    jumps, flat = (float(v) if isinstance(v, (int, float)) else float(to_tensor(v, name).reshape(-1)[0])
                   for v in out)
    want_jumps, want_flat = _staircase(_Landscape(loss_fn.direction.tolist(), loss_fn.hard), start, stop, n)
    if which == "jumps":
        if jumps == want_jumps:
            return None
        shifted = _staircase(_Landscape(loss_fn.direction.tolist(), loss_fn.hard), start, stop, n, inclusive=False)
        if jumps == shifted[0]:
            return (f"{name}: {jumps:g} jumps, expected {want_jumps:g}: sample n values from start to stop, both "
                    "ends included (torch.linspace)")
        return (f"{name}: {jumps:g} jumps, expected {want_jumps:g}: count the intervals between neighbouring "
                "samples whose loss values differ (n samples have n - 1 intervals)")
    if abs(flat - want_flat) <= 1e-9 * (1 + abs(want_flat)):
        return None
    variants = [(_staircase(_Landscape(loss_fn.direction.tolist(), loss_fn.hard), start, stop, n, units=False)[1],
                 "that is the run counted in intervals: give it in the parameter's units (times the spacing)"),
                (_staircase(_Landscape(loss_fn.direction.tolist(), loss_fn.hard), start, stop, n, runs="samples")[1],
                 "a run of k + 1 equal samples spans k intervals: measure the width between its first and last "
                 "sample"),
                (_staircase(_Landscape(loss_fn.direction.tolist(), loss_fn.hard), start, stop, n, inclusive=False)[1],
                 "sample n values from start to stop, both ends included (torch.linspace)")]
    for value, why in variants:
        if abs(flat - value) <= 1e-9 * (1 + abs(value)):
            return f"{name}: longest flat run {flat:.6g}, expected {want_flat:.6g}: {why}"
    return f"{name}: longest flat run {flat:.6g}, expected {want_flat:.6g}"


@task("10.4", "staircase", points=2, reference=("course.grading.lecture10", "staircase_reference"))
def _check_staircase(impl):
    forbidden = forbidden_call(impl, "staircase", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def cases(which):
        def run():
            require(_staircase_problem(impl, _Landscape((1.0, 0.0)), 0.0, 2.0, 201, "a hard loss along x, 201 "
                                       "samples over 2 px", which))
            require(_staircase_problem(impl, _Landscape((0.6, 0.8)), -1.5, 1.5, 121, "a hard loss along a slant, "
                                       "121 samples", which))
            require(_staircase_problem(impl, _Landscape((1.0, 0.0), hard=False), 0.0, 1.0, 51, "a soft loss, 51 "
                                       "samples", which))
        return run
    return grade_parts((1, "the jumps", cases("jumps")),
                       (1, "the longest flat run", cases("flat")))
