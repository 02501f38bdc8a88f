"""The checks of lecture 11's graded tasks (style transfer and DeepDream): 11.1 gram_matrix, 11.2 style_loss,
11.3 random_directions, 11.4 deep_dream_step, 11.5 compare_runs (a design: how to judge two stylised meshes).

Each check runs the student's function next to a reference on fixed, seeded-random and stress inputs and
says what to fix, recognising the typical mistakes of the task. ``import course.grading`` imports this
module, which registers its checks in ``course.grading.TASKS``.

* 11.1, the Gram matrix of feature maps F (C, H, W) (or (1, C, H, W)): ``G = F Fᵀ / (H W)`` with F flattened to
  (C, H W): feature co-activations averaged over the positions (``course.style.gram_matrix``).
* 11.2, the style loss over layers: ``Σ_l ‖G_l - T_l‖²_F / ‖T_l‖²_F`` (``course.style.style_loss``).
* 11.3, views on the sphere: n unit vectors uniform on the sphere from a given generator
  (``course.style.transfer.random_directions``); graded by statistics: unit length, seeded, the heights z uniform
  on [-1, 1] (uniform angles crowd the poles), the azimuths uniform, no direction preferred.
* 11.4, one DeepDream step: ``x + step · g / mean |g|`` with g the gradient of the objective at x (ascent; the
  step normalised so its size does not depend on the gradient's scale), returned detached, x unchanged; where
  g is 0 everywhere (a flat objective) x comes back unchanged, not NaN.
* 11.5, judging two results (an analysis: the student designs it): which of two runs looks more stylish from a
  random direction, from n views drawn uniform on the sphere, with the difference's standard error and a
  verdict. What the task leaves to the student is the design: rendering both runs from the *same* views (the
  view-to-view variation, much larger than the difference, then cancels: a run compared with itself gives
  exactly 0), and the standard error that goes with that design (the spread of the paired differences / √n).
  Graded on the grader's own "runs" (render functions of the direction whose losses it knows) through the
  views the student's function actually asked for.

The references are written here, in float64; ``tests/test_grading_11.py`` checks that they agree with the
package. A graded function that calls them, or the package functions doing the task's work, scores 0.
"""
from __future__ import annotations

import math

import torch

from .helpers import Fail, _call, _match, compare, generator, grade_parts, require, to_tensor
from .registry import forbidden_call, task

__all__ = ["gram_matrix_reference", "style_loss_reference", "random_directions_reference",
           "deep_dream_step_reference", "compare_runs_reference"]

FORBIDDEN = [("course.style", "gram_matrix"), ("course.style", "style_loss"), ("course.style", "RandomFeatures"),
             ("course.style.transfer", "random_directions"), ("course.style.transfer", "deep_dream_mesh"),
             ("course.grading.lecture11", "gram_matrix_reference"),
             ("course.grading.lecture11", "style_loss_reference"),
             ("course.grading.lecture11", "random_directions_reference"),
             ("course.grading.lecture11", "deep_dream_step_reference"),
             ("course.grading.lecture11", "compare_runs_reference"),
             ("course.style.transfer", "held_out_style_loss")]


# ------------------------------------------------------------------------------------- the references

def gram_matrix_reference(features) -> torch.Tensor:
    """11.1: (C, C) ``F Fᵀ / (H W)`` of features (C, H, W) or (1, C, H, W)."""
    return _gram(features)


def style_loss_reference(grams, target_grams) -> torch.Tensor:
    """11.2: ``Σ_l ‖G_l - T_l‖² / ‖T_l‖²`` over the lists of (C_l, C_l) matrices."""
    return _style(grams, target_grams)


def random_directions_reference(n, gen) -> torch.Tensor:
    """11.3: (n, 3) float64 unit vectors uniform on the sphere, from the generator ``gen``."""
    return _directions(n, gen)


def deep_dream_step_reference(x, objective, step_size) -> torch.Tensor:
    """11.4: ``x + step_size · g / mean |g|``, g = ∇ objective(x), detached; x itself where g = 0."""
    return _dream(x, objective, step_size)


def compare_runs_reference(render_a, render_b, loss, n, gen):
    """11.5: (mean of the paired differences loss(render_a(d)) - loss(render_b(d)) over n directions uniform on
    the sphere drawn from gen, its standard error std / √n (n - 1 in the variance), "a", "b" or "none")."""
    return _compare(render_a, render_b, loss, n, gen)


def _gram(features, scale="hw"):
    f = features[0] if features.dim() == 4 else features
    f = f.reshape(f.shape[0], -1)
    g = f @ f.T
    if scale == "hw":
        return g / f.shape[1]
    if scale == "chw":
        return g / (f.shape[0] * f.shape[1])
    return g


def _style(grams, targets, relative=True, squared=True, reduce="sum"):
    terms = []
    for g, t in zip(grams, targets):
        d = ((g - t) ** 2).sum()
        d = d if squared else d.sqrt()
        if relative:
            d = d / ((t ** 2).sum() if squared else (t ** 2).sum().sqrt())
        terms.append(d)
    total = torch.stack(terms)
    return total.sum() if reduce == "sum" else total.mean()


def _directions(n, gen, kind="uniform"):
    u = torch.rand(n, 2, generator=gen, dtype=torch.float64)
    phi = 2 * math.pi * u[:, 1]
    if kind == "angles":                                                    # θ uniform: crowds the poles
        theta = math.pi * u[:, 0]
        z = torch.cos(theta)
    else:
        z = 2 * u[:, 0] - 1
    r = (1 - z * z).clamp_min(0).sqrt()
    return torch.stack([r * torch.cos(phi), r * torch.sin(phi), z], 1)


def _dream(x, objective, step_size, sign=1.0, norm="mean", guard=True):
    y = x.detach().clone().requires_grad_(True)
    (g,) = torch.autograd.grad(objective(y), y)
    if norm == "mean":
        scale = g.abs().mean()
        scale = torch.where(scale > 0, scale, torch.ones_like(scale)) if guard else scale   # g = 0: x unchanged
    elif norm == "l2":
        scale = g.norm()
        scale = torch.where(scale > 0, scale, torch.ones_like(scale))
    else:
        scale = torch.ones((), dtype=g.dtype)
    return (x.detach() + sign * step_size * g / scale).detach()


# ------------------------------------------------------------------------------------ 11.1 gram_matrix

def _features(seed, shape, dtype=torch.float64):
    return torch.relu(torch.randn(*shape, generator=generator(seed), dtype=torch.float64)).to(dtype)


def _gram_problem(impl, features, label):
    name = f"gram_matrix({label})"
    got = to_tensor(_call(impl, features), name)
    expected = _gram(features)
    low = features.dtype == torch.float32
    message = compare(got, expected, name=name, check_dtype=True, **({} if low else dict(atol=1e-12, rtol=1e-10)))
    if message is None or "dtype" in message:
        return message
    f = features[0] if features.dim() == 4 else features
    flat = f.reshape(f.shape[0], -1)
    explanation = _match(got, [
        (_gram(features, "none"), "not averaged: divide F Fᵀ by the number of positions H W, so that a small style "
                                  "image and a large render compare"),
        (_gram(features, "chw"), "divided by C H W: divide by the number of positions H W only"),
        (flat.T @ flat / flat.shape[1], "that is Fᵀ F, (H W, H W), position against position: the Gram matrix is "
                                        "F Fᵀ, (C, C), feature against feature"),
        (flat.T @ flat, "that is Fᵀ F, (H W, H W): the Gram matrix is F Fᵀ / (H W), (C, C)"),
    ])
    if explanation:
        return f"{name}: {explanation}"
    if features.dim() == 4 and "shape" in message:
        return f"{message} (a (1, C, H, W) input is one image: drop the batch dimension first)"
    return message


@task("11.1", "gram_matrix", points=2, reference=("course.style", "gram_matrix"))
def _check_gram_matrix(impl):
    forbidden = forbidden_call(impl, "gram_matrix", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def basic():
        require(_gram_problem(impl, _features(111, (8, 6, 5)), "8 features on 6 x 5, float64"))
        require(_gram_problem(impl, _features(112, (3, 16, 16)), "3 features on 16 x 16, float64"))

    def stress():
        require(_gram_problem(impl, _features(113, (1, 5, 7, 9)), "a batch of one (1, 5, 7, 9), float64"))
        require(_gram_problem(impl, _features(114, (4, 1, 1)), "one position, float64"))
        require(_gram_problem(impl, _features(115, (6, 12, 10), torch.float32), "float32"))
    return grade_parts((1, "feature maps (C, H, W)", basic), (1, "a batch of one, one position, float32", stress))


# ------------------------------------------------------------------------------------- 11.2 style_loss

def _grams(seed, sizes, dtype=torch.float64):
    out = []
    for k, c in enumerate(sizes):
        f = _features(seed + k, (c, 6, 6))
        out.append(_gram(f).to(dtype))
    return out


def _style_problem(impl, grams, targets, label):
    name = f"style_loss({label})"
    args = ([g.clone() for g in grams], [t.clone() for t in targets])
    got = to_tensor(impl(*args), name)
    expected = _style(grams, targets)
    low = grams[0].dtype == torch.float32
    message = compare(got, expected, name=name, check_dtype=True, **({} if low else dict(atol=1e-12, rtol=1e-10)))
    if message is None or "dtype" in message:
        return message
    f = lambda **kw: _style(grams, targets, **kw)                           # noqa: E731
    explanation = _match(got, [
        (f(relative=False), "each layer's error must be relative to its target, ‖G - T‖² / ‖T‖², so that a layer "
                            "with weak features counts as much as a strong one"),
        (f(squared=False), "that is ‖G - T‖ / ‖T‖ (norms): use the squared norms, ‖G - T‖² / ‖T‖²"),
        (f(reduce="mean"), "the mean over the layers: sum them"),
        (_style(grams[:1], targets[:1]), "only the first layer counts: sum over every layer of the lists"),
        (_style(grams[-1:], targets[-1:]), "only the last layer counts: sum over every layer of the lists"),
    ])
    return f"{name}: {explanation}" if explanation else message


def _style_gradient(impl):
    grams, targets = _grams(121, (4, 3)), _grams(131, (4, 3))
    leaves = [g.clone().requires_grad_(True) for g in grams]
    out = impl(leaves, [t.clone() for t in targets])
    if not (isinstance(out, torch.Tensor) and out.requires_grad):
        return ("style_loss: the value is right but no gradient reaches the Gram matrices: compute with tensor "
                "operations (no .item(), float() or numpy) and return the tensor")
    got = torch.autograd.grad(out, leaves, allow_unused=True)
    ref_leaves = [g.clone().requires_grad_(True) for g in grams]
    want = torch.autograd.grad(_style(ref_leaves, targets), ref_leaves)
    for k, (a, b) in enumerate(zip(got, want)):
        if a is None:
            return f"style_loss: no gradient reaches layer {k}: is it detached?"
        bad = compare(a, b, name=f"d style_loss / d grams[{k}]", atol=1e-10, rtol=1e-9)
        if bad:
            return bad
    return None


@task("11.2", "style_loss", points=2, reference=("course.style", "style_loss"))
def _check_style_loss(impl):
    forbidden = forbidden_call(impl, "style_loss", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def basic():
        require(_style_problem(impl, _grams(121, (4, 3, 5)), _grams(131, (4, 3, 5)), "3 layers, float64"))
        g = _grams(141, (6,))
        require(_style_problem(impl, g, [x.clone() for x in g], "one layer, a perfect match"))

    def stress():
        weak = [x * 1e-3 for x in _grams(151, (4,))] + _grams(152, (3,))
        require(_style_problem(impl, _grams(161, (4, 3)), weak, "a layer 1000x weaker than the other"))
        require(_style_problem(impl, _grams(171, (5, 2), torch.float32), _grams(181, (5, 2), torch.float32),
                               "float32"))
        require(_style_gradient(impl))
    return grade_parts((1, "layers summed, each relative", basic), (1, "weak layers, float32, the gradient", stress))


# ----------------------------------------------------------------------------- 11.3 random_directions

def _directions_problem(impl, n, seed):
    name = f"random_directions({n}, generator seeded {seed})"
    out = to_tensor(impl(n, generator(seed)), name)
    if tuple(out.shape) != (n, 3):
        return f"{name}: shape ({n}, 3) expected, got {tuple(out.shape)}", None
    if out.dtype != torch.float64:
        return f"{name}: dtype float64 expected, got {str(out.dtype).replace('torch.', '')}", None
    if not bool(torch.isfinite(out).all()):
        return f"{name}: NaN or inf in the directions", None
    length = out.norm(dim=1)
    if float((length - 1).abs().max()) > 1e-9:
        return (f"{name}: the directions must be unit vectors, got lengths from {float(length.min()):.4g} to "
                f"{float(length.max()):.4g}"), None
    return None, out


def _uniformity(d, name):
    """Statistics of directions uniform on the sphere, each with a bound 5 standard errors wide (n = 40000:
    a correct sampler fails one of them about once in a million runs): every coordinate's mean is 0 (variance
    1/3), the heights z = cos θ are uniform on [-1, 1] (Archimedes: the fraction above a height h is
    (1 - h) / 2), and so is the azimuth."""
    n = d.shape[0]
    se = lambda p: 5 * math.sqrt(p * (1 - p) / n)                           # noqa: E731
    z = d[:, 2]
    polar = float((z.abs() > 0.9).double().mean())                          # 10% of the sphere's area
    if abs(polar - 0.1) > se(0.1):
        crowd = "crowded" if polar > 0.1 else "empty"
        return (f"{name}: {100 * polar:.1f}% of the directions have |z| > 0.9 (the two caps that hold 10% of the "
                f"sphere's area): the poles are {crowd}. Uniform angles θ, φ are not uniform on the sphere: draw "
                "z = cos θ uniform in [-1, 1] (Archimedes: equal heights, equal areas) and φ uniform in [0, 2π)")
    for k, axis in enumerate("xyz"):
        mean = float(d[:, k].mean())
        if abs(mean) > 5 * math.sqrt(1 / 3 / n):
            return (f"{name}: the mean of {axis} is {mean:.3f}, not 0: some directions are preferred (is φ drawn in "
                    "[0, 2π) and z in [-1, 1]?)")
    for lo, hi in ((-1.0, -0.5), (-0.5, 0.0), (0.0, 0.5), (0.5, 1.0)):
        frac = float(((z >= lo) & (z < hi)).double().mean())
        if abs(frac - 0.25) > se(0.25):
            return f"{name}: {100 * frac:.1f}% of the heights z fall in [{lo}, {hi}), 25% expected: z must be uniform"
    phi = torch.atan2(d[:, 1], d[:, 0])
    for k in range(4):
        lo = -math.pi + k * math.pi / 2
        frac = float(((phi >= lo) & (phi < lo + math.pi / 2)).double().mean())
        if abs(frac - 0.25) > se(0.25):
            return (f"{name}: {100 * frac:.1f}% of the azimuths fall in one quarter turn, 25% expected: draw φ "
                    "uniform in [0, 2π)")
    return None


@task("11.3", "random_directions", points=3, reference=("course.style.transfer", "random_directions"))
def _check_random_directions(impl):
    forbidden = forbidden_call(impl, "random_directions", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def unit_and_seeded():
        message, a = _directions_problem(impl, 50, 301)
        require(message)
        _, b = _directions_problem(impl, 50, 301)
        if not torch.equal(a, b):
            require("random_directions: two calls with generators seeded alike gave different directions: draw "
                       "every random number from the generator argument (torch.rand(..., generator=gen))")
        _, c = _directions_problem(impl, 50, 302)
        if torch.equal(a, c):
            require("random_directions: generators seeded differently gave the same directions: use the "
                       "generator argument")
        message, one = _directions_problem(impl, 1, 303)
        require(message)

    def uniform():
        message, d = _directions_problem(impl, 40000, 311)
        require(message)
        require(_uniformity(d, "random_directions(40000)"))
    return grade_parts((1, "unit vectors, seeded", unit_and_seeded), (2, "uniform on the sphere", uniform))


# ------------------------------------------------------------------------------- 11.4 deep_dream_step

def _objectives():
    """(label, x, objective, step) problems with known gradients: a quadratic bowl turned upside down, a
    product, a ReLU'd response of an image to a filter (as DeepDream's)."""
    g = generator(401)
    x1 = torch.randn(5, dtype=torch.float64, generator=g)
    a = torch.randn(5, dtype=torch.float64, generator=g)
    x2 = torch.rand(6, 6, 3, dtype=torch.float64, generator=g)
    w = torch.randn(4, 3, 3, 3, dtype=torch.float64, generator=g)

    def response(img):
        f = torch.nn.functional.conv2d(img.permute(2, 0, 1)[None] - 0.5, w)
        return (torch.relu(f) ** 2).mean()
    return [("a quadratic, 5 entries", x1, lambda x: -((x - a) ** 2).sum() + 3.0 * (a * x).sum(), 0.1),
            ("a product x0 x1 x2 of 3 entries", torch.tensor([0.5, -2.0, 1.5], dtype=torch.float64),
             lambda x: x[0] * x[1] * x[2], 0.05),
            ("a filter response of a 6 x 6 x 3 image", x2, response, 0.02)]


def _dream_problem(impl, label, x, objective, step):
    name = f"deep_dream_step({label})"
    before = x.clone()
    raw = impl(x, objective, step)
    out = to_tensor(raw, name)
    if not torch.equal(x, before):
        return f"{name}: x was changed in place: return a new tensor and leave x as it was"
    if isinstance(raw, torch.Tensor) and raw.requires_grad:
        return (f"{name}: the result still requires grad: return it detached (x + ... computed under no_grad, or "
                ".detach())")
    expected = _dream(x, objective, step)
    if not bool(torch.isfinite(out).all()) and bool(torch.isfinite(expected).all()):
        y = x.detach().clone().requires_grad_(True)
        (g,) = torch.autograd.grad(objective(y), y)
        if not bool(g.any()):
            return (f"{name}: NaN in the result: g is 0 everywhere here (a flat objective), so mean |g| = 0 and "
                    "g / mean |g| is 0 / 0: where mean |g| is 0 there is no direction to climb, return x unchanged")
    message = compare(out, expected, name=name, check_dtype=True, atol=1e-12, rtol=1e-10)
    if message is None or "dtype" in message or "shape" in message:
        return message
    explanation = _match(out, [
        (_dream(x, objective, step, sign=-1.0), "that step goes down the objective: DeepDream climbs it (x + ..., "
                                                "gradient ascent)"),
        (_dream(x, objective, step, norm="none"), "the step is not normalised: divide the gradient by its mean "
                                                  "absolute value, so the step's size does not depend on its scale"),
        (_dream(x, objective, step, norm="l2"), "normalised by the gradient's norm: divide by its mean absolute "
                                                "value, mean |g|"),
        (_dream(x, objective, step, sign=-1.0, norm="none"), "that is a plain descent step: climb (+) and divide "
                                                             "the gradient by its mean absolute value"),
    ])
    return f"{name}: {explanation}" if explanation else message


@task("11.4", "deep_dream_step", points=3, reference=("course.grading.lecture11", "deep_dream_step_reference"))
def _check_deep_dream_step(impl):
    forbidden = forbidden_call(impl, "deep_dream_step", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    problems = _objectives()

    def simple():
        for label, x, objective, step in problems[:2]:
            require(_dream_problem(impl, label, x, objective, step))

    def image():
        label, x, objective, step = problems[2]
        require(_dream_problem(impl, label, x, objective, step))
        big = lambda y: 1e6 * objective(y)                                  # noqa: E731
        require(_dream_problem(impl, label + ", scaled by 1e6", x, big, step))

    def flat():
        x = torch.full((6, 6, 3), 0.5, dtype=torch.float64)                # grey: no zero-mean filter responds
        require(_dream_problem(impl, "a flat objective (g = 0 everywhere)", x, lambda y: 0.0 * y.sum() + 2.0, 0.05))
        _, x2, objective, step = problems[2]
        dead = lambda y: objective(y) * 0.0                                 # noqa: E731
        require(_dream_problem(impl, "a filter response times 0", x2, dead, step))
    return grade_parts((1, "simple objectives", simple), (1, "an image's filter response, any scale", image),
                       (1, "g = 0: x unchanged", flat))


# ------------------------------------------------------------------- 11.5 compare_runs (a design)

def _compare(render_a, render_b, loss, n, gen, paired=True, se="paired", ddof=1, sign=1.0, threshold=2.0,
             kind="uniform"):
    """The reference of 11.5 and, through its switches, the typical mistakes' answers."""
    d = _directions(n, gen, kind)
    la = torch.stack([torch.as_tensor(loss(render_a(x)), dtype=torch.float64).reshape(()) for x in d])
    d_b = d if paired else _directions(n, gen, kind)
    lb = torch.stack([torch.as_tensor(loss(render_b(x)), dtype=torch.float64).reshape(()) for x in d_b])
    diffs = la - lb
    mean = diffs.mean()
    if se == "paired":
        error = diffs.std(correction=ddof) / math.sqrt(n)
    elif se == "unpaired":
        error = (la.var(correction=ddof) / n + lb.var(correction=ddof) / n).sqrt()
    else:                                                                   # the spread, not its mean's
        error = diffs.std(correction=ddof)
    verdict = "none"
    if sign * float(mean) < -threshold * float(error):
        verdict = "a"
    elif sign * float(mean) > threshold * float(error):
        verdict = "b"
    return mean.detach(), error.detach(), verdict


class _Run:
    """A grader's stand-in for a stylised mesh seen from direction d: ``render(d)`` returns a small "image"
    (4, 4, 3) whose mean is the loss this run has from d, and records every direction asked for."""

    def __init__(self, value):
        self.value, self.calls = value, []

    def __call__(self, d):
        d = torch.as_tensor(d, dtype=torch.float64).detach().reshape(-1)
        if d.numel() != 3:
            raise Fail(f"compare_runs: render takes one direction (3,), it was given shape {tuple(d.shape)}")
        self.calls.append(d.clone())
        return torch.full((4, 4, 3), float(self.value(d)), dtype=torch.float64)


def _image_loss(image):
    return torch.as_tensor(image, dtype=torch.float64).mean()


def _common(d):                                             # what every view of both runs shares: large
    return 5.0 + 1.5 * d[2] + math.sin(3.0 * float(d[0])) + 0.8 * float(d[1]) ** 2


def _runs(gap=0.04):
    """Two runs whose losses share a large view-to-view variation and differ by a small, smooth amount: run a
    lower by ``gap`` on average (measurable only when both are rendered from the same views)."""
    return (_Run(lambda d: _common(d) - gap + 0.05 * float(d[1])), _Run(lambda d: _common(d)))


def _compare_call(impl, render_a, render_b, n, seed, label):
    name = f"compare_runs({label}, n = {n})"
    out = impl(render_a, render_b, _image_loss, n, generator(seed))
    if not isinstance(out, (tuple, list)) or len(out) != 3:
        raise Fail(f"{name}: return a tuple (difference, standard_error, verdict), got "
                   f"{type(out).__name__ if not isinstance(out, (tuple, list)) else f'{len(out)} values'}")
    diff, error, verdict = out
    values = []
    for value, what in ((diff, "difference"), (error, "standard_error")):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = torch.tensor(float(value), dtype=torch.float64)        # a plain number is fine too
        t = to_tensor(value, f"{name} {what}").to(torch.float64)
        if t.numel() != 1:
            raise Fail(f"{name}: {what} must be one number, got shape {tuple(t.shape)}")
        values.append(float(t.reshape(())))
    if verdict not in ("a", "b", "none"):
        raise Fail(f"{name}: the verdict must be \"a\", \"b\" or \"none\", got {verdict!r}")
    for run, who in ((render_a, "render_a"), (render_b, "render_b")):
        if len(run.calls) != n:
            raise Fail(f"{name}: {who} was called {len(run.calls)} times: render each run once from each of the n "
                       "views")
        length = torch.stack(run.calls).norm(dim=1)
        if float((length - 1).abs().max()) > 1e-9:
            raise Fail(f"{name}: the directions must be unit vectors, got lengths from {float(length.min()):.4g} "
                       f"to {float(length.max()):.4g}")
    return name, values[0], values[1], verdict


def _losses(run):
    return torch.tensor([float(run.value(d)) for d in run.calls], dtype=torch.float64)


@task("11.5", "compare_runs", points=5, reference=("course.grading.lecture11", "compare_runs_reference"))
def _check_compare_runs(impl):
    forbidden = forbidden_call(impl, "compare_runs", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def views():
        a, b = _runs()
        _compare_call(impl, a, b, 40, 501, "two runs")
        a2, b2 = _runs()
        _compare_call(impl, a2, b2, 40, 501, "two runs")
        if not torch.equal(torch.stack(a.calls), torch.stack(a2.calls)):
            require("compare_runs: two calls with generators seeded alike asked for different views: draw every "
                    "random number from the generator argument")
        a3, b3 = _runs()
        _compare_call(impl, a3, b3, 40, 502, "two runs")
        if torch.equal(torch.stack(a.calls), torch.stack(a3.calls)):
            require("compare_runs: generators seeded differently gave the same views: use the generator argument")
        a4, b4 = _runs()
        _compare_call(impl, a4, b4, 2000, 503, "two runs")
        require(_uniformity(torch.stack(a4.calls), "compare_runs(n = 2000): the views of run a"))

    def itself():
        run = _Run(lambda d: _common(d))
        same = _Run(lambda d: _common(d))
        name, diff, error, verdict = _compare_call(impl, run, same, 50, 511, "a run against an identical copy")
        if diff != 0.0 or error != 0.0 or verdict != "none":
            different = not torch.equal(torch.stack(run.calls), torch.stack(same.calls))
            why = (" The two runs were rendered from different views, so the difference carries the views' own "
                   "variation (here it is all there is). Render both runs from the same n views: that "
                   "variation then cancels in each view's difference.") if different else ""
            require(f"{name}: a run compared with an identical copy must give difference 0, standard error 0 and "
                    f"\"none\", got {diff:.4g}, {error:.4g}, {verdict!r}.{why}")

    def difference():
        a, b = _runs()
        name, diff, _, _ = _compare_call(impl, a, b, 60, 521, "two runs")
        if not torch.equal(torch.stack(a.calls), torch.stack(b.calls)):
            require(f"{name}: run a and run b were rendered from different views: the difference of two means "
                    "over different views carries the views' variation, about 5 times the gap it is after here; "
                    "render both from the same views and average the differences")
        la, lb = _losses(a), _losses(b)
        want = float(la.mean() - lb.mean())
        if abs(diff - want) > 1e-9 * max(1.0, abs(want)):
            if abs(diff + want) <= 1e-9 * max(1.0, abs(want)):
                require(f"{name}: the difference is b - a: return loss(a) - loss(b) (negative when a is more "
                        "stylish)")
            require(f"{name}: the difference must be the mean over your views of loss(render_a(d)) - "
                    f"loss(render_b(d)): {want:.6g} from the views you asked for, got {diff:.6g}")

    def standard_error():
        a, b = _runs()
        name, _, error, _ = _compare_call(impl, a, b, 60, 531, "two runs")
        la, lb = _losses(a), _losses(b)
        paired = [float((la - lb).std(correction=c)) / math.sqrt(60) for c in (1, 0)]
        if any(abs(error - p) <= 1e-9 * max(1.0, p) for p in paired):
            return
        unpaired = [float((la.var(correction=c) / 60 + lb.var(correction=c) / 60).sqrt()) for c in (1, 0)]
        spread = [float((la - lb).std(correction=c)) for c in (1, 0)]
        if any(abs(error - u) <= 1e-9 * max(1.0, u) for u in unpaired):
            require(f"{name}: {error:.4g} is the standard error of two independent means, √(var a / n + var b / n): "
                    "the views are shared, so the errors are not independent; the standard error of the mean of "
                    f"the n paired differences is their standard deviation / √n, here {paired[0]:.4g}")
        if any(abs(error - s) <= 1e-9 * max(1.0, s) for s in spread):
            require(f"{name}: {error:.4g} is the spread of the differences, not the standard error of their mean: "
                    "divide by √n")
        require(f"{name}: the standard error of the mean of the n paired differences is their standard deviation "
                f"/ √n: {paired[0]:.4g} from the views you asked for, got {error:.4g}")

    def verdict():
        for gap, n, seed in ((0.04, 60, 541), (-0.04, 60, 542), (0.004, 30, 543), (0.0, 30, 544)):
            a, b = _runs(gap)
            name, diff, error, said = _compare_call(impl, a, b, n, seed, f"run a lower by {gap:g} on average")
            want = "a" if diff < -2 * error else "b" if diff > 2 * error else "none"
            if said != want:
                flipped = "b" if want == "a" else "a" if want == "b" else None
                hint = (" (the verdict names the run with the LOWER loss: the more stylish)" if said == flipped
                        else "")
                require(f"{name}: difference {diff:.4g} and standard error {error:.4g} call for {want!r} (a measurable "
                        f"difference is more than 2 standard errors), got {said!r}{hint}")

    return grade_parts((1, "n unit views from the generator, uniform on the sphere", views),
                       (1, "a run against itself", itself), (1, "the difference", difference),
                       (1, "its standard error", standard_error), (1, "the verdict", verdict))
