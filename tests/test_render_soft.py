"""render() with visibility="nmr" and "soft" (lecture 08): the same scenes, differentiable visibility."""
import pytest
import torch

from course.camera import Camera
from course.mesh import Mesh
from course.models import icosphere
from course.raster import rasterize
from course.render import RenderSettings, Scene, render
from course.shading import AmbientLight, DirectionalLight, Material
from screen_helpers import far_from_edges


def sphere_scene(size=32, requires_grad=False, colors=False):
    mesh = icosphere(2, dtype=torch.float64)
    verts = mesh.verts.clone().requires_grad_(requires_grad)
    vc = None
    if colors:
        vc = (0.5 + 0.4 * torch.sin(3 * mesh.verts)).requires_grad_(requires_grad)
    mesh = Mesh(verts, mesh.faces, vert_colors=vc)
    cam = Camera.look_at((0.4, 0.5, 3.0), (0.0, 0.0, 0.0), fov_y=40.0, width=size, height=size,
                         dtype=torch.float64)
    lights = (AmbientLight(intensity=0.3), DirectionalLight(direction=(0.3, -0.5, -1.0), intensity=0.8))
    return Scene([mesh], cam, lights=lights, materials=Material(specular=0.2), background=(0.1, 0.2, 0.3))


@pytest.mark.parametrize("shading", ["gouraud", "flat", "unlit"])
def test_soft_tends_to_the_hard_image_away_from_edges(shading):
    """Along σ = γ² → 0 the soft image equals the hard one at pixels more than a pixel from any edge (Gouraud
    and flat shading light the same points in both; unlit shows the interpolated vertex colours)."""
    scene = sphere_scene(colors=shading == "unlit")
    hard = render(scene, RenderSettings(shading=shading, cull_backfaces=True)).image
    soft = render(scene, RenderSettings(shading=shading, cull_backfaces=True, visibility="soft", sigma=1e-8,
                                        gamma=1e-4, soft_threshold=1e-8))
    assert "soft_rasterize" in soft.passes and "rasterize" not in soft.passes
    mask = far_from_edges(scene.meshes[0], scene.camera)
    assert mask.sum() > 100
    assert (soft.image - hard)[mask].abs().max() < 1e-3


def test_soft_gradients_reach_verts_colors_and_camera():
    scene = sphere_scene(requires_grad=True, colors=True)
    cam = scene.camera
    t = cam.t.clone().requires_grad_(True)
    K = cam.K.clone().requires_grad_(True)
    scene.camera = Camera(K, cam.R, t, cam.width, cam.height, near=cam.near, far=cam.far)
    for shading in ("phong", "unlit"):
        out = render(scene, RenderSettings(shading=shading, visibility="soft", sigma=1e-4, gamma=1e-2,
                                           return_silhouette=True))
        target = torch.rand(out.image.shape, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
        loss = ((out.image - target) ** 2).sum() + out.silhouette.sum()
        gv, gc, gt, gk = torch.autograd.grad(loss, [scene.meshes[0].verts, scene.meshes[0].vert_colors, t, K])
        for g in (gv, gc, gt, gk):
            assert torch.isfinite(g).all() and g.abs().sum() > 0
        assert gk[0, 0] != 0                                                 # the focal length


def test_nmr_keeps_the_hard_image_and_adds_a_silhouette_gradient():
    scene = sphere_scene(requires_grad=True)
    hard = render(scene, RenderSettings(shading="silhouette", return_silhouette=True))
    nmr = render(scene, RenderSettings(shading="silhouette", return_silhouette=True, visibility="nmr"))
    assert torch.equal(hard.image, nmr.image) and torch.equal(hard.silhouette, nmr.silhouette)
    assert "nmr" in nmr.passes
    assert not hard.silhouette.requires_grad                                 # the z-buffer: no gradient at all
    g_nmr, = torch.autograd.grad(nmr.silhouette.sum(), scene.meshes[0].verts)
    assert torch.isfinite(g_nmr).all() and g_nmr.abs().sum() > 0
    # growing the silhouette: the outward radial component of the gradient dominates
    v = scene.meshes[0].verts.detach()
    assert (g_nmr * v).sum() > 0
    # no gradient asked: no NMR pass
    with torch.no_grad():
        assert "nmr" not in render(scene, RenderSettings(visibility="nmr")).passes


def test_soft_and_nmr_reject_what_they_cannot_draw():
    with pytest.raises(ValueError, match="shadows"):
        RenderSettings(visibility="soft", shadows="map")
    with pytest.raises(ValueError, match="antialias"):
        RenderSettings(visibility="soft", antialias="supersample")
    with pytest.raises(ValueError, match="shading"):
        RenderSettings(visibility="soft", shading="depth")
    with pytest.raises(ValueError, match="antialias='none'"):
        RenderSettings(visibility="nmr", antialias="adaptive")
    with pytest.raises(ValueError, match="visibility"):
        RenderSettings(visibility="fuzzy")
    for name in ("sigma", "gamma", "soft_threshold"):
        with pytest.raises(ValueError, match=name):
            RenderSettings(visibility="soft", **{name: 0.0})


def test_soft_returns_depth_and_normals_from_the_hard_fragments_when_asked():
    scene = sphere_scene()
    out = render(scene, RenderSettings(visibility="soft", return_depth=True, shading="flat"))
    frags = rasterize(scene.meshes[0], scene.camera)
    assert "rasterize" in out.passes and torch.equal(out.depth, frags.depth)
    assert out.image.shape == (32, 32, 3) and torch.isfinite(out.image).all()
