"""Tests of course.inverse: each loop improves its metric in a short run, histories, seeding, bad inputs."""
import math

import pytest
import torch

from course import models
from course.camera import Camera, axis_angle_to_matrix
from course.inverse import (CameraFit, FitHistory, SilhouetteFit, camera_problem, center_error, circle_views,
                        fit_camera, fit_silhouettes, hard_silhouettes, rotation_error, self_intersections,
                        shaded_face_colors, sphere_views)
from course.mesh import Mesh

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
    from course.nmr import nmr_rasterize
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
        fit_camera(mesh, ref, start, steps=1, method="exact", progress=False)
    with pytest.raises(ValueError, match="samples"):
        fit_camera(mesh, ref, start, steps=1, method="edge_sampling", samples=0, progress=False)
    with pytest.raises(ValueError, match="lr_end"):
        fit_camera(mesh, ref, start, steps=1, lr_end=0.0, progress=False)
    with pytest.raises(ValueError, match="NaN"):
        fit_camera(mesh, torch.full((16, 16), float("nan")), start, steps=1, progress=False)


# ------------------------------------------------------------------ camera: every gradient, one problem

def test_camera_problem_shapes_and_start_angle():
    mesh, colors, ref_cam, start, ref = camera_problem(size=20, degrees=35.0)
    assert ref.shape == (20, 20, 3) and colors.shape == (mesh.faces.shape[0], 3)
    assert 0 <= float(ref.min()) and float(ref.max()) <= 1 and float(ref.sum()) > 0
    assert rotation_error(start.R, ref_cam.R) == pytest.approx(35.0, abs=1e-6)
    assert float(start.eye.norm()) == pytest.approx(float(ref_cam.eye.norm()), rel=1e-12)
    _, none, _, _, sil = camera_problem(size=20, shaded=False)
    assert none is None and sil.shape == (20, 20) and float(sil.min()) >= 0 and float(sil.max()) <= 1
    assert float(sil.sum()) > float(ref.sum(-1).gt(0).sum()) * 0.5


def test_shaded_face_colors_are_lambert():
    mesh = models.icosphere(1, dtype=torch.float64)
    c = shaded_face_colors(mesh, light=(0.0, 1.0, 0.0), albedo=(1.0, 1.0, 1.0), ambient=0.0)
    n = mesh.face_normals()
    assert torch.allclose(c[:, 0], n[:, 1].clamp(min=0), atol=1e-12)


def test_hard_gradient_leaves_the_camera_where_it_started():
    mesh, colors, ref_cam, start, ref = camera_problem(models.teapot(2, dtype=torch.float64), size=16)
    r = fit_camera(mesh, ref, start, steps=3, method="hard", face_colors=colors, reference_camera=ref_cam,
                   progress=False)
    assert torch.equal(r.camera.R, start.R.detach()) and r.history.metrics["rotation_deg"][-1] == pytest.approx(30.0)


def _ellipsoid():
    m = models.icosphere(2, dtype=torch.float64)
    return Mesh(m.verts * torch.tensor([0.9, 0.5, 0.6], dtype=torch.float64), m.faces)


def _pose_gradient(mesh, colors, start, ref, method, **options):
    """dL/dω at ω = 0 (L2 loss against ref) by autograd through exact_coverage or by _boundary_backward."""
    from course.coverage import exact_coverage
    from course.inverse.pose import _boundary_backward, _detached
    from course.inverse.losses import l2_loss
    omega = torch.zeros(3, dtype=torch.float64, requires_grad=True)
    size = start.width
    cam = Camera(start.K, start.R @ axis_angle_to_matrix(omega), start.t, size, size, start.near, start.far)
    if method == "exact":
        l2_loss(exact_coverage(mesh, cam, colors), ref).backward()
    else:
        image = exact_coverage(mesh, _detached(cam), colors)
        _boundary_backward(lambda im: l2_loss(im, ref), image, mesh, cam, method, colors, 0.0,
                           options.get("generator"), options.get("samples", 0))
    return omega.grad


def test_reynolds_step_is_the_exact_gradient_of_the_pose():
    """The boundary integral carried into ω equals autograd through the closed-form image."""
    mesh, colors, ref_cam, start, ref = camera_problem(_ellipsoid(), size=16)
    exact = _pose_gradient(mesh, colors, start, ref, "exact")
    reynolds = _pose_gradient(mesh, colors, start, ref, "reynolds")
    assert exact.abs().max() > 1e-4
    assert torch.allclose(exact, reynolds, rtol=1e-9, atol=1e-14), (exact, reynolds)


def test_edge_sampling_pose_gradient_is_unbiased():
    mesh, colors, ref_cam, start, ref = camera_problem(_ellipsoid(), size=16)
    exact = _pose_gradient(mesh, colors, start, ref, "exact")
    runs = torch.stack([_pose_gradient(mesh, colors, start, ref, "edge_sampling", samples=400,
                                       generator=torch.Generator().manual_seed(k)) for k in range(8)])
    spread = runs.std(0) / math.sqrt(8)
    assert (runs.mean(0) - exact).abs().le(4 * spread + 1e-12).all(), (runs.mean(0), exact, spread)
    assert (runs[0] != runs[1]).any()


@pytest.mark.parametrize("method", ["soft", "nmr"])
def test_soft_and_nmr_turn_the_camera_toward_the_reference(method):
    mesh, colors, ref_cam, start, ref = camera_problem(size=32, degrees=20.0)
    r = fit_camera(mesh, ref, start, steps=20, method=method, face_colors=colors, reference_camera=ref_cam,
                   progress=False, snapshot_every=None)
    rot = r.history.metrics["rotation_deg"]
    assert rot[-1] < rot[0] - 3.0, rot
    assert all(math.isfinite(x) for x in r.history.loss)


@pytest.mark.parametrize("method", ["reynolds", "edge_sampling"])
def test_boundary_gradients_turn_the_camera_toward_the_reference(method):
    mesh, colors, ref_cam, start, ref = camera_problem(_ellipsoid(), size=16, degrees=20.0)
    run = lambda seed: fit_camera(mesh, ref, start, steps=4, method=method, face_colors=colors,
                                  reference_camera=ref_cam, samples=400, seed=seed, progress=False,
                                  snapshot_every=None)
    a = run(0)
    rot = a.history.metrics["rotation_deg"]
    assert rot[-1] < rot[0] - 1.0, rot
    if method == "edge_sampling":                                           # seeded: same seed, same path
        assert torch.equal(a.camera.R, run(0).camera.R) and not torch.equal(a.camera.R, run(1).camera.R)


def test_self_intersections():
    assert self_intersections(models.icosphere(2)).shape == (0, 2)
    pairs = self_intersections(models.teapot(3))                           # the spout and handle enter the body
    assert pairs.shape[1] == 2 and pairs.shape[0] > 0 and (pairs[:, 0] < pairs[:, 1]).all()
    two = models.icosphere(1, dtype=torch.float64)
    both = Mesh(torch.cat([two.verts, two.verts + torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64)]),
                torch.cat([two.faces, two.faces + two.verts.shape[0]]))
    far = Mesh(torch.cat([two.verts, two.verts + torch.tensor([3.0, 0.0, 0.0], dtype=torch.float64)]), both.faces)
    assert self_intersections(both).shape[0] > 0 and self_intersections(far).shape[0] == 0
    with pytest.raises(ValueError, match="mesh"):
        self_intersections("mesh")
