"""Lighting math, texture lookup and the shading models, checked by hand, by gradcheck and at the edge cases."""
import math

import numpy as np
import pytest
import torch

from course.shading import (
    AmbientLight, DirectionalLight, Material, PointLight, blinn_phong, lambert, light_terms, normalize,
    phong, sample_texture, shade,
)

D = torch.float64


def unit(*v):
    t = torch.tensor(v, dtype=D)
    return t / t.norm()


# ------------------------------------------------------------------------------------------- hand checks

@pytest.mark.parametrize("light, cos", [((0, 0, 1), 1.0), ((1, 0, 1), math.sqrt(0.5)), ((1, 0, 0), 0.0),
                                        ((0, 0, -1), 0.0), ((1, 0, -1), 0.0)])
def test_lambert_is_albedo_times_clamped_cosine(light, cos):
    n = torch.tensor([[0.0, 0.0, 2.0]], dtype=D)                             # not unit: lambert normalises
    out = lambert(n, torch.tensor(light, dtype=D), torch.tensor([0.5, 1.0, 0.25], dtype=D))
    assert out.shape == (1, 3)
    torch.testing.assert_close(out[0], torch.tensor([0.5, 1.0, 0.25], dtype=D) * cos)


def test_blinn_phong_peaks_at_one_when_half_vector_is_the_normal():
    n = torch.tensor([[0.0, 1.0, 0.0]], dtype=D)
    l, v = unit(1, 1, 0), unit(-1, 1, 0)                                     # mirror pair: h = n
    assert blinn_phong(n, l, v, 50.0).item() == pytest.approx(1.0)
    off = blinn_phong(n, l, unit(-1, 2, 0), 50.0).item()                     # h tilts away from n
    assert 0 < off < 1
    assert blinn_phong(n, l, unit(-1, 2, 0), 200.0).item() < off              # higher exponent: tighter


def test_blinn_phong_hand_value_and_zero_when_light_is_behind():
    n = torch.tensor([[0.0, 0.0, 1.0]], dtype=D)
    l, v = torch.tensor([0.0, 0.0, 1.0], dtype=D), unit(1, 0, 1)             # h at 22.5° from n
    assert blinn_phong(n, l, v, 4.0).item() == pytest.approx(math.cos(math.pi / 8) ** 4)
    assert blinn_phong(n, -l, v, 4.0).item() == 0.0                          # n·l < 0: no highlight
    assert blinn_phong(n, torch.tensor([1.0, 0, 0], dtype=D), v, 4.0).item() == 0.0   # n·l = 0


def test_phong_mirror_vector_peak_and_hand_value():
    n = torch.tensor([[0.0, 1.0, 0.0]], dtype=D)
    l = unit(1, 1, 0)
    assert phong(n, l, unit(-1, 1, 0), 10.0).item() == pytest.approx(1.0)   # v = mirror of l
    # v 45° away from the mirror direction r = (-1, 1, 0)/√2: r·v = cos 45°
    assert phong(n, l, torch.tensor([0.0, 1.0, 0.0], dtype=D), 2.0).item() == pytest.approx(0.5)
    assert phong(n, -l, unit(-1, 1, 0), 10.0).item() == 0.0


def test_shade_combines_ambient_diffuse_and_specular():
    p = torch.zeros(1, 3, dtype=D)
    n = torch.tensor([[0.0, 0.0, 1.0]], dtype=D)
    v = torch.tensor([[0.0, 0.0, 1.0]], dtype=D)
    lights = [AmbientLight((1.0, 1.0, 1.0), 0.2), DirectionalLight((0.0, 0.0, -1.0), (1.0, 0.5, 0.0), 2.0)]
    m = Material(ambient=0.5, diffuse=1.0, specular=0.25, shininess=8.0)
    out = shade(p, n, v, torch.tensor([0.4, 0.4, 0.4], dtype=D), lights, m)
    # light straight on, viewer straight on: n·l = 1, h = n → highlight 1
    radiance = torch.tensor([2.0, 1.0, 0.0], dtype=D)
    expect = 0.4 * (0.5 * 0.2 + radiance) + 0.25 * radiance
    torch.testing.assert_close(out[0], expect)


def test_point_light_inverse_square_falloff_and_direction():
    p = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]], dtype=D)
    light = PointLight(position=(0.0, 0.0, 3.0), intensity=9.0)
    l, radiance = light.incident(p)
    torch.testing.assert_close(l, torch.tensor([[0.0, 0, 1], [0, 0, 1]], dtype=D))
    torch.testing.assert_close(radiance[:, 0], torch.tensor([1.0, 9.0 / 4], dtype=D))
    _, flat = PointLight(position=(0.0, 0.0, 3.0), intensity=9.0, falloff=False).incident(p)
    torch.testing.assert_close(flat[:, 0], torch.tensor([9.0, 9.0], dtype=D))


def test_directional_light_travels_along_its_direction():
    sun = DirectionalLight(direction=(0.0, -2.0, 0.0))                       # shining down
    l, _ = sun.incident(torch.zeros(1, 3))
    torch.testing.assert_close(l, torch.tensor([[0.0, 1.0, 0.0]]))          # toward the light: up
    up_facing = torch.tensor([[0.0, 1.0, 0.0]])
    assert lambert(up_facing, l, (1.0, 1.0, 1.0))[0, 0] == 1.0


# ----------------------------------------------------------------------------------------------- textures

TEX = torch.tensor([[[1.0], [2.0]],                                          # row 0 (top):    1 2
                    [[3.0], [4.0]]], dtype=D)                                # row 1 (bottom): 3 4


@pytest.mark.parametrize("mode", ["bilinear", "nearest"])
def test_texel_centres_follow_the_uv_convention(mode):
    # texel (r, c) centre: u = (c + 0.5) / 2, v = 1 - (r + 0.5) / 2
    uv = torch.tensor([[0.25, 0.75], [0.75, 0.75], [0.25, 0.25], [0.75, 0.25]], dtype=D)
    out = sample_texture(TEX, uv, mode)[:, 0]
    torch.testing.assert_close(out, torch.tensor([1.0, 2.0, 3.0, 4.0], dtype=D))


def test_uv_origin_is_the_bottom_left_texel():
    assert sample_texture(TEX, torch.tensor([0.0, 0.0], dtype=D), "nearest").item() == 3.0
    assert sample_texture(TEX, torch.tensor([0.0, 0.0], dtype=D), "bilinear").item() == 3.0
    assert sample_texture(TEX, torch.tensor([1.0, 1.0], dtype=D), "nearest").item() == 2.0
    # nearest takes the texel that contains uv; on a texel boundary, the one to the right / below
    assert sample_texture(TEX, torch.tensor([0.5, 0.75], dtype=D), "nearest").item() == 2.0
    assert sample_texture(TEX, torch.tensor([0.25, 0.5], dtype=D), "nearest").item() == 3.0
    assert sample_texture(TEX, torch.tensor([0.49, 0.51], dtype=D), "nearest").item() == 1.0


def test_bilinear_midpoints_blend_neighbours():
    uv = torch.tensor([[0.5, 0.75], [0.25, 0.5], [0.5, 0.5], [0.375, 0.75]], dtype=D)
    out = sample_texture(TEX, uv)[:, 0]
    torch.testing.assert_close(out, torch.tensor([1.5, 2.0, 2.5, 1.25], dtype=D))


@pytest.mark.parametrize("mode", ["bilinear", "nearest"])
def test_lookups_clamp_to_the_edge(mode):
    uv = torch.tensor([[-3.0, 0.75], [5.0, 0.75], [0.25, 9.0], [0.75, -9.0], [-1.0, -1.0]], dtype=D)
    out = sample_texture(TEX, uv, mode)[:, 0]
    torch.testing.assert_close(out, torch.tensor([1.0, 2.0, 1.0, 4.0, 3.0], dtype=D))


def test_texture_shapes_dtype_and_errors():
    tex = torch.rand(4, 5, 3, generator=torch.Generator().manual_seed(0))
    out = sample_texture(tex, np.zeros((2, 7, 2), dtype=np.float32))
    assert out.shape == (2, 7, 3) and out.dtype == torch.float32
    assert sample_texture(torch.ones(3, 3), torch.zeros(2)).shape == (1,)   # (Ht, Wt) texture: one channel
    with pytest.raises(ValueError, match="'bilinear' or 'nearest'"):
        sample_texture(tex, torch.zeros(2), "trilinear")
    with pytest.raises(ValueError, match=r"uv must have shape \(\.\.\., 2\)"):
        sample_texture(tex, torch.zeros(3))


# ------------------------------------------------------------------------------------------- gradients

def _random_dirs(n, seed, hemisphere=None):
    g = torch.Generator().manual_seed(seed)
    d = torch.randn(n, 3, generator=g, dtype=D)
    if hemisphere is not None:                                               # keep n·l well away from 0
        d = d + 3 * hemisphere
    return d


def test_gradcheck_lambert():
    n = _random_dirs(6, 0).requires_grad_()
    l = _random_dirs(6, 1, hemisphere=n.detach() / n.detach().norm(dim=-1, keepdim=True)).requires_grad_()
    albedo = torch.rand(6, 3, dtype=D, generator=torch.Generator().manual_seed(2)).requires_grad_()
    assert torch.autograd.gradcheck(lambert, (n, l, albedo))


@pytest.mark.parametrize("fn", [blinn_phong, phong])
def test_gradcheck_specular(fn):
    n = _random_dirs(5, 3).requires_grad_()
    nn = n.detach() / n.detach().norm(dim=-1, keepdim=True)
    l = (nn * 2 + 0.3 * _random_dirs(5, 4)).requires_grad_()                # lit, near the normal
    v = (nn * 2 + 0.3 * _random_dirs(5, 5)).requires_grad_()
    s = torch.tensor(7.0, dtype=D, requires_grad=True)
    assert torch.autograd.gradcheck(fn, (n, l, v, s))


def test_gradcheck_sample_texture_bilinear():
    g = torch.Generator().manual_seed(6)
    tex = torch.rand(3, 4, 2, dtype=D, generator=g).requires_grad_()
    # away from texel-centre lines (where floor() switches cells) and inside [0, 1]
    uv = torch.tensor([[0.2, 0.3], [0.55, 0.7], [0.8, 0.45]], dtype=D, requires_grad=True)
    assert torch.autograd.gradcheck(lambda t, u: sample_texture(t, u, "bilinear"), (tex, uv))
    assert torch.autograd.gradcheck(lambda t: sample_texture(t, uv.detach(), "nearest"), (tex,))


def test_gradcheck_shade():
    g = torch.Generator().manual_seed(7)
    p = torch.randn(4, 3, dtype=D, generator=g).requires_grad_()
    n = torch.tensor([[0.1, 0.2, 1.0]], dtype=D).repeat(4, 1).requires_grad_()
    v = torch.tensor([[0.0, 0.3, 1.0]], dtype=D).repeat(4, 1).requires_grad_()
    base = torch.rand(4, 3, dtype=D, generator=g).requires_grad_()
    pos = torch.tensor([0.5, 1.0, 4.0], dtype=D, requires_grad=True)
    ks = torch.tensor([0.3, 0.2, 0.1], dtype=D, requires_grad=True)

    def f(p, n, v, base, pos, ks):
        lights = [AmbientLight(intensity=0.1), DirectionalLight((0.2, -0.1, -1.0)), PointLight(pos, intensity=5.0)]
        return shade(p, n, v, base, lights, Material(specular=ks, shininess=12.0))
    assert torch.autograd.gradcheck(f, (p, n, v, base, pos, ks))


# ---------------------------------------------------------------------------------- no NaN, dtype agreement

def test_no_nan_at_zero_vectors_grazing_and_opposite_light():
    zero = torch.zeros(1, 3, dtype=D, requires_grad=True)
    n = torch.tensor([[0.0, 0.0, 1.0]], dtype=D, requires_grad=True)
    grazing = torch.tensor([[1.0, 0.0, 0.0]], dtype=D, requires_grad=True)   # n·l = 0 exactly
    cases = [
        lambda: lambert(zero, grazing, (1.0, 1.0, 1.0)).sum(),
        lambda: lambert(n, grazing, (1.0, 1.0, 1.0)).sum(),
        lambda: blinn_phong(n, grazing, -grazing, 0.5).sum(),                 # l = -v: half vector is zero
        lambda: blinn_phong(zero, zero, zero, 0.5).sum(),
        lambda: phong(n, grazing, n, 0.5).sum(),
        lambda: phong(zero, grazing, zero, 30.0).sum(),
        lambda: normalize(zero).sum(),
        lambda: shade(zero, zero, zero, (1.0, 1.0, 1.0), [PointLight((0.0, 0.0, 0.0)), AmbientLight()]).sum(),
    ]
    for case in cases:
        out = case()
        grads = torch.autograd.grad(out, [zero, n, grazing], allow_unused=True)
        assert torch.isfinite(out)
        assert all(g is None or torch.isfinite(g).all() for g in grads)


def test_normalize_keeps_zero_vectors_zero():
    torch.testing.assert_close(normalize(torch.zeros(2, 3)), torch.zeros(2, 3))
    torch.testing.assert_close(normalize(torch.tensor([[3.0, 0.0, 4.0]])), torch.tensor([[0.6, 0.0, 0.8]]))


def test_float32_matches_float64_and_keeps_dtype():
    g = torch.Generator().manual_seed(8)
    p, n, v, base = (torch.rand(50, 3, dtype=D, generator=g) - 0.5 for _ in range(4))
    v = v + torch.tensor([0.0, 0.0, 2.0], dtype=D)
    n = n + torch.tensor([0.0, 0.0, 1.0], dtype=D)
    lights = [AmbientLight(), DirectionalLight((0.3, -0.5, -1.0)), PointLight((1.0, 1.0, 3.0), intensity=4.0)]
    out64 = shade(p, n, v, base.abs(), lights)
    out32 = shade(p.float(), n.float(), v.float(), base.abs().float(), lights)
    assert out64.dtype == D and out32.dtype == torch.float32
    torch.testing.assert_close(out32.double(), out64, atol=1e-5, rtol=1e-5)
    tex = torch.rand(5, 6, 3, dtype=D, generator=g)
    uv = torch.rand(40, 2, dtype=D, generator=g)
    torch.testing.assert_close(sample_texture(tex.float(), uv.float()).double(), sample_texture(tex, uv),
                               atol=1e-6, rtol=1e-6)


def test_numpy_inputs_and_broadcast_shapes():
    n = np.tile([[0.0, 0.0, 1.0]], (2, 4, 1))                                # (H, W, 3) image of normals
    out = lambert(n, (0.0, 0.0, 1.0), (1.0, 0.5, 0.0))
    assert out.shape == (2, 4, 3) and out.dtype == D
    assert blinn_phong(n, (0.0, 0.0, 1.0), (0.0, 0.0, 1.0), 5.0).shape == (2, 4)


def test_light_terms_per_point_materials_and_errors():
    p = torch.zeros(2, 3)
    n = torch.tensor([[0.0, 0.0, 1.0]] * 2)
    m = Material(diffuse=torch.tensor([[1.0, 1.0, 1.0], [0.5, 0.5, 0.5]]), specular=0.0)
    diffuse, specular = light_terms(p, n, n, [DirectionalLight((0.0, 0.0, -1.0))], m)
    torch.testing.assert_close(diffuse[:, 0], torch.tensor([1.0, 0.5]))
    assert specular.abs().max() == 0
    with pytest.raises(TypeError, match="unknown light"):
        light_terms(p, n, n, ["sun"])
    with pytest.raises(ValueError, match="specular_model"):
        Material(specular_model="cook_torrance")
