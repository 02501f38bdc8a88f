"""Shadow maps (course/shadows.py): analytic shadows of squares and boxes on a ground plane.

Scene: ``plane(4)`` (y = 0, facing up) and a square occluder of half-size 0.5 at height 0.5. Tolerances are
in texels (``1 / fx`` world units for an orthographic map, ``z / fx`` for a perspective one).
"""
import math

import pytest
import torch

from course.mesh import Mesh
from course.models import cube, plane
from course.shading import DirectionalLight, PointLight
from course.camera import Camera
from course.shadows import (CUBE_FACES, ShadowMap, SpotLight, area_light_samples, area_shadow_factor, biased_depth,
                            biased_lit, light_camera, light_space, pcf, shadow_factor, shadow_map)

# every test runs on the compiled kernels and on the torch path (tests/conftest.py)
pytestmark = pytest.mark.usefixtures("both_backends")

UP = (0.0, 1.0, 0.0)


def moved(mesh, offset):
    return Mesh(mesh.verts + torch.tensor(offset, dtype=mesh.verts.dtype), mesh.faces)


def square(size, center, dtype=torch.float32):
    """A plane(size) moved to ``center``: a two-sided square occluder (parallel to the ground)."""
    return moved(plane(size, dtype=dtype), center)


def ground_grid(n=161, half=1.9, dtype=torch.float32):
    xs = torch.linspace(-half, half, n, dtype=dtype)
    X, Z = torch.meshgrid(xs, xs, indexing="ij")
    pts = torch.stack([X, torch.zeros_like(X), Z], -1).reshape(-1, 3)
    return pts, torch.tensor(UP, dtype=dtype).expand_as(pts), torch.maximum(X.abs(), Z.abs()).reshape(-1)


def line_x(x0, x1, n, dtype=torch.float32):
    x = torch.linspace(x0, x1, n, dtype=dtype)
    pts = torch.stack([x, torch.zeros_like(x), torch.zeros_like(x)], -1)
    return x, pts, torch.tensor(UP, dtype=dtype).expand_as(pts)


def scene(dtype=torch.float32):
    return [plane(4.0, dtype=dtype), square(1.0, (0.0, 0.5, 0.0), dtype)]


# ------------------------------------------------------------------------------------------ light cameras

def test_light_cameras_fit_the_scene():
    meshes = scene()
    cam = light_camera(DirectionalLight((0.0, -1.0, 0.0)), meshes, resolution=64)
    assert cam.orthographic and cam.width == cam.height == 64
    assert torch.allclose(cam.R[2], torch.tensor([0.0, -1.0, 0.0]), atol=1e-6)      # looks along the light
    corners = torch.tensor([[-2.0, 0.0, -2.0], [2.0, 0.0, 2.0], [2.0, 0.0, -2.0], [-2.0, 0.0, 2.0]])
    xy, z = cam.project(corners)
    assert (xy >= 0).all() and (xy <= 64).all() and (z > cam.near).all() and (z < cam.far).all()
    spot = light_camera(SpotLight((0.0, 2.0, 0.0), (0.0, -1.0, 0.0), angle=70.0), meshes, resolution=32)
    assert not spot.orthographic
    assert math.isclose(float(spot.K[1, 1]), 16 / math.tan(math.radians(35)), rel_tol=1e-5)
    cube_cams = light_camera(PointLight((0.0, 1.0, 0.0)), meshes, resolution=16)
    assert len(cube_cams) == len(CUBE_FACES) == 6
    axes = torch.stack([c.R[2] for c in cube_cams])                                # forward of each face
    assert torch.allclose(axes, torch.tensor([[1.0, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]),
                          atol=1e-6)
    assert all(math.isclose(float(c.K[0, 0]), 8.0, rel_tol=1e-6) for c in cube_cams)   # 90° fov


# ------------------------------------------------------------------------------------- directional lights

def test_directional_shadow_is_the_occluders_projection():
    sm = shadow_map(scene(), DirectionalLight((0.0, -1.0, 0.0)), 256)
    assert isinstance(sm, ShadowMap) and sm.depth.shape == (1, 256, 256) and sm.depth.dtype == torch.float32
    assert torch.isinf(sm.depth).any() and torch.isfinite(sm.depth).any()
    texel = 1 / float(sm.camera.K[0, 0])
    pts, nrm, m = ground_grid()
    f = shadow_factor(pts, nrm, sm)
    assert ((f == 0) | (f == 1)).all()
    assert (f[m < 0.5 - 2 * texel] == 0).all()                                    # under the occluder
    assert (f[m > 0.5 + 2 * texel] == 1).all()                                    # well outside it
    # the outline along the x axis: the first lit point is at the projection x = 0.5, within 2 texels
    x, p, n = line_x(0.0, 1.0, 2001)
    first_lit = float(x[shadow_factor(p, n, sm) == 1].min())
    assert abs(first_lit - 0.5) <= 2 * texel
    # the occluder itself (at height 0.5, facing the light) is lit
    top = torch.tensor([[0.1, 0.5, 0.1], [-0.3, 0.5, 0.2]])
    assert (shadow_factor(top, torch.tensor([UP, UP]), sm) == 1).all()


def test_shadow_acne_without_bias_and_none_with_the_default():
    ground = plane(4.0)
    sm = shadow_map(ground, DirectionalLight((1.0, -1.0, 0.3)), 256)              # tilted: θ ≈ 47°
    pts, nrm, _ = ground_grid()
    acne = float((shadow_factor(pts, nrm, sm, bias=0.0, slope_bias=0.0) < 1).float().mean())
    assert acne > 0.3                                                             # measured: 0.50
    assert float((shadow_factor(pts, nrm, sm) < 1).float().mean()) < 1e-3        # default bias
    assert float((shadow_factor(pts, nrm, sm, pcf=5) < 1).float().mean()) < 1e-3  # scaled with the kernel
    # a constant bias alone must cover the slope: half a diagonal texel times tan θ is not enough
    texel = 1 / float(sm.camera.K[0, 0])
    small = float((shadow_factor(pts, nrm, sm, bias=0.2 * texel, slope_bias=0.0) < 1).float().mean())
    assert 0.01 < small < acne


def test_lookup_is_the_textbook_comparison_at_the_texel_holding_the_point():
    sm = shadow_map(scene(), DirectionalLight((0.6, -1.0, 0.3)), 64)
    g = torch.Generator().manual_seed(0)
    pts = torch.cat([torch.rand(4000, 1, generator=g) * 3.6 - 1.8, torch.zeros(4000, 1),
                     torch.rand(4000, 1, generator=g) * 3.6 - 1.8], 1)
    xy, z = sm.camera.project(pts)
    stored = sm.depth[0, xy[:, 1].floor().long(), xy[:, 0].floor().long()]         # texel (i, j) ∋ (x, y)
    expected = (~(z - 0.01 > stored)).float()
    got = shadow_factor(pts, None, sm, bias=0.01)
    assert torch.equal(got, expected)
    assert 0.05 < float((got == 0).float().mean()) < 0.5                          # the shadow is in the sample


def test_peter_panning_detaches_the_shadow_by_bias_times_sin_theta():
    # a thin wall standing on the ground at x = 0.5 (y in [0, 1], z in [-.5, .5]), lit from the upper left:
    # the ground point at x = 0.5 + s sees the wall at distance s / sin θ along the ray, so a bias b keeps it
    # lit up to s = b sin θ (a closed box would not show it: the map stores its far, lit side)
    wall = Mesh(torch.tensor([[0.5, 0.0, -0.5], [0.5, 0.0, 0.5], [0.5, 1.0, 0.5], [0.5, 1.0, -0.5]]),
                torch.tensor([[0, 1, 2], [0, 2, 3]]))
    light = DirectionalLight((math.sin(math.pi / 4), -math.cos(math.pi / 4), 0.0))  # 45°, travelling to +x
    sm = shadow_map([plane(4.0), wall], light, 512)
    texel = 1 / float(sm.camera.K[0, 0])
    x, p, n = line_x(0.52, 1.9, 2000)

    def extent(**kw):
        shadowed = x[shadow_factor(p, n, sm, **kw) == 0]
        return float(shadowed.min()), float(shadowed.max())

    start, end = extent()
    assert abs(start - 0.5) <= 2.5 * texel and abs(end - 1.5) <= 2 * texel       # from the box to h tan θ
    bias = 0.3
    start_b, end_b = extent(bias=bias, slope_bias=0.0)
    gap = start_b - 0.5
    assert abs(gap - bias * math.sin(math.pi / 4)) <= 2 * texel                  # 0.212: a detached shadow
    assert abs(end_b - 1.5) <= 2 * texel                                         # the far end stays


def test_pcf_softens_only_the_outline():
    sm = shadow_map(scene(), DirectionalLight((0.0, -1.0, 0.0)), 128)
    texel = 1 / float(sm.camera.K[0, 0])
    pts, nrm, m = ground_grid()
    hard, soft = shadow_factor(pts, nrm, sm), shadow_factor(pts, nrm, sm, pcf=5)
    far = (m - 0.5).abs() > 4 * texel
    assert torch.equal(hard[far], soft[far])
    assert ((soft > 0) & (soft < 1)).sum() > 100                                 # intermediate on the outline
    assert torch.allclose(soft * 25, (soft * 25).round())                        # multiples of 1/k²
    x, p, n = line_x(0.3, 0.7, 401)
    profile = shadow_factor(p, n, sm, pcf=5)
    assert (profile.diff() >= 0).all() and profile[0] == 0 and profile[-1] == 1
    ramp = x[(profile > 0) & (profile < 1)]
    assert 3 * texel <= float(ramp.max() - ramp.min()) <= 6 * texel              # about k - 1 texels wide


# --------------------------------------------------------------------------------- point and spot lights

def test_point_light_cube_map_shadows_in_all_six_directions():
    occluders = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            c = torch.zeros(3)
            c[axis] = sign
            box = cube(0.4)
            occluders.append(moved(box, tuple(c.tolist())))
    light = PointLight(position=(0.0, 0.0, 0.0))
    sm = shadow_map(occluders, light, 64, bounds=((0.0, 0.0, 0.0), 2.5))         # receivers at distance 2
    assert sm.kind == "point" and sm.depth.shape == (6, 64, 64)
    dirs = torch.eye(3).repeat_interleave(2, 0) * torch.tensor([1.0, -1.0]).repeat(3)[:, None]   # +x, -x, ...
    behind = 2 * dirs
    f = shadow_factor(behind, -dirs, sm)
    assert (f == 0).all()
    # beside each occluder (at 30° off its axis; the box subtends about 11°): lit
    beside = []
    for d in dirs:
        other = torch.roll(d, 1)
        v = d + math.tan(math.radians(30)) * other
        beside.append(2 * v / v.norm())
    beside = torch.stack(beside)
    assert (shadow_factor(beside, -beside, sm) == 1).all()
    # a point outside the fitted far plane counts as lit (the out-of-frustum policy)
    assert float(shadow_factor(torch.tensor([[9.0, 0.0, 0.0]]), None, sm)[0]) == 1.0


def test_spot_light_perspective_shadow():
    light = SpotLight(position=(0.0, 2.0, 0.0), direction=(0.0, -1.0, 0.0), angle=90.0)
    sm = shadow_map([plane(6.0), square(0.5, (0.0, 1.0, 0.0))], light, 256)
    assert sm.kind == "spot" and not sm.camera.orthographic
    texel = 2.0 / float(sm.camera.K[0, 0])                                        # at the ground, z = 2
    pts, nrm, m = ground_grid(n=121, half=2.9)
    f = shadow_factor(pts, nrm, sm)
    r = pts[:, [0, 2]].abs().max(1).values
    assert (f[m < 0.5 - 2 * texel] == 0).all()                                    # magnified ×2 by perspective
    assert (f[(m > 0.5 + 2 * texel) & (r < 1.9)] == 1).all()
    assert (f[r > 2.05] == 1).all()                                               # outside the cone: lit


# ------------------------------------------------------------------------------------------- area lights

def test_area_light_samples_are_stratified_and_reproducible():
    rect = area_light_samples("rectangle", (0.0, 2.0, 0.0), (0.0, -1.0, 0.0), (0.6, 0.2), 16, seed=3)
    assert rect.shape == (16, 3) and torch.allclose(rect[:, 1], torch.tensor(2.0))
    assert torch.equal(rect, area_light_samples("rectangle", (0.0, 2.0, 0.0), (0.0, -1.0, 0.0), (0.6, 0.2), 16,
                                                seed=3))
    a = area_light_samples("rectangle", (0, 0, 0), (0, 0, 1), 1.0, 16, u_axis=(1, 0, 0), seed=0)
    cell = ((a[:, 0] + 0.5) * 4).floor() * 4 + ((a[:, 1] + 0.5) * 4).floor()     # one point per 4×4 cell
    assert sorted(cell.long().tolist()) == list(range(16))
    disk = area_light_samples("disk", (1.0, 1.0, 1.0), (0.0, 0.0, 1.0), 0.5, 64, seed=1, dtype=torch.float64)
    assert disk.dtype == torch.float64
    rad = (disk[:, :2] - 1).norm(dim=1)
    assert (rad <= 0.5 + 1e-12).all() and torch.allclose(disk[:, 2], torch.tensor(1.0, dtype=torch.float64))
    assert abs(float((rad < 0.5 / math.sqrt(2)).double().mean()) - 0.5) <= 0.1   # equal-area strata


def _analytic_visibility(x, w, H=2.0, h=0.5, edge=1.0):
    """Fraction of a w-wide light at height H (centred above x = 0) that the ground point (x, 0, 0) sees past
    an occluder edge at x = edge, height h: light points with x_l > x + (edge - x) H / h are visible."""
    xl = x + (edge - x) * H / h
    return ((w / 2 - xl) / w).clamp(0, 1)


def test_area_light_converges_to_the_analytic_soft_shadow():
    meshes = [plane(5.0), square(2.0, (0.0, 0.5, 0.0))]                           # occluder edge at x = 1
    x, p, n = line_x(1.0, 1.7, 141)
    w = 0.6
    exact = _analytic_visibility(x, w)                                            # penumbra x ∈ [1.233, 1.433]
    factors = {}
    for count in (4, 8, 16, 32, 64):
        samples = area_light_samples("rectangle", (0.0, 2.0, 0.0), (0.0, -1.0, 0.0), w, count,
                                     u_axis=(1.0, 0.0, 0.0), seed=0)
        factors[count] = area_shadow_factor(p, n, meshes, samples, resolution=256, light_normal=(0.0, -1.0, 0.0))
    steps = [float((factors[2 * c] - factors[c]).abs().mean()) for c in (4, 8, 16, 32)]
    assert steps[-1] < steps[0] / 2                                               # N vs 2N differences shrink
    errors = {c: float((factors[c] - exact).abs().mean()) for c in factors}
    assert errors[64] < errors[16] < errors[4] and errors[64] < 0.01              # measured: .028, .013, .005
    assert float((factors[64] - exact).abs().max()) < 0.08                        # measured: 0.045


def test_penumbra_widens_with_the_light():
    meshes = [plane(5.0), square(2.0, (0.0, 0.5, 0.0))]
    x, p, n = line_x(0.9, 1.9, 201)
    spacing = float(x[1] - x[0])
    widths = []
    for w in (0.3, 0.9):
        s = area_light_samples("rectangle", (0.0, 2.0, 0.0), (0.0, -1.0, 0.0), w, 36, u_axis=(1, 0, 0), seed=0)
        f = area_shadow_factor(p, n, meshes, s, resolution=256, light_normal=(0.0, -1.0, 0.0))
        assert (f.diff() >= -1e-6).all()                                          # lit increases away from it
        widths.append(spacing * float(((f > 0) & (f < 1)).sum()))
    assert widths[1] > 2 * widths[0]
    for got, w in zip(widths, (0.3, 0.9)):
        assert abs(got - w / 3) <= 0.25 * w / 3 + 4 * spacing                     # width w h / (H - h) = w / 3


def test_area_light_with_cube_maps_matches_one_sided_maps():
    meshes = [plane(4.0), square(1.0, (0.0, 0.5, 0.0))]
    x, p, n = line_x(0.0, 1.2, 61)
    s = area_light_samples("disk", (0.0, 2.0, 0.0), (0.0, -1.0, 0.0), 0.3, 4, seed=2)
    cube_f = area_shadow_factor(p, n, meshes, s, resolution=128)
    spot_f = area_shadow_factor(p, n, meshes, s, resolution=128, light_normal=(0.0, -1.0, 0.0))
    assert float((cube_f - spot_f).abs().mean()) < 0.03
    assert cube_f[0] == 0 and cube_f[-1] == 1


# ------------------------------------------------------------------- pass 2's building blocks, by hand

F64 = torch.float64
INF = float("inf")


def test_light_space_by_hand():
    K = torch.tensor([[10.0, 0.0, 5.0], [0.0, 20.0, 6.0], [0.0, 0.0, 1.0]], dtype=F64)
    R, t = torch.eye(3, dtype=F64), torch.tensor([0.0, 0.0, 2.0], dtype=F64)
    p = torch.tensor([[1.0, 0.5, 2.0], [0.0, 0.0, 0.0]], dtype=F64)        # camera space (1, .5, 4), (0, 0, 2)
    persp = light_space(p, K, R, t, False)
    assert persp.dtype == F64 and torch.equal(persp, torch.tensor([[7.5, 8.5, 4.0], [5.0, 6.0, 2.0]], dtype=F64))
    ortho = light_space(p, K, R, t, True)                                   # no division by depth
    assert torch.equal(ortho, torch.tensor([[15.0, 16.0, 4.0], [5.0, 6.0, 2.0]], dtype=F64))
    cam = Camera(K, R, t, 16, 16, 0.1, 10.0, False)                         # a Camera: its own K, R, t and mode
    assert torch.equal(light_space(p, cam), persp)
    sm = shadow_map(scene(), SpotLight((0.0, 2.0, 0.0), (0.0, -1.0, 0.0), 70.0), 32)
    pts, _, _ = ground_grid(n=5)
    xy, z = sm.camera.project(pts)
    assert torch.equal(light_space(pts, sm.camera), torch.cat([xy, z[:, None]], 1))


def test_biased_depth_and_biased_lit_by_hand():
    # total bias = 0.25 + 1.0 * 0.125 * tan θ: 0.25 for tan θ = 0, 0.5 for tan θ = 2 (exact in binary)
    z = torch.tensor([1.0, 1.5, 1.625, 5.0], dtype=F64)
    stored = torch.tensor([1.0, 1.0, 1.0, INF], dtype=F64)                  # the last texel is empty
    tan = torch.tensor([0.0, 2.0, 2.0, 0.0], dtype=F64)
    assert torch.equal(biased_depth(z, 0.125, tan, 0.25, 1.0), torch.tensor([0.75, 1.0, 1.125, 4.75], dtype=F64))
    lit = biased_lit(z, stored, torch.full_like(z, 0.125), tan, 0.25, 1.0)
    assert lit.dtype == torch.bool and lit.tolist() == [True, True, False, True]   # exactly at stored: lit
    assert biased_lit(z, stored, 0.125, tan, 0.0, 0.0).tolist() == [True, False, False, True]
    assert biased_lit(z[:0], stored[:0], 0.1, 0.0, 0.1, 1.0).shape == (0,)


def test_pcf_by_hand():
    depth = torch.tensor([[1.0, INF, 1.0], [INF, 1.0, INF], [1.0, 1.0, 1.0]], dtype=F64)
    coords = torch.tensor([[1.5, 1.5], [0.2, 0.2], [3.0, 0.5], [1.5, 1.5]], dtype=F64)
    depths = torch.tensor([2.0, 2.0, 0.5, 1.0], dtype=F64)
    assert pcf(depth, coords, depths, 1).tolist() == [0.0, 0.0, 1.0, 1.0]  # x = W reads the last column
    three = pcf(depth, coords, depths, 3)
    assert three.dtype == F64
    # centre: the 3 empty texels of 9; corner: 5 neighbours outside (lit) + 2 empty of the 4 inside
    assert torch.allclose(three, torch.tensor([3 / 9, 7 / 9, 1.0, 1.0], dtype=F64), rtol=0, atol=1e-15)
    # a cube-map face clamps instead: the corner reads (0, 0) four times, (0, 1) and (1, 0) twice, (1, 1) once
    assert float(pcf(depth, coords[1:2], depths[1:2], 3, outside="clamp")[0]) == 4 / 9
    assert pcf(depth.float(), coords, depths, 3).dtype == torch.float32     # depth_map's dtype


@pytest.mark.parametrize("k", [1, 3])
@pytest.mark.parametrize("light", [DirectionalLight((0.6, -1.0, 0.3)),
                                   SpotLight((0.3, 2.0, 0.1), (0.0, -1.0, 0.0), 90.0)], ids=["directional", "spot"])
def test_shadow_factor_is_light_space_then_bias_then_pcf(light, k):
    sm = shadow_map(scene(F64), light, 48)
    pts, _, _ = ground_grid(n=41, half=1.5, dtype=F64)
    x, y, z = light_space(pts, sm.camera).unbind(1)
    fx = sm.camera.K[0, 0]
    texel = 1 / fx if sm.camera.orthographic else z / fx
    z_test = biased_depth(z, texel, 0.0, 0.01, 0.0)
    expected = pcf(sm.depth[0], torch.stack([x, y], 1), z_test, k)
    got = shadow_factor(pts, None, sm, bias=0.01, pcf=k)
    assert torch.equal(got, expected) and got.unique().numel() >= 2
    if k == 1:
        stored = sm.depth[0, y.floor().long().clamp(0, 47), x.floor().long().clamp(0, 47)]
        assert torch.equal(biased_lit(z, stored, texel, 0.0, 0.01, 0.0).to(F64), got)


def test_building_blocks_reject_bad_inputs():
    K, R, t = torch.eye(3), torch.eye(3), torch.zeros(3)
    with pytest.raises(TypeError, match="needs a Camera, or K, R and t"):
        light_space(torch.zeros(2, 3), K)
    cam = Camera(K, R, t, 4, 4, 0.1, 10.0, False)
    with pytest.raises(TypeError, match="takes no R or t"):
        light_space(torch.zeros(2, 3), cam, R, t)
    with pytest.raises(ValueError, match="points must have shape"):
        light_space(torch.zeros(2, 2), K, R, t)
    z = torch.ones(3)
    with pytest.raises(ValueError, match="z must have shape"):
        biased_lit(torch.ones(3, 1), torch.ones(3, 1), 0.1, 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="stored must have one depth per point"):
        biased_lit(z, torch.ones(2), 0.1, 0.0, 0.0, 0.0)
    depth = torch.ones(4, 4)
    for k in (0, 2, -1, 1.5, True):
        with pytest.raises(ValueError, match="k must be an odd integer"):
            pcf(depth, torch.zeros(3, 2), z, k)
    with pytest.raises(ValueError, match=r"depth_map must be one \(H, W\) map"):
        pcf(depth[None], torch.zeros(3, 2), z, 1)
    with pytest.raises(ValueError, match="coords must have shape"):
        pcf(depth, torch.zeros(3, 3), z, 1)
    with pytest.raises(ValueError, match="coords contains NaN"):
        pcf(depth, torch.full((3, 2), float("nan")), z, 1)
    with pytest.raises(ValueError, match="depths must have one value per point"):
        pcf(depth, torch.zeros(3, 2), torch.ones(4), 1)
    with pytest.raises(ValueError, match="outside must be 'lit' or 'clamp'"):
        pcf(depth, torch.zeros(3, 2), z, 1, outside="dark")


# --------------------------------------------------------------------------------- precision and inputs

@pytest.mark.parametrize("direction", [(0.0, -1.0, 0.0), (0.6, -1.0, 0.3)])
def test_float32_and_float64_agree(direction):
    factors = []
    for dtype in (torch.float32, torch.float64):
        sm = shadow_map(scene(dtype), DirectionalLight(direction), 128)
        assert sm.depth.dtype == dtype
        pts, nrm, _ = ground_grid(dtype=dtype)
        f = shadow_factor(pts, nrm, sm, pcf=3)
        assert f.dtype == dtype
        factors.append(f.double())
    differ = (factors[0] - factors[1]).abs() > 1e-6                               # beyond float32 rounding of j / 9
    assert float(differ.double().mean()) < 0.005                                  # measured: 0


def test_no_nan_in_degenerate_cases():
    meshes = scene()
    pts = torch.tensor([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [1e6, 0.0, 0.0], [0.3, 0.5, 0.3], [1.0, 0.0, 1.0]])
    nrm = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1e-9, 0.0]])
    for light in (DirectionalLight((0.0, -1.0, 0.0)), PointLight((0.0, 1.0, 0.0)),
                  SpotLight((0.0, 1.0, 0.0), (0.0, -1.0, 0.0), 60.0)):
        sm = shadow_map(meshes, light, 32)
        for k in (1, 3):
            f = shadow_factor(pts, nrm, sm, pcf=k)
            assert torch.isfinite(f).all() and ((f >= 0) & (f <= 1)).all()
    assert float(shadow_factor(pts[:1], nrm[:1], shadow_map(meshes, PointLight((0.0, 1.0, 0.0)), 8))[0]) == 1.0
    assert shadow_factor(torch.zeros(0, 3), torch.zeros(0, 3), sm).shape == (0,)


def test_bad_inputs_raise_clear_errors():
    meshes = scene()
    sm = shadow_map(meshes, DirectionalLight(), 16)
    pts, nrm, _ = ground_grid(n=4)
    with pytest.raises(ValueError, match="points_world must have shape"):
        shadow_factor(pts[:, :2], nrm, sm)
    with pytest.raises(ValueError, match="normals must have one row per point"):
        shadow_factor(pts, nrm[:3], sm)
    with pytest.raises(ValueError, match="normals must have shape"):
        shadow_factor(pts, nrm[:, :2], sm)
    for k in (0, 2, 4, -1, 1.5):
        with pytest.raises(ValueError, match="pcf must be an odd integer"):
            shadow_factor(pts, nrm, sm, pcf=k)
    for res in (0, -3, 2.5):
        with pytest.raises(ValueError, match="resolution must be a positive integer"):
            shadow_map(meshes, DirectionalLight(), res)
    with pytest.raises(ValueError, match="light.direction must be a non-zero vector"):
        shadow_map(meshes, DirectionalLight((0.0, 0.0, 0.0)), 8)
    with pytest.raises(ValueError, match="SpotLight.angle"):
        shadow_map(meshes, SpotLight(angle=180.0), 8)
    with pytest.raises(TypeError, match="light must be"):
        shadow_map(meshes, "sun", 8)
    with pytest.raises(TypeError, match="shadow_map must be a ShadowMap"):
        shadow_factor(pts, nrm, sm.depth)
    with pytest.raises(ValueError, match="kind must be"):
        area_light_samples("triangle", (0, 0, 0), (0, 1, 0), 1.0, 4)
    with pytest.raises(ValueError, match="n must be a positive integer"):
        area_light_samples("disk", (0, 0, 0), (0, 1, 0), 1.0, 0)
    with pytest.raises(ValueError, match="size must be positive"):
        area_light_samples("rectangle", (0, 0, 0), (0, 1, 0), -1.0, 4)
    with pytest.raises(ValueError, match="samples must have shape"):
        area_shadow_factor(pts, nrm, meshes, torch.zeros(4, 2))
