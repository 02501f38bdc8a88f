"""A camera from the course's own images (issue 23): soft rasterization of textures and of the alpha blend, the
camera fit against ``render()`` references, its pyramid and its search over starts, and its errors."""
import math

import pytest
import torch

from course import models
from course.camera import Camera, axis_angle_to_matrix
from course.inverse import shaded_face_colors
from course.inverse.pose import _area, _candidate_starts, _pyramid, camera_problem, fit_camera, rotation_error
from course.mesh import Mesh
from course.raster import interpolate, rasterize
from course.render import RenderSettings, Scene, default_lights, render
from course.soft import soft_rasterize
from course.textures import sample_texture
from screen_helpers import far_from_edges

SHARP = dict(sigma=1e-8, gamma=1e-4, threshold=1e-8)        # σ = γ² → 0: the soft image tends to the hard one


def teapot_scene(size=32, lights=True):
    mesh = models.teapot(2, dtype=torch.float64)
    cam = Camera.look_at((1.5, 1.0, 2.5), fov_y=40, width=size, height=size, dtype=torch.float64)
    return Scene(mesh, cam, lights=default_lights() if lights else ())


# ------------------------------------------------------------------------------ soft rasterization: textures

def test_soft_texture_is_the_hard_lookup_away_from_edges():
    """Read per pixel and face at its perspective-correct barycentrics, the texture of the sharp soft image is
    the hard rasterizer's lookup (interpolated uvs, bilinear) wherever no edge is within a pixel."""
    scene = teapot_scene(64)
    mesh, cam = scene.meshes[0], scene.camera
    frags = rasterize(mesh, cam, cull_backfaces=True)
    hard = sample_texture(mesh.texture, interpolate(mesh.uvs, frags, mesh.faces))           # (H, W, 3)
    soft = soft_rasterize(mesh, cam, mode="color", texture=mesh.texture, uvs=mesh.uvs, **SHARP)
    mask = far_from_edges(mesh, cam) & frags.mask
    assert mask.sum() > 100
    assert (soft - hard)[mask].abs().max() < 1e-3


@pytest.mark.parametrize("shading", ["flat", "gouraud", "unlit"])
def test_soft_render_of_a_textured_scene_tends_to_the_hard_render(shading):
    """render()'s soft path draws the texture times the lighting; at σ = γ² → 0 it is the hard render() image
    away from edges (flat and Gouraud light the same points in both)."""
    scene = teapot_scene(64)
    hard = render(scene, RenderSettings(shading=shading, cull_backfaces=True)).image
    soft = render(scene, RenderSettings(shading=shading, cull_backfaces=True, visibility="soft", sigma=1e-8,
                                        gamma=1e-4, soft_threshold=1e-8))
    assert "texture" in soft.passes and "soft_rasterize" in soft.passes
    mask = far_from_edges(scene.meshes[0], scene.camera)
    assert mask.sum() > 100
    assert (soft.image - hard)[mask].abs().max() < 1e-3


def test_soft_texture_gradients_reach_texture_uvs_verts_and_camera():
    mesh = models.teapot(2, dtype=torch.float64)
    verts = mesh.verts.clone().requires_grad_(True)
    texture = mesh.texture.clone().requires_grad_(True)
    uvs = mesh.uvs.clone().requires_grad_(True)
    base = Camera.look_at((1.5, 1.0, 2.5), fov_y=40, width=24, height=24, dtype=torch.float64)
    t = base.t.clone().requires_grad_(True)
    cam = Camera(base.K, base.R, t, 24, 24, base.near, base.far)
    factor = torch.full((mesh.faces.shape[0], 3), 0.8, dtype=torch.float64, requires_grad=True)
    image = soft_rasterize(Mesh(verts, mesh.faces), cam, mode="color", sigma=1e-4, gamma=1e-2, texture=texture,
                           uvs=uvs, face_colors=factor, specular=0.1 * torch.ones_like(factor), blend="alpha")
    target = torch.rand(image.shape, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    grads = torch.autograd.grad(((image - target) ** 2).sum(), [verts, texture, uvs, t, factor])
    for g in grads:
        assert torch.isfinite(g).all() and g.abs().sum() > 0


def test_soft_texture_times_colours_plus_specular():
    """texture · colour + specular: a white texture gives the colours plus specular, exactly as without one."""
    mesh = models.teapot(2, dtype=torch.float64)
    cam = Camera.look_at((1.5, 1.0, 2.5), fov_y=40, width=16, height=16, dtype=torch.float64)
    colors = torch.rand(mesh.faces.shape[0], 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    spec = 0.2 * colors.flip(1)
    white = torch.ones(4, 4, 3, dtype=torch.float64)
    textured = soft_rasterize(mesh, cam, mode="color", sigma=1e-4, gamma=1e-2, texture=white, uvs=mesh.uvs,
                              face_colors=colors, specular=spec, background=0.3)
    plain = soft_rasterize(mesh, cam, mode="color", sigma=1e-4, gamma=1e-2, face_colors=colors + spec, background=0.3)
    assert torch.allclose(textured, plain, atol=1e-12)


def test_alpha_blend_is_the_silhouette_over_the_background():
    """One colour for every face: the alpha blend is exactly α c + (1 - α) background, α the soft silhouette,
    so no face outweighs the background beyond its edge; the softmax blend spreads the colour far wider."""
    mesh = models.icosphere(2, dtype=torch.float64)
    cam = Camera.look_at((0.0, 0.0, 3.0), fov_y=40, width=24, height=24, dtype=torch.float64)
    c = torch.tensor([0.9, 0.5, 0.1], dtype=torch.float64)
    colors = c.expand(mesh.faces.shape[0], 3)
    bg = torch.tensor([0.1, 0.2, 0.3], dtype=torch.float64)
    opts = dict(sigma=3e-3, gamma=1e-4)
    alpha = soft_rasterize(mesh, cam, mode="silhouette", sigma=opts["sigma"])[..., None]
    blended = soft_rasterize(mesh, cam, mode="color", face_colors=colors, background=bg, blend="alpha", **opts)
    assert torch.allclose(blended, alpha * c + (1 - alpha) * bg, atol=1e-12)
    softmax = soft_rasterize(mesh, cam, mode="color", face_colors=colors, background=bg, **opts)
    outside = alpha[..., 0] < 0.05                                           # well outside the silhouette
    assert (softmax - bg)[outside].abs().max() > 0.5 and (blended - bg)[outside].abs().max() < 0.05


def test_soft_texture_bad_inputs():
    mesh = models.teapot(2, dtype=torch.float64)
    cam = Camera.look_at((1.5, 1.0, 2.5), fov_y=40, width=8, height=8, dtype=torch.float64)
    tex, uvs = mesh.texture, mesh.uvs
    F = mesh.faces.shape[0]
    with pytest.raises(ValueError, match="uvs"):
        soft_rasterize(mesh, cam, mode="color", texture=tex)
    with pytest.raises(ValueError, match="uvs must have shape"):
        soft_rasterize(mesh, cam, mode="color", texture=tex, uvs=uvs[:5])
    with pytest.raises(ValueError, match="channels"):
        soft_rasterize(mesh, cam, mode="color", texture=tex, uvs=uvs, face_colors=torch.ones(F, 1))
    with pytest.raises(ValueError, match="specular needs"):
        soft_rasterize(mesh, cam, mode="color", texture=tex, uvs=uvs, specular=torch.ones(F, 3))
    with pytest.raises(ValueError, match="specular must have the shape"):
        soft_rasterize(mesh, cam, mode="color", face_colors=torch.ones(F, 3), specular=torch.ones(F, 2))
    with pytest.raises(ValueError, match="silhouette"):
        soft_rasterize(mesh, cam, mode="silhouette", texture=tex, uvs=uvs)
    with pytest.raises(ValueError, match="blend"):
        soft_rasterize(mesh, cam, mode="color", face_colors=torch.ones(F, 3), blend="over")
    with pytest.raises(ValueError, match="soft_blend"):
        RenderSettings(visibility="soft", soft_blend="over")
    two = Scene([mesh, mesh], cam)
    with pytest.raises(ValueError, match="join_meshes"):
        render(two, RenderSettings(visibility="soft"))


# ---------------------------------------------------------------------------------- the fit's machinery

def test_pyramid_and_area():
    assert _pyramid(96, 96, 4) == [(12, 12), (24, 24), (48, 48), (96, 96)]
    assert _pyramid(32, 32, 4) == [(16, 16), (32, 32)]                       # no level below 12 pixels
    assert _pyramid(8, 8, 4) == [(8, 8)] and _pyramid(64, 64, 1) == [(64, 64)]
    image = torch.rand(8, 6, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    small = _area(image, (4, 3))
    assert small.shape == (4, 3, 3) and torch.allclose(small[0, 0], image[:2, :2].mean((0, 1)))
    assert torch.allclose(small.mean((0, 1)), image.mean((0, 1)))


def test_candidate_starts_orbit_about_the_target():
    cam = Camera.look_at((1.5, 1.0, 2.5), fov_y=40, width=16, height=16, dtype=torch.float64)
    target = torch.zeros(3, dtype=torch.float64)
    starts = _candidate_starts(cam, 7, 30.0, target)
    assert len(starts) == 7 and starts[0] is cam
    for s in starts[1:]:
        assert rotation_error(s.R, cam.R) == pytest.approx(30.0, abs=1e-9)
        assert float(s.eye.norm()) == pytest.approx(float(cam.eye.norm()), rel=1e-12)   # an orbit: same distance
    assert len(_candidate_starts(cam, 3, 30.0, target)) == 3


def test_camera_problem_textured_is_the_render_of_its_scene():
    mesh, scene, ref_cam, start, image = camera_problem(size=24, textured=True)
    assert isinstance(scene, Scene) and scene.camera is ref_cam and scene.lights
    assert image.shape == (24, 24, 3) and torch.equal(image, render(scene).image)
    assert rotation_error(start.R, ref_cam.R) == pytest.approx(30.0, abs=1e-6)
    with pytest.raises(ValueError, match="texture"):
        camera_problem(models.cube(dtype=torch.float64), textured=True)


# --------------------------------------------------------------------------------------- the camera fit

def _tilted_start(ref_cam, degrees, axis):
    """The reference camera orbited about the origin by ``degrees`` about the world ``axis`` (roll included)."""
    a = torch.tensor(axis, dtype=torch.float64)
    Q = axis_angle_to_matrix(a / a.norm() * math.radians(degrees))
    return Camera(ref_cam.K, ref_cam.R @ Q, ref_cam.t, ref_cam.width, ref_cam.height, ref_cam.near, ref_cam.far)


def test_textured_render_reference_recovered_from_40_degrees():
    """The course's full pipeline as the reference (texture, lights, Phong shading, render()), a start 40° away
    about a tilted axis: the fit lands within 2° and 2 % of the viewing distance."""
    mesh, scene, ref_cam, _, image = camera_problem(size=64, textured=True)
    start = _tilted_start(ref_cam, 40.0, (0.6, -0.5, -0.6))
    r = fit_camera(scene, image, start, reference_camera=ref_cam, steps=120, starts=3, progress=False,
                   snapshot_every=None)
    assert r.history.metrics["rotation_deg"][0] > 10.0
    assert r.rotation_error_deg <= 2.0 and r.center_error_pct <= 2.0, (r.rotation_error_deg, r.center_error_pct)


def test_search_picks_the_start_nearest_the_answer():
    """Panned 30° about the camera's own y axis, the start has an exact answer among its orbits: the search
    ranks the starts by their coarse loss and goes on from that one."""
    mesh, colors, ref_cam, _, image = camera_problem(size=32)
    start = _candidate_starts(ref_cam, 2, 30.0, torch.zeros(3, dtype=torch.float64))[1]    # ref panned +30°
    r = fit_camera(mesh, image, start, face_colors=colors, reference_camera=ref_cam, steps=40, starts=3,
                   progress=False, snapshot_every=20)
    assert rotation_error(start.R, ref_cam.R) == pytest.approx(30.0, abs=1e-9)
    assert r.history.metrics["rotation_deg"][0] < 1e-6                      # the winner started at the answer
    assert r.rotation_error_deg < 2.0
    assert len(r.history.loss) == 40 and r.history.snapshot_steps == [0, 20, 40]
    assert all(s.shape == (32, 32, 3) for s in r.history.snapshots)         # full size, whatever the level


def test_nmr_and_hard_fit_a_scene():
    mesh, scene, ref_cam, start, image = camera_problem(models.teapot(2, dtype=torch.float64), size=16,
                                                        textured=True)
    r = fit_camera(scene, image, start, method="nmr", steps=2, reference_camera=ref_cam, progress=False)
    assert len(r.history.loss) == 2 and all(math.isfinite(x) for x in r.history.loss)
    hard = fit_camera(scene, image, start, method="hard", steps=2, progress=False)
    assert torch.equal(hard.camera.R, start.R)                              # zero gradient: it never moves


def test_fit_camera_scene_errors():
    mesh, scene, ref_cam, start, image = camera_problem(models.teapot(2, dtype=torch.float64), size=16,
                                                        textured=True)
    for method in ("reynolds", "edge_sampling"):
        with pytest.raises(ValueError, match="shaded_face_colors"):
            fit_camera(scene, image, start, method=method, steps=1, progress=False)
    with pytest.raises(ValueError, match="shaded_face_colors|Scene"):
        fit_camera(mesh, image, start, steps=1, progress=False)             # a render() image, no colours
    with pytest.raises(ValueError, match="face_colors"):
        fit_camera(scene, image, start, face_colors=shaded_face_colors(mesh), steps=1, progress=False)
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        fit_camera(scene, image[..., 0], start, steps=1, progress=False)
    with pytest.raises(ValueError, match="shadows"):
        fit_camera(scene, image, start, render_settings=RenderSettings(shadows="map"), steps=1, progress=False)
    with pytest.raises(ValueError, match="render_settings"):
        fit_camera(mesh, image, start, face_colors=shaded_face_colors(mesh), render_settings=RenderSettings(),
                   steps=1, progress=False)
    colors = shaded_face_colors(mesh)
    for bad in (dict(starts=0), dict(starts=8), dict(levels=0), dict(search_steps=5), dict(spread=0.0),
                dict(supersample=0)):
        with pytest.raises(ValueError, match=next(iter(bad))):
            fit_camera(mesh, image, start, face_colors=colors, steps=2, progress=False, **bad)
