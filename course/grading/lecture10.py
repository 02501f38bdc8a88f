"""The checks of lecture 10's graded tasks (inverse rendering): 10.1 silhouette_iou_loss, 10.2 smoothness_loss,
10.3 gradient_step.

Each check runs the student's function next to a reference on fixed, seeded-random and stress inputs and
says what to fix, recognising the typical mistakes of the task. ``import course.grading`` imports this
module, which registers its checks in ``course.grading.TASKS``.

The three tasks are the pieces of every fit in lecture 10 (Kato, Ushiku and Harada, CVPR 2018):

* 10.1, the silhouette loss: per view, ``1 - |ŝ ⊙ s|₁ / |ŝ + s - ŝ ⊙ s|₁`` (one minus the soft IoU of the
  rendered silhouette ŝ and the target s), summed over the views; a view whose union is empty is a perfect
  match and scores 0 (never 0 / 0).
* 10.2, the smoothness loss: ``Σ (1 - n₁·n₂)²`` over the interior edges (shared by exactly two faces, found by
  vertex index), n₁, n₂ the unit normals of the edge's two faces (a zero-area face has the normal 0).
* 10.3, one step of gradient descent: clear the parameters' old gradients, evaluate the loss, backpropagate,
  and move every parameter by ``-lr × its gradient`` in place, outside the autograd graph; return the loss
  of the parameters before the step.

The references are written here from these formulas, in float64; ``tests/test_grading_10.py`` checks that
they agree with ``course.losses.silhouette_iou_loss`` and ``course.losses.smoothness_loss`` (and the step with
``torch.optim.SGD``). They are public so that those tests (and a curious student) can read them; a graded
function that calls them, or the package functions doing the task's work, scores 0.
"""
from __future__ import annotations

import types

import torch

from .helpers import _close, compare, generator, grade_parts, require, summarize_exception, to_tensor
from .registry import _code_names, forbidden_call, task

__all__ = ["silhouette_iou_loss_reference", "smoothness_loss_reference", "gradient_step_reference"]

FORBIDDEN = [("course.losses", "silhouette_iou_loss"), ("course.losses", "smoothness_loss"),
             ("course.losses", "interior_edges"), ("course.fit", "fit_silhouettes"),
             ("course.grading.lecture10", "silhouette_iou_loss_reference"),
             ("course.grading.lecture10", "smoothness_loss_reference"),
             ("course.grading.lecture10", "gradient_step_reference")]


# ------------------------------------------------------------------------------------- the references

def silhouette_iou_loss_reference(pred, target) -> torch.Tensor:
    """10.1: ``Σ_views 1 - |ŝ ⊙ s|₁ / |ŝ + s - ŝ ⊙ s|₁``, a scalar in pred's dtype; pred, target (H, W) or
    (N, H, W) in [0, 1]; an empty union gives 0. Differentiable in pred."""
    return _iou_loss(pred, target)


def smoothness_loss_reference(verts, faces) -> torch.Tensor:
    """10.2: ``Σ (1 - n₁·n₂)²`` over the interior edges of the mesh, a scalar in verts' dtype; verts (V, 3),
    faces (F, 3) int64. Differentiable in verts."""
    return _smoothness(verts, faces)


def gradient_step_reference(params, loss_fn, lr):
    """10.3: one step of gradient descent on the leaf tensors ``params`` (a list), in place; returns the loss
    (a detached scalar tensor) before the step."""
    return _step(params, loss_fn, lr)


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


@task("10.1", "silhouette_iou_loss", points=3, reference=("course.losses", "silhouette_iou_loss"))
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
    return grade_parts((1, "one view", one_view),
                       (1, "several views", views),
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


@task("10.2", "smoothness_loss", points=3, reference=("course.losses", "smoothness_loss"))
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


# ------------------------------------------------------------------------------ 10.3 one gradient step

def _step(params, loss_fn, lr, *, zero=True, sign=-1.0):
    """10.3 and its typical mistakes: ``zero`` (clear old gradients first), ``sign`` (-1: descend)."""
    if zero:
        for p in params:
            p.grad = None
    loss = loss_fn()
    loss.backward()
    with torch.no_grad():
        for p in params:
            if p.grad is not None:
                p.add_(p.grad, alpha=sign * lr)
    return loss.detach()


def _uses_torch_optim(impl) -> bool:
    """True when the student's code names ``optim`` (``torch.optim.SGD`` ...): an optimiser does the task."""
    code = getattr(impl, "__code__", None)
    if not isinstance(code, types.CodeType):
        return False
    names = _code_names(code)
    return bool(names & {"optim", "SGD", "Adam", "Optimizer"})


def _quadratic(seed, n=3, dtype=torch.float64):
    """A least-squares loss ``|A x - b|²`` of a parameter x (n,), and the start x0."""
    g = generator(seed)
    A = torch.randn(n + 2, n, generator=g, dtype=torch.float64).to(dtype)
    b = torch.randn(n + 2, generator=g, dtype=torch.float64).to(dtype)
    x0 = torch.randn(n, generator=g, dtype=torch.float64).to(dtype)
    return (lambda x: ((A @ x - b) ** 2).sum()), x0


def _layer(seed, dtype=torch.float64):
    """A tiny model with two parameters, W (2, 3) and c (2,): the loss ``Σ (tanh(W u + c) - y)²``."""
    g = generator(seed)
    u = torch.randn(5, 3, generator=g, dtype=torch.float64).to(dtype)
    y = torch.rand(5, 2, generator=g, dtype=torch.float64).to(dtype)
    W0 = torch.randn(2, 3, generator=g, dtype=torch.float64).to(dtype)
    c0 = torch.randn(2, generator=g, dtype=torch.float64).to(dtype)
    return (lambda W, c: ((torch.tanh(u @ W.T + c) - y) ** 2).sum()), [W0, c0]


def _run_steps(fn, f, starts, lr, steps, stale=None):
    """Run ``fn(params, loss_fn, lr)`` ``steps`` times on fresh leaves made from ``starts``; returns the params
    list as given (the same objects), the losses returned, and the exception (if any)."""
    params = [s.clone().requires_grad_(True) for s in starts]
    if stale is not None:
        for p, s in zip(params, stale):
            p.grad = s.clone()
    losses = []
    for _ in range(steps):
        losses.append(fn(params, lambda: f(*params), lr))
    return params, losses


def _step_problem(impl, f, starts, lr, steps, label, stale=None) -> str | None:
    name = f"gradient_step({label})"
    listed = [s.clone().requires_grad_(True) for s in starts]
    if stale is not None:
        for p, s in zip(listed, stale):
            p.grad = s.clone()
    objects = list(listed)
    got_losses = []
    try:
        for _ in range(steps):
            got_losses.append(impl(listed, lambda: f(*listed), lr))
    except RuntimeError as exc:
        text = str(exc)
        if "leaf Variable" in text or "in-place" in text:
            return (f"{name}: {summarize_exception(exc)}: an in-place update of a parameter is recorded by "
                    "autograd unless it runs under `with torch.no_grad():`")
        raise
    ref_params, ref_losses = _run_steps(_step, f, starts, lr, steps, stale)
    for k, (p, q) in enumerate(zip(listed, objects)):
        if p is not q:
            return (f"{name}: params[{k}] was replaced by a new tensor: update the parameters in place "
                    "(p -= lr * p.grad under torch.no_grad()), so that the caller's tensors (and an optimiser's "
                    "references to them) see the step")
        if not p.is_leaf or p.grad_fn is not None:
            return (f"{name}: params[{k}] is no longer a leaf: the update was recorded in the graph; do it under "
                    "torch.no_grad()")
        if not p.requires_grad:
            return f"{name}: params[{k}] no longer requires a gradient: keep requires_grad=True for the next step"
    if all(torch.equal(p.detach(), s) for p, s in zip(listed, starts)):
        return (f"{name}: the parameters did not change: move each one by -lr × its gradient, in place "
                "(p -= lr * p.grad under torch.no_grad())")
    for k, (p, q) in enumerate(zip(listed, ref_params)):
        low = p.dtype == torch.float32
        message = compare(p.detach(), q.detach(), name=f"{name}: params[{k}] after {steps} step(s)", check_dtype=True,
                          **({} if low else dict(atol=1e-10, rtol=1e-10)))
        if message is None:
            continue
        if "shape" in message or "dtype" in message:
            return message
        up, _ = _run_steps(lambda *a: _step(*a, sign=1.0), f, starts, lr, steps, stale)
        if _close(p.detach(), up[k].detach(), 1e-8):
            return f"{name}: the step went uphill: move against the gradient, p - lr × grad"
        stale_run, _ = _run_steps(lambda *a: _step(*a, zero=False), f, starts, lr, steps, stale)
        if _close(p.detach(), stale_run[k].detach(), 1e-8):
            return (f"{name}: the gradients were not cleared: backward() adds to .grad, so the old gradient was "
                    "added to this step's; set p.grad = None (or zero it) before backward()")
        return message
    for k, (got, want) in enumerate(zip(got_losses, ref_losses)):
        value = torch.tensor(float(got), dtype=torch.float64) if isinstance(got, (int, float)) else to_tensor(got, f"{name}: the returned loss")
        if value.numel() != 1:
            return f"{name}: return the loss, one number, got shape {tuple(value.shape)}"
        if abs(float(value) - float(want)) > 1e-9 * (1 + abs(float(want))):
            after = float(f(*[p.detach() for p in ref_params])) if k == steps - 1 else None
            if after is not None and abs(float(value) - after) <= 1e-9 * (1 + abs(after)):
                return f"{name}: the returned loss is the one after the step: return the loss before it (the one you backpropagated)"
            return (f"{name}: step {k}: returned loss {float(value):.6g}, expected {float(want):.6g} (the loss "
                    "before the step)")
        if isinstance(got, torch.Tensor) and got.requires_grad:
            return f"{name}: the returned loss still holds the graph: return loss.detach() (or float(loss))"
    return None


@task("10.3", "gradient_step", points=3, reference=("torch.optim.sgd", "SGD"))   # one SGD step (no momentum)
def _check_gradient_step(impl):
    forbidden = forbidden_call(impl, "gradient_step", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    if _uses_torch_optim(impl):
        return 0, ("gradient_step uses torch.optim, which does this task's work for you: write the update "
                   "yourself (p -= lr * p.grad under torch.no_grad())")

    def one_step():
        f, x0 = _quadratic(121)
        require(_step_problem(impl, f, [x0], 0.05, 1, "one step on |A x - b|², float64"))
        f, x0 = _quadratic(122, n=1)
        require(_step_problem(impl, f, [x0], 0.2, 1, "one parameter, float64"))

    def several():
        f, starts = _layer(123)
        require(_step_problem(impl, f, starts, 0.1, 4, "4 steps on two parameters, float64"))
        f, x0 = _quadratic(124)
        require(_step_problem(impl, f, [x0], 0.02, 3, "3 steps, float64"))

    def stress():
        f, x0 = _quadratic(125)
        require(_step_problem(impl, f, [x0], 0.05, 1, "a stale gradient left in .grad, float64",
                              stale=[torch.full_like(x0, 7.0)]))
        f, starts = _layer(126, torch.float32)
        require(_step_problem(impl, f, starts, 0.1, 2, "float32"))
    return grade_parts((1, "one step", one_step),
                       (1, "several steps, two parameters", several),
                       (1, "a stale gradient, float32", stress))
