"""Reparameterization (course.warp, ``image_gradient(method="reparameterization")``) against the exact gradient."""
import math

import pytest
import torch

import course.warp as warp
from course.camera import Camera
from course.mesh import Mesh
from course.visibility import image_gradient
from test_visibility import ALL, problem, rel


def _grid(n):
    """A deterministic n × n midpoint grid in place of the random samples: the estimator then becomes a
    quadrature of ``∫ f ∇·V``, whose only error is the grid's."""
    def points(pixels, samples, generator):
        assert samples == n * n
        x = (torch.arange(n, dtype=torch.float64) + 0.5) / n
        X, Y = torch.meshgrid(x, x, indexing="xy")
        return torch.stack([X, Y], -1).reshape(-1, 2).repeat(pixels, 1)
    return points


@pytest.mark.parametrize("kind, ortho, model", [("occlusion", False, "flat"), ("intersect", True, "affine")])
def test_the_warped_integral_is_the_exact_gradient(monkeypatch, kind, ortho, model):
    """The warp is right (continuous, the jumps' normal speed on them, 0 on the pixel's border) exactly when
    ``∫ f ∇·V`` over each pixel is the derivative: integrated on a fine grid, the estimator converges to the
    exact gradient (occlusion; intersection lines with affine colours): 5x the points a side cut the error by
    more than 2x, and at 150² it is below 20% (3% on the occlusion scene). (∇·V is bounded, but steep where a
    jump runs a hair from a pixel's side or meets another at a small angle: a grid point that lands there is
    an outlier; 120² put one in a pixel of the intersection scene, 0.43 off, 121² 0.04.)"""
    mesh, cam, colors, weights = problem(kind, ortho, size=(8, 10))
    if model == "affine":
        colors = torch.rand(mesh.verts.shape[0], 3, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    exact = image_gradient(mesh, cam, colors, weights, method="exact", model=model, wrt=ALL[:4])
    errors = []
    for n in (30, 150):
        monkeypatch.setattr(warp, "_stratified", _grid(n))
        g = image_gradient(mesh, cam, colors, weights, method="reparameterization", model=model, samples=n * n,
                           wrt=ALL[:4])
        errors.append(max(rel(x, y) for x, y in zip(g, exact)))
    assert errors[1] < (3e-2 if kind == "occlusion" else 0.2) and errors[1] < errors[0] / 2, errors


def test_one_warp_per_point_is_biased_and_the_bias_shrinks_with_the_kernel(monkeypatch):
    """Two jumps in one pixel moving differently (the near edge of a strip moves, its far edge does not):
    following only the nearest one (``warp="nearest"``, Loubet et al.'s one dominant discontinuity) leaves V
    discontinuous halfway between them, and the integral misses that jump: biased, less so as the kernel
    shrinks. The bounded and harmonic warps are exact at every kernel size."""
    mesh, cam, colors, weights = _strip()
    exact, = image_gradient(mesh, cam, colors, weights, method="exact", wrt=("t",))
    monkeypatch.setattr(warp, "_stratified", _grid(200))
    bias = []
    for kernel in (None, 0.1, 0.03):
        near, = image_gradient(mesh, cam, colors, weights, method="reparameterization", samples=200 ** 2,
                               wrt=("t",), warp="nearest", kernel=kernel)
        for w in ("bounded", "harmonic"):
            good, = image_gradient(mesh, cam, colors, weights, method="reparameterization", samples=200 ** 2,
                                   wrt=("t",), kernel=kernel, warp=w)
            assert rel(good, exact) < 1e-2, (w, kernel, rel(good, exact))
        bias.append(rel(near, exact))
    assert bias[0] > 0.15 and bias[0] > bias[1] > 0.05 > 0.01 > bias[2], bias   # 20%, 6.7%, 0.5%


def _strip():
    """A one-pixel image crossed by a strip (a quad of one colour) whose two long edges lie at different
    depths: a move of the camera along x shifts the near edge 4x as far as the far one."""
    cam = Camera(torch.tensor([[4.0, 0, 0.5], [0, 4.0, 0.5], [0, 0, 1]], dtype=torch.float64),
                 torch.eye(3, dtype=torch.float64), torch.zeros(3, dtype=torch.float64), 1, 1)
    # screen x = 4 X / Z + 0.5: the left edge at x ≈ 0.3 (depth 1), the right edge at x ≈ 0.7 (depth 4)
    v = torch.tensor([[-0.05, -1.0, 1.0], [-0.05, 1.0, 1.0], [0.2, 1.5, 4.0], [0.2, -1.5, 4.0]], dtype=torch.float64)
    mesh = Mesh(v, torch.tensor([[0, 1, 2], [0, 2, 3]]))
    colors = torch.tensor([[1.0, 0.5, 0.2], [1.0, 0.5, 0.2]], dtype=torch.float64)
    weights = torch.ones(1, 1, 3, dtype=torch.float64)
    return mesh, cam, colors, weights


@pytest.mark.parametrize("kind", ["occlusion", "intersect"])
def test_it_is_unbiased_and_seeded(kind):
    """Random samples: the mean of 16 seeded runs lies within 4 standard errors (estimated from the runs'
    own spread) of the exact gradient, for every parameter; the same seed gives the same numbers; the error
    of one run falls as the samples grow (16x the samples: at least 2x smaller; heavy tails near the points
    where a jump meets the pixel's border keep it from the 4x of independent samples)."""
    mesh, cam, colors, weights = problem(kind, size=(12, 14))
    exact = image_gradient(mesh, cam, colors, weights, method="exact", wrt=ALL[:4])

    def runs(n, k=16):
        out = [image_gradient(mesh, cam, colors, weights, method="reparameterization", samples=n, seed=s,
                              wrt=ALL[:4]) for s in range(k)]
        return [torch.stack([o[i] for o in out]) for i in range(4)]

    few, many = runs(16), runs(256)
    for name, g, y in zip(ALL, many, exact):
        u = torch.randn(y.shape, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
        proj = (g * u).reshape(16, -1).sum(1)                               # one random direction
        z = (float(proj.mean()) - float((y * u).sum())) / (float(proj.std()) / 4)
        assert abs(z) < 4, (name, z)
    rms = lambda g, y: float(((g - y) ** 2).reshape(16, -1).sum(1).mean().sqrt())
    assert rms(few[1], exact[1]) > 2 * rms(many[1], exact[1])
    again = image_gradient(mesh, cam, colors, weights, method="reparameterization", samples=16, seed=0, wrt=ALL[:4])
    assert all(torch.equal(a, b[0]) for a, b in zip(again, few))
    gen = image_gradient(mesh, cam, colors, weights, method="reparameterization", samples=16,
                         generator=torch.Generator().manual_seed(0), wrt=ALL[:4])
    assert all(torch.equal(a, b[0]) for a, b in zip(gen, few))


def test_colours_are_exact_and_float32_gets_its_float64_answer():
    mesh, cam, colors, weights = problem("sphere", size=(10, 12))
    c, = image_gradient(mesh, cam, colors, weights, method="reparameterization", wrt=("colors",))
    assert torch.equal(c, image_gradient(mesh, cam, colors, weights, method="exact", wrt=("colors",))[0])
    g64 = image_gradient(mesh.__class__(mesh.verts.float().double(), mesh.faces),    # the same float32 inputs
                         cam.to(dtype=torch.float32).to(dtype=torch.float64), colors.float().double(),
                         weights.float().double(), method="reparameterization", samples=4)
    g32 = image_gradient(mesh.__class__(mesh.verts.float(), mesh.faces), cam.to(dtype=torch.float32), colors.float(),
                         weights.float(), method="reparameterization", samples=4)
    assert g32.dtype == torch.float32 and torch.isfinite(g32).all()
    assert rel(g32.double(), g64) < 1e-6                                   # measured 2.4e-8


def test_degenerate_inputs_and_no_jumps():
    """Finite on the degenerate scene of the other methods; zero where nothing jumps (one colour, nothing
    on screen)."""
    v = torch.tensor([[-0.5, -0.4, 0.0], [0.6, -0.3, 0.0], [0.0, 0.5, 0.0],
                      [0.1, 0.1, 0.2], [0.2, 0.2, 0.2], [0.3, 0.3, 0.2],
                      [0.0, -0.2, 0.1], [0.0, 0.3, 0.1], [0.0, 0.0, 0.6],
                      [-0.3, 0.2, 2.7], [0.3, 0.25, 2.7], [0.0, -0.3, 3.5]], dtype=torch.float64)
    mesh = Mesh(v, torch.arange(12).view(4, 3))
    cam = Camera.look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov_y=50.0, width=16, height=16, near=0.5,
                         dtype=torch.float64)
    g = torch.Generator().manual_seed(1)
    colors = torch.rand(4, 3, generator=g, dtype=torch.float64)
    weights = torch.randn(16, 16, 3, generator=g, dtype=torch.float64)
    for w in ("bounded", "harmonic", "nearest"):
        out = image_gradient(mesh, cam, colors, weights, method="reparameterization", wrt=ALL, warp=w, kernel=None)
        assert all(torch.isfinite(x).all() for x in out)
    away = Camera.look_at((0.0, 0.0, -3.0), (0.0, 0.0, -6.0), fov_y=30.0, width=8, height=8, dtype=torch.float64)
    zero = image_gradient(mesh, away, colors, weights[:8, :8], method="reparameterization", wrt=("verts", "t"))
    assert all(float(x.abs().sum()) == 0 for x in zero)


@pytest.mark.parametrize("options, match", [
    (dict(samples=0), "samples"), (dict(samples=2.5), "samples"), (dict(kernel=0.0), "kernel"),
    (dict(kernel="wide"), "kernel"), (dict(kernel=math.inf), "kernel"), (dict(warp="spin"), "warp"),
    (dict(generator=3), "generator"), (dict(order=2), "unexpected"),
])
def test_bad_options_are_named(options, match):
    mesh, cam, colors, weights = problem(size=(8, 8))
    with pytest.raises((ValueError, TypeError), match=match):
        image_gradient(mesh, cam, colors, weights, method="reparameterization", **options)


def _crossing_field(y, pieces, velocities, warp_kind):
    """V and ∇·V at points y (N, 2) of one pixel holding straight pieces (P, 2, 2) that move rigidly by
    ``velocities`` (P, 2) (numbers: the fields are linear in the velocities, so they come out as values)."""
    a, b = pieces[:, 0], pieces[:, 1]
    P = a.shape[0]
    s0, s1 = torch.zeros(P, dtype=torch.float64), torch.ones(P, dtype=torch.float64)
    px, pp = torch.zeros(y.shape[0], dtype=torch.int64), torch.zeros(P, dtype=torch.int64)
    vel = lambda j, s: velocities[j]                                        # noqa: E731
    if warp_kind == "bounded":
        return warp.bounded_warp_field(y, px, 1, a, b, s0, s1, pp, vel, 1.0)
    return warp.warp_field(y, px, 1, a, b, s0, s1, pp, vel, lambda j, g: torch.zeros(j.numel(), dtype=torch.float64),
                           1.0, warp_kind)


@pytest.mark.parametrize("where", ["side", "junction"])
def test_the_bounded_warps_divergence_stays_bounded(where):
    """Where a moving jump meets the pixel's border, or an occluding edge meets the occluded one (two normal
    speeds at one point), the harmonic warp's V jumps and ∇·V grows like 1/r (the estimator's second moment
    then diverges, logarithmically); the bounded warp meets both constraints there (V · n = v_n on each) and
    its divergence stays bounded: max |∇·V| on circles of radius 1e-2 to 1e-6 around the point."""
    if where == "side":                                                     # a jump crossing the left side
        centre = torch.tensor([0.0, 0.3], dtype=torch.float64)
        pieces = torch.tensor([[[0.0, 0.3], [1.0, 0.5]]], dtype=torch.float64)
        velocities = torch.tensor([[0.1, 0.3]], dtype=torch.float64)
        angles = torch.linspace(-1.5, 1.5, 61, dtype=torch.float64)        # inside the pixel
    else:                                                                   # a T: y = 0.5 over x = 0.5 below it
        centre = torch.tensor([0.5, 0.5], dtype=torch.float64)
        pieces = torch.tensor([[[0.0, 0.5], [1.0, 0.5]], [[0.5, 0.0], [0.5, 0.5]]], dtype=torch.float64)
        velocities = torch.tensor([[0.0, 0.2], [0.3, 0.0]], dtype=torch.float64)
        angles = torch.linspace(0.0, 2 * math.pi, 121, dtype=torch.float64)
    worst = {}
    for kind in ("bounded", "harmonic"):
        for r in (1e-2, 1e-4, 1e-6):
            y = centre + r * torch.stack([torch.cos(angles), torch.sin(angles)], 1)
            V, div = _crossing_field(y, pieces, velocities, kind)
            assert torch.isfinite(V).all() and torch.isfinite(div).all()
            worst[kind, r] = float(div.abs().max())
    assert worst["bounded", 1e-6] <= 2 * worst["bounded", 1e-2] + 1e-9, worst
    assert worst["harmonic", 1e-6] > 1e3 * worst["harmonic", 1e-2], worst      # ~1/r
    if where == "junction":                                                 # V meets both constraints at the T
        V, _ = _crossing_field(centre[None] + 1e-9, pieces, velocities, "bounded")
        assert torch.allclose(V[0], torch.tensor([0.3, 0.2], dtype=torch.float64), atol=1e-6)


@pytest.mark.parametrize("case", ["sphere verts", "camera t", "affine verts"])
def test_one_run_at_256_samples_is_within_a_quarter(case):
    """The per-run relative L2 error at 256 samples a pixel (mean of 4 seeds): the harmonic warp with f taken
    relative to the background was 0.34 (a sphere's silhouette), 0.86 (the camera's translation) and 1.25
    (vertex colours) on these scenes; the bounded warp with each pixel's mean colour as a control variate is
    0.08, 0.11 and 0.08 (``python -m course bench gradients`` has the time against error)."""
    kind, model, wrt = {"sphere verts": ("sphere", "flat", "verts"), "camera t": ("occlusion", "flat", "t"),
                        "affine verts": ("occlusion", "affine", "verts")}[case]
    mesh, cam, colors, weights = problem(kind, size=(16, 20))
    if model == "affine":
        colors = torch.rand(mesh.verts.shape[0], 3, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    exact, = image_gradient(mesh, cam, colors, weights, method="exact", model=model, wrt=(wrt,))
    errors = [rel(image_gradient(mesh, cam, colors, weights, method="reparameterization", model=model, wrt=(wrt,),
                                 samples=256, seed=seed)[0], exact) for seed in range(4)]
    assert sum(errors) / 4 <= 0.25, errors


def test_the_bounded_warp_meets_its_constraints_to_a_millionth():
    """On the jumps V · n = v_n and on the pixel's sides V · n = 0, up to the softening of its weights
    (1/(d² + ε²), ε = 2^-14 px): integrated along random pieces (crossing each other and the sides), the misfit
    is below 2e-6 of ∫ |v_n| (4e-7 on the curves, 6e-7 on the sides, measured over 100 configurations; 20 here): the
    estimator's only bias."""
    g = torch.Generator().manual_seed(0)
    misfit = total = 0.0
    m = 20_000
    t = (torch.arange(m, dtype=torch.float64) + 0.5) / m
    for _ in range(20):
        P = int(torch.randint(1, 4, (1,), generator=g))
        a = torch.rand(P, 2, generator=g, dtype=torch.float64) * 1.4 - 0.2
        b = torch.rand(P, 2, generator=g, dtype=torch.float64) * 1.4 - 0.2
        da, db = torch.randn(P, 2, generator=g, dtype=torch.float64), torch.randn(P, 2, generator=g, dtype=torch.float64)
        vel = lambda j, s: da[j] + s[:, None] * (db[j] - da[j])            # noqa: E731
        field = lambda y: warp.bounded_warp_field(                          # noqa: E731
            y, torch.zeros(len(y), dtype=torch.long), 1, a, b, torch.zeros(P, dtype=torch.float64),
            torch.ones(P, dtype=torch.float64), torch.zeros(P, dtype=torch.long), vel, 1.0)[0]
        ab = b - a
        n = torch.stack([-ab[:, 1], ab[:, 0]], 1) / ab.norm(dim=1, keepdim=True)
        for k in range(P):
            y = a[k] + t[:, None] * ab[k]
            inside = ((y > 0) & (y < 1)).all(1)
            if not inside.any():
                continue
            v = (vel(torch.full((int(inside.sum()),), k), t[inside]) * n[k]).sum(1)
            dl = float(ab[k].norm()) / m
            misfit += float(((field(y[inside]) * n[k]).sum(1) - v).abs().sum()) * dl
            total += float(v.abs().sum()) * dl
        for axis in (0, 1):
            for at in (0.0, 1.0):
                y = torch.stack([torch.full((m,), at, dtype=torch.float64), t], 1)[:, [axis, 1 - axis]]
                misfit += float(field(y)[:, axis].abs().sum()) / m
    assert misfit < 2e-6 * total, misfit / total
