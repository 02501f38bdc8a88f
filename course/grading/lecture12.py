"""The checks of lecture 12's graded tasks (differentiable shadows): 12.1 project_onto_plane,
12.2 shadow_velocity, 12.3 variance_lit, 12.4 light_step, 12.5 tight_distribution.

Each check runs the student's function next to a reference on fixed, seeded-random and stress inputs and
says what to fix, recognising the typical mistakes of the task. ``import course.grading`` imports this
module, which registers its checks in ``course.grading.TASKS``.

* 12.1, the shadow of points on a plane under a directional light: ``x' = x - h / (n̂ · l) · l`` with
  ``h = n̂ · (x - p)`` the height above the plane (``course.shadows.gradients.project_onto_plane``).
* 12.2, how fast those shadows move when the light turns: the derivative of 12.1 along ``dl``,
  ``v = -h / (n̂ · l) · dl + h (n̂ · dl) / (n̂ · l)² · l`` (both the step's direction and its length change).
* 12.3, a variance shadow map's test: with the moments μ = E[z], m₂ = E[z²] at a receiver of depth d,
  ``σ² = max(m₂ - μ², min_variance)`` and the fraction lit ``σ² / (σ² + (d - μ)²)`` where d > μ, 1 elsewhere
  (the one-sided Chebyshev (Cantelli) inequality: an *upper* bound on the true lit fraction P(z ≥ d), which
  the map uses as its estimate; ``course.shadows.prefiltered.variance_visibility`` after its map lookup).
* 12.4, one step of the light fit on the sphere of directions: the gradient's part along the light is
  dropped (it would only change the length), the step taken, the result renormalised:
  ``normalize(l - lr (g - (g · l) l))``.
* 12.5, an analysis: where the map's estimate is exact. Given μ, σ² and a receiver at d > μ, a depth
  distribution with those two moments whose true lit fraction P(z ≥ d) equals the bound. It is unique: weight
  p = σ² / (σ² + t²) at the receiver's own depth d = μ + t and 1 - p at the occluder's depth μ - σ² / t (one
  planar occluder over the receiver, Donnelly and Lauritzen's exact case). The check grades the properties
  (a distribution, its mean, its variance, its lit fraction), so it names what is off, and recognises the
  answers of the typical mistakes (μ ± σ, the weights swapped, the occluder at μ - σ, a bound with σ).

The references are written here, in float64; ``tests/test_grading_12.py`` checks that they agree with the
package. A graded function that calls them, or the package functions doing the task's work, scores 0.
"""
from __future__ import annotations

import torch

from .helpers import _call, _match, _unpack, compare, generator, grade_parts, require, to_tensor
from .registry import forbidden_call, task

__all__ = ["project_onto_plane_reference", "shadow_velocity_reference", "variance_lit_reference",
           "light_step_reference", "tight_distribution_reference"]

FORBIDDEN = [("course.shadows.gradients", "project_onto_plane"), ("course.shadows.gradients", "split_by_shadows"),
             ("course.shadows.prefiltered", "variance_visibility"), ("course.shadows.fit", "fit_light_direction"),
             ("course.grading.lecture12", "project_onto_plane_reference"),
             ("course.grading.lecture12", "shadow_velocity_reference"),
             ("course.grading.lecture12", "variance_lit_reference"),
             ("course.grading.lecture12", "light_step_reference"),
             ("course.grading.lecture12", "tight_distribution_reference")]


# ------------------------------------------------------------------------------------- the references

def project_onto_plane_reference(points, plane_point, plane_normal, light) -> torch.Tensor:
    """12.1: (N, 3) the points slid along ``light`` onto the plane through ``plane_point`` with ``plane_normal``."""
    return _project(points, plane_point, plane_normal, light)


def shadow_velocity_reference(points, plane_point, plane_normal, light, dlight) -> torch.Tensor:
    """12.2: (N, 3) d/dε of 12.1 with the light ``light + ε dlight``, at ε = 0."""
    return _velocity(points, plane_point, plane_normal, light, dlight)


def variance_lit_reference(mu, m2, depth, min_variance=1e-6) -> torch.Tensor:
    """12.3: the variance shadow map's lit fraction, Chebyshev's (Cantelli's) upper bound, elementwise."""
    return _lit(mu, m2, depth, min_variance)


def light_step_reference(light, grad, lr) -> torch.Tensor:
    """12.4: (3,) ``normalize(l - lr (g - (g · l) l))``."""
    return _step(light, grad, lr)


def tight_distribution_reference(mu, var, depth):
    """12.5: (depths (..., 2), weights (..., 2)): the two-point depth distribution with mean ``mu``, variance
    ``var`` whose lit fraction at ``depth`` > ``mu`` is Cantelli's bound: the occluder first, the receiver second."""
    return _tight(mu, var, depth)


def _project(x, p, n, l, kind="light"):
    n_hat = n / n.norm()
    h = (x - p) @ n_hat
    if kind == "no_point":                                                  # the height of x above the origin
        h = x @ n_hat
    if kind == "orthogonal":                                                # dropped straight onto the plane
        return x - h[:, None] * n_hat
    if kind == "sign":
        return x + (h / (n_hat @ l))[:, None] * l
    return x - (h / (n_hat @ l))[:, None] * l


def _velocity(x, p, n, l, dl, kind="full"):
    n_hat = n / n.norm()
    h = (x - p) @ n_hat
    cos, dcos = n_hat @ l, n_hat @ dl
    first = -(h / cos)[:, None] * dl                                        # the step's direction turns
    second = (h * dcos / cos ** 2)[:, None] * l                             # and its length changes
    if kind == "direction_only":
        return first
    if kind == "length_only":
        return second
    if kind == "sign":
        return -(first + second)
    return first + second


def _lit(mu, m2, d, min_variance, kind="full"):
    var = m2 if kind == "no_mean" else m2 - mu * mu
    if kind != "no_clamp":
        var = var.clamp_min(min_variance)
    gap = d - mu
    if kind == "std":
        s = var.sqrt()
        p = s / (s + gap.abs())
    else:
        p = var / (var + gap * gap)
    if kind == "both_sides":
        return p
    return torch.where(d > mu, p, torch.ones_like(p))


def _step(l, g, lr, kind="full"):
    tangent = g - (g @ l) * l
    if kind == "no_projection":
        tangent = g
    if kind == "ascent":
        out = l + lr * tangent
    else:
        out = l - lr * tangent
    if kind == "no_normalize":
        return out
    return out / out.norm()


def _tight(mu, var, d, kind="full"):
    """(depths (..., 2), weights (..., 2)), the occluder's first; ``kind`` gives a typical mistake's answer."""
    t = d - mu
    p = var / (var + t * t)                                                 # Cantelli's bound
    occluder = mu - var / t                                                 # p d + (1 - p) z_o = μ
    if kind == "symmetric":                                                 # two depths, one σ either side
        s = var.sqrt()
        return torch.stack([mu - s, mu + s], -1), torch.full(mu.shape + (2,), 0.5, dtype=mu.dtype)
    if kind == "swapped":
        return torch.stack([occluder, d], -1), torch.stack([p, 1 - p], -1)
    if kind == "sigma":                                                     # the occluder one σ in front
        occluder = mu - var.sqrt()
    if kind == "std":                                                       # a bound written with σ, not σ²
        s = var.sqrt()
        p = s / (s + t)
        occluder = mu - p * t / (1 - p)
    return torch.stack([occluder, d], -1), torch.stack([1 - p, p], -1)


def _unit(v):
    return v / v.norm()


# ---------------------------------------------------------------------------- 12.1 project_onto_plane

def _planes():
    """(label, points, plane_point, plane_normal, light) cases: the floor, a tilted wall with a long normal,
    a light that is not a unit vector, points below the plane."""
    g = generator(1201)
    pts = torch.rand(6, 3, generator=g, dtype=torch.float64) * 2 + torch.tensor([-1.0, 0.5, -1.0],
                                                                               dtype=torch.float64)
    wall = torch.randn(5, 3, generator=g, dtype=torch.float64)
    return [("the floor y = 0, light (0.3, -1, 0.2)", pts, torch.zeros(3, dtype=torch.float64),
             torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64), torch.tensor([0.3, -1.0, 0.2], dtype=torch.float64)),
            ("a tilted plane through (1, 2, -1), normal (2, 4, 1) (not unit), light of length 3", wall,
             torch.tensor([1.0, 2.0, -1.0], dtype=torch.float64), torch.tensor([2.0, 4.0, 1.0], dtype=torch.float64),
             3 * _unit(torch.tensor([-0.4, -1.0, 0.3], dtype=torch.float64))),
            ("the floor y = 0.5, points above and below it", pts - torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64),
             torch.tensor([0.0, 0.5, 0.0], dtype=torch.float64), torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64),
             torch.tensor([0.5, -1.0, 0.0], dtype=torch.float64))]


def _project_problem(impl, label, x, p, n, l):
    name = f"project_onto_plane({label})"
    got = to_tensor(_call(impl, x, p, n, l), name)
    expected = _project(x, p, n, l)
    low = x.dtype == torch.float32
    message = compare(got, expected, name=name, check_dtype=True, **({} if low else dict(atol=1e-12, rtol=1e-10)))
    if message is None or "dtype" in message or "shape" in message:
        return message
    explanation = _match(got, [
        (_project(x, p, n, l, "sign"), "the points moved toward the light: slide them *along* the light, "
                                       "x - h / (n̂ · l) · l (n̂ · l < 0 when the light comes down on the plane)"),
        (_project(x, p, n, l, "orthogonal"), "the points were dropped straight down the normal: a shadow slides "
                                             "along the light's direction l, by h / (n̂ · l)"),
        (_project(x, p, n, l, "no_point"), "the height ignores plane_point: h = n̂ · (x - p), the distance above the "
                                           "plane through p"),
    ])
    if explanation:
        return f"{name}: {explanation}"
    on_plane = ((got - p) @ _unit(n)).abs().max()
    if float(on_plane) > 1e-6:
        return f"{message} (the results are not on the plane: n̂ · (x' - p) reaches {float(on_plane):.3g})"
    return message


@task("12.1", "project_onto_plane", points=2, reference=("course.shadows.gradients", "project_onto_plane"))
def _check_project(impl):
    forbidden = forbidden_call(impl, "project_onto_plane", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    cases = _planes()

    def floor():
        require(_project_problem(impl, *cases[0]))

    def stress():
        require(_project_problem(impl, *cases[1]))
        require(_project_problem(impl, *cases[2]))
        label, x, p, n, l = cases[0]
        require(_project_problem(impl, label + ", float32", x.float(), p.float(), n.float(), l.float()))
    return grade_parts((1, "the floor", floor), (1, "a tilted plane, long vectors, points below, float32", stress))


# ------------------------------------------------------------------------------- 12.2 shadow_velocity

def _velocity_cases():
    g = generator(1221)
    up = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)
    zero = torch.zeros(3, dtype=torch.float64)
    edge = torch.tensor([[-0.5, 0.8, -0.3], [0.6, 0.9, 0.1]], dtype=torch.float64)
    pts = torch.randn(5, 3, generator=g, dtype=torch.float64)
    return [("an occluder edge above the floor, the light tilting in x", edge, zero, up,
             torch.tensor([0.3, -1.0, 0.2], dtype=torch.float64), torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64)),
            ("the floor, the light steepening (dl along l's own vertical)", edge, zero, up,
             torch.tensor([0.3, -1.0, 0.2], dtype=torch.float64), torch.tensor([0.0, -1.0, 0.0], dtype=torch.float64)),
            ("a tilted plane, normal (2, 4, 1), a random turn of the light", pts,
             torch.tensor([1.0, 2.0, -1.0], dtype=torch.float64), torch.tensor([2.0, 4.0, 1.0], dtype=torch.float64),
             torch.tensor([-0.4, -1.0, 0.3], dtype=torch.float64), torch.randn(3, generator=g, dtype=torch.float64))]


def _velocity_problem(impl, label, x, p, n, l, dl):
    name = f"shadow_velocity({label})"
    got = to_tensor(_call(impl, x, p, n, l, dl), name)
    expected = _velocity(x, p, n, l, dl)
    low = x.dtype == torch.float32
    message = compare(got, expected, name=name, check_dtype=True, **({} if low else dict(atol=1e-12, rtol=1e-10)))
    if message is None or "dtype" in message or "shape" in message:
        return message
    explanation = _match(got, [
        (_velocity(x, p, n, l, dl, "direction_only"), "only -h / (n̂ · l) · dl: the slide's length h / (n̂ · l) "
                                                      "changes too when n̂ · l does, add h (n̂ · dl) / (n̂ · l)² · l"),
        (_velocity(x, p, n, l, dl, "length_only"), "only the change of the slide's length: the direction l turns "
                                                   "too, add -h / (n̂ · l) · dl"),
        (_velocity(x, p, n, l, dl, "sign"), "the velocity has the wrong sign: differentiate x - h / (n̂ · l) · l"),
    ])
    if explanation:
        return f"{name}: {explanation}"
    drift = (got @ _unit(n)).abs().max()
    if float(drift) > 1e-6:
        return (f"{message} (a shadow stays on its plane, so its velocity is parallel to the plane: n̂ · v reaches "
                f"{float(drift):.3g})")
    return message


@task("12.2", "shadow_velocity", points=3, reference=("course.grading.lecture12", "shadow_velocity_reference"))
def _check_velocity(impl):
    forbidden = forbidden_call(impl, "shadow_velocity", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    cases = _velocity_cases()

    def tilt():
        require(_velocity_problem(impl, *cases[0]))

    def steeper():
        require(_velocity_problem(impl, *cases[1]))

    def general():
        require(_velocity_problem(impl, *cases[2]))
        label, x, p, n, l, dl = cases[0]
        require(_velocity_problem(impl, label + ", float32", x.float(), p.float(), n.float(), l.float(), dl.float()))
    return grade_parts((1, "the light tilting sideways", tilt), (1, "the light steepening", steeper),
                       (1, "a tilted plane, float32", general))


# --------------------------------------------------------------------------------- 12.3 variance_lit

def _moments(seed, n, dtype=torch.float64):
    """Moments of depth distributions (mean in [1, 3], spread up to 0.3) and receivers in front of, at and
    behind them."""
    g = generator(seed)
    mu = 1 + 2 * torch.rand(n, generator=g, dtype=torch.float64)
    var = 0.3 * torch.rand(n, generator=g, dtype=torch.float64) ** 2
    d = mu + torch.randn(n, generator=g, dtype=torch.float64)
    return mu.to(dtype), (var + mu * mu).to(dtype), d.to(dtype)


def _lit_problem(impl, label, mu, m2, d, min_variance):
    name = f"variance_lit({label})"
    got = to_tensor(_call(impl, mu, m2, d, min_variance), name)
    expected = _lit(mu, m2, d, min_variance)
    low = mu.dtype == torch.float32
    message = compare(got, expected, name=name, check_dtype=True, **(dict(atol=1e-5, rtol=1e-4) if low
                                                                      else dict(atol=1e-12, rtol=1e-10)))
    if message is None or "dtype" in message or "shape" in message:
        return message
    explanation = _match(got, [
        (_lit(mu, m2, d, min_variance, "both_sides"), "a receiver in front of the occluders' mean depth (d <= μ) "
                                                      "is fully lit: return 1 there, the bound only where d > μ"),
        (_lit(mu, m2, d, min_variance, "std"), "that is σ / (σ + |d - μ|): Chebyshev's bound uses the variance, "
                                               "σ² / (σ² + (d - μ)²)"),
        (_lit(mu, m2, d, min_variance, "no_mean"), "the variance is m₂ - μ², not m₂: E[z²] holds the mean's square "
                                                   "too"),
        (_lit(mu, m2, d, min_variance, "no_clamp"), "the variance is not clamped: take max(m₂ - μ², min_variance), "
                                                    "or a flat occluder (σ² = 0, even below 0 by rounding) breaks"),
    ])
    if explanation:
        return f"{name}: {explanation}"
    if not bool(torch.isfinite(got).all()):
        return f"{name}: NaN or inf in the result: clamp the variance to min_variance before dividing"
    return message


@task("12.3", "variance_lit", points=2, reference=("course.shadows.prefiltered", "variance_visibility"))
def _check_variance(impl):
    forbidden = forbidden_call(impl, "variance_lit", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def basic():
        require(_lit_problem(impl, "20 receivers, float64", *_moments(1231, 20), 1e-6))

    def stress():
        mu = torch.tensor([2.0, 2.0, 2.0, 1.0], dtype=torch.float64)
        m2 = mu * mu - torch.tensor([0.0, 1e-12, -1e-12, 0.0], dtype=torch.float64)    # flat: σ² = 0, or rounding
        d = torch.tensor([2.5, 2.0, 2.0 + 1e-4, 0.5], dtype=torch.float64)
        require(_lit_problem(impl, "flat occluders (σ² = 0 or just below), min_variance 1e-4", mu, m2, d, 1e-4))
        require(_lit_problem(impl, "a 4 x 5 map of receivers, float32", *(t.view(4, 5) for t in
                                                                            _moments(1232, 20, torch.float32)), 1e-6))
    return grade_parts((1, "Chebyshev's bound", basic), (1, "flat occluders, a 2-D map, float32", stress))


# ------------------------------------------------------------------------------------ 12.4 light_step

def _step_cases():
    g = generator(1241)
    l1 = _unit(torch.tensor([0.3, -1.0, 0.2], dtype=torch.float64))
    l2 = _unit(torch.randn(3, generator=g, dtype=torch.float64))
    return [("light (0.3, -1, 0.2) normalised, a gradient across it", l1,
             torch.tensor([0.5, 0.1, -0.2], dtype=torch.float64), 0.1),
            ("a random light, a random gradient", l2, torch.randn(3, generator=g, dtype=torch.float64), 0.05),
            ("a gradient along the light itself (no step at all)", l1, 2.0 * l1, 0.3)]


def _step_problem(impl, label, l, g, lr):
    name = f"light_step({label})"
    before = l.clone()
    raw = impl(l, g.clone(), lr)
    got = to_tensor(raw, name)
    if not torch.equal(l, before):
        return f"{name}: light was changed in place: return a new tensor and leave the argument as it was"
    expected = _step(l, g, lr)
    message = compare(got, expected, name=name, check_dtype=True, atol=1e-12, rtol=1e-10)
    if message is None or "dtype" in message or "shape" in message:
        return message
    explanation = _match(got, [
        (_step(l, g, lr, "ascent"), "that step goes up the loss: subtract lr times the gradient"),
        (_step(l, g, lr, "no_normalize"), "the result is not a unit vector: divide the stepped light by its norm"),
        (_step(l, g, lr, "no_projection"), "the gradient's part along the light was kept: drop it first, "
                                           "g - (g · l) l (it only changes the length, which renormalising undoes "
                                           "only in part)"),
    ])
    return f"{name}: {explanation}" if explanation else message


@task("12.4", "light_step", points=2, reference=("course.grading.lecture12", "light_step_reference"))
def _check_step(impl):
    forbidden = forbidden_call(impl, "light_step", FORBIDDEN)
    if forbidden:
        return 0, forbidden
    cases = _step_cases()

    def basic():
        require(_step_problem(impl, *cases[0]))
        require(_step_problem(impl, *cases[1]))

    def along():
        require(_step_problem(impl, *cases[2]))
    return grade_parts((1, "a step on the sphere", basic), (1, "a gradient along the light", along))


# ------------------------------------------------------------ 12.5 where the map's estimate is exact (an analysis)

def _texels(seed, n, dtype=torch.float64):
    """μ in [1, 3], σ in [0.03, 0.3], receivers 0.05 to 1 behind the mean."""
    g = generator(seed)
    mu = 1 + 2 * torch.rand(n, generator=g, dtype=torch.float64)
    var = (0.03 + 0.27 * torch.rand(n, generator=g, dtype=torch.float64)) ** 2
    d = mu + 0.05 + 0.95 * torch.rand(n, generator=g, dtype=torch.float64)
    return mu.to(dtype), var.to(dtype), d.to(dtype)


def _tight_problem(impl, label, mu, var, d):
    name = f"tight_distribution({label})"
    out = _call(impl, mu, var, d)
    z, w = _unpack(out, ("depths", "weights"), "tight_distribution")
    want = tuple(mu.shape) + (2,)
    for value, what in ((z, "depths"), (w, "weights")):
        if tuple(value.shape) != want:
            return f"{name}: {what} should have shape {want} (two depths per texel), got {tuple(value.shape)}"
        if value.dtype != mu.dtype:
            return f"{name}: {what} should be {mu.dtype} like the inputs, got {value.dtype}"
    if not bool(torch.isfinite(z).all() & torch.isfinite(w).all()):
        return f"{name}: NaN or inf among the depths or weights"
    low = mu.dtype == torch.float32
    z, w = z.double(), w.double()
    m, v, dd = mu.double(), var.double(), d.double()
    order = z.argsort(-1)                                                   # nearest the light first
    z, w = z.gather(-1, order), w.gather(-1, order)
    got = torch.stack([z, w], -1)
    explanation = _match(got, [(torch.stack([t.double() for t in _tight(m, v, dd, kind)], -1), why) for kind, why in (
        ("symmetric", "two depths μ ± σ with weight 1/2 have the right mean and variance, but the receiver is "
                      "lit by the weight at depths ≥ d, not by the bound: to reach it, put the lit weight at the "
                      "receiver's own depth d and solve for the other depth"),
        ("swapped", "the weights are swapped: the lit weight, Cantelli's p = σ² / (σ² + (d - μ)²), belongs to "
                    "the depth d, 1 - p to the occluder"),
        ("sigma", "the occluder one σ in front of the mean does not keep the mean: p d + (1 - p) z_o = μ fixes z_o"),
        ("std", "the lit weight is σ / (σ + (d - μ)): the bound is σ² / (σ² + (d - μ)²), with the variance"),
    )], tol=1e-4)
    if explanation:
        return f"{name}: {explanation}"
    tol = 1e-4 if low else 1e-9
    scale = m.abs() + v.sqrt() + 1
    if bool((w < -tol).any()) or not torch.allclose(w.sum(-1), torch.ones_like(m), atol=tol, rtol=0):
        return (f"{name}: the weights are not a distribution (each >= 0, summing to 1): sums reach "
                f"{float((w.sum(-1) - 1).abs().max()) + 1:.6g}, the smallest weight is {float(w.min()):.3g}")
    mean = (w * z).sum(-1)
    if not torch.allclose(mean, m, atol=0, rtol=0) and bool(((mean - m).abs() > tol * scale).any()):
        k = int((mean - m).abs().argmax())
        return (f"{name}: the mean Σ w z is {float(mean.flatten()[k]):.6g} where μ = {float(m.flatten()[k]):.6g}: "
                "the distribution must keep the texel's mean")
    variance = (w * (z - m[..., None]) ** 2).sum(-1)
    if bool(((variance - v).abs() > tol * (v + tol)).any()):
        k = int(((variance - v).abs() / v).argmax())
        return (f"{name}: the variance Σ w (z - μ)² is {float(variance.flatten()[k]):.6g} where σ² = "
                f"{float(v.flatten()[k]):.6g}: the distribution must keep the texel's variance")
    bound = v / (v + (dd - m) ** 2)
    lit = (w * (z >= dd[..., None] - tol * scale[..., None])).sum(-1)      # weight not in front of the receiver
    if bool(((lit - bound).abs() > 10 * tol).any()):
        k = int((lit - bound).abs().argmax())
        return (f"{name}: the weight at depths >= d (what really lights the receiver) is "
                f"{float(lit.flatten()[k]):.6g}, the map's estimate (Cantelli's bound) {float(bound.flatten()[k]):.6g}: "
                "the bound is reached only by weight exactly at the receiver's depth d")
    return None


@task("12.5", "tight_distribution", points=4,
      reference=("course.grading.lecture12", "tight_distribution_reference"))
def _check_tight(impl):
    forbidden = forbidden_call(impl, "tight_distribution", FORBIDDEN)
    if forbidden:
        return 0, forbidden

    def random():
        require(_tight_problem(impl, "12 texels, float64", *_texels(1251, 12)))

    def map32():
        require(_tight_problem(impl, "a 3 x 4 map, float32", *(t.view(3, 4) for t in _texels(1252, 12,
                                                                                           torch.float32))))

    def extremes():
        mu = torch.tensor([2.0, 2.0, 0.5], dtype=torch.float64)
        var = torch.tensor([1.0, 1e-6, 0.04], dtype=torch.float64)
        d = torch.tensor([2.001, 3.0, 0.5 + 1e-3], dtype=torch.float64)
        require(_tight_problem(impl, "a receiver just behind a wide texel's mean, a nearly flat texel", mu, var, d))
    return grade_parts((2, "random texels", random), (1, "a 2-D map, float32", map32),
                       (1, "a receiver just behind the mean, a nearly flat texel", extremes))
