"""Tests of course.fit: each loop improves its metric in a short run, histories, seeding, bad inputs."""
import math

import pytest
import torch

from course import models
from course.camera import Camera, axis_angle_to_matrix
from course.fit import (CameraFit, FitHistory, SilhouetteFit, center_error, circle_views, fit_camera,
                        fit_silhouettes, hard_silhouettes, rotation_error, sphere_views)

SIZE = 32


@pytest.fixture(scope="module")
def torus():
    return models.torus(0.8, 0.3, 24, 12)


@pytest.fixture(scope="module")
def silhouette_fit(torus):
    cams = circle_views(4, size=SIZE)
    return fit_silhouettes(torus, cams, steps=30, lr=0.02, subdivisions=2, seed=0, snapshot_every=10,
                           progress=False, held_out=sphere_views(6, size=SIZE))


def test_silhouette_fit_improves_iou(silhouette_fit):
    r = silhouette_fit
    assert isinstance(r, SilhouetteFit) and isinstance(r.history, FitHistory)
    assert r.iou > r.start_iou + 0.1, (r.start_iou, r.iou)
    assert r.history.loss[-1] < r.history.loss[0]
    assert r.per_view_iou.shape == (6,)


def test_silhouette_history_shape(silhouette_fit):
    h = silhouette_fit.history
    assert len(h.loss) == 30 and len(h.metrics["iou_loss"]) == 30
    assert h.snapshot_steps == [0, 10, 20, 30]
    assert all(s.shape == silhouette_fit.mesh.verts.shape for s in h.snapshots)
    assert torch.equal(h.snapshots[-1], silhouette_fit.mesh.verts)
    assert all(math.isfinite(x) for x in h.loss)


def test_silhouette_fit_seeded(torus):
    cams = circle_views(2, size=24)
    held = sphere_views(2, size=24)
    run = lambda seed: fit_silhouettes(torus, cams, steps=3, subdivisions=1, seed=seed, progress=False,
                                       held_out=held, method="nmr")
    a, b, c = run(1), run(1), run(2)
    assert a.history.loss == b.history.loss and torch.equal(a.mesh.verts, b.mesh.verts)
    assert not torch.equal(a.mesh.verts, c.mesh.verts)


def test_silhouette_fit_nmr_runs(torus):
    r = fit_silhouettes(torus, circle_views(2, size=24), steps=2, method="nmr", subdivisions=1, progress=False,
                        held_out=sphere_views(2, size=24), snapshot_every=None, laplacian=0.1, edge_length=0.1)
    assert len(r.history.loss) == 2 and r.history.snapshots == []


@pytest.mark.parametrize("kwargs, match", [
    (dict(steps=-1), "steps"), (dict(lr=0.0), "lr"), (dict(method="hard"), "method"),
    (dict(smoothness=-1.0), "smoothness"), (dict(sigma=0.0), "sigma"), (dict(snapshot_every=0), "snapshot_every"),
    (dict(start="sphere"), "start"),
])
def test_silhouette_fit_bad_inputs(torus, kwargs, match):
    with pytest.raises(ValueError, match=match):
        fit_silhouettes(torus, circle_views(1, size=16), progress=False, **{"steps": 1, **kwargs})


def test_silhouette_fit_bad_cameras(torus):
    with pytest.raises(ValueError, match="cameras"):
        fit_silhouettes(torus, [], steps=1, progress=False)
    with pytest.raises(ValueError, match="same image size"):
        fit_silhouettes(torus, circle_views(1, size=16) + circle_views(1, size=24), steps=1, progress=False)
    with pytest.raises(ValueError, match="target_mesh"):
        fit_silhouettes(torus.verts, circle_views(1, size=16), steps=1, progress=False)


def test_views_disjoint():
    ring, spiral = circle_views(8), sphere_views(16)
    train = sphere_views(8, offset=1.9)
    eyes = lambda cams: torch.stack([c.eye for c in cams])
    for a in (ring, train):
        assert torch.cdist(eyes(a), eyes(spiral)).min() > 0.1
    assert torch.allclose(eyes(spiral).norm(dim=1), torch.full((16,), 3.0), atol=1e-5)


# ------------------------------------------------------------------------------------------ camera

def _camera_problem(size=SIZE, degrees=30.0):
    mesh = models.teapot(4)
    ref_cam = Camera.look_at((1.5, 1.0, 2.5), fov_y=40, width=size, height=size)
    Ry = axis_angle_to_matrix(torch.tensor([0.0, math.radians(degrees), 0.0]))   # about world y, not the view axis
    start = Camera.look_at(Ry @ ref_cam.eye, fov_y=40, width=size, height=size)
    return mesh, ref_cam, start, hard_silhouettes(mesh, [ref_cam])[0]


def test_camera_fit_halves_errors():
    mesh, ref_cam, start, ref = _camera_problem()
    r = fit_camera(mesh, ref, start, steps=80, reference_camera=ref_cam, progress=False, snapshot_every=40)
    assert isinstance(r, CameraFit)
    h = r.history
    assert h.metrics["rotation_deg"][0] == pytest.approx(30.0, abs=1e-3)
    assert r.rotation_error_deg < 15.0 and r.center_error_pct < 0.5 * h.metrics["center_pct"][0]
    assert len(h.loss) == 80 and len(h.metrics["rotation_deg"]) == 81
    assert h.snapshot_steps == [0, 40, 80] and all(s.shape == (SIZE, SIZE) for s in h.snapshots)
    assert torch.allclose(r.camera.K, start.K)


def test_camera_fit_reproducible():
    mesh, ref_cam, start, ref = _camera_problem(size=24)
    a = fit_camera(mesh, ref, start, steps=3, progress=False)
    b = fit_camera(mesh, ref, start, steps=3, progress=False)
    assert a.history.loss == b.history.loss and torch.equal(a.camera.R, b.camera.R)
    assert a.rotation_error_deg is None


def test_camera_fit_color_and_nmr_run():
    mesh, ref_cam, start, _ = _camera_problem(size=24)
    colors = (mesh.face_normals().detach() + 1) / 2                          # (F, 3) in [0, 1]
    from course.soft import nmr_rasterize
    ref = nmr_rasterize(mesh, ref_cam, face_colors=colors).detach()
    for method in ("soft", "nmr"):
        r = fit_camera(mesh, ref, start, steps=2, method=method, face_colors=colors, progress=False,
                       reference_camera=ref_cam)
        assert len(r.history.loss) == 2 and all(math.isfinite(x) for x in r.history.loss)


def test_error_metrics():
    cam = Camera.look_at((0.0, 0.0, 3.0), fov_y=40, width=8, height=8)
    R = axis_angle_to_matrix(torch.tensor([0.0, math.radians(10.0), 0.0]))
    assert rotation_error(cam.R, cam.R @ R) == pytest.approx(10.0, abs=1e-3)
    other = Camera.look_at((0.0, 0.3, 3.0), fov_y=40, width=8, height=8)
    assert center_error(other, cam) == pytest.approx(10.0, rel=1e-5)


def test_camera_fit_bad_inputs():
    mesh, ref_cam, start, ref = _camera_problem(size=16)
    with pytest.raises(ValueError, match="reference_image"):
        fit_camera(mesh, ref[:8], start, steps=1, progress=False)
    with pytest.raises(ValueError, match="reference_image"):
        fit_camera(mesh, ref[None, None], start, steps=1, progress=False)
    with pytest.raises(ValueError, match="face_colors"):
        fit_camera(mesh, torch.zeros(16, 16, 3), start, steps=1, progress=False)
    with pytest.raises(ValueError, match="camera_start"):
        fit_camera(mesh, ref, "camera", steps=1, progress=False)
    with pytest.raises(ValueError, match="method"):
        fit_camera(mesh, ref, start, steps=1, method="hard", progress=False)
    with pytest.raises(ValueError, match="lr_end"):
        fit_camera(mesh, ref, start, steps=1, lr_end=0.0, progress=False)
    with pytest.raises(ValueError, match="NaN"):
        fit_camera(mesh, torch.full((16, 16), float("nan")), start, steps=1, progress=False)
