"""Rasterizer: hand-checked grids, the naive oracle, watertightness, depth, clipping and stress cases."""
import math

import pytest
import torch
from hypothesis import given, settings, strategies as st

import course.raster as raster
import course.scan as scan
from course import kernels
from course.camera import Camera, axis_angle_to_matrix
from course.mesh import Mesh
from course.models import cube, icosphere, plane
from course.raster import (Fragments, barycentric_2d, edge_function, inside_triangle, interpolate,
                           perspective_correct_bary, rasterize, rasterize_naive, zbuffer_resolve)

# every test runs on the compiled kernels and on the torch path (tests/conftest.py)
pytestmark = pytest.mark.usefixtures("both_backends")


def ortho8(width=8, height=8, dtype=torch.float64):
    """One world unit per pixel, world (0, 0) at the image centre, looking down -z."""
    return Camera.look_at((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), ortho_height=height, width=width, height=height,
                          dtype=dtype)


def screen_mesh(points_xy, faces, z=0.0, size=8):
    """A mesh given in the screen coordinates of ``ortho8`` (x right, y down)."""
    return Mesh([[x - size / 2, size / 2 - y, z] for x, y in points_xy], faces)


def random_pose(seed):
    g = torch.Generator().manual_seed(seed)
    w = torch.randn(3, generator=g, dtype=torch.float64)
    return axis_angle_to_matrix(w), torch.randn(3, generator=g, dtype=torch.float64)


def bumpy_sphere(seed, subdivisions=2):
    """A closed, star-shaped (non-convex) mesh: an icosphere with random radii."""
    g = torch.Generator().manual_seed(seed)
    m = icosphere(subdivisions, dtype=torch.float64)
    r = 1 + 0.25 * torch.rand(m.num_verts, 1, generator=g, dtype=torch.float64)
    return Mesh(m.verts * r, m.faces)


# ----------------------------------------------------------------------------------- hand-checked 8 × 8

def test_asymmetric_triangle_8x8_hand_checked():
    # vertices (1, 1), (7, 3), (2, 7) on screen: an asymmetric triangle, so any axis flip shows
    mesh = screen_mesh([(1, 1), (7, 3), (2, 7)], [[0, 1, 2]])
    expected = torch.tensor([
        [0, 0, 0, 0, 0, 0, 0, 0],
        [0, 1, 0, 0, 0, 0, 0, 0],    # (2.5, 1.5) lies exactly on the edge (1,1)→(7,3), a right edge: out
        [0, 1, 1, 1, 1, 0, 0, 0],    # (5.5, 2.5) on the same edge: out
        [0, 1, 1, 1, 1, 1, 0, 0],
        [0, 0, 1, 1, 1, 0, 0, 0],
        [0, 0, 1, 1, 0, 0, 0, 0],
        [0, 0, 1, 0, 0, 0, 0, 0],
        [0, 0, 0, 0, 0, 0, 0, 0]], dtype=torch.bool)
    # worked out with the three edge functions at each centre (j + 0.5, i + 0.5)
    centres = torch.stack(torch.meshgrid(torch.arange(8.0) + 0.5, torch.arange(8.0) + 0.5, indexing="xy"), -1)
    by_hand = inside_triangle(torch.tensor([[1.0, 1], [7, 3], [2, 7]]), centres.reshape(-1, 2)).view(8, 8)
    assert torch.equal(by_hand, expected)
    for rast in (rasterize, rasterize_naive):
        fr = rast(mesh, ortho8())
        assert torch.equal(fr.mask, expected)
        assert torch.equal(fr.face_id, torch.where(expected, 0, -1))
    fr = rasterize(mesh, ortho8())
    assert torch.allclose(fr.depth[expected], torch.full((int(expected.sum()),), 5.0, dtype=torch.float64))
    assert torch.isinf(fr.depth[~expected]).all()
    # barycentrics reproduce the pixel centre
    tri = torch.tensor([[1.0, 1], [7, 3], [2, 7]], dtype=torch.float64)
    p = fr.bary[expected] @ tri
    rows, cols = expected.nonzero(as_tuple=True)
    assert torch.allclose(p, torch.stack([cols + 0.5, rows + 0.5], 1).double(), atol=1e-12)


def test_nearer_face_wins_and_ties_go_to_lower_id():
    back = [(0, 0), (8, 0), (0, 8)]
    mesh = Mesh(torch.cat([screen_mesh(back, [[0, 1, 2]], z=0.0).verts,
                           screen_mesh(back, [[0, 1, 2]], z=1.0).verts]), [[0, 1, 2], [3, 4, 5]])
    fr = rasterize(mesh, ortho8())
    assert set(fr.face_id[fr.mask].tolist()) == {1}                         # z = 1 is nearer to the eye at z = 5
    assert torch.allclose(fr.depth[fr.mask], torch.tensor(4.0, dtype=torch.float64))
    same = Mesh(torch.cat([mesh.verts[:3], mesh.verts[:3]]), [[0, 1, 2], [3, 4, 5]])
    assert set(rasterize(same, ortho8()).face_id[rasterize(same, ortho8()).mask].tolist()) == {0}


def test_edge_function_is_exactly_antisymmetric():
    g = torch.Generator().manual_seed(0)
    a, b, p = (torch.randn(1000, 2, generator=g, dtype=torch.float64) * 100 for _ in range(3))
    assert torch.equal(edge_function(a, b, p), -edge_function(b, a, p))


def test_square_split_in_two_covers_diagonal_once():
    mesh = screen_mesh([(0, 0), (8, 0), (8, 8), (0, 8)], [[0, 1, 2], [0, 2, 3]])   # diagonal through centres
    fr = rasterize(mesh, ortho8())
    assert fr.mask.all()
    counts = torch.zeros(64, dtype=torch.long)
    for f in range(2):
        pix, _, _ = scan._scan_convert(raster._screen_triangles(
            _cam_verts(mesh, ortho8()), mesh.faces[f:f + 1], ortho8(), False), 8, 8)
        counts += torch.bincount(pix, minlength=64)
    assert torch.equal(counts, torch.ones(64, dtype=torch.long))


def _cam_verts(mesh, cam):
    return raster._camera_space(mesh.verts, cam)


# ---------------------------------------------------------------------------------- oracle: naive loop

@pytest.mark.parametrize("orthographic", [False, True])
@pytest.mark.parametrize("cull", [False, True])
def test_fast_path_equals_naive(orthographic, cull):
    mesh = bumpy_sphere(3)
    kw = dict(ortho_height=3.0) if orthographic else dict(fov_y=50)
    cam = Camera.look_at((0.5, 1.0, 3.0), (0.1, 0.0, 0.0), width=33, height=27, dtype=torch.float64, **kw)
    fast, naive = rasterize(mesh, cam, cull_backfaces=cull), rasterize_naive(mesh, cam, cull_backfaces=cull)
    assert torch.equal(fast.face_id, naive.face_id)
    assert torch.allclose(fast.depth[fast.mask], naive.depth[naive.mask])


def test_chunking_gives_identical_fragments():
    mesh = icosphere(3)
    cam = Camera.look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov_y=40, width=64, height=48)
    whole = rasterize(mesh, cam)
    st_all = raster._screen_triangles(_cam_verts(mesh, cam), mesh.faces, cam, False)
    assert len(list(scan._chunks(st_all, 64, 48, (97, 97)))) > 20               # many tiny chunks
    chunked = scan._zbuffer(st_all, cam, budget=(97, 97))
    assert torch.equal(chunked.view(48, 64), whole.face_id)


# --------------------------------------------------------------------------- watertightness (property)

def layer_counts(mesh, cam):
    """Per pixel, over ALL faces (not only the visible one): fragments of front faces and of back faces."""
    st_all = raster._screen_triangles(raster._camera_space(mesh.verts, cam), mesh.faces, cam, False)
    pix, _, face = scan._scan_convert(st_all, cam.width, cam.height)
    xy, _ = cam.project(mesh.verts.double())
    tri = xy[mesh.faces]
    front = edge_function(tri[:, 0], tri[:, 1], tri[:, 2])[face] < 0        # CCW on screen (y down)
    n = cam.width * cam.height
    count = lambda sel: torch.bincount(pix[sel], minlength=n).view(cam.height, cam.width)
    return count(front), count(~front)


def random_camera(seed, ortho, distance=4.0):
    R, _ = random_pose(seed)
    eye = R @ torch.tensor([0.0, 0.0, distance], dtype=torch.float64)
    kw = dict(ortho_height=3.2) if ortho else dict(fov_y=45)
    return Camera.look_at(eye, (0.0, 0.0, 0.0), up=R[:, 1], width=40, height=36, dtype=torch.float64, **kw)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), ortho=st.booleans())
def test_convex_mesh_front_faces_cover_silhouette_exactly_once(seed, ortho):
    g = torch.Generator().manual_seed(seed)
    axes = 0.6 + torch.rand(3, generator=g, dtype=torch.float64)            # a random ellipsoid: convex
    mesh = icosphere(2, dtype=torch.float64)
    mesh = Mesh(mesh.verts * axes, mesh.faces)
    front, back = layer_counts(mesh, random_camera(seed, ortho))
    assert front.max() <= 1 and back.max() <= 1                             # no double cover
    assert torch.equal(front, back)                                         # no crack in either layer
    assert torch.equal(front == 1, rasterize(mesh, random_camera(seed, ortho)).mask)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), ortho=st.booleans())
def test_closed_mesh_is_watertight(seed, ortho):
    """A ray through any pixel centre enters a closed surface as often as it leaves it: for every pixel the
    front-face fragments equal the back-face fragments. A crack or a double cover breaks the balance."""
    mesh = bumpy_sphere(seed, subdivisions=2)
    cam = random_camera(seed, ortho)
    front, back = layer_counts(mesh, cam)
    assert torch.equal(front, back)
    assert torch.equal(front > 0, rasterize(mesh, cam).mask)


def test_pixel_aligned_grid_is_watertight():
    """A subdivided plane whose edges pass exactly through pixel centres (the hard case for fill rules)."""
    m = plane(size=10.0, subdivisions=10, dtype=torch.float64)              # 1-unit squares, xz plane
    verts = m.verts[:, [0, 2, 1]] * torch.tensor([1.0, -1.0, 1.0], dtype=torch.float64) + 0.5
    mesh = Mesh(verts, m.faces)                                             # facing +z, shifted half a pixel
    front, back = layer_counts(mesh, ortho8())
    assert torch.equal(front, torch.ones(8, 8, dtype=torch.long)) and back.sum() == 0


# ------------------------------------------------------------------------------------- depth (property)

@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_depth_is_the_ray_plane_depth(seed):
    g = torch.Generator().manual_seed(seed)
    tri = torch.randn(3, 3, generator=g, dtype=torch.float64)
    mesh = Mesh(tri, [[0, 1, 2]])
    cam = Camera.look_at((0.0, 0.0, 4.0), (0.0, 0.0, 0.0), fov_y=60, width=24, height=20, dtype=torch.float64)
    fr = rasterize(mesh, cam)
    origins, dirs = cam.rays()
    n = torch.linalg.cross(tri[1] - tri[0], tri[2] - tri[0])
    t = ((tri[0] - origins) @ n) / (dirs @ n)                               # (H, W) ray parameter
    z = cam.to_camera((origins + t[..., None] * dirs).reshape(-1, 3))[:, 2].view(20, 24)
    assert torch.allclose(fr.depth[fr.mask], z[fr.mask], rtol=1e-9, atol=1e-9)
    assert (fr.bary[fr.mask] > -1e-9).all()


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_silhouette_invariant_under_rigid_motion(seed):
    mesh = bumpy_sphere(seed, subdivisions=1)
    cam = Camera.look_at((0.3, 0.4, 3.5), (0.0, 0.0, 0.0), fov_y=50, width=32, height=32, dtype=torch.float64)
    Q, T = random_pose(seed + 1)                                            # move the world rigidly
    moved = Mesh(mesh.verts @ Q.T + T, mesh.faces)
    cam2 = Camera(cam.K, cam.R @ Q.T, cam.t - cam.R @ Q.T @ T, 32, 32, cam.near, cam.far)
    a, b = rasterize(mesh, cam), rasterize(moved, cam2)
    assert (a.mask != b.mask).sum() <= 1                                    # a centre on an edge may round
    assert (a.face_id != b.face_id).sum() <= 2


# ---------------------------------------------------------------------------------------- clipping

def test_triangle_behind_camera_never_appears():
    mesh = Mesh([[-1.0, -1.0, 6.0], [1.0, -1.0, 6.0], [0.0, 1.0, 6.0]], [[0, 1, 2]])  # eye at z = 5, looks -z
    cam = Camera.look_at((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov_y=60, width=16, height=16)
    assert not rasterize(mesh, cam).mask.any()


def test_ground_plane_crossing_near_plane_is_clipped_not_dropped():
    m = plane(size=40.0, subdivisions=4, dtype=torch.float64)               # y = 0, large, under the eye
    cam = Camera.look_at((0.0, 1.0, 0.0), (0.0, 1.0, -1.0), fov_y=90, width=32, height=32, near=0.5, far=15.0,
                         dtype=torch.float64)
    fr = rasterize(m, cam)
    origins, dirs = cam.rays()
    t = -origins[..., 1] / dirs[..., 1]                                     # hit y = 0
    z = t * (dirs @ cam.R[2])                                               # camera depth of the hit
    hits = (dirs[..., 1] < 0) & (z >= cam.near) & (z <= cam.far) & ((origins + t[..., None] * dirs).abs()[..., [0, 2]] <= 20).all(-1)
    assert torch.equal(fr.mask, hits)
    assert torch.allclose(fr.depth[hits], z[hits])
    assert torch.isfinite(fr.bary).all()


def test_near_clipped_mesh_stays_watertight():
    mesh = bumpy_sphere(7, subdivisions=2)
    cam = Camera.look_at((0.0, 0.0, 1.05), (0.0, 0.0, 0.0), fov_y=100, width=40, height=40, near=0.3,
                         dtype=torch.float64)                               # near plane cuts the sphere
    fr = rasterize(mesh, cam)
    assert fr.mask.float().mean() > 0.5 and torch.isfinite(fr.depth[fr.mask]).all()
    assert (fr.depth[fr.mask] >= cam.near - 1e-9).all()
    fast, naive = fr, rasterize_naive(mesh, cam)
    assert torch.equal(fast.face_id, naive.face_id)


def test_far_plane_clips_per_pixel():
    m = plane(size=40.0, subdivisions=2, dtype=torch.float64)               # y = 0, reaching past the far plane
    cam = Camera.look_at((0.0, 1.0, 0.0), (0.0, 0.0, -4.0), fov_y=60, width=24, height=24, far=6.0,
                         dtype=torch.float64)
    fr = rasterize(m, cam)
    origins, dirs = cam.rays()
    t = -origins[..., 1] / dirs[..., 1]
    z = t * (dirs @ cam.R[2])                                               # camera depth of the hit
    hits = (dirs[..., 1] < 0) & (z <= cam.far)
    assert hits.any() and (~hits & (dirs[..., 1] < 0)).any()                # the far plane cuts the view
    assert torch.equal(fr.mask, hits)


# ---------------------------------------------------------------------------------------- stress

def test_degenerate_and_sliver_triangles_are_finite():
    verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [2, 0, 0],                # collinear: zero area
                          [-2, -2, 0], [2, -2, 0], [0, 2, 0],               # a big triangle behind them
                          [-3, 1, 0.5], [3, 1 + 1e-9, 0.5], [3, 1, 0.5],    # sliver
                          [0, -1, 1], [0, -1, 1], [0, -1, 1]], dtype=torch.float64)  # collapsed to a point
    mesh = Mesh(verts, [[0, 1, 2], [3, 4, 5], [6, 7, 8], [9, 10, 11]])
    cam = Camera.look_at((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov_y=60, width=32, height=32, dtype=torch.float64)
    fr = rasterize(mesh, cam)
    assert set(fr.face_id.unique().tolist()) <= {-1, 1, 2}
    assert torch.isfinite(fr.bary).all() and torch.isfinite(fr.depth[fr.mask]).all()
    verts.requires_grad_(True)
    fr = rasterize(Mesh(verts, mesh.faces), cam)
    (fr.bary.sum() + fr.depth[fr.mask].sum()).backward()
    assert torch.isfinite(verts.grad).all()


def test_edge_on_triangle_gives_finite_gradients():
    verts = torch.tensor([[0.0, -1, -1], [0, 1, -1], [0, 0, 1]], dtype=torch.float64, requires_grad=True)
    cam = Camera.look_at((1e-7, 0.0, 5.0), (0.0, 0.0, 0.0), fov_y=60, width=16, height=16, dtype=torch.float64)
    fr = rasterize(Mesh(verts, [[0, 1, 2]]), cam)
    (fr.bary.sum() + fr.depth[fr.mask].sum()).backward()
    assert torch.isfinite(verts.grad).all()


@pytest.mark.parametrize("scale", [1e-4, 1.0, 1e4])
def test_scale_invariance(scale):
    mesh = bumpy_sphere(1, subdivisions=2)
    cam = lambda s: Camera.look_at((0.4 * s, 0.3 * s, 3.0 * s), (0.0, 0.0, 0.0), fov_y=50, width=32, height=32,
                                   near=0.1 * s, far=100 * s, dtype=torch.float64)
    ref = rasterize(mesh, cam(1.0))
    fr = rasterize(Mesh(mesh.verts * scale, mesh.faces), cam(scale))
    same = (fr.face_id == ref.face_id) & ref.mask
    assert (fr.face_id != ref.face_id).sum() <= 1
    assert torch.allclose(fr.depth[same] / scale, ref.depth[same], rtol=1e-7)


def test_float32_matches_float64():
    mesh64 = bumpy_sphere(2, subdivisions=3)
    cam64 = Camera.look_at((0.4, 0.3, 3.0), (0.0, 0.0, 0.0), fov_y=50, width=48, height=40, dtype=torch.float64)
    f64 = rasterize(mesh64, cam64)
    f32 = rasterize(mesh64.to(dtype=torch.float32), cam64.to(dtype=torch.float32))
    assert f32.bary.dtype == torch.float32 and f32.depth.dtype == torch.float32
    same = f32.face_id == f64.face_id
    assert same.float().mean() > 0.995
    assert torch.allclose(f32.bary[same & f64.mask].double(), f64.bary[same & f64.mask], atol=1e-4)
    assert torch.allclose(f32.depth[same & f64.mask].double(), f64.depth[same & f64.mask], rtol=1e-4)


def test_empty_view_and_zero_visible_faces():
    cam = Camera.look_at((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov_y=60, width=8, height=8)
    far_away = Mesh([[100.0, 100, 0], [101, 100, 0], [100, 101, 0]], [[0, 1, 2]])
    fr = rasterize(far_away, cam)
    assert not fr.mask.any() and torch.isinf(fr.depth).all() and (fr.bary == 0).all()


# -------------------------------------------------------------------------------------- gradients

def test_interpolate_gradcheck_attr_and_verts():
    verts = torch.tensor([[-1.0, -1, 0], [1.2, -0.9, 0.3], [0.1, 1.1, -0.2]], dtype=torch.float64)
    attr = torch.rand(3, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    cam = Camera.look_at((0.1, 0.2, 4.0), (0.0, 0.0, 0.0), fov_y=40, width=10, height=9, dtype=torch.float64)
    faces = torch.tensor([[0, 1, 2]])

    def f(a, v):
        return interpolate(a, rasterize(Mesh(v, faces), cam), faces)

    assert torch.autograd.gradcheck(f, (attr.requires_grad_(), verts.requires_grad_()), eps=1e-7, atol=1e-6)


def test_depth_and_bary_gradcheck_camera():
    verts = torch.tensor([[-1.0, -1, 0], [1.2, -0.9, 0.3], [0.1, 1.1, -0.2]], dtype=torch.float64)
    base = Camera.look_at((0.1, 0.2, 4.0), (0.0, 0.0, 0.0), fov_y=40, width=10, height=9, dtype=torch.float64)
    mesh = Mesh(verts, [[0, 1, 2]])

    def f(K, R, t):
        fr = rasterize(mesh, Camera(K, R, t, 10, 9))
        return fr.bary, fr.depth[fr.mask]

    inputs = tuple(x.clone().requires_grad_() for x in (base.K, base.R, base.t))
    assert torch.autograd.gradcheck(f, inputs, eps=1e-7, atol=1e-6)


def test_no_graph_when_nothing_requires_grad():
    fr = rasterize(icosphere(1), Camera.look_at((0.0, 0.0, 3.0), fov_y=40, width=16, height=16))
    assert not fr.bary.requires_grad and not fr.depth.requires_grad


# ------------------------------------------------------------------------------------ small helpers

def test_barycentric_2d_and_perspective_correction():
    tri = torch.tensor([[0.0, 0.0], [4.0, 0.0], [0.0, 2.0]])
    w = barycentric_2d(tri, torch.tensor([[0.0, 0.0], [2.0, 1.0], [1.0, 0.5]]))
    assert torch.allclose(w, torch.tensor([[1.0, 0, 0], [0, 0.5, 0.5], [0.5, 0.25, 0.25]]))
    assert torch.isfinite(barycentric_2d(torch.zeros(3, 2), torch.ones(2, 2))).all()
    pc = perspective_correct_bary(torch.tensor([[0.5, 0.5, 0.0]]), torch.tensor([[1.0, 3.0, 2.0]]))
    assert torch.allclose(pc, torch.tensor([[0.75, 0.25, 0.0]]))              # the nearer vertex weighs more


def test_zbuffer_resolve():
    face_map, depth_map = zbuffer_resolve(torch.tensor([0, 0, 2, 2, 2]), torch.tensor([2.0, 1.0, 3.0, 3.0, -1.0]),
                                          torch.tensor([5, 7, 1, 0, 9]), 4)
    assert face_map.tolist() == [7, -1, 9, -1]
    assert depth_map[0] == 1.0 and depth_map[2] == -1.0 and torch.isinf(depth_map[[1, 3]]).all()
    face_map, _ = zbuffer_resolve(torch.tensor([1, 1]), torch.tensor([3.0, 3.0]), torch.tensor([4, 2]), 2)
    assert face_map.tolist() == [-1, 2]                                      # tie → lower face id
    with pytest.raises(ValueError, match="pixel_index"):
        zbuffer_resolve(torch.tensor([5]), torch.tensor([1.0]), torch.tensor([0]), 4)


# ------------------------------------------------------------------------------------------ errors

def test_bad_inputs_raise_clear_errors():
    cam = Camera.look_at((0.0, 0.0, 5.0), fov_y=60, width=8, height=8)
    with pytest.raises(TypeError, match="Camera"):
        rasterize(icosphere(0), "camera")
    with pytest.raises(TypeError, match="verts"):
        rasterize(object(), cam)
    bad = icosphere(0)
    bad.faces = bad.faces.clone()
    bad.faces[0, 0] = 99
    with pytest.raises(ValueError, match="vertex 99 but the mesh has 12 vertices"):
        rasterize(bad, cam)
    bad.faces[0, 0] = -1
    with pytest.raises(ValueError, match="negative vertex index"):
        rasterize(bad, cam)
    with pytest.raises(ValueError, match="width must be a positive integer"):
        Camera.look_at((0.0, 0.0, 5.0), fov_y=60, width=0, height=8)
    with pytest.raises(ValueError, match="attr"):
        interpolate(torch.zeros(5), rasterize(icosphere(0), cam), icosphere(0).faces)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_lattice_grid_covers_every_centre_exactly_once(seed):
    """A grid mesh over the whole image whose vertices sit on a quarter-pixel lattice: many pixel centres
    fall exactly on edges and vertices, the case a fill rule exists for."""
    g = torch.Generator().manual_seed(seed)
    n, cell = 6, 2.0                                                        # 6 × 6 cells of 2 px over 12 × 12
    ij = torch.stack(torch.meshgrid(torch.arange(n + 1.0), torch.arange(n + 1.0), indexing="ij"), -1)
    xy = (ij * cell).double() - 0.0
    jitter = torch.randint(-3, 4, xy.shape, generator=g).double() * 0.25    # ±0.75 px in quarter pixels
    inner = (ij > 0) & (ij < n)                                             # keep the border on the border
    xy = xy + jitter * inner
    q = torch.arange((n + 1) ** 2).view(n + 1, n + 1)
    a, b, c, d = q[:-1, :-1].flatten(), q[:-1, 1:].flatten(), q[1:, 1:].flatten(), q[1:, :-1].flatten()
    flip = torch.randint(0, 2, a.shape, generator=g).bool()                 # random diagonal per cell
    faces = torch.cat([torch.stack([a, b, torch.where(flip, c, d)], 1),        # a→b→c→d around the cell
                       torch.stack([torch.where(flip, a, b), c, d], 1)])
    mesh = screen_mesh(xy.view(-1, 2).tolist(), faces, size=12)
    front, back = layer_counts(mesh, ortho8(12, 12))
    # jitter may fold a cell over (a triangle turns back-facing); with the border fixed, front minus back
    # coverage is still exactly 1 at every centre: a crack or a double cover would break it
    assert torch.equal(front - back, torch.ones(12, 12, dtype=torch.long))


def test_a_million_faces_at_1024_stay_under_2_gb():
    """Chunking bounds memory: 1.3 M faces at 1024 × 1024 (measured in this process with Linux's peak RSS)."""
    import os
    if not os.path.exists("/proc/self/clear_refs"):
        pytest.skip("needs Linux /proc to measure peak memory")
    mesh = icosphere(8)                                                     # 1,310,720 faces
    cam = Camera.look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov_y=40, width=1024, height=1024)
    kb = lambda key: int(next(line.split()[1] for line in open("/proc/self/status") if line.startswith(key)))
    try:
        open("/proc/self/clear_refs", "w").write("5")                       # reset the peak (VmHWM)
    except OSError:
        pytest.skip("cannot reset the peak memory counter here")
    base = kb("VmRSS:")
    fr = rasterize(mesh, cam)
    peak_mb = (kb("VmHWM:") - base) / 1024
    assert peak_mb < 2048, f"peak {peak_mb:.0f} MB"
    assert 0.70 < fr.mask.float().mean() < 0.78                             # the sphere's disc, radius asin(1/3)


# ------------------------------------------------------------------------------------- near-ties in depth

def two_planes(d0, separation, orthographic):
    """Two parallel squares facing a camera at the origin that looks along +z: the far one at depth
    ``d0 (1 + separation)`` holds faces 0 and 1 (the lower ids), the near one at ``d0`` faces 2 and 3. Every
    pixel of the 6 x 6 image is covered by both."""
    square = lambda z: [[-1, -1, z], [1, -1, z], [1, 1, z], [-1, 1, z]]        # noqa: E731
    verts = torch.tensor(square(d0 * (1 + separation)) + square(d0), dtype=torch.float64)
    faces = torch.tensor([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    view = dict(ortho_height=1.0) if orthographic else dict(fov_y=20.0)
    cam = Camera.look_at((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), width=6, height=6, dtype=torch.float64, **view)
    return Mesh(verts, faces), cam


# d0: depths where the float32 keys of the two planes tie at separation 3.3e-8 (then the lower face id, the far
# plane, wins without the float64 refinement); 1e-5 is far above float32's step
@pytest.mark.parametrize("orthographic, d0", [(False, 3.7), (True, 2.0)])
@pytest.mark.parametrize("separation", [3.3e-8, 1e-5])
def test_near_ties_rasterize_raycast_and_exact_coverage_agree(orthographic, d0, separation, monkeypatch):
    """Surfaces 3.3e-8 apart in relative depth look the same to a float32 key; rasterize re-decides such
    near-ties in float64 and shows the nearer plane, as raycast (float64 t) and exact_coverage do."""
    from course.coverage import exact_coverage
    from course.raytrace import raycast
    mesh, cam = two_planes(d0, separation, orthographic)
    near = lambda face_id: bool((face_id >= 2).all())                          # noqa: E731
    assert near(rasterize(mesh, cam).face_id)
    assert near(rasterize(mesh, cam, samples=[[0.25, 0.25], [0.5, 0.5], [0.9, 0.1]]).face_id)
    assert near(rasterize_naive(mesh, cam).face_id)
    assert near(raycast(mesh, cam).face_id)
    colors = torch.tensor([[1.0, 0.0, 0.0]] * 2 + [[0.0, 1.0, 0.0]] * 2, dtype=torch.float64)
    image = exact_coverage(mesh, cam, colors)                                  # every pixel fully covered
    torch.testing.assert_close(image, colors[2].expand(6, 6, 3))
    if separation < 1e-7:                                                      # float32 keys alone: a tie
        monkeypatch.setattr(scan, "REFINE_TIES", False)                        # (a switch of the torch path)
        with kernels.using("torch"):
            assert bool((rasterize(mesh, cam).face_id <= 1).all())              # the lower id, the far plane


@pytest.mark.parametrize("orthographic", [False, True])
def test_depth_ties_below_float32_follow_float64_and_rounding_ties_the_lower_face_id(orthographic):
    """Apart by 1e-10 (float64 sees it, float32 does not): the nearer plane in rasterize and raycast. Apart by
    1e-13 or coincident: float64 rounding, a tie (scan.TIE_RTOL = 1e-12), the lower face id in rasterize."""
    from course.raytrace import raycast
    mesh, cam = two_planes(2.0, 1e-10, orthographic)
    for face_id in (rasterize(mesh, cam).face_id, raycast(mesh, cam).face_id,
                    rasterize(mesh, cam, samples=[[0.3, 0.6]]).face_id, rasterize_naive(mesh, cam).face_id):
        assert bool((face_id >= 2).all())
    for separation in (1e-13, 0.0):
        mesh, cam = two_planes(2.0, separation, orthographic)
        for face_id in (rasterize(mesh, cam).face_id, rasterize(mesh, cam, samples=[[0.3, 0.6]]).face_id,
                        rasterize_naive(mesh, cam).face_id):
            assert bool((face_id <= 1).all())
    assert bool((raycast(mesh, cam).face_id <= 1).all())                       # coincident: equal t, lower id


@pytest.mark.parametrize("far_first", [True, False])
@pytest.mark.parametrize("orthographic, d0", [(False, 3.7), (True, 2.0)])
def test_near_ties_across_chunks(far_first, orthographic, d0):
    """One triangle per chunk (and a few samples per step): a near-tie found when a later chunk displaces a
    key (far plane first) or loses to one (near plane first) is decided in float64 all the same."""
    mesh, cam = two_planes(d0, 3.3e-8, orthographic)
    faces = mesh.faces if far_first else mesh.faces.flip(0)
    near_ids = (2, 3) if far_first else (0, 1)
    verts, faces = raster._check_inputs(Mesh(mesh.verts, faces), cam)
    for reach in (0.5, 0.0):
        st = raster._screen_triangles(raster._camera_space(verts, cam), faces, cam, False, reach=reach)
        if reach:
            face_id = scan._zbuffer(st, cam, budget=(1, 1))
        else:
            pixels = torch.arange(36)
            offsets = torch.tensor([[0.25, 0.25], [0.75, 0.5]], dtype=torch.float64)
            face_id = scan._sample_zbuffer(st, cam, pixels, offsets, budget=2)
        assert all(int(f) in near_ids for f in face_id.reshape(-1))


def test_near_tie_notes_catch_a_displaced_key():
    """The float32 keys can even swap two surfaces (two roundings): a later fragment whose key is a few steps
    *below* the one it displaces is noted with it, and float64 depth decides between them."""
    zbuf = torch.full((2,), scan.EMPTY_KEY, dtype=torch.int64)
    ties = scan._NearTies(zbuf)
    key = lambda bits, face: torch.tensor([(bits << 32) | face])                # noqa: E731
    for k, first in ((key(1000, 5), True), (key(998, 7), False), (key(1200, 9), False)):
        before = None if first else zbuf.index_select(0, torch.tensor([0]))
        zbuf.scatter_reduce_(0, torch.tensor([0]), k, reduce="amin")
        ties.check(torch.tensor([0]), k, before)
    noted = sorted(int(f) for f in torch.cat(ties.faces))
    assert 5 in noted and 7 in noted and 9 not in noted                        # 1200 is far behind
    depth = {5: 1.0, 7: 1.0 + 1e-9, 9: 2.0}                                     # face 5 is nearer in float64
    faces = scan._faces_of(zbuf)                                                # float32: face 7 won
    assert int(faces[0]) == 7 and int(faces[1]) == -1
    out = ties.resolve(faces, lambda s, f: torch.tensor([depth[int(x)] for x in f], dtype=torch.float64))
    assert out.tolist() == [5, -1]
