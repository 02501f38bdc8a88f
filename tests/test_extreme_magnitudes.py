"""Extreme magnitudes (numerics round two): directions of any norm, lights far away, scenes at 1e±20 in
float32 and 1e±160 in float64. Each either gives the answer of the same scene at unit scale, to the dtype's
rounding, or is refused with an error that names the limit; never a silent wrong image."""
import pytest
import torch

from course import kernels
from course.camera import Camera, look_at
from course.mesh import Mesh
from course.raster import rasterize
from course.raytrace import raycast
from course.shading import DirectionalLight
from course.shadows.gradients import project_onto_plane, shadow_raytrace, shadow_scene, shadowed_coverage
from course.shadows.maps import light_camera
from course.shadows.prefiltered import shadow_map_image


@pytest.fixture(scope="module")
def floater():
    mesh, cam, colors, light = shadow_scene("floater", 12)
    return mesh, cam, colors, light, shadowed_coverage(mesh, cam, colors, light)


@pytest.mark.parametrize("scale", [1e-300, 1e-200, 1e-20, 1e20, 1e154, 1e160, 1e300])
def test_a_directional_light_of_any_norm_casts_the_same_shadow(floater, scale):
    """|l|² overflowed beyond ~1e154 (every face in shadow, 0.595 off) and underflowed below ~1e-154 (refused
    as a zero vector); a direction's length does not matter."""
    mesh, cam, colors, light, ref = floater
    assert float((shadowed_coverage(mesh, cam, colors, light * scale) - ref).abs().max()) < 1e-12
    vsm = shadow_map_image(mesh, cam, colors, light, resolution=16)
    assert float((shadow_map_image(mesh, cam, colors, light * scale, resolution=16) - vsm).abs().max()) < 1e-12
    ray = shadow_raytrace(mesh, cam, colors, light, supersample=2)
    assert torch.equal(shadow_raytrace(mesh, cam, colors, light * scale, supersample=2), ray)
    x = project_onto_plane(torch.tensor([[0.2, 1.0, 0.1]], dtype=torch.float64), (0, 0, 0), (0, 2e-200, 0),
                           light * scale)
    assert float((x - project_onto_plane(x.new_tensor([[0.2, 1.0, 0.1]]), (0, 0, 0), (0, 1, 0), light)).abs().max()) < 1e-12
    d = DirectionalLight(direction=tuple((light * scale).tolist()))
    to_light, _ = d.incident(torch.zeros(1, 3, dtype=torch.float64))
    assert torch.allclose(to_light[0], -light / light.norm(), atol=1e-15)


def test_a_zero_direction_is_still_refused(floater):
    mesh, cam, colors, _, _ = floater
    with pytest.raises(ValueError, match="zero vector"):
        shadowed_coverage(mesh, cam, colors, torch.zeros(3, dtype=torch.float64))


@pytest.mark.parametrize("distance", [1e6, 1e15, 1e16, 1e17, 1e20, 1e100])
def test_a_point_light_far_away_is_the_directional_light(floater, distance):
    """p + (x - p) h_p / (h_p - h) cancelled p against -p: 0.028 off at 1e15, 0.29 at 1e16, no shadow at all from
    1e17; x + (x - p) h / (h_p - h) is the same point without the cancellation."""
    mesh, cam, colors, light, ref = floater
    centre = torch.tensor([0.05, 0.8, 0.2], dtype=torch.float64)
    position = centre - distance * light / light.norm()
    image = shadowed_coverage(mesh, cam, colors, position, point=True)
    bound = 1e-4 if distance == 1e6 else 1e-12                              # 1e6 away: the rays still diverge
    assert float((image - ref).abs().max()) < bound


def scaled(scale, dtype, orthographic=False, size=16):
    mesh, _, _, _ = shadow_scene("box", size)
    view = dict(ortho_height=4.5 * scale) if orthographic else dict(fov_y=50.0)
    eye = torch.tensor((0.9, 3.2, 3.6), dtype=torch.float64) * scale
    target = torch.tensor((0.0, 0.3, 0.0), dtype=torch.float64) * scale
    cam = Camera.look_at(eye, target, width=size, height=size, near=0.1 * scale, far=100 * scale, dtype=dtype,
                         **view)
    return Mesh((mesh.verts * scale).to(dtype), mesh.faces), cam


@pytest.mark.parametrize("orthographic", [False, True])
@pytest.mark.parametrize("scale, dtype, tol", [(1e20, torch.float32, 3e-6), (1e-20, torch.float32, 3e-6),
                                               (2.0 ** 40, torch.float32, 3e-6), (1e160, torch.float64, 1e-14),
                                               (1e-160, torch.float64, 1e-14), (1e250, torch.float64, 1e-14)])
def test_a_scene_at_any_scale_has_the_unit_scene_surface(orthographic, scale, dtype, tol):
    """float32 at 1e20 gave NaN barycentrics and depth on every covered pixel (cross products ~1e40), 1e-20 and
    float64 at 1e-160 wrong ones (subnormal products): the surface stage now scales the corners by a power of
    two first. Both paths, with and without a gradient recorded, bit for bit alike."""
    ref = rasterize(*scaled(1.0, torch.float64, orthographic))
    mesh, cam = scaled(scale, dtype, orthographic)
    got = {}
    for backend in ("numba", "torch"):
        with kernels.using(backend):
            got[backend] = rasterize(mesh, cam)
            v = mesh.verts.clone().requires_grad_()
            graded = rasterize(Mesh(v, mesh.faces), cam)
            assert torch.equal(graded.bary.detach(), got[backend].bary)
    a, b = got["numba"], got["torch"]
    assert torch.equal(a.face_id, b.face_id) and torch.equal(a.bary, b.bary) and torch.equal(a.depth, b.depth)
    assert torch.equal(a.face_id, ref.face_id) and bool((a.face_id >= 0).sum() > 50)
    hit = ref.face_id >= 0
    assert bool(torch.isfinite(a.bary[hit]).all())
    assert float((a.bary.double() - ref.bary)[hit].abs().max()) < tol * 10
    assert float(((a.depth.double() / scale - ref.depth) / ref.depth)[hit].abs().max()) < tol


@pytest.mark.parametrize("orthographic", [False, True])
@pytest.mark.parametrize("scale", [1e-150, 1e150, 1e-300, 1e300])
def test_raycast_at_any_scale_finds_the_rasterized_faces(orthographic, scale):
    """Möller–Trumbore's triple products overflowed at 1e150 (nothing hit) and underflowed at 1e-150. (An
    orthographic camera 1e300 units high, fx ~ 1e-299 pixels per unit, was refused as a zero focal length:
    fx fy underflowed.)"""
    mesh, cam = scaled(scale, torch.float64, orthographic)
    ray, ras = raycast(mesh, cam), rasterize(mesh, cam)
    assert torch.equal(ray.face_id >= 0, ras.face_id >= 0) and bool((ray.face_id >= 0).sum() > 50)
    assert torch.equal(ray.bary, ras.bary) or float((ray.bary - ras.bary).abs().max()) < 1e-9


@pytest.mark.parametrize("gap", [3e-15, 1e-100, 1e-300])
def test_look_at_takes_an_eye_and_target_close_at_small_scale(gap):
    """Refused as "the same point" below unit scale: 3e-15 apart near the origin is a direction."""
    R, t = look_at(torch.tensor((0.0, 0.0, gap), dtype=torch.float64), (0.0, 0.0, 0.0))
    assert torch.allclose(R[2], torch.tensor([0.0, 0.0, -1.0], dtype=R.dtype))
    cam = Camera.look_at((0.0, 0.0, 1e20), (0.0, 0.0, 0.0), fov_y=40.0, width=4, height=4, dtype=torch.float32)
    assert torch.allclose(cam.R[2], torch.tensor([0.0, 0.0, -1.0]))


def test_look_at_refuses_points_equal_within_rounding():
    with pytest.raises(ValueError, match="same point"):
        look_at((1e20, 0.0, 0.0), (1e20 + 1e3, 0.0, 0.0))
    with pytest.raises(ValueError, match="same point"):
        look_at((0.5, 0.5, 0.5), (0.5, 0.5, 0.5))


def test_a_light_camera_takes_a_direction_of_any_norm():
    mesh, _, _, light = shadow_scene("box", 8)
    a = light_camera(DirectionalLight(direction=tuple(light.tolist())), mesh, resolution=16)
    for s in (1e-200, 1e200):
        b = light_camera(DirectionalLight(direction=tuple((light * s).tolist())), mesh, resolution=16)
        assert torch.allclose(a.R, b.R, atol=1e-15) and torch.allclose(a.t, b.t, atol=1e-12)


@pytest.mark.parametrize("scale", [1.0, 1e-200, 1e200])
def test_look_at_is_differentiable_at_any_scale(scale):
    """The power-of-two scaling inside look_at is a product autograd sees (``torch.ldexp`` would not be):
    float64 gradcheck w.r.t. the eye and the target, at unit scale and far from it."""
    eye = torch.tensor([0.3, 1.0, 2.0], dtype=torch.float64) * scale
    target = torch.tensor([0.1, -0.2, 0.05], dtype=torch.float64) * scale

    def rotation(e, t):
        R, _ = look_at(e * scale, t * scale)
        return R
    e, t = (eye / scale).requires_grad_(), (target / scale).requires_grad_()
    assert torch.autograd.gradcheck(rotation, (e, t))
