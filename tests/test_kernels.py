"""The compiled kernels (course.kernels) against their torch twins: the same face ids, bit for bit, on the bench
scenes and on the scenes that are hard for a rasterizer or a ray tracer (near-plane clipping, culling,
orthographic cameras, the far plane, coplanar faces, random triangle soups, axis-aligned and degenerate rays),
in float32 and float64; and the barycentrics and depth of the no-gradient fast path bit-identical to the
differentiable torch code."""
import math
import os
import subprocess
import sys
from types import SimpleNamespace

import pytest
import torch
from hypothesis import given, settings, strategies as st

from course import kernels
from course.bench.raster import scene as bench_scene
from course.bvh import BVH
from course.camera import Camera
from course.mesh import Mesh
from course.models import cube, icosphere, plane, teapot
from course.raster import rasterize
from course.raytrace import raycast, visible

pytestmark = pytest.mark.skipif(not kernels.available(), reason="Numba is not installed")


def both(fn):
    """fn() on the kernels, then on the torch path."""
    with kernels.using("numba"):
        a = fn()
    with kernels.using("torch"):
        b = fn()
    return a, b


def assert_same_fragments(a, b):
    assert torch.equal(a.face_id, b.face_id), f"{int((a.face_id != b.face_id).sum())} face ids differ"
    assert torch.equal(a.bary, b.bary) and torch.equal(a.depth, b.depth)    # bit-identical


def z_fighting():
    """Two squares in one plane, overlapping: every pixel a tie, decided by the lower face id."""
    sq = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]
    verts = torch.tensor(sq + [[x * 0.7 + 0.2, y * 0.7, z] for x, y, z in sq], dtype=torch.float64)
    faces = torch.tensor([[4, 5, 6], [4, 6, 7], [0, 1, 2], [0, 2, 3]])
    return Mesh(verts, faces)


def soup(seed, n=60, spread=1.5, size=0.6, dtype=torch.float64):
    """Random triangles (slivers, tiny ones, crossings) around the origin."""
    g = torch.Generator().manual_seed(seed)
    centres = (torch.rand(n, 1, 3, generator=g, dtype=torch.float64) - 0.5) * 2 * spread
    scale = size * torch.rand(n, 1, 1, generator=g, dtype=torch.float64) ** 3   # many small ones
    verts = (centres + scale * torch.randn(n, 3, 3, generator=g, dtype=torch.float64)).reshape(-1, 3)
    return Mesh(verts.to(dtype), torch.arange(3 * n).view(n, 3))


def cameras(dtype, size=(48, 40)):
    W, H = size
    return {
        "perspective": Camera.look_at((0.6, 0.8, 3.2), (0.0, 0.0, 0.0), fov_y=45.0, width=W, height=H, dtype=dtype),
        "orthographic": Camera.look_at((0.6, 0.8, 3.2), (0.0, 0.0, 0.0), ortho_height=3.0, width=W, height=H,
                                       dtype=dtype),
        "near plane cuts": Camera.look_at((0.2, 0.3, 1.1), (0.0, 0.0, 0.0), fov_y=70.0, width=W, height=H,
                                          near=0.9, dtype=dtype),
        "far plane cuts": Camera.look_at((0.0, 0.5, 3.0), (0.0, 0.0, 0.0), fov_y=45.0, width=W, height=H,
                                         far=3.1, dtype=dtype),
        "inside": Camera.look_at((0.05, 0.02, 0.1), (1.0, 0.3, 0.2), fov_y=90.0, width=W, height=H, near=0.01,
                                 dtype=dtype),
    }


MESHES = {"teapot": lambda dt: teapot(3, dtype=dt), "cube": lambda dt: cube(dtype=dt),
          "icosphere": lambda dt: icosphere(3, dtype=dt), "z-fighting": lambda dt: Mesh(z_fighting().verts.to(dt),
                                                                                          z_fighting().faces),
          "soup": lambda dt: soup(1, dtype=dt), "plane": lambda dt: plane(size=3.0, subdivisions=6, dtype=dt)}


# ------------------------------------------------------------------------------------------ rasterize

@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("mesh_name", list(MESHES))
def test_rasterize_kernels_match_torch(mesh_name, dtype):
    mesh = MESHES[mesh_name](dtype)
    for cam_name, cam in cameras(dtype).items():
        for cull in (False, True):
            a, b = both(lambda: rasterize(mesh, cam, cull_backfaces=cull))
            assert_same_fragments(a, b)


@pytest.mark.parametrize("name", ["S1", "S4"])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_rasterize_kernels_match_torch_on_the_bench_scenes(name, dtype):
    mesh, cam = bench_scene(name, dtype)
    for cull in (False, True):
        a, b = both(lambda: rasterize(mesh, cam, cull_backfaces=cull))
        assert_same_fragments(a, b)
        assert a.mask.float().mean() > 0.3


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), ortho=st.booleans(), f32=st.booleans())
def test_rasterize_kernels_match_torch_on_random_soups(seed, ortho, f32):
    """Random triangles, random pixel-grid alignments: the same coverage (fill rule), the same nearest face."""
    dtype = torch.float32 if f32 else torch.float64
    mesh = soup(seed, dtype=dtype)
    g = torch.Generator().manual_seed(seed)
    eye = torch.randn(3, generator=g, dtype=torch.float64)
    eye = 3.5 * eye / eye.norm()
    view = dict(ortho_height=3.0) if ortho else dict(fov_y=50.0)
    cam = Camera.look_at(eye, (0.0, 0.0, 0.0), width=37, height=29, dtype=dtype, **view)
    a, b = both(lambda: rasterize(mesh, cam))
    assert_same_fragments(a, b)


def vanishing_wall(d, gap, square_first, tilt=0.0):
    """A wall x = 1 from depth 0.3 to 1e15 filling a 4096 × 64 image whose vanishing line (the column u = cx,
    turned by ``tilt`` radians about the optical axis) passes d px from the first column's centres, and a square
    a relative ``gap`` behind it (in front when gap < 0) from depth 1e3 on: near the line q = 1/z ≈ 1e-11."""
    W, H, fx = 4096, 64, 1300.0
    K = torch.tensor([[fx, 0.0, 0.5 - d], [0.0, fx, 32.0], [0.0, 0.0, 1.0]], dtype=torch.float64)
    c, s = math.cos(tilt), math.sin(tilt)
    R = torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)
    cam = Camera(K, R, torch.zeros(3, dtype=torch.float64), W, H, near=0.1, far=1e16)

    def quad(x, z0, z1, y=1e12):
        return torch.tensor([[x, -y, z0], [x, -y, z1], [x, y, z1], [x, y, z0]], dtype=torch.float64)
    wall, square = quad(1.0, 0.3, 1e15), quad(1.0 + gap, 1e3, 1e15)
    verts = R.T @ torch.cat([square, wall] if square_first else [wall, square]).T
    faces = torch.tensor([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    return Mesh(verts.T.contiguous(), faces), cam, (0, 1) if square_first else (2, 3)


@pytest.mark.parametrize("d", [1e-7, 1e-9, 1e-11])
@pytest.mark.parametrize("gap", [1e-4, 1e-6, -1e-4])
@pytest.mark.parametrize("square_first", [True, False])
def test_the_zbuffer_is_exact_near_a_vanishing_line(d, gap, square_first):
    """Where q = 1/z runs to 0 the plane is evaluated from the corner of least q and stepped from the span's
    end of least q: both paths agree with float64 ray casting (the torch path once showed the square behind on
    up to 52 of 64 rows, the kernel on 3 at d = 1e-11)."""
    mesh, cam, square = vanishing_wall(d, gap, square_first)
    a, b = both(lambda: rasterize(mesh, cam).face_id)
    ray = raycast(mesh, cam).face_id
    assert torch.equal(a, b)
    assert torch.equal((a == square[0]) | (a == square[1]), (ray == square[0]) | (ray == square[1]))
    assert torch.equal(a >= 0, ray >= 0) and int((a >= 0).sum()) > 64 * 1000
    if gap < 0:                                                             # in front: it shows where it reaches
        assert int(((a == square[0]) | (a == square[1])).sum()) > 0


def test_the_zbuffer_is_exact_near_an_oblique_vanishing_line():
    mesh, cam, square = vanishing_wall(1e-9, 1e-5, True, tilt=0.01)
    a, b = both(lambda: rasterize(mesh, cam).face_id)
    ray = raycast(mesh, cam).face_id
    assert torch.equal(a, b)
    assert torch.equal(a >= 2, ray >= 2) and bool((a >= 2).any())


def test_pixel_aligned_grid_one_face_per_shared_edge_pixel():
    """Edges through pixel centres: both paths cover every centre exactly once (the top-left rule)."""
    m = plane(size=10.0, subdivisions=10, dtype=torch.float64)
    verts = m.verts[:, [0, 2, 1]] * torch.tensor([1.0, -1.0, 1.0], dtype=torch.float64) + 0.5
    cam = Camera(torch.tensor([[1.0, 0, 4], [0, 1.0, 4], [0, 0, 1]], dtype=torch.float64),
                 torch.eye(3, dtype=torch.float64), torch.tensor([0.0, 0.0, 5.0], dtype=torch.float64), 8, 8,
                 orthographic=True)
    a, b = both(lambda: rasterize(Mesh(verts, m.faces), cam))
    assert_same_fragments(a, b)
    assert bool(a.mask.all())


def test_surface_without_gradient_is_the_differentiable_surface():
    """The no-gradient fast path (kernels.surface) against the torch code autograd records, bit for bit."""
    for dtype in (torch.float32, torch.float64):
        mesh = teapot(3, dtype=dtype)
        cam = cameras(dtype)["near plane cuts"]
        with kernels.using("numba"):
            fast = rasterize(mesh, cam)
            verts = mesh.verts.clone().requires_grad_(True)
            graph = rasterize(Mesh(verts, mesh.faces), cam)
        assert graph.bary.requires_grad and not fast.bary.requires_grad
        assert torch.equal(fast.face_id, graph.face_id)
        assert torch.equal(fast.bary, graph.bary.detach()) and torch.equal(fast.depth, graph.depth.detach())


def test_near_ties_are_noted_even_when_the_buffer_overflows(monkeypatch):
    """Coplanar faces everywhere: with room for only 4 notes the kernel reports how many it needed, the caller
    calls it again with room for all, and every pixel gets the face the torch path gives (the lower face id)."""
    from course import scan
    from course.kernels import zbuffer
    from course.raster import _camera_space, _screen_triangles
    mesh = z_fighting()
    cam = Camera.look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov_y=40.0, width=64, height=64, dtype=torch.float64)
    st = _screen_triangles(_camera_space(mesh.verts, cam), mesh.faces, cam, False)
    returned = []
    real = zbuffer.nearest_faces

    def spy(*args):
        returned.append(real(*args))
        return returned[-1]
    monkeypatch.setattr(zbuffer, "nearest_faces", spy)
    with kernels.using("numba"):
        faces = scan._kernel_zbuffer(st, cam, capacity=4)
    with kernels.using("torch"):
        expected = scan._zbuffer(st, cam)
    assert len(returned) == 2 and returned[0] > 4 and returned[1] == returned[0]   # overflowed, then fitted
    assert torch.equal(faces, expected)
    covered = faces[faces >= 0]
    assert covered.numel() > 1000 and int(covered.min()) == 0               # faces 0, 1 (lower ids) win the overlap


# ------------------------------------------------------------------------------------------ ray casting

@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("mesh_name", list(MESHES))
def test_raycast_kernels_match_torch(mesh_name, dtype):
    mesh = MESHES[mesh_name](dtype)
    bvh = BVH(mesh)
    for cam in cameras(dtype).values():
        a, b = both(lambda: raycast(mesh, cam, bvh=bvh))
        assert_same_fragments(a, b)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_bvh_hits_match_torch_for_incoherent_axis_aligned_and_degenerate_rays(dtype):
    """Closest hits of random rays from inside and outside, rays along the axes (zero direction components,
    origins on box planes), rays with t ranges, and a zero direction (hits nothing): face, t and bary equal."""
    mesh = teapot(3, dtype=dtype)
    bvh = BVH(mesh)
    g = torch.Generator().manual_seed(3)
    o = torch.randn(3000, 3, generator=g, dtype=torch.float64) * 1.5
    d = torch.randn(3000, 3, generator=g, dtype=torch.float64)
    corners = bvh.boxes[1:, 0].double()                                     # origins on box planes
    o_axis = torch.cat([torch.rand(600, 3, generator=g, dtype=torch.float64) - 0.5, corners])
    sign = torch.where(torch.arange(o_axis.shape[0]) % 2 == 0, 1.0, -1.0).double()[:, None]
    axis = torch.eye(3, dtype=torch.float64)[torch.arange(o_axis.shape[0]) % 3] * sign   # along +-x, y, z
    o = torch.cat([o, o_axis, torch.zeros(1, 3, dtype=torch.float64)]).to(dtype)
    d = torch.cat([d, axis, torch.zeros(1, 3, dtype=torch.float64)]).to(dtype)
    t_lo = torch.rand(o.shape[0], generator=g, dtype=torch.float64).to(dtype) * 0.5
    for kw in (dict(), dict(t_min=t_lo, t_max=t_lo + 1.0)):
        a, b = both(lambda: bvh.intersect(o, d, **kw))
        assert torch.equal(a.face_id, b.face_id)
        assert torch.equal(a.t, b.t) and torch.equal(a.bary, b.bary)
        assert a.hit.float().mean() > 0.1 and not bool(a.hit[-1])
        ah, bh = both(lambda: bvh.intersect(o, d, any_hit=True, **kw))
        assert torch.equal(ah.hit, bh.hit) and torch.equal(ah.hit, a.hit)   # any hit: the same rays blocked


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), f32=st.booleans())
def test_bvh_kernel_matches_torch_and_brute_force_on_random_soups(seed, f32):
    from course.bench.raytrace import brute_force
    dtype = torch.float32 if f32 else torch.float64
    mesh = soup(seed, n=80, dtype=dtype)
    bvh = BVH(mesh, leaf_size=1 + seed % 4)
    g = torch.Generator().manual_seed(seed)
    o = torch.randn(400, 3, generator=g, dtype=torch.float64).to(dtype) * 2
    d = torch.randn(400, 3, generator=g, dtype=torch.float64).to(dtype)
    a, b = both(lambda: bvh.intersect(o, d))
    assert torch.equal(a.face_id, b.face_id) and torch.equal(a.t, b.t) and torch.equal(a.bary, b.bary)
    tris = mesh.verts[mesh.faces]
    assert torch.equal(a.face_id, brute_force(o, d, tris))


def test_shadow_rays_match_torch():
    """visible(): point, directional and area lights, with and without normals, both paths alike."""
    from course.raytrace import rectangle_light_samples
    ground = plane(size=4.0, subdivisions=4, dtype=torch.float64)
    pot = teapot(3, dtype=torch.float64)
    mesh = Mesh(torch.cat([pot.verts, ground.verts]), torch.cat([pot.faces, ground.faces + pot.verts.shape[0]]))
    bvh = BVH(mesh)
    g = torch.Generator().manual_seed(0)
    pts = torch.cat([(torch.rand(500, 3, generator=g, dtype=torch.float64) - 0.5) * 3 * torch.tensor([1.0, 0, 1.0]),
                     pot.verts[:200]])
    n = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64).expand(pts.shape[0], 3)
    samples = rectangle_light_samples((-0.5, 3.0, -0.5), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), pts.shape[0], grid=3)
    for args, kw in [((pts, (1.0, 3.0, 1.0)), {}), ((pts, (0.3, -1.0, 0.2)), dict(directional=True)),
                     ((pts, (1.0, 3.0, 1.0)), dict(normals=n)), ((pts, samples), {})]:
        a, b = both(lambda: visible(*args, bvh, **kw))
        assert torch.equal(a, b)
        assert 0 < float(a.double().mean()) < 1


# -------------------------------------------------------------------------------------- the switches

def test_backend_switches():
    assert kernels.backend() in kernels.BACKENDS
    with kernels.using("torch"):
        assert kernels.backend() == "torch" and not kernels.active(torch.zeros(1))
    assert kernels.active(torch.zeros(1)) == (kernels.backend() == "numba")
    assert not kernels.active(torch.zeros(1, device="meta"))                # not a CPU tensor: the torch path
    with pytest.raises(ValueError, match="backend must be one of"):
        kernels.set_backend("cuda")


def test_environment_variable_forces_the_torch_path():
    code = "from course import kernels; print(kernels.backend())"
    for value, expected in (("torch", "torch"), ("numba", "numba")):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             env=dict(os.environ, COURSE_KERNELS=value))
        assert out.stdout.strip() == expected, out.stderr
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=dict(os.environ, COURSE_KERNELS="fortran"))
    assert out.returncode != 0 and "COURSE_KERNELS must be one of" in out.stderr


def test_bad_input_is_refused_before_any_kernel_runs():
    """Out-of-range face indices and NaN vertices would read out of bounds inside a kernel: refused first."""
    cam = cameras(torch.float64)["perspective"]
    verts = torch.rand(4, 3, dtype=torch.float64)
    with kernels.using("numba"):
        with pytest.raises(ValueError, match="out of range|index"):
            rasterize(SimpleNamespace(verts=verts, faces=torch.tensor([[0, 1, 7]])), cam)
        with pytest.raises(ValueError, match="out of range|index"):
            BVH(SimpleNamespace(verts=verts, faces=torch.tensor([[0, -1, 2]])))
        bad = verts.clone()
        bad[1, 2] = float("nan")
        with pytest.raises(ValueError, match="NaN"):
            rasterize(SimpleNamespace(verts=bad, faces=torch.tensor([[0, 1, 2]])), cam)
        with pytest.raises(ValueError, match="NaN"):
            BVH(SimpleNamespace(verts=bad, faces=torch.tensor([[0, 1, 2]])))
        bvh = BVH(SimpleNamespace(verts=verts, faces=torch.tensor([[0, 1, 2]])))
        with pytest.raises(ValueError, match="finite"):
            bvh.intersect(torch.full((1, 3), float("nan")), torch.ones(1, 3))


# ------------------------------------------------------------------------ the boundary term's z-buffer queries

@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), ortho=st.booleans())
def test_visible_at_points_matches_torch(seed, ortho):
    """boundary._visible_at at random points, points on edges and vertices, points off the image."""
    from course.boundary import _visible_at
    mesh = soup(seed)
    g = torch.Generator().manual_seed(seed)
    view = dict(ortho_height=3.0) if ortho else dict(fov_y=50.0)
    cam = Camera.look_at((0.4, 0.7, 3.3), (0.0, 0.0, 0.0), width=37, height=29, dtype=torch.float64, **view)
    xy, _ = cam.project(mesh.verts)
    pts = torch.cat([torch.rand(3000, 2, generator=g, dtype=torch.float64) * torch.tensor([45.0, 35.0]) - 4,
                     xy, (xy[mesh.faces[:, 0]] + xy[mesh.faces[:, 1]]) / 2])        # vertices, edge midpoints
    for cull in (False, True):
        a, b = both(lambda: _visible_at(mesh, cam, pts, cull_backfaces=cull))
        assert torch.equal(a, b)
        assert (a >= 0).any() and (a < 0).any()


@pytest.mark.parametrize("method", ["reynolds", "edge_sampling"])
def test_boundary_gradients_match_torch(method):
    from course.bench.gradients import make_scene, weights_for
    from course.visibility import image_gradient
    for name in ("spheres", "S4-64"):
        sc = make_scene(name)
        w = weights_for(sc, "random")
        a, b = both(lambda: image_gradient(sc["mesh"], sc["camera"], sc["colors"], w, method=method,
                                           model=sc["model"], background=sc["background"]))
        assert torch.equal(a, b) and a.abs().sum() > 0


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_sub_pixel_samples_match_torch(dtype):
    """rasterize(samples=..., pixels=...): stage 1 compiled, the sample z-buffer after it; the same fragments."""
    mesh = teapot(3, dtype=dtype)
    g = torch.Generator().manual_seed(0)
    offsets = torch.rand(5, 2, generator=g, dtype=torch.float64)
    for cam in cameras(dtype).values():
        for kw in (dict(samples=offsets), dict(samples=offsets, pixels=torch.arange(0, 48 * 40, 7)),
                   dict(pixels=torch.rand(40, 48, generator=g) > 0.5)):
            a, b = both(lambda: rasterize(mesh, cam, cull_backfaces=True, **kw))
            assert_same_fragments(a, b)


@pytest.mark.skipif(not kernels.available(), reason="Numba not installed")
def test_a_render_in_inference_mode_leaves_the_kernels_usable_outside_it():
    """The kernels' kept scratch buffers are ordinary tensors even when the first call that made them ran under
    ``torch.inference_mode()`` (the exact images of the fits do), so a later render outside it still works."""
    import threading
    out = {}

    def run():                                                              # a fresh thread: fresh scratch
        camera = Camera.look_at((0.0, 0.5, 3.0), fov_y=40, width=37, height=23)
        with torch.inference_mode():
            first = rasterize(teapot(3), camera).face_id.clone()
        out["same"] = torch.equal(rasterize(teapot(3), camera).face_id, first)
    thread = threading.Thread(target=run)
    thread.start()
    thread.join()
    assert out == {"same": True}
