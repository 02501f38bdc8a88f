"""Shadows in render(): a shadow pass only for lights that cast shadows, only when something lit is seen;
a light's direct term weighted per pixel by the shadow map, ambient light never shadowed."""
import pytest
import torch

from course.camera import Camera
from course.mesh import Mesh
from course.models import cube, plane
from course.render import RenderSettings, Scene, render
from course.shading import AmbientLight, DirectionalLight, PointLight

# every test runs on the compiled kernels and on the torch path (tests/conftest.py)
pytestmark = pytest.mark.usefixtures("both_backends")

F64 = torch.float64


def box_over_ground():
    ground = plane(6.0, 1, dtype=F64)
    box = cube(1.0, dtype=F64)
    box = Mesh(box.verts + torch.tensor([0.0, 1.0, 0.0], dtype=F64), box.faces)   # floats 0.5 above the ground
    cam = Camera.look_at((0.0, 6.0, 0.01), (0.0, 0.0, 0.0), fov_y=50.0, width=64, height=64).to(dtype=F64)
    return [box, ground], cam


def test_a_box_shadows_the_ground_below_it_and_only_the_direct_light_is_removed():
    meshes, cam = box_over_ground()
    sun = DirectionalLight(direction=(0.0, -1.0, 0.0), intensity=0.8)
    sc = Scene(meshes, cam, lights=(AmbientLight(intensity=0.25), sun), background=(0.0, 0.0, 0.0))
    plain = render(sc, RenderSettings(shading="phong"))
    shadowed = render(sc, RenderSettings(shading="phong", shadows="map", shadow_resolution=256))
    assert "shadow_maps" in shadowed.passes and "shadow_maps" not in plain.passes
    # seen from straight above, the box hides its own shadow; a ring around it is ground, lit in both
    diff = (plain.image - shadowed.image).abs().sum(-1)
    assert diff.max() < 1e-6 or (diff > 1e-3).float().mean() < 0.05
    # tilt the sun: the shadow falls beside the box, on visible ground
    tilted = DirectionalLight(direction=(1.0, -1.0, 0.0), intensity=0.8)
    sc = Scene(meshes, cam, lights=(AmbientLight(intensity=0.25), tilted), background=(0.0, 0.0, 0.0))
    plain = render(sc, RenderSettings(shading="phong", clamp=False))
    ambient_only = render(Scene(meshes, cam, lights=(AmbientLight(intensity=0.25),)), RenderSettings(
        shading="phong", clamp=False)).image
    shadowed = render(sc, RenderSettings(shading="phong", shadows="map", shadow_resolution=256, clamp=False))
    darker = (plain.image - shadowed.image).sum(-1) > 1e-3
    assert darker.float().mean() > 0.02                                     # a shadow is there
    assert (shadowed.image <= plain.image + 1e-9).all()                     # never brighter
    # in the shadow only the ambient term is left
    torch.testing.assert_close(shadowed.image[darker], ambient_only[darker], atol=1e-9, rtol=0)
    # the shadow lies on the side the light travels to (+x: the right of the image, seen from above)
    cols = darker.nonzero()[:, 1].double()
    assert cols.mean() > 32


@pytest.mark.parametrize("shading", ["flat", "gouraud", "phong"])
def test_unoccluded_light_gives_the_unshadowed_image(shading):
    """A single plane lit from above cannot shadow itself: with shadows on, the image is the same."""
    ground = plane(4.0, 2, dtype=F64)
    cam = Camera.look_at((0.5, 3.0, 2.0), (0.0, 0.0, 0.0), fov_y=50.0, width=32, height=32).to(dtype=F64)
    sc = Scene(ground, cam, lights=(AmbientLight(intensity=0.2), DirectionalLight(direction=(0.2, -1.0, 0.1)),
                                    PointLight(position=(0.0, 2.0, 0.0), intensity=2.0)))
    a = render(sc, RenderSettings(shading=shading)).image
    b = render(sc, RenderSettings(shading=shading, shadows="map", shadow_resolution=128, shadow_pcf=3)).image
    c = render(sc, RenderSettings(shading=shading, shadows="rays")).image
    torch.testing.assert_close(a, b, atol=1e-6, rtol=0)
    torch.testing.assert_close(a, c, atol=1e-6, rtol=0)


def test_shadow_maps_and_shadow_rays_agree_away_from_the_outline():
    """The same scene, the same shading: a 1024² shadow map and exact shadow rays differ only along the
    shadow's outline (the map's texels), on a small fraction of the pixels."""
    from course.models import teapot
    pot = teapot(4, dtype=F64)
    ground = plane(3.0, 1, dtype=F64)
    ground = Mesh(ground.verts + torch.tensor([0.0, float(pot.verts[:, 1].min()), 0.0], dtype=F64), ground.faces)
    cam = Camera.look_at((1.5, 2.0, 3.0), (0.0, 0.0, 0.0), fov_y=40.0, width=64, height=64).to(dtype=F64)
    for light in (DirectionalLight(direction=(0.5, -1.0, -0.3)), PointLight(position=(1.0, 2.0, 0.5), intensity=4.0)):
        sc = Scene([pot, ground], cam, lights=(AmbientLight(intensity=0.2), light))
        none = render(sc, RenderSettings(clamp=False)).image
        by_map = render(sc, RenderSettings(shadows="map", clamp=False))
        by_rays = render(sc, RenderSettings(shadows="rays", clamp=False))
        assert "shadow_rays" in by_rays.passes and "shadow_maps" not in by_rays.passes
        shadowed = (none - by_rays.image).sum(-1) > 0.05
        assert shadowed.float().mean() > 0.03                               # the pot shadows the ground
        differ = (by_map.image - by_rays.image).abs().sum(-1) > 0.05
        assert differ.float().mean() < 0.25 * shadowed.float().mean()


def test_shadow_pass_skipped_where_not_needed():
    meshes, cam = box_over_ground()
    no_cast = DirectionalLight(direction=(1.0, -1.0, 0.0), cast_shadows=False)
    sc = Scene(meshes, cam, lights=(AmbientLight(), no_cast))
    r = render(sc, RenderSettings(shadows="map"))
    assert "shadow_maps" not in r.passes
    assert torch.equal(r.image, render(sc, RenderSettings()).image)
    lit = Scene(meshes, cam, lights=(AmbientLight(), DirectionalLight(direction=(1.0, -1.0, 0.0))))
    assert "shadow_maps" not in render(lit, RenderSettings(shading="unlit", shadows="map")).passes
    away = Camera.look_at((0.0, 6.0, 0.01), (0.0, 12.0, 0.0), fov_y=30.0, width=16, height=16).to(dtype=F64)
    empty = render(Scene(meshes, away, lights=lit.lights), RenderSettings(shadows="map"))
    assert "shadow_maps" not in empty.passes                               # nothing visible receives it


def test_bad_shadow_settings():
    with pytest.raises(ValueError, match="shadows must be one of"):
        RenderSettings(shadows="soft")
    assert RenderSettings(shadows="rays").shadows == "rays"
    with pytest.raises(ValueError, match="shadow_pcf"):
        RenderSettings(shadows="map", shadow_pcf=2)
    with pytest.raises(ValueError, match="shadow_resolution"):
        RenderSettings(shadows="map", shadow_resolution=0)
