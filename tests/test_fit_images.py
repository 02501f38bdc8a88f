"""A mesh from shaded images (course.inverse.fit_mesh_from_images): the exact gradient, short fits, bad input."""
import pytest
import torch

from course import inverse as fit, models
from course.inverse.shaded import _reynolds_backward
from course.coverage import exact_coverage
from course.mesh import Mesh

SMALL = dict(n_views=6, size=32, resolution=24, progress=False)


@pytest.fixture(scope="module")
def teapot():
    return models.teapot(4, dtype=torch.float64)


def test_reynolds_backward_matches_central_differences_of_the_exact_loss(teapot):
    """The gradient ``_reynolds_backward`` hands the optimiser (edges' motion, plus the shading's dependence on
    the normals chained through the colours) against float64 central differences of the box-filtered loss,
    on a sphere whose outline and shading both change with its vertices."""
    sphere = models.icosphere(2, 0.6, dtype=torch.float64)
    cams = fit.sphere_views(2, offset=1.9, size=24, dtype=torch.float64)
    targets = fit.shaded_images(teapot, cams)
    bg = torch.tensor(fit.SKY, dtype=torch.float64)

    def image_loss(image, target):
        return (image - target).square().mean() / 2

    def loss(v):
        mesh = Mesh(v, sphere.faces)
        colors = fit.shaded_face_colors(mesh)
        return sum(image_loss(exact_coverage(mesh, c, colors, bg), t) for c, t in zip(cams, targets))

    v = sphere.verts.clone().requires_grad_(True)
    total = _reynolds_backward(image_loss, v, sphere.faces, fit.shaded_face_colors(Mesh(v, sphere.faces)),
                                   cams, targets, fit.SKY)
    assert float(total) == pytest.approx(float(loss(sphere.verts)), rel=1e-12)
    moved = (v.grad.norm(dim=1) > 0).nonzero()[:, 0]
    assert moved.numel() > 10
    h = 1e-6
    for k in moved[:: max(1, moved.numel() // 6)].tolist():
        for d in range(3):
            x = sphere.verts.clone()
            x[k, d] += h
            up = loss(x)
            x[k, d] -= 2 * h
            fd = (up - loss(x)) / (2 * h)
            assert float(v.grad[k, d]) == pytest.approx(float(fd), rel=1e-5, abs=1e-10)


def test_short_fits_improve_the_held_out_images(teapot):
    """From the carved hull, a few steps of each gradient and optimiser raise the held-out PSNR and lower the
    image loss; 20 soft Large Steps raise it by more than 0.3 dB."""
    results = {}
    for gradient, optimizer, steps in (("soft", "large_steps", 20), ("soft", "adam", 10),
                                       ("reynolds", "large_steps", 2)):
        r = fit.fit_mesh_from_images(teapot, gradient=gradient, optimizer=optimizer, steps=steps,
                                     lr=0.01 if optimizer == "large_steps" else 0.002, **SMALL)
        assert len(r.history.loss) == steps and r.history.snapshot_steps[-1] == steps
        assert r.history.loss[-1] < r.history.loss[0]
        assert r.psnr > r.start_psnr
        assert r.mesh.faces.shape == r.start.faces.shape
        results[gradient, optimizer] = r
    ls = results["soft", "large_steps"]
    assert ls.psnr > ls.start_psnr + 0.3, (ls.start_psnr, ls.psnr)


def test_a_sphere_start_moves_toward_the_target(teapot):
    r = fit.fit_mesh_from_images(teapot, start="sphere", subdivisions=2, steps=20, lr=0.02, **SMALL)
    assert r.start.verts.shape[0] == 162
    assert r.iou > r.start_iou + 0.05


def test_shaded_images_and_held_out_psnr(teapot):
    cams = fit.sphere_views(2, size=16, dtype=torch.float64)
    exact = fit.shaded_images(teapot, cams)
    sampled = fit.shaded_images(teapot, cams, exact=False)
    assert exact.shape == sampled.shape == (2, 16, 16, 3)
    assert float((exact - sampled).abs().mean()) < 0.02                    # 4 x 4 samples against the integral
    corner = exact[0, 0, 0]
    assert torch.allclose(corner, torch.tensor(fit.SKY, dtype=torch.float64))
    same = fit.held_out_psnr(teapot, teapot, cams)
    assert bool(torch.isinf(same).all())                                   # identical images: no error
    sphere = models.icosphere(2, 0.6, dtype=torch.float64)
    assert bool((fit.held_out_psnr(sphere, teapot, cams) < 30).all())


@pytest.mark.parametrize("kwargs, message", [
    (dict(gradient="exact"), "gradient must be one of"),
    (dict(optimizer="sgd"), "optimizer must be"),
    (dict(start="cube"), "start must be"),
    (dict(laplacian=-1.0), "laplacian must be"),
    (dict(steps=-1), "steps must be"),
    (dict(n_views=0), "n_views"),
])
def test_bad_arguments_are_named(teapot, kwargs, message):
    with pytest.raises(ValueError, match=message):
        fit.fit_mesh_from_images(teapot, **{**SMALL, **kwargs})
    with pytest.raises(ValueError, match="target_mesh must be a Mesh"):
        fit.fit_mesh_from_images("teapot")
