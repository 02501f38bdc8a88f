"""sRGB (IEC 61966-2-1): the transfer curves, and where the course applies them — PNG output, display and
texture loading — while all shading stays linear."""
import numpy as np
import pytest
import torch
from PIL import Image

from course.shading import linear_to_srgb, srgb_to_linear

D = torch.float64


def reference_encode(x: float) -> float:
    """The standard's piecewise curve, written out once more in plain Python."""
    return 12.92 * x if x <= 0.0031308 else 1.055 * x ** (1 / 2.4) - 0.055


# ------------------------------------------------------------------------------------------- the curves

@pytest.mark.parametrize("linear, encoded", [(0.0, 0.0), (1.0, 1.0), (0.5, 0.735357), (0.18, 0.461356),
                                             (0.002, 0.02584), (0.214041, 0.5)])
def test_known_values(linear, encoded):
    assert float(linear_to_srgb(torch.tensor(linear, dtype=D))) == pytest.approx(encoded, abs=1e-6)
    assert float(srgb_to_linear(torch.tensor(encoded, dtype=D))) == pytest.approx(linear, abs=1e-6)


def test_matches_the_piecewise_definition_on_both_sides_of_the_knee():
    x = torch.linspace(0, 1, 2001, dtype=D)
    expected = torch.tensor([reference_encode(float(v)) for v in x], dtype=D)
    torch.testing.assert_close(linear_to_srgb(x), expected, rtol=0, atol=1e-12)


def test_round_trip_both_ways():
    x = torch.linspace(-0.1, 1.2, 5001, dtype=D)                             # beyond [0, 1]: not clamped
    torch.testing.assert_close(srgb_to_linear(linear_to_srgb(x)), x, rtol=0, atol=1e-12)
    torch.testing.assert_close(linear_to_srgb(srgb_to_linear(x)), x, rtol=0, atol=1e-12)


def test_the_two_segments_meet_at_the_threshold():
    # the straight segment ends at linear 0.0031308 / encoded 0.04045; the power curve starts there (to the
    # standard's rounding of its constants, a few 1e-9)
    eps = 1e-9
    below, above = torch.tensor([0.0031308 - eps, 0.0031308 + eps], dtype=D)
    assert float(linear_to_srgb(above) - linear_to_srgb(below)) == pytest.approx(0.0, abs=1e-7)
    assert float(linear_to_srgb(torch.tensor(0.0031308, dtype=D))) == pytest.approx(0.04045, abs=1e-7)
    lo, hi = torch.tensor([0.04045 - eps, 0.04045 + eps], dtype=D)
    assert float(srgb_to_linear(hi) - srgb_to_linear(lo)) == pytest.approx(0.0, abs=1e-8)


def test_curves_are_monotonic_and_brighten_mid_tones():
    x = torch.linspace(0, 1, 1001, dtype=D)
    y = linear_to_srgb(x)
    assert bool((y[1:] > y[:-1]).all())
    assert bool((y[1:-1] > x[1:-1]).all())                                   # encoding lifts every mid tone


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_dtype_and_shape_are_kept(dtype):
    x = torch.rand(4, 5, 3, generator=torch.Generator().manual_seed(0), dtype=dtype)
    for f in (linear_to_srgb, srgb_to_linear):
        y = f(x)
        assert y.shape == x.shape and y.dtype == dtype and y.device == x.device


def test_gradients_are_finite_and_match_autograd_at_zero_and_the_knee():
    smooth = torch.tensor([1e-6, 0.002, 0.01, 0.5, 1.0], dtype=D, requires_grad=True)   # away from the knee
    assert torch.autograd.gradcheck(linear_to_srgb, (smooth,))
    assert torch.autograd.gradcheck(srgb_to_linear, (smooth,))
    x = torch.tensor([0.0, 1e-6, 0.0031308, 0.01, 0.5, 1.0], dtype=D, requires_grad=True)
    linear_to_srgb(x).sum().backward()
    assert torch.isfinite(x.grad).all() and float(x.grad[0]) == pytest.approx(12.92)
    expected = (1.055 / 2.4) * 0.5 ** (1 / 2.4 - 1)                          # d/dx of the power branch at 0.5
    assert float(x.grad[4]) == pytest.approx(expected)


# --------------------------------------------------------------------------------------------- PNG output

def test_png_stores_the_srgb_encoding_of_a_linear_image(tmp_path):
    from course.render_cli import _save_png
    image = torch.tensor([[[0.5, 0.0, 1.0], [0.25, 0.002, 2.0]]], dtype=D)   # (1, 2, 3), 2.0 clamps to 1
    _save_png(image, str(tmp_path / "a.png"))
    with Image.open(tmp_path / "a.png") as img:
        pixels = np.asarray(img)
    assert pixels.tolist() == [[[188, 0, 255], [137, 7, 255]]]                # 0.7354·255 = 187.5 → 188
    _save_png(image, str(tmp_path / "raw.png"), srgb=False)
    with Image.open(tmp_path / "raw.png") as img:
        assert np.asarray(img).tolist() == [[[128, 0, 255], [64, 1, 255]]]  # the switch: values as they are


# ------------------------------------------------------------------------------------------ display

def test_show_image_encodes_colour_images_but_not_scalar_ones():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from course import viz
    ramp = torch.tensor([[[0.5, 0.5, 0.5, 0.5]]], dtype=D)                   # RGBA: alpha is not encoded
    shown = viz.show_image(ramp).images[-1].get_array()
    np.testing.assert_allclose(np.asarray(shown)[0, 0], [0.735357, 0.735357, 0.735357, 0.5], atol=1e-6)
    raw = viz.show_image(ramp, srgb=False).images[-1].get_array()
    np.testing.assert_allclose(np.asarray(raw)[0, 0], [0.5] * 4)
    scalar = viz.show_image(torch.full((2, 2), 0.5, dtype=D), cmap="gray").images[-1].get_array()
    np.testing.assert_allclose(np.asarray(scalar), 0.5)                      # a quantity: never encoded
    fig = viz.image_grid([ramp[..., :3], ramp[..., :3]], srgb=False)
    np.testing.assert_allclose(np.asarray(fig.axes[0].images[-1].get_array())[0, 0], [0.5] * 3)
    assert float(ramp[0, 0, 0]) == 0.5                                       # the caller's image is untouched
    plt.close("all")


# ---------------------------------------------------------------------------------------- texture loading

def write_textured_square(folder, texel):
    """An OBJ + MTL + PNG square whose 4×4 texture is one 8-bit colour ``texel`` (3 ints)."""
    import trimesh
    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uv = verts[:, :2].copy()
    image = Image.fromarray(np.full((4, 4, 3), texel, dtype=np.uint8))
    visual = trimesh.visual.TextureVisuals(uv=uv, image=image)
    path = folder / "square.obj"
    trimesh.Trimesh(verts, faces, process=False, visual=visual).export(path)
    assert any(p.suffix == ".png" for p in folder.iterdir())                 # the texture went to its own file
    return path


def test_load_mesh_decodes_an_srgb_png_texture_to_linear(tmp_path):
    from course.mesh import load_mesh
    path = write_textured_square(tmp_path, (188, 128, 0))
    mesh = load_mesh(path, dtype=D)
    assert mesh.texture.shape == (4, 4, 3) and mesh.texture.dtype == D
    expected = srgb_to_linear(torch.tensor([188, 128, 0], dtype=D) / 255)     # ≈ (0.5029, 0.2159, 0)
    torch.testing.assert_close(mesh.texture[0, 0], expected, rtol=0, atol=1e-12)
    assert float(mesh.texture[0, 0, 0]) == pytest.approx(0.5, abs=0.003)     # 188 is sRGB for linear 0.5


def test_load_mesh_switch_keeps_the_stored_values(tmp_path):
    from course.mesh import load_mesh
    path = write_textured_square(tmp_path, (188, 128, 0))
    mesh = load_mesh(path, dtype=D, srgb_textures=False)
    torch.testing.assert_close(mesh.texture[0, 0], torch.tensor([188, 128, 0], dtype=D) / 255,
                               rtol=0, atol=1e-6)


# ---------------------------------------------------------------------------------- shading stays linear

def test_render_returns_linear_values_and_only_the_png_is_encoded(tmp_path):
    from course.camera import Camera
    from course.mesh import Mesh
    from course.models import plane
    from course.render import RenderSettings, Scene, render
    from course.render_cli import _save_png
    square = plane(size=2.0, dtype=D)
    square = Mesh(square.verts, square.faces, uvs=square.uvs, texture=torch.full((4, 4, 3), 0.5, dtype=D))
    camera = Camera.look_at((0.0, 2.0, 0.001), (0.0, 0.0, 0.0), fov_y=30, width=8, height=8).to(dtype=D)
    image = render(Scene(square, camera), RenderSettings(shading="unlit")).image
    assert image.dtype == D
    torch.testing.assert_close(image[4, 4], torch.full((3,), 0.5, dtype=D))  # the texel, not its encoding
    _save_png(image, str(tmp_path / "square.png"))
    with Image.open(tmp_path / "square.png") as img:
        assert np.asarray(img)[4, 4].tolist() == [188, 188, 188]
