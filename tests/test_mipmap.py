"""Mipmaps (lecture 05): the pyramid, the exact screen-space uv derivatives that pick a level, trilinear lookup,
and ``render(texture_filter="trilinear")``."""
import math

import pytest
import torch

from course import models
from course.camera import Camera
from course.raster import Fragments, interpolate, rasterize
from course.render import RenderSettings, Scene, render
from course.shading import mip_level, mip_pyramid, sample_texture, sample_texture_mip, uv_derivatives

F64 = torch.float64


# ------------------------------------------------------------------------------------------------- pyramid

@pytest.mark.parametrize("shape, sizes", [
    ((8, 8, 3), [(8, 8), (4, 4), (2, 2), (1, 1)]),
    ((5, 7, 2), [(5, 7), (3, 4), (2, 2), (1, 1)]),
    ((1, 6, 3), [(1, 6), (1, 3), (1, 2), (1, 1)]),
    ((1, 1, 3), [(1, 1)]),
])
def test_pyramid_halves_each_side_down_to_one_texel(shape, sizes):
    levels = mip_pyramid(torch.rand(shape, dtype=F64, generator=torch.Generator().manual_seed(0)))
    assert [tuple(level.shape) for level in levels] == [s + shape[2:] for s in sizes]


def test_pyramid_of_a_constant_is_the_constant_and_level_zero_is_the_texture():
    texture = torch.tensor([0.2, 0.5, 0.9], dtype=F64).expand(6, 10, 3)
    levels = mip_pyramid(texture)
    assert levels[0] is texture or torch.equal(levels[0], texture)
    for level in levels:
        torch.testing.assert_close(level, torch.tensor([0.2, 0.5, 0.9], dtype=F64).expand_as(level),
                                   rtol=0, atol=1e-15)


def test_pyramid_averages_2x2_blocks_and_keeps_the_mean_for_odd_sizes():
    checker = torch.tensor([[0.0, 1.0], [1.0, 0.0]], dtype=F64)             # (2, 2): a 2D texture stays 2D
    assert mip_pyramid(checker)[1].tolist() == [[0.5]]
    texture = torch.rand(4, 6, 3, dtype=F64, generator=torch.Generator().manual_seed(1))
    level1 = mip_pyramid(texture)[1]
    torch.testing.assert_close(level1, texture.reshape(2, 2, 3, 2, 3).mean((1, 3)))
    odd = torch.rand(5, 7, 3, dtype=F64, generator=torch.Generator().manual_seed(2))
    for level in mip_pyramid(odd):                                           # area weights: mean kept exactly
        torch.testing.assert_close(level.mean((0, 1)), odd.mean((0, 1)), rtol=0, atol=1e-14)
    row = torch.tensor([[3.0, 6.0, 9.0]], dtype=F64)                         # n = 3 → 2 footprints of 1.5
    assert mip_pyramid(row)[1][0].tolist() == pytest.approx([4.0, 8.0])


def test_pyramid_is_differentiable_and_rejects_bad_shapes():
    texture = torch.rand(4, 4, 3, dtype=F64, requires_grad=True)
    mip_pyramid(texture)[-1].sum().backward()                                # the last level is the mean
    torch.testing.assert_close(texture.grad, torch.full_like(texture, 1 / 16))
    for bad in (torch.zeros(4), torch.zeros(0, 4, 3), torch.zeros(2, 2, 2, 3)):
        with pytest.raises(ValueError, match="texture must have shape"):
            mip_pyramid(bad)


# ---------------------------------------------------------------------------------------- uv derivatives

def _bumpy_plane():
    """A subdivided plane with jittered uvs: uv is affine on each face but differs from face to face."""
    mesh = models.plane(size=2.0, subdivisions=3, dtype=F64)
    jitter = torch.rand(mesh.uvs.shape, dtype=F64, generator=torch.Generator().manual_seed(3)) - 0.5
    mesh.uvs = mesh.uvs + 0.05 * jitter
    return mesh


def _camera(orthographic: bool, width=40, height=30) -> Camera:
    kind = dict(ortho_height=2.0) if orthographic else dict(fov_y=50.0)
    return Camera.look_at((0.4, 1.1, 2.2), (0.1, 0.0, -0.2), width=width, height=height, dtype=F64, **kind)


def _shifted(camera: Camera, dx: float, dy: float) -> Camera:
    """The same camera with the principal point moved by (dx, dy) pixels: every pixel centre then sees what
    the original camera sees at (x - dx, y - dy)."""
    K = camera.K.clone()
    K[0, 2] += dx
    K[1, 2] += dy
    return Camera(K, camera.R, camera.t, camera.width, camera.height, camera.near, camera.far,
                  orthographic=camera.orthographic)


@pytest.mark.parametrize("orthographic", [False, True], ids=["perspective", "orthographic"])
def test_uv_derivatives_match_central_finite_differences(orthographic):
    mesh, cam, h = _bumpy_plane(), _camera(orthographic), 1e-4
    frags = rasterize(mesh, cam)
    duv_dx, duv_dy = uv_derivatives(mesh.uvs, mesh.faces, frags, mesh.verts, cam)
    assert duv_dx.shape == duv_dy.shape == (30, 40, 2) and duv_dx.dtype == F64
    interior = frags.mask.clone()
    fd = []
    for step in ((h, 0.0), (0.0, h)):
        plus, minus = rasterize(mesh, _shifted(cam, *step)), rasterize(mesh, _shifted(cam, -step[0], -step[1]))
        interior &= (plus.face_id == frags.face_id) & (minus.face_id == frags.face_id)
        uv_plus, uv_minus = interpolate(mesh.uvs, plus, mesh.faces), interpolate(mesh.uvs, minus, mesh.faces)
        fd.append(-(uv_plus - uv_minus) / (2 * h))                           # shift +h ⇔ sample at x - h
    assert interior.sum() > 300
    scale = float(duv_dy[interior].abs().max())
    for exact, approx in zip((duv_dx, duv_dy), fd):
        torch.testing.assert_close(exact[interior], approx[interior], rtol=0, atol=1e-7 * scale)
    assert torch.equal(duv_dx[~frags.mask], torch.zeros_like(duv_dx[~frags.mask]))
    if orthographic:                                                         # uv is affine on screen per face
        per_face = {}
        for f, d in zip(frags.face_id[frags.mask].tolist(), duv_dx[frags.mask]):
            per_face.setdefault(f, d)
            torch.testing.assert_close(d, per_face[f], rtol=0, atol=1e-12)


def test_uv_derivatives_work_fragment_by_fragment_on_any_shape():
    """Samples (P, S) in any order: each fragment's derivative comes from its own hit point, not its index."""
    mesh, cam = _bumpy_plane(), _camera(False)
    frags = rasterize(mesh, cam)
    duv_dx, duv_dy = uv_derivatives(mesh.uvs, mesh.faces, frags, mesh.verts, cam)
    perm = torch.randperm(30 * 40, generator=torch.Generator().manual_seed(4))
    shuffled = Fragments(frags.face_id.reshape(-1)[perm].reshape(300, 4),
                         frags.bary.reshape(-1, 3)[perm].reshape(300, 4, 3),
                         frags.depth.reshape(-1)[perm].reshape(300, 4))
    sx, sy = uv_derivatives(mesh.uvs, mesh.faces, shuffled, mesh.verts, cam)
    assert sx.shape == (300, 4, 2)
    torch.testing.assert_close(sx, duv_dx.reshape(-1, 2)[perm].reshape(300, 4, 2), rtol=0, atol=1e-15)
    torch.testing.assert_close(sy, duv_dy.reshape(-1, 2)[perm].reshape(300, 4, 2), rtol=0, atol=1e-15)


def test_uv_derivatives_of_sub_pixel_samples_match_finite_differences():
    """Supersampled fragments (P, S): the derivative at each sample's own position, per pixel step."""
    mesh, cam, h = _bumpy_plane(), _camera(False), 1e-4
    offsets = torch.tensor([[0.25, 0.25], [0.75, 0.6], [0.1, 0.9]], dtype=F64)   # (S, 2) within the pixel
    frags = rasterize(mesh, cam, samples=offsets)
    duv = uv_derivatives(mesh.uvs, mesh.faces, frags, mesh.verts, cam)
    assert duv[0].shape == (30 * 40, 3, 2)
    for axis in (0, 1):
        step = torch.zeros(2, dtype=F64)
        step[axis] = h
        plus, minus = rasterize(mesh, cam, samples=offsets + step), rasterize(mesh, cam, samples=offsets - step)
        interior = frags.mask & (plus.face_id == frags.face_id) & (minus.face_id == frags.face_id)
        fd = (interpolate(mesh.uvs, plus, mesh.faces) - interpolate(mesh.uvs, minus, mesh.faces)) / (2 * h)
        assert interior.sum() > 500
        scale = float(duv[axis][interior].abs().max())
        torch.testing.assert_close(duv[axis][interior], fd[interior], rtol=0, atol=1e-7 * scale)


def test_uv_derivatives_float32_agree_with_float64_and_need_no_gradient():
    mesh, cam = _bumpy_plane(), _camera(False)
    verts = mesh.verts.clone().requires_grad_(True)
    frags = rasterize(type(mesh)(verts, mesh.faces), cam)
    duv_dx, duv_dy = uv_derivatives(mesh.uvs, mesh.faces, frags, verts, cam)
    assert not duv_dx.requires_grad and not duv_dy.requires_grad
    cam32, mesh32 = cam.to(dtype=torch.float32), mesh.to(dtype=torch.float32)
    frags32 = rasterize(mesh32, cam32)
    dx32, dy32 = uv_derivatives(mesh32.uvs, mesh32.faces, frags32, mesh32.verts, cam32)
    assert dx32.dtype == torch.float32
    same = frags32.face_id == frags.face_id
    torch.testing.assert_close(dy32[same].double(), duv_dy[same].detach(), rtol=1e-4, atol=1e-6)


def test_uv_derivatives_reject_bad_input():
    mesh, cam = _bumpy_plane(), _camera(False)
    frags = rasterize(mesh, cam)
    with pytest.raises(ValueError, match="uvs must have shape"):
        uv_derivatives(mesh.uvs[:, :1], mesh.faces, frags, mesh.verts, cam)
    with pytest.raises(ValueError, match="faces must have shape"):
        uv_derivatives(mesh.uvs, mesh.faces[:, :2], frags, mesh.verts, cam)
    with pytest.raises(ValueError, match="fragments reference face"):
        uv_derivatives(mesh.uvs, mesh.faces[:2], frags, mesh.verts, cam)


# ----------------------------------------------------------------------------------------- trilinear lookup

def _texture(h=16, w=16, seed=5):
    return torch.rand(h, w, 3, dtype=F64, generator=torch.Generator().manual_seed(seed))


def _uv(n=200, seed=6):
    return torch.rand(n, 2, dtype=F64, generator=torch.Generator().manual_seed(seed)) * 1.2 - 0.1


def test_trilinear_is_bilinear_where_the_texture_is_magnified():
    texture, uv = _texture(), _uv()
    footprint = torch.rand(200, 2, dtype=F64, generator=torch.Generator().manual_seed(7)) / 16 / math.sqrt(2)
    assert (mip_level(footprint, footprint.flip(-1), (16, 16)) == 0).all()  # at most one texel per pixel
    got = sample_texture_mip(texture, uv, footprint, footprint.flip(-1))
    torch.testing.assert_close(got, sample_texture(texture, uv, "bilinear"), rtol=0, atol=1e-15)


def test_trilinear_blends_the_two_levels_around_the_level_of_detail():
    texture, uv = _texture(), _uv()
    levels = mip_pyramid(texture)
    for lam in (1.0, 2.5, 3.25):
        d = torch.tensor([2 ** lam / 16, 0.0], dtype=F64).expand(200, 2)    # footprint 2^λ texels along u
        lo = int(lam)
        f = lam - lo
        want = (1 - f) * sample_texture(levels[lo], uv) + f * sample_texture(levels[lo + 1], uv)
        torch.testing.assert_close(sample_texture_mip(levels, uv, d, d.flip(-1)), want, rtol=0, atol=1e-14)


@pytest.mark.parametrize("size", [(16, 16), (5, 7)])
def test_trilinear_at_a_huge_footprint_is_the_texture_mean(size):
    texture, uv = _texture(*size), _uv()
    huge = torch.full((200, 2), 50.0, dtype=F64)
    got = sample_texture_mip(texture, uv, huge, huge)
    torch.testing.assert_close(got, texture.mean((0, 1)).expand(200, 3), rtol=0, atol=1e-14)
    inf = torch.full((200, 2), float("inf"), dtype=F64)                     # edge-on faces: still the mean
    torch.testing.assert_close(sample_texture_mip(texture, uv, inf, inf), got)


def test_trilinear_gradients_are_finite_and_reach_texture_and_uv():
    texture = _texture().requires_grad_(True)
    uv = _uv().requires_grad_(True)
    d = (torch.rand(200, 2, dtype=F64, generator=torch.Generator().manual_seed(8)) * 0.3).requires_grad_(True)
    out = sample_texture_mip(texture, uv, d, d.flip(-1))
    out.square().sum().backward()
    assert torch.isfinite(texture.grad).all() and texture.grad.abs().sum() > 0
    assert torch.isfinite(uv.grad).all() and uv.grad.abs().sum() > 0
    assert d.grad is None                                                    # the level is not differentiated


def test_trilinear_rejects_bad_input():
    texture, uv = _texture(), _uv()
    d = torch.zeros(200, 2, dtype=F64)
    with pytest.raises(ValueError, match="uv must have shape"):
        sample_texture_mip(texture, uv[:, :1], d[:, :1], d[:, :1])
    with pytest.raises(ValueError, match="duv_dx and duv_dy must have uv's shape"):
        sample_texture_mip(texture, uv, d[:10], d)
    with pytest.raises(ValueError, match="pyramid is empty"):
        sample_texture_mip([], uv, d, d)
    with pytest.raises(ValueError, match="mip level 1"):
        sample_texture_mip([texture, torch.zeros(8, 8, 4, dtype=F64)], uv, d, d)


# ------------------------------------------------------------------------------------------------- render

def _receding_plane(width=48, height=48, texture_size=64):
    """A checkerboard floor running from just under the camera to far away: magnified near, minified far."""
    mesh = models.plane(size=8.0, dtype=F64)
    mesh.texture = models.checker_texture(size=texture_size, checks=16, dtype=F64)
    cam = Camera.look_at((0.0, 0.5, 4.2), (0.0, 0.0, 2.5), width=width, height=height, fov_y=60.0, dtype=F64)
    return mesh, cam


def test_render_trilinear_differs_from_bilinear_only_where_minified():
    mesh, cam = _receding_plane()
    scene = Scene(mesh, cam)
    bilinear = render(scene, RenderSettings(shading="unlit"))
    trilinear = render(scene, RenderSettings(shading="unlit", texture_filter="trilinear"))
    frags = trilinear.fragments
    level = mip_level(*uv_derivatives(mesh.uvs, mesh.faces, frags, mesh.verts, cam), (64, 64))
    magnified, minified = frags.mask & (level == 0), frags.mask & (level > 1)
    assert magnified.sum() > 100 and minified.sum() > 100
    diff = (trilinear.image - bilinear.image).abs().amax(-1)
    assert float(diff[magnified].max()) < 1e-12
    assert float(diff[~frags.mask].max()) == 0
    assert float(diff[minified].mean()) > 0.02
    lit = render(scene, RenderSettings(texture_filter="trilinear"))         # the default Phong path runs too
    assert torch.isfinite(lit.image).all()


def test_render_trilinear_cures_the_moire_that_supersampling_leaves():
    """Far away, where one pixel covers more than 4 texels, 4×4 supersampling still aliases; mipmapping does not.
    Errors against an 8×8 supersampled reference (each sample itself trilinear), in float64."""
    mesh = models.plane(size=40.0, dtype=F64)                                # a floor to the horizon
    mesh.texture = models.checker_texture(size=256, checks=128, dtype=F64)   # checks of 2 texels

    def camera(scale):                                                       # the same view at scale× resolution
        return Camera.look_at((0.0, 1.0, 20.5), (0.0, 0.0, 14.0), width=64 * scale, height=64 * scale,
                              fov_y=50.0, far=1000.0, dtype=F64)

    def image(texture_filter, scale):                                        # render at scale×, box-average down
        img = render(Scene(mesh, camera(scale)), RenderSettings(shading="unlit", texture_filter=texture_filter)).image
        return img.reshape(64, scale, 64, scale, 3).mean((1, 3))

    frags = rasterize(mesh, camera(1))
    level = mip_level(*uv_derivatives(mesh.uvs, mesh.faces, frags, mesh.verts, camera(1)), (256, 256))
    far = frags.mask & (level > 2)
    far[frags.mask.any(1).nonzero()[0]] = False                              # the far edge row: coverage, not texture
    assert far.sum() > 300
    ref = image("trilinear", 8)
    err = {name: float(((image(f, s) - ref) ** 2)[far].mean())
           for name, f, s in [("bilinear", "bilinear", 1), ("ss4", "bilinear", 4), ("trilinear", "trilinear", 1)]}
    assert err["ss4"] < err["bilinear"] / 4                                  # supersampling helps ...
    assert err["trilinear"] < err["ss4"] / 4                                 # ... mipmapping far more, at 1/16 the cost


def test_render_settings_reject_an_unknown_texture_filter():
    with pytest.raises(ValueError, match="'bilinear', 'nearest', 'trilinear'"):
        RenderSettings(texture_filter="anisotropic")
