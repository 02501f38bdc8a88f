"""render(): what each shading mode draws, that every skipped pass changes nothing, errors and the CLI."""
import numpy as np
import pytest
import torch
from PIL import Image

from course.camera import Camera
from course.mesh import Mesh
from course.models import cube, default_scene_mesh, icosphere, plane
from course.render import (
    SHADING_MODES, RenderSettings, Scene, default_lights, frame_camera, plan_passes, render,
)
from course.render_cli import cli
from course.shading import AmbientLight, DirectionalLight, Material, PointLight


def front_ortho(size=32, height=4.0, dtype=torch.float32):
    """Orthographic camera on +z looking at the origin; the image spans ``height`` world units."""
    return Camera.look_at((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), ortho_height=height, width=size, height=size,
                          near=1.0, far=10.0, dtype=dtype)


def oblique(mesh, size=32):
    return frame_camera(mesh, width=size, height=size, direction=(0.7, 0.5, 1.0))


LIGHTS = (AmbientLight(intensity=0.2), DirectionalLight((0.3, -0.6, -1.0)), PointLight((1.0, 2.0, 3.0), intensity=8.0))


# -------------------------------------------------------------------------------------------- what is drawn

def test_unlit_cube_silhouette_area_and_background():
    # the cube spans [-1, 1]²: pixel edges 8 and 24 of a 32-pixel image 4 units high → 16 × 16 pixels
    result = render(Scene(cube(), front_ortho(), background=(0.1, 0.2, 0.3)),
                    RenderSettings(shading="unlit", return_silhouette=True, return_depth=True))
    assert result.silhouette.sum().item() == 256
    assert result.silhouette[8:24, 8:24].all()
    outside = result.silhouette == 0
    torch.testing.assert_close(result.image[outside], torch.tensor([0.1, 0.2, 0.3]).expand(768, 3),
                               rtol=0, atol=0)
    torch.testing.assert_close(result.image[~outside], torch.tensor([0.7, 0.7, 0.7]).expand(256, 3))
    assert torch.isinf(result.depth[outside]).all() and (result.depth[~outside] == 4.0).all()
    assert result.passes == ("rasterize",)


def test_texture_orientation_end_to_end():
    # 2×2 texture on the plane seen from above, -z at the image top: texel (row 0, col 0) lands top-left
    tex = torch.tensor([[[1.0, 0, 0], [0, 1.0, 0]], [[0, 0, 1.0], [1.0, 1.0, 0]]])
    p = plane()
    mesh = Mesh(p.verts, p.faces, uvs=p.uvs, texture=tex)
    cam = Camera.look_at((0.0, 5.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, -1.0), ortho_height=2.0, width=8, height=8)
    result = render(Scene(mesh, cam), RenderSettings(shading="unlit", texture_filter="nearest"))
    img = result.image
    for (r, c), color in zip([(1, 1), (1, 6), (6, 1), (6, 6)], tex.reshape(4, 3)):
        torch.testing.assert_close(img[r, c], color)
    assert "texture" in result.passes


def test_textured_teapot_has_a_plausible_mean_colour():
    mesh = default_scene_mesh()
    result = render(Scene(mesh, oblique(mesh, 48), default_lights()), RenderSettings(return_silhouette=True))
    hit = result.silhouette > 0
    assert 0.15 < hit.float().mean() < 0.8                                   # framed: neither tiny nor cropped
    mean = result.image[hit].mean(0)
    assert ((mean > 0.1) & (mean < 0.9)).all()
    assert result.image[hit].std(0).min() > 0.05                             # a texture, not a flat fill
    assert result.passes == ("rasterize", "texture", "normals", "lighting")


def test_every_mode_renders_finite_images_in_range():
    mesh = default_scene_mesh()
    scene = Scene(mesh, oblique(mesh), default_lights())
    for mode in SHADING_MODES:
        image = render(scene, RenderSettings(shading=mode, wireframe=True)).image
        assert image.shape == (32, 32, 3) and torch.isfinite(image).all(), mode
        assert image.min() >= 0 and image.max() <= 1, mode


def test_flat_shading_gives_one_colour_per_cube_face():
    cam = frame_camera(cube(), width=48, height=48, direction=(1.0, 0.8, 1.3))
    cam = Camera(cam.K, cam.R, cam.t, 48, 48, near=cam.near, far=cam.far, orthographic=False)
    # no highlight: it depends on each triangle's centroid, so the two halves of a side would differ
    result = render(Scene(cube(), cam, [AmbientLight(), DirectionalLight((-0.2, -0.5, -0.9))], materials=Material(
        specular=0.0)), RenderSettings(shading="flat", return_normals=True))
    hit = result.fragments.mask
    colours = {tuple(np.round(c.tolist(), 5)) for c in result.image[hit]}
    assert len(colours) == 3                                                 # three visible sides
    assert len({tuple(np.round(n.tolist(), 5)) for n in result.normals[hit]}) == 3


def test_gouraud_equals_phong_on_a_flat_plane():
    cam = Camera.look_at((0.0, 5.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, -1.0), ortho_height=3.0, width=24, height=24,
                         dtype=torch.float64)
    scene = Scene(plane(dtype=torch.float64), cam, [AmbientLight(), DirectionalLight((0.3, -1.0, 0.2))])
    gouraud = render(scene, RenderSettings(shading="gouraud")).image
    phong = render(scene, RenderSettings(shading="phong")).image
    torch.testing.assert_close(gouraud, phong, rtol=0, atol=1e-12)


def test_gouraud_and_phong_differ_only_inside_faces():
    sphere = icosphere(1)
    scene = Scene(sphere, oblique(sphere), [AmbientLight(), DirectionalLight((0.2, -0.3, -1.0))],
                  materials=Material(specular=0.8, shininess=60.0))
    gouraud = render(scene, RenderSettings(shading="gouraud"))
    phong = render(scene, RenderSettings(shading="phong"))
    mask = phong.fragments.mask
    assert torch.equal(gouraud.fragments.face_id, phong.fragments.face_id)
    assert torch.equal(gouraud.image[~mask], phong.image[~mask])             # background untouched
    diff = (gouraud.image - phong.image).abs().amax(-1)
    assert diff[mask].max() > 0.05                                           # the highlight is interpolated away
    assert diff[mask].mean() < 0.1                                           # but mostly they agree


def test_wireframe_draws_visible_edges_only():
    result = render(Scene(cube(), front_ortho()), RenderSettings(shading="wireframe"))
    img = result.image[..., 0]
    assert (img[~result.fragments.mask] == 1).all()                          # background stays white
    # the border runs along pixel boundaries: a 1-pixel line covers half of each inside pixel next to it
    assert img[8, 16] == 0.5 and img[16, 8] == 0.5 and img[23, 16] == 0.5 and img[16, 23] == 0.5
    assert img[16, 12] == 1 and img[12, 16] == 1                             # inside a triangle
    diag = torch.stack([img[i, i] for i in range(9, 23)])                    # pixel centres on a diagonal
    anti = torch.stack([img[i, 31 - i] for i in range(9, 23)])
    assert (diag == 0).all() != (anti == 0).all()                            # exactly one diagonal is an edge
    assert result.passes == ("rasterize", "wireframe")


def test_multiple_meshes_join_once_with_their_own_materials():
    left = cube(1.0).transformed(torch.tensor([[1.0, 0, 0, -1], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]))
    right = icosphere(1, 0.5).transformed(torch.tensor([[1.0, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]))
    mats = [Material(base_color=(1.0, 0.0, 0.0)), Material(base_color=(0.0, 0.0, 1.0))]
    result = render(Scene([left, right], front_ortho(), materials=mats), RenderSettings(shading="silhouette"))
    torch.testing.assert_close(result.image[16, 8], torch.tensor([1.0, 0.0, 0.0]))
    torch.testing.assert_close(result.image[16, 24], torch.tensor([0.0, 0.0, 1.0]))
    assert result.passes[0] == "join"
    mats = [Material(base_color=(1.0, 0.0, 0.0), specular=0.0), Material(base_color=(0.0, 0.0, 1.0), specular=0.0)]
    lit = render(Scene([left, right], front_ortho(), LIGHTS, materials=mats), RenderSettings(shading="gouraud"))
    assert lit.image[16, 8, 2] == 0 and lit.image[16, 24, 0] == 0            # each keeps its own colour
    flat = render(Scene([left, right], front_ortho(), LIGHTS, materials=mats), RenderSettings(shading="flat"))
    assert flat.image[16, 8, 0] > 0 and flat.image[16, 24, 2] > 0


# ----------------------------------------------------------------------------- skips give the same image

def textured_scene(lights=()):
    mesh = default_scene_mesh()
    return Scene(mesh, oblique(mesh), lights)


def test_unlit_skips_normals_and_lighting_and_forcing_them_changes_nothing():
    scene = textured_scene(LIGHTS)
    skipped = render(scene, RenderSettings(shading="unlit"))
    forced = render(scene, RenderSettings(shading="unlit"), _force=("normals", "lighting", "autograd"))
    assert "normals" not in skipped.passes and "lighting" not in skipped.passes
    assert {"normals", "lighting", "autograd"} <= set(forced.passes)
    assert torch.equal(skipped.image, forced.image)


def test_a_lit_mode_without_lights_is_drawn_unlit():
    scene = textured_scene(lights=())
    phong = render(scene, RenderSettings(shading="phong"))
    assert torch.equal(phong.image, render(scene, RenderSettings(shading="unlit")).image)
    assert phong.passes == ("rasterize", "texture")


def test_silhouette_skips_texture_lookups():
    scene = textured_scene()
    skipped = render(scene, RenderSettings(shading="silhouette"))
    forced = render(scene, RenderSettings(shading="silhouette"), _force=("texture",))
    assert "texture" not in skipped.passes and "texture" in forced.passes
    assert torch.equal(skipped.image, forced.image)


def test_no_autograd_graph_unless_something_requires_grad():
    scene = textured_scene(LIGHTS)
    plain = render(scene)
    assert "autograd" not in plain.passes and not plain.image.requires_grad
    graphed = render(scene, _force=("autograd",))
    assert torch.equal(plain.image, graphed.image)


def test_culling_back_faces_of_a_closed_mesh_changes_nothing():
    sphere = icosphere(2)
    scene = Scene(sphere, oblique(sphere), LIGHTS)
    culled = render(scene, RenderSettings(cull_backfaces=True))
    assert "cull_backfaces" in culled.passes
    assert torch.equal(culled.image, render(scene).image)


def test_plan_passes_lists_stages_in_order():
    scene = textured_scene(LIGHTS)
    assert plan_passes(scene, RenderSettings(wireframe=True, cull_backfaces=True)) == (
        "cull_backfaces", "rasterize", "texture", "normals", "lighting", "wireframe")
    assert plan_passes(scene, RenderSettings(shading="depth")) == ("rasterize",)


def test_nothing_visible_returns_the_background_without_shading():
    cam = Camera.look_at((0.0, 0.0, 5.0), (0.0, 0.0, 10.0), fov_y=40.0, width=8, height=8)   # looking away
    result = render(Scene(cube(), cam, LIGHTS, background=(0.0, 1.0, 0.0)))
    assert (result.image == torch.tensor([0.0, 1.0, 0.0])).all()
    assert result.passes == ("rasterize",)


# --------------------------------------------------------------------------------- gradients and dtypes

def test_gradients_reach_vertices_camera_light_and_material():
    sphere = icosphere(1)
    verts = sphere.verts.clone().requires_grad_()
    light_pos = torch.tensor([1.0, 2.0, 3.0], requires_grad=True)
    shininess = torch.tensor(20.0, requires_grad=True)
    scene = Scene(Mesh(verts, sphere.faces), oblique(sphere), [PointLight(light_pos, intensity=8.0)],
                  materials=Material(shininess=shininess))
    result = render(scene, RenderSettings(clamp=False))
    assert "autograd" in result.passes and result.image.requires_grad
    result.image.sum().backward()
    for g in (verts.grad, light_pos.grad, shininess.grad):
        assert torch.isfinite(g).all() and g.abs().sum() > 0


def test_float32_matches_float64():
    sphere32, sphere64 = icosphere(2), icosphere(2, dtype=torch.float64)
    cam32 = oblique(sphere32)
    cam64 = cam32.to(dtype=torch.float64)
    img32 = render(Scene(sphere32, cam32, LIGHTS)).image
    img64 = render(Scene(sphere64, cam64, LIGHTS)).image
    assert img64.dtype == torch.float64 and img32.dtype == torch.float32
    torch.testing.assert_close(img32.double(), img64, atol=1e-4, rtol=0)


# ------------------------------------------------------------------------------------------------ errors

def test_bad_scenes_and_settings_raise_clear_errors():
    cam = front_ortho(8)
    with pytest.raises(ValueError, match="no meshes"):
        Scene([], cam)
    with pytest.raises(TypeError, match="Camera"):
        Scene(cube(), "camera")
    with pytest.raises(TypeError, match="not a Mesh"):
        Scene([cube(), "teapot"], cam)
    with pytest.raises(ValueError, match="background must be 3 numbers"):
        Scene(cube(), cam, background=(1.0, 1.0))
    with pytest.raises(ValueError, match="phong, gouraud, flat, unlit"):
        RenderSettings(shading="toon")
    with pytest.raises(ValueError, match="one Material or one per mesh"):
        Scene(cube(), cam, materials=[Material(), Material()])
    with pytest.raises(ValueError, match="float64 but the camera is torch.float32"):
        Scene(cube(dtype=torch.float64), cam)
    empty = front_ortho(8)
    empty.width = 0
    with pytest.raises(ValueError, match="image is empty"):
        Scene(cube(), empty)
    with pytest.raises(ValueError, match="cannot force"):
        render(Scene(cube(), cam), _force=("shadows",))


# --------------------------------------------------------------------------------------------------- CLI

def test_cli_renders_the_default_scene(tmp_path, capsys):
    out = tmp_path / "teapot.png"
    assert cli(["--out", str(out), "--size", "40", "32", "--wireframe"]) == 0
    with Image.open(out) as img:
        assert img.size == (40, 32) and img.mode == "RGB"
        pixels = np.asarray(img)
    assert pixels.min() < 128 and pixels.max() == 255                        # a teapot on white
    assert str(out) in capsys.readouterr().out


def test_cli_renders_a_mesh_file(tmp_path):
    import trimesh
    path = tmp_path / "box.obj"
    box = cube()
    trimesh.Trimesh(box.verts.numpy(), box.faces.numpy(), process=False).export(path)
    out = tmp_path / "box.png"
    args = [str(path), "--out", str(out), "--width", "24", "--shading", "flat", "--background", "0", "0", "0",
            "--eye", "3", "2", "4", "--fov", "50"]
    assert cli(args) == 0
    with Image.open(out) as img:
        assert img.size == (24, 24)
        assert np.asarray(img)[0, 0].tolist() == [0, 0, 0]                   # the chosen background


def test_cli_reports_a_missing_file_in_one_line(tmp_path, capsys):
    code = cli([str(tmp_path / "nope.obj"), "--out", str(tmp_path / "x.png")])
    err = capsys.readouterr().err
    assert code == 1 and "nope.obj" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.png").exists()


def test_cli_reports_an_unreadable_file_and_bad_sizes(tmp_path, capsys):
    bad = tmp_path / "bad.obj"
    bad.write_text("this is not a mesh\n")
    assert cli([str(bad), "--out", str(tmp_path / "x.png")]) == 1
    assert cli(["--out", str(tmp_path / "x.png"), "--size", "0", "8"]) == 1
    assert cli(["--out", str(tmp_path / "no_dir" / "x.png"), "--size", "8", "8"]) == 1
    err = capsys.readouterr().err
    assert err.count("error:") == 3 and "Traceback" not in err
    assert cli(["--shading", "toon", "--out", "x.png"]) == 2                 # argparse usage error
