"""The penumbra-gradient estimators of lecture 14 (course.shadows.penumbra) against the exact gradient of the
form factor: shadow rays are unbiased for F and blind to the occluders; edge sampling of the silhouettes seen
from each point is unbiased for the occluders' gradient (its mean over seeds converges to the exact one);
finite differences of the shadow-ray estimate approach it as the samples grow; the variance shadow map's
estimate is differentiable, its gradient that of its own function."""
import math

import pytest
import torch

from course.mesh import Mesh
from course.shadows.area import light_form_factor
from course.shadows.penumbra import (penumbra_gradient, penumbra_scene, shadow_ray_form_factor,
                                     vsm_form_factor)


@pytest.fixture(scope="module", params=["square", "overlap"])
def scene(request):
    return penumbra_scene(request.param, 6)


def test_shadow_rays_are_unbiased_for_the_form_factor(scene):
    exact = light_form_factor(scene.points, scene.normals, scene.light, scene.occluders)
    runs = torch.stack([shadow_ray_form_factor(scene.points, scene.normals, scene.light, scene.occluders, 1024,
                                               seed=s) for s in range(16)])
    mean, se = runs.mean(0), runs.std(0) / 4
    lit = se > 0                                                            # (a point in the umbra: 0 and 0)
    assert torch.equal(mean[~lit], exact[~lit].clamp_max(1e-15) * 0) or float(exact[~lit].abs().max()) < 1e-12
    z = (mean - exact)[lit] / se[lit]                                       # about N(0, 1) (t, 15 degrees)
    assert float(z.abs().max()) < 6 and float(z.pow(2).mean().sqrt()) < 1.5, z


def test_autograd_through_shadow_rays_misses_the_occluders(scene):
    assert float(penumbra_gradient(scene, "shadow_rays", samples=32).abs().max()) == 0.0
    assert float(penumbra_gradient(scene, "exact").abs().max()) > 1e-3


def test_edge_sampling_converges_to_the_exact_gradient(scene):
    """Per coordinate, the mean over 12 seeds lies within 4 standard errors of the exact gradient, and its
    relative error falls as the edge samples grow."""
    exact = penumbra_gradient(scene, "exact")
    errors = []
    for M in (32, 512):
        runs = torch.stack([penumbra_gradient(scene, "edge_sampling", samples=8, edge_samples=M, seed=s)
                            for s in range(12)])
        mean, se = runs.mean(0), runs.std(0) / math.sqrt(12)
        assert bool(((mean - exact).abs() <= 4 * se + 1e-3 * float(exact.abs().max())).all()), (M, mean, exact, se)
        errors.append(float((runs - exact).norm(dim=(1, 2)).mean() / exact.norm()))
    assert errors[1] < errors[0] / 2, errors
    assert errors[1] < 0.05


def test_the_edge_term_leaves_the_estimate_unchanged(scene):
    a = shadow_ray_form_factor(scene.points, scene.normals, scene.light, scene.occluders, 16, seed=3)
    b = shadow_ray_form_factor(scene.points, scene.normals, scene.light, scene.occluders, 16, seed=3,
                               edge_samples=16)
    assert torch.equal(a, b.detach())


def test_finite_differences_approach_the_exact_gradient(scene):
    exact = penumbra_gradient(scene, "exact")
    g = penumbra_gradient(scene, "finite_differences", samples=2048, step=2e-2, seed=1)
    assert float((g - exact).norm() / exact.norm()) < 0.15


def test_the_vsm_gradient_is_the_derivative_of_its_own_estimate():
    scene = penumbra_scene("square", 4)
    verts = scene.occluders.verts.clone()

    def f(v):
        F = vsm_form_factor(scene.points, scene.normals, scene.light, Mesh(v, scene.occluders.faces), scene.floor,
                            grid=2, resolution=24, blur=1.0)
        return (scene.weights * F).sum()
    g = penumbra_gradient(scene, "vsm", grid=2, resolution=24, blur=1.0)
    for i, j in ((0, 0), (1, 1), (2, 2), (3, 0)):
        e = torch.zeros_like(verts)
        e[i, j] = 1e-6
        fd = float((f(verts + e) - f(verts - e)) / 2e-6)
        assert abs(float(g[i, j]) - fd) <= 1e-6 * max(1.0, abs(fd)), (i, j, float(g[i, j]), fd)


def test_bad_input_is_named():
    scene = penumbra_scene("square", 2)
    with pytest.raises(ValueError, match="unknown penumbra scene"):
        penumbra_scene("cube")
    with pytest.raises(ValueError, match="method must be one of"):
        penumbra_gradient(scene, "magic")
    with pytest.raises(ValueError, match="samples must be a positive"):
        shadow_ray_form_factor(scene.points, scene.normals, scene.light, scene.occluders, 0)
    with pytest.raises(ValueError, match="shape"):
        shadow_ray_form_factor(scene.points[:, :2], scene.normals, scene.light, scene.occluders)
