"""Tests of course.inverse.views: learned views move, stay valid, ascend the loss; the fixed baseline does not move."""
import math

import pytest
import torch

from course import models
from course.inverse import losses
from course.inverse import FitHistory, circle_views, sphere_views
from course.inverse.views import (ViewFit, default_separation, fit_with_learned_views, ring_angles, separation_penalty,
                              view_camera, view_directions)
from course.soft import soft_rasterize

SIZE = 32
N = 4


@pytest.fixture(scope="module")
def torus():
    return models.torus(0.8, 0.3, 24, 12)


def _fit(target, learn_views, **kwargs):
    args = dict(n_views=N, size=SIZE, steps=24, lr=0.03, subdivisions=2, view_every=2, seed=0, snapshot_every=10,
                held_out=sphere_views(6, size=SIZE), progress=False)
    return fit_with_learned_views(target, learn_views=learn_views, **{**args, **kwargs})


@pytest.fixture(scope="module")
def learned(torus):
    return _fit(torus, True)


@pytest.fixture(scope="module")
def fixed(torus):
    return _fit(torus, False)


def _angles(history, step):
    return torch.tensor([history.metrics["azimuth_deg"][step], history.metrics["elevation_deg"][step]],
                        dtype=torch.float64).T                                 # (N, 2) degrees


# ------------------------------------------------------------------------------------------- views

def test_view_camera_matches_circle_views():
    for cam, (az, el) in zip(circle_views(8, size=SIZE), ring_angles(8, dtype=torch.float32)):
        mine = view_camera(az, el, size=SIZE)
        assert torch.allclose(mine.R, cam.R, atol=1e-6) and torch.allclose(mine.t, cam.t, atol=1e-5)
        assert torch.equal(mine.K, cam.K)


def test_view_gradient_matches_finite_differences(torus):
    # the silhouette loss as a function of one view, both images soft: autograd against central differences
    target, sphere = torus.to(dtype=torch.float64), models.icosphere(1, 0.6, dtype=torch.float64)

    def loss(angles):
        cam = view_camera(angles[0], angles[1], size=16)
        render = lambda m: soft_rasterize(m, cam, sigma=3e-3, cull_backfaces=False).clamp(0, 1)
        return losses.silhouette_iou_loss(render(sphere), render(target))

    angles = torch.tensor([0.3, 0.4], dtype=torch.float64, requires_grad=True)
    (grad,) = torch.autograd.grad(loss(angles), angles)
    h = 1e-6                                                              # 1e-5 straddles kinks of the soft edges
    fd = torch.stack([(loss(angles.detach() + h * e) - loss(angles.detach() - h * e)) / (2 * h)
                      for e in torch.eye(2, dtype=torch.float64)])
    assert grad.abs().max() > 1e-3                                        # the view matters
    assert torch.allclose(grad, fd, rtol=1e-3, atol=1e-6), (grad, fd)


def test_separation_penalty_is_a_hinge():
    apart = ring_angles(4)                                                # 90° apart in azimuth
    assert float(separation_penalty(apart, 35.0)) == 0.0
    close = torch.tensor([[0.0, 0.0], [0.1, 0.0]], dtype=torch.float64, requires_grad=True)   # 5.7° apart
    p = separation_penalty(close, 35.0)
    p.backward()
    assert p > 0 and close.grad[0, 0] > 0 and close.grad[1, 0] < 0       # descent pushes them apart
    same = torch.zeros(2, 2, dtype=torch.float64, requires_grad=True)   # coinciding views: finite gradient
    separation_penalty(same, 35.0).backward()
    assert torch.isfinite(same.grad).all()


def test_ring_start_satisfies_default_separation():
    # the views start unpushed: the ring is already as far apart as the default asks
    for n in (2, 4, 6, 8, 12):
        assert float(separation_penalty(ring_angles(n), default_separation(n))) == 0.0, n
    assert abs(default_separation(8) - 57.4) < 0.1


# ---------------------------------------------------------------------------------------------- fits

def test_fits_improve_iou(learned, fixed):
    for r in (learned, fixed):
        assert isinstance(r, ViewFit) and isinstance(r.history, FitHistory)
        assert r.iou > r.start_iou + 0.1, (r.start_iou, r.iou)
        assert r.per_view_iou.shape == (6,)
        assert r.history.loss[-1] < r.history.loss[0]
    assert learned.start_iou == fixed.start_iou                           # the same start, only the views differ


def test_history_shape(learned):
    h = learned.history
    assert len(h.loss) == 24 and len(h.metrics["iou_loss"]) == 24
    assert len(h.metrics["azimuth_deg"]) == 24 and all(len(a) == N for a in h.metrics["elevation_deg"])
    assert h.snapshot_steps == [0, 10, 20, 24]
    assert torch.equal(h.snapshots[-1], learned.mesh.verts)
    assert all(math.isfinite(x) for x in h.loss)


def test_learned_views_move_and_stay_valid(learned):
    start = ring_angles(N)
    assert torch.allclose(_angles(learned.history, 0), torch.rad2deg(start))
    final = torch.stack([learned.azimuth_deg, learned.elevation_deg], 1)   # (N, 2) degrees
    assert torch.isfinite(final).all()
    assert (final - torch.rad2deg(start)).abs().max() > 2.0               # they moved
    assert (final[:, 1].abs() <= 80.0 + 1e-4).all()                         # the elevation clamp
    eyes = torch.stack([c.eye for c in learned.cameras])                  # (N, 3)
    assert torch.allclose(eyes.norm(dim=1), torch.full((N,), 3.0), atol=1e-4)   # distance kept
    assert torch.pdist(eyes).min() > 0.3                                  # distinct views
    dirs = view_directions(torch.deg2rad(final.double()))
    assert torch.allclose(eyes.double() / 3.0, dirs, atol=1e-5)           # the cameras are at the angles


def test_fixed_views_do_not_move(fixed):
    ring = torch.rad2deg(ring_angles(N))
    for step in range(len(fixed.history.loss)):
        assert torch.allclose(_angles(fixed.history, step), ring)
    for mine, cam in zip(fixed.cameras, circle_views(N, size=SIZE)):
        assert torch.allclose(mine.R, cam.R, atol=1e-6) and torch.allclose(mine.t, cam.t, atol=1e-5)


def test_seeded(torus):
    run = lambda seed: _fit(torus, True, steps=4, view_every=1, subdivisions=1, seed=seed, size=16,
                            held_out=sphere_views(2, size=16))
    a, b, c = run(1), run(1), run(2)
    assert a.history.loss == b.history.loss and torch.equal(a.mesh.verts, b.mesh.verts)
    assert a.history.metrics["azimuth_deg"] == b.history.metrics["azimuth_deg"]
    assert torch.equal(a.azimuth_deg, b.azimuth_deg) and torch.equal(a.elevation_deg, b.elevation_deg)
    assert not torch.equal(a.mesh.verts, c.mesh.verts)


def test_one_view_step_follows_the_objective(torus):
    # the shape barely moves (lr 1e-9); the views take one Adam step up ("worst") or down ("best") the loss
    run = lambda **kw: _fit(torus, steps=2, view_every=1, lr=1e-9, view_lr=0.02, separation=0.0, subdivisions=1,
                            held_out=sphere_views(2, size=SIZE), **kw)
    before, up = run(learn_views=True).history.metrics["iou_loss"]
    assert up > before, (before, up)
    assert run(learn_views=True, view_objective="best").history.metrics["iou_loss"][1] < before
    same = run(learn_views=False).history.metrics["iou_loss"]
    assert same[0] == before and abs(same[1] - before) < 1e-6           # no view step: no change


@pytest.mark.parametrize("kwargs, match", [
    (dict(n_views=0), "n_views"), (dict(size=2), "size"), (dict(view_lr=0.0), "view_lr"),
    (dict(view_every=0), "view_every"), (dict(separation=-1.0), "separation"),
    (dict(min_separation_deg=200.0), "min_separation_deg"), (dict(max_elevation_deg=90.0), "max_elevation_deg"),
    (dict(learn_views="yes"), "learn_views"), (dict(view_objective="max"), "view_objective"), (dict(steps=-1), "steps"), (dict(lr=0.0), "lr"),
    (dict(sigma=float("nan")), "sigma"), (dict(distance=-3.0), "distance"), (dict(smoothness=-1.0), "smoothness"),
    (dict(snapshot_every=0), "snapshot_every"), (dict(radius=0.0), "radius"), (dict(held_out=[]), "held_out"),
    (dict(held_out="sphere"), "held_out"),
])
def test_bad_inputs(torus, kwargs, match):
    with pytest.raises(ValueError, match=match):
        fit_with_learned_views(torus, progress=False, **{"steps": 1, "size": 16, **kwargs})


def test_bad_target():
    with pytest.raises(ValueError, match="target_mesh"):
        fit_with_learned_views(models.torus().verts, steps=1, size=16, progress=False)


# ------------------------------------------------------------------ view_objective="task": MVTN's scheme

def test_surface_points_lie_on_the_surface_uniformly_by_area():
    from course.inverse.views import surface_points
    from course.mesh import Mesh
    # two triangles of area 1 and 3 in the plane z = 0: a quarter of the points in the first
    verts = torch.tensor([[0, 0, 0], [1, 0, 0], [0, 2, 0], [2, 0, 0], [5, 0, 0], [2, 2, 0]], dtype=torch.float64)
    mesh = Mesh(verts, torch.tensor([[0, 1, 2], [3, 4, 5]]))
    p = surface_points(mesh, 4000, seed=1)
    assert p.shape == (4000, 3) and (p[:, 2] == 0).all()
    first = (p[:, 0] <= 1 + 1e-12) & (2 * p[:, 0] + p[:, 1] <= 2 + 1e-12)
    assert abs(float(first.double().mean()) - 0.25) < 0.03
    assert torch.equal(p, surface_points(mesh, 4000, seed=1))                    # seeded
    with pytest.raises(ValueError, match="n"):
        surface_points(mesh, 0)


def test_chamfer_distance_is_zero_on_itself_and_symmetric():
    from course.inverse.views import chamfer_distance
    g = torch.Generator().manual_seed(0)
    a, b = torch.rand(50, 3, generator=g, dtype=torch.float64), torch.rand(70, 3, generator=g, dtype=torch.float64)
    assert float(chamfer_distance(a, a)) < 1e-15                                # cdist's rounding
    assert float(chamfer_distance(a, b)) == pytest.approx(float(chamfer_distance(b, a)))
    grid = torch.cartesian_prod(*[torch.arange(3, dtype=torch.float64)] * 3)    # points 1 apart: a shift of 0.1
    moved = grid + torch.tensor([0.1, 0.0, 0.0], dtype=torch.float64)          # has each point's twin nearest
    assert float(chamfer_distance(grid, moved)) == pytest.approx(0.02)


@pytest.fixture
def float64_default():
    before = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    yield
    torch.set_default_dtype(before)


def test_task_view_gradient_matches_finite_differences_of_the_look_ahead(float64_default):
    """dT/dφ with T the chamfer distance of the shape after one silhouette step: the finite difference of two
    first derivatives against central differences of T itself (float64)."""
    torus = models.torus(0.8, 0.3, 24, 12)
    from course.inverse import start_verts
    from course.inverse.views import _silhouettes, _task_view_gradient, chamfer_distance, surface_points
    from course.mesh import Mesh
    base, faces = start_verts(models.icosphere(1, 0.5), 0)
    verts = base + 0.03 * torch.randn(base.shape, generator=torch.Generator().manual_seed(3), dtype=base.dtype)
    points, lr, sigma = surface_points(torus, 500, 0), 0.05, 3e-4
    cam = lambda a: [view_camera(az, el, size=16) for az, el in a]

    def d_loss(angles):
        v = verts.clone().requires_grad_(True)
        cams = cam(angles)
        loss = losses.silhouette_iou_loss(_silhouettes(Mesh(v, faces), cams, sigma), _silhouettes(torus, cams, sigma),
                                          reduction="mean")
        return torch.autograd.grad(loss, v)[0]

    a = ring_angles(3)
    got = _task_view_gradient(torus, faces, verts, d_loss(a), a.clone().requires_grad_(True), cam, sigma, lr, points)
    fd, h = torch.zeros_like(a), 1e-5
    for i in range(3):
        for j in range(2):
            e = torch.zeros_like(a)
            e[i, j] = h
            fd[i, j] = (chamfer_distance(verts - lr * d_loss(a + e), points)
                        - chamfer_distance(verts - lr * d_loss(a - e), points)) / (2 * h)
    assert float(fd.norm()) > 0
    assert float((got - fd).norm() / fd.norm()) < 5e-3


def test_task_views_move_and_the_fit_improves(torus):
    run = _fit(torus, True, view_objective="task", task_points=300, steps=8, view_every=2)
    start, end = _angles(run.history, 0), _angles(run.history, -1)
    assert (start - end).abs().max() > 0.1                                     # the views moved (degrees)
    assert run.history.metrics["iou_loss"][-1] < run.history.metrics["iou_loss"][0]
    with pytest.raises(ValueError, match="task_points"):
        fit_with_learned_views(torus, view_objective="task", task_points=0, steps=1, size=16, progress=False)
