"""Variance shadow maps drawn smoothly (course.shadows.prefiltered): Chebyshev's test by hand, the image and its
gradient converging to the exact ones (course.shadows.gradients) as the map sharpens, and the bench's rows."""
import pytest
import torch

from course.mesh import Mesh
from course.shadows.prefiltered import moment_map, shadow_map_image, variance_visibility
from course.shadows.gradients import shadow_image_gradient, shadow_scene, shadowed_coverage

OCCLUDER = slice(3, 6)


def test_chebyshev_bound_by_hand():
    """A constant map μ = 2, E[z²] = 4.25 (σ² = 0.25): lit at or before μ, σ² / (σ² + (d - μ)²) beyond."""
    moments = torch.tensor([2.0, 4.25], dtype=torch.float64).expand(8, 8, 2)
    coords = torch.full((3, 2), 4.0, dtype=torch.float64)
    p = variance_visibility(moments, coords, torch.tensor([1.5, 2.0, 3.0], dtype=torch.float64))
    assert torch.allclose(p, torch.tensor([1.0, 1.0, 0.25 / 1.25], dtype=torch.float64))
    outside = variance_visibility(moments, torch.tensor([[-3.0, 4.0]], dtype=torch.float64),
                                  torch.tensor([9.0], dtype=torch.float64))
    assert float(outside) == 1.0                                            # beyond the map: lit


def test_moment_map_holds_the_nearest_depth():
    """With a sharp coverage and no blur, E[z] is the occluder's depth where it covers and the floor's beyond,
    and the variance vanishes away from the outlines."""
    mesh, _, _, light = shadow_scene("floor_view")
    moments, to_ls = moment_map(mesh, light, 32, sigma=0.05, blur=0.0, region=mesh.verts[OCCLUDER])
    xy, z = to_ls(mesh.verts[OCCLUDER].mean(0, keepdim=True))              # the occluder's centroid
    j, i = int(xy[0, 0]), int(xy[0, 1])
    tri_z = to_ls(mesh.verts[OCCLUDER])[1]
    assert float(tri_z.min()) - 1e-9 <= float(moments[i, j, 0]) <= float(tri_z.max()) + 1e-9
    assert float(moments[i, j, 1] - moments[i, j, 0] ** 2) < 1e-6
    corner_z = float(moments[0, 0, 0])                                      # no occluder there: the floor
    assert corner_z > float(tri_z.max()) + 1.0


def test_image_and_gradient_approach_the_exact_ones():
    """On the floor seen alone, the VSM image's error to the exact image falls with the map's resolution, and
    with a sharp map its gradient w.r.t. the occluder and the light points the exact one's way."""
    mesh, cam, colors, light = shadow_scene("floor_view", 16)
    w = torch.rand(16, 16, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    exact_image = shadowed_coverage(mesh, cam, colors, light)
    errors = []
    for res in (32, 128):
        image = shadow_map_image(mesh, cam, colors, light, resolution=res, blur=0.5, supersample=4,
                                 region=mesh.verts[OCCLUDER])
        errors.append(float((image - exact_image).abs().mean()))
    assert errors[1] < errors[0] / 4 and errors[1] < 2e-3
    verts, d = mesh.verts.clone().requires_grad_(), light.clone().requires_grad_()
    image = shadow_map_image(Mesh(verts, mesh.faces), cam, colors, d, resolution=128, blur=0.5, supersample=4,
                             region=mesh.verts[OCCLUDER])
    (image * w).sum().backward()
    g = torch.cat([verts.grad[OCCLUDER].reshape(-1), d.grad])
    ge = shadow_image_gradient(mesh, cam, colors, light, w, method="exact", wrt=("verts", "light"))
    ge = torch.cat([ge[0][OCCLUDER].reshape(-1), ge[1]])
    assert torch.isfinite(g).all()
    assert float(g @ ge / (g.norm() * ge.norm())) > 0.9                    # cosine similarity


def test_bad_input():
    mesh, cam, colors, light = shadow_scene("floor_view", 8)
    with pytest.raises(ValueError, match="resolution"):
        moment_map(mesh, light, 4)
    with pytest.raises(ValueError, match="sigma"):
        moment_map(mesh, light, 16, sigma=0.0)
    with pytest.raises(ValueError, match="blur"):
        moment_map(mesh, light, 16, blur=-1.0)
    with pytest.raises(ValueError, match="supersample"):
        shadow_map_image(mesh, cam, colors, light, supersample=0)


def test_bench_rows():
    """``bench shadow-gradients`` on a tiny setting: Reynolds equals exact to rounding, central differences to
    their error, the VSM rows carry an image error."""
    from course.bench.shadow_gradients import measure
    rows = measure(size=8, repeat=1, resolutions=(32,), blurs=(1.0,), samples=(200,))
    by = {r["method"]: r for r in rows}
    assert by["exact"]["error"] == 0 and by["reynolds"]["error"] < 1e-9
    assert by["finite_differences"]["error"] < 1e-5
    assert 0 < by["vsm blur 1"]["error"] and by["vsm blur 1"]["image_error"] > 0
    assert all(r["ms"] > 0 for r in rows)


@pytest.mark.parametrize("name", ["floater", "box", "floor_view"])
def test_the_light_gradient_is_the_derivative_of_the_image(name):
    """The map is placed from the light (its frame, its bounding box, its texel size, the background's depth), and
    the blur and the coverage's softness are in texels: autograd differentiates the placement too. Placed under
    no_grad, the light gradient was 40-80 % off central differences of the same image (floater: [1.49, -0.16,
    -3.02] against [3.64, -0.08, -5.84])."""
    mesh, cam, colors, light = shadow_scene(name, 12)
    w = torch.rand(12, 12, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)

    def f(lt):
        return (shadow_map_image(mesh, cam, colors, lt, resolution=25) * w).sum()   # 24: a shading point
    # lands on a texel centre's column, where bilinear lookup has a kink (central differences average its sides)
    lt = light.clone().requires_grad_()
    f(lt).backward()
    for h in (1e-5, 1e-6):                                                  # converged: both steps agree
        fd = torch.stack([(f(light + e) - f(light - e)) / (2 * h)
                          for e in torch.eye(3, dtype=torch.float64) * h])
        assert torch.allclose(lt.grad, fd, rtol=1e-5, atol=1e-6), (lt.grad, fd)


def test_the_gradient_of_an_occluder_vertex_on_the_maps_bounding_box():
    """A vertex that bounds the map moves the map: its gradient holds that part too (floor_view's occluder lies
    off camera, so the image's dependence on it is the shadow's alone)."""
    mesh, cam, colors, light = shadow_scene("floor_view", 12)
    w = torch.rand(12, 12, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64)

    def f(v):
        return (shadow_map_image(Mesh(v, mesh.faces), cam, colors, light, resolution=25, region=v[3:]) * w).sum()
    v = mesh.verts.clone().requires_grad_()
    f(v).backward()
    h = 1e-6
    for i in range(3, 6):
        fd = torch.stack([(f(mesh.verts + e) - f(mesh.verts - e)) / (2 * h)
                          for e in (torch.eye(3, dtype=torch.float64) * h)[:, None, :] * (torch.arange(6) == i)[None, :, None]])
        assert torch.allclose(v.grad[i], fd, rtol=1e-5, atol=1e-6), (i, v.grad[i], fd)
