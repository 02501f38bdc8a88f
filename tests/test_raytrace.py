"""Ray tracing: the watertight test against Möller–Trumbore, the BVH against brute force, raycast against
rasterize, shadow rays and area lights, and stress cases (grazing rays, empty scenes, tiny and huge scales)."""
import math
from types import SimpleNamespace

import pytest
import torch

from course.camera import Camera
from course.mesh import Mesh
from course.models import cube, icosphere, teapot
from course.raster import rasterize
from course.raytrace import (BVH, disk_light_samples, intersect_triangles, moller_trumbore, raycast,
                             rectangle_light_samples, visible)

# every test runs on the compiled kernels and on the torch path (tests/conftest.py)
pytestmark = pytest.mark.usefixtures("both_backends")


def brute_force(test, o, d, tris, t_min=0.0):
    """Every ray against every triangle: hit counts (N,), and the closest face (N,) and its t (N,)."""
    N, F = o.shape[0], tris.shape[0]
    t, _, hit = test(o[:, None].expand(-1, F, -1).reshape(-1, 3), d[:, None].expand(-1, F, -1).reshape(-1, 3),
                     tris[None].expand(N, -1, -1, -1).reshape(-1, 3, 3))
    t, hit = t.view(N, F), hit.view(N, F) & (t.view(N, F) >= t_min)
    t = torch.where(hit, t, torch.full_like(t, math.inf))
    best, face = t.min(1)                                                   # min: ties to the lower index
    return hit.sum(1), torch.where(torch.isfinite(best), face, -1), best


def aimed_rays(mesh, n_per_edge, seed, distance=100.0):
    """Rays from far outside a closed mesh around the origin, aimed at points of its shared edges and at its
    vertices (``d = p - o``: t = 1 at the aimed point). They all pass near the centre, so all enter."""
    g = torch.Generator().manual_seed(seed)
    dt = mesh.verts.dtype
    e = mesh.faces[:, [0, 1]].repeat(n_per_edge, 1)
    a, b = mesh.verts[e[:, 0]], mesh.verts[e[:, 1]]
    s = torch.rand(a.shape[0], 1, generator=g, dtype=dt)
    s[: mesh.faces.shape[0]] = 0.5                                          # and the exact midpoints
    p = torch.cat([a + s * (b - a), mesh.verts])
    o = p + distance * (p + 0.1 * torch.randn(p.shape, generator=g, dtype=dt))
    return o, p - o


# ------------------------------------------------------------------------------------- ray–triangle

@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_watertight_never_leaks_where_moller_trumbore_does(dtype):
    mesh = icosphere(2, dtype=dtype)
    tris = mesh.verts[mesh.faces]
    o, d = aimed_rays(mesh, 2, seed=1)
    n_wt, _, _ = brute_force(intersect_triangles, o, d, tris)
    n_mt, _, _ = brute_force(moller_trumbore, o, d, tris)
    # every ray enters and leaves the closed mesh: at least two hits (an entry and an exit)
    assert (n_wt >= 2).all(), f"watertight test leaked {(n_wt < 2).sum()} of {len(n_wt)} rays"
    assert (n_mt < 2).sum() > 0, "Möller–Trumbore should leak some rays aimed at shared edges"
    # and the entry (t = 1, the aimed point) is hit by the watertight test on every ray
    F = tris.shape[0]
    t, _, hit = intersect_triangles(o[:, None].expand(-1, F, -1).reshape(-1, 3),
                                    d[:, None].expand(-1, F, -1).reshape(-1, 3),
                                    tris[None].expand(o.shape[0], -1, -1, -1).reshape(-1, 3, 3))
    near_one = (hit & ((t - 1).abs() < 1e-3)).view(-1, F).any(1)
    assert near_one.all()


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_watertight_axis_rays_through_cube_edges_and_vertices(dtype):
    """Axis-parallel rays (two direction components exactly 0) through the cube's vertices, edges, face
    diagonals and interior: each hits the top face and the bottom face, and nothing is NaN."""
    mesh = cube(2.0, dtype=dtype)
    tris = mesh.verts[mesh.faces]
    xs = torch.tensor([-1.0, -0.5, 0.0, 0.5, 1.0], dtype=dtype)
    x, y = torch.meshgrid(xs, xs, indexing="ij")
    o = torch.stack([x.reshape(-1), y.reshape(-1), torch.full((25,), 5.0, dtype=dtype)], 1)
    d = torch.tensor([0.0, 0.0, -1.0], dtype=dtype).expand(25, 3)
    n, face, t = brute_force(intersect_triangles, o, d, tris)
    assert (face >= 0).all() and torch.allclose(t, torch.full_like(t, 4.0))
    hits = BVH(mesh).intersect(o, d)                                        # origins on the boxes' planes
    assert torch.equal(hits.face_id, face) and torch.equal(hits.t, t) and not torch.isnan(hits.bary).any()
    side = torch.tensor([[1.0, 0.3, 5.0], [-1.0, -1.0, 5.0], [1.0, 1.0, -5.0]], dtype=dtype)
    down = torch.tensor([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]], dtype=dtype)
    _, face_s, t_s = brute_force(intersect_triangles, side, down, tris)    # grazing along the side faces
    assert (face_s >= 0).all() and torch.equal(BVH(mesh).intersect(side, down).face_id, face_s)
    t_all, _, hit = intersect_triangles(o[:, None].expand(-1, 12, -1).reshape(-1, 3),
                                        d[:, None].expand(-1, 12, -1).reshape(-1, 3),
                                        tris[None].expand(25, -1, -1, -1).reshape(-1, 3, 3))
    t_all = t_all.view(25, 12)
    assert ((hit.view(25, 12) & ((t_all - 6).abs() < 1e-6)).any(1)).all()   # the bottom face too
    diag = torch.tensor([[3.0, 3.0, 3.0]], dtype=dtype)                    # through the corner (1, 1, 1)
    n, face, t = brute_force(intersect_triangles, diag, -diag, tris)
    assert face[0] >= 0 and abs(float(t[0]) - 2 / 3) < 1e-6


def test_float32_edge_function_that_rounds_to_zero_is_redone_in_float64():
    """Edge BC passes 2^-44 beside the ray (0, 0, 0) + t (0, 0, 1); in float32 the edge function
    (1 + 2^-22)² - (1 + 2^-21) rounds to exactly 0, which would let both triangles of the edge claim the ray.
    The float64 fallback gives the exact sign: only the second triangle is hit, as in float64."""
    e = 2.0 ** -22
    A, B, C, A2 = [1, -1, 1], [-1, -(1 + e), 1], [1 + e, 1 + 2 * e, 1], [-1, 1, 1]
    for dtype in (torch.float32, torch.float64):
        tris = torch.tensor([[A, B, C], [A2, C, B]], dtype=dtype)
        o, d = torch.zeros(2, 3, dtype=dtype), torch.tensor([[0.0, 0.0, 1.0]] * 2, dtype=dtype)
        t, bary, hit = intersect_triangles(o, d, tris)
        assert hit.tolist() == [False, True] and float(t[1]) == 1.0


def test_parallel_and_in_plane_rays_miss_without_nan():
    tri = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]], dtype=torch.float64).expand(4, 3, 3)
    o = torch.tensor([[-1.0, 0.25, 0], [0.2, 0.2, 1], [0.2, 0.2, 1], [0.25, 0.25, 0]], dtype=torch.float64)
    d = torch.tensor([[1.0, 0, 0], [1, 0, 0], [0, 0, -1], [0, 0, 0]], dtype=torch.float64)
    for test in (intersect_triangles, moller_trumbore):
        t, bary, hit = test(o, d, tri)
        assert hit.tolist() == [False, False, True, False]
        assert not torch.isnan(t).any() and not torch.isnan(bary).any()
    t, bary, _ = intersect_triangles(o, d, tri)
    assert torch.allclose(bary[2], torch.tensor([0.6, 0.2, 0.2], dtype=torch.float64)) and float(t[2]) == 1.0


def test_ray_triangle_bad_shapes():
    with pytest.raises(ValueError):
        intersect_triangles(torch.zeros(3, 3), torch.zeros(3, 2), torch.zeros(3, 3, 3))
    with pytest.raises(ValueError):
        intersect_triangles(torch.zeros(3, 3), torch.zeros(3, 3), torch.zeros(2, 3, 3))
    with pytest.raises(ValueError):
        moller_trumbore(torch.zeros(3), torch.zeros(3), torch.zeros(1, 3, 3))


# ----------------------------------------------------------------------------------------------- BVH

def random_rays(n, seed, dtype=torch.float64, spread=2.0):
    g = torch.Generator().manual_seed(seed)
    o = spread * torch.randn(n, 3, generator=g, dtype=dtype)
    d = torch.randn(n, 3, generator=g, dtype=dtype)
    d[: n // 8, 1:] = 0                                                     # axis-parallel rays too
    d[n // 8: n // 4, 0] = 0
    return o, d


@pytest.mark.parametrize("name", ["icosphere", "teapot"])
def test_bvh_matches_brute_force(name):
    mesh = icosphere(2, dtype=torch.float64) if name == "icosphere" else teapot(4, dtype=torch.float64)
    bvh = BVH(mesh)
    assert bvh.count.sum() == mesh.faces.shape[0] and (bvh.count <= 4).all()
    assert torch.equal(torch.sort(bvh.order).values, torch.arange(mesh.faces.shape[0]))
    o, d = random_rays(400, seed=2, spread=0.7)
    _, face, t = brute_force(intersect_triangles, o, d, mesh.verts[mesh.faces])
    hits = bvh.intersect(o, d)
    assert (face >= 0).sum() > 50
    assert torch.equal(hits.face_id, face)
    m = face >= 0
    assert torch.allclose(hits.t[m], t[m], rtol=1e-12, atol=0) and torch.isinf(hits.t[~m]).all()
    assert torch.allclose(hits.bary.sum(1)[m], torch.ones(int(m.sum()), dtype=torch.float64))
    assert not torch.isnan(hits.t).any() and not torch.isnan(hits.bary).any()
    # a t window: skip the first surface
    t_min = torch.where(m, t * 1.0001, torch.zeros_like(t))
    _, face2, t2 = brute_force(intersect_triangles, o, d, mesh.verts[mesh.faces], t_min=t_min[:, None])
    hits2 = bvh.intersect(o, d, t_min=t_min)
    assert torch.equal(hits2.face_id, face2)
    # any-hit agrees with closest-hit on hit / miss, and its hit is a real one within the window
    anyh = bvh.intersect(o, d, any_hit=True)
    assert torch.equal(anyh.hit, hits.hit) and (anyh.t[m] >= 0).all()
    short = bvh.intersect(o, d, t_max=torch.where(m, t * 0.999, torch.ones_like(t)), any_hit=True)
    assert not short.hit[m].any()


def coherent_rays(n_packets, seed, dtype=torch.float64):
    """Packets of 16 rays, each a narrow fan (shared or nearby origins, directions 0.02 apart), some aimed
    exactly along an axis (zero components, mixed signs inside the packet) and some from one origin."""
    g = torch.Generator().manual_seed(seed)
    base_o = 2.0 * torch.randn(n_packets, 1, 3, generator=g, dtype=dtype)
    base_d = -base_o + 0.3 * torch.randn(n_packets, 1, 3, generator=g, dtype=dtype)   # towards the mesh
    base_d = base_d / base_d.norm(dim=2, keepdim=True)
    o = base_o + 1e-3 * torch.randn(n_packets, 16, 3, generator=g, dtype=dtype)
    o[::3] = base_o[::3]                                                    # one origin, a pinhole's fan
    d = base_d + 0.02 * (torch.rand(n_packets, 16, 3, generator=g, dtype=dtype) - 0.5)
    d[::5, :, 1:] = 0.0                                                     # along x: y and z components 0
    d[::5, :, 0] = torch.where(base_d[::5, :, 0] < 0, -1.0, 1.0)
    d[1::5, :8, 2] = 0.0                                                    # zero and both signs in one packet
    d[1::5, 8:, 2] = torch.linspace(-0.01, 0.01, 8, dtype=dtype)
    return o.reshape(-1, 3), d.reshape(-1, 3)


@pytest.mark.parametrize("any_hit", [False, True])
def test_packets_find_the_same_hits_as_single_rays_and_brute_force(any_hit):
    """Coherent rays go down the tree 16 at a time; the hits must not depend on it."""
    mesh = teapot(4, dtype=torch.float64)
    bvh = BVH(mesh)
    o, d = coherent_rays(60, seed=5)
    _, face, t = brute_force(intersect_triangles, o, d, mesh.verts[mesh.faces])
    assert (face >= 0).sum() > 200 and (face < 0).sum() > 50
    packed = bvh.intersect(o, d, any_hit=any_hit)
    alone = bvh.intersect(o, d, any_hit=any_hit, packet=1)
    assert torch.equal(packed.hit, face >= 0) and torch.equal(alone.hit, face >= 0)
    if not any_hit:
        assert torch.equal(packed.face_id, face) and torch.equal(alone.face_id, face)
        assert torch.equal(packed.t, alone.t)
    with pytest.raises(ValueError, match="packet"):
        bvh.intersect(o, d, packet=0)


def test_beam_box_never_drops_a_box_one_of_its_rays_meets():
    """The interval slab test of a packet against many boxes: wherever one ray of the packet meets a box
    (the per-ray slab test), the packet's test must say "maybe"; and for one ray it is that slab test."""
    from course.bvh import _beam, _beam_box
    from course.intersect import _slab
    g = torch.Generator().manual_seed(6)
    P, K = 3000, 16
    lo = torch.randn(P, 1, 3, generator=g, dtype=torch.float64)
    hi = lo + torch.rand(P, 1, 3, generator=g, dtype=torch.float64)
    o = 3 * torch.randn(P, 1, 3, generator=g, dtype=torch.float64) + 0.05 * torch.randn(P, K, 3, generator=g,
                                                                                          dtype=torch.float64)
    aim = (lo + hi) / 2 - o[:, :1] + 0.7 * torch.randn(P, 1, 3, generator=g, dtype=torch.float64)
    d = aim + 0.05 * torch.randn(P, K, 3, generator=g, dtype=torch.float64)  # about half the packets hit
    d[::7, :, 0] = 0.0
    inv = 1 / d
    t_lo, t_hi = torch.zeros(P, K, dtype=torch.float64), torch.full((P, K), math.inf, dtype=torch.float64)
    per_ray = _slab(o, inv, torch.stack([lo, hi], 2).expand(P, K, 2, 3), t_lo, t_hi)    # (P, K)
    beam = _beam(o.amin(1), o.amax(1), inv.amin(1), inv.amax(1), t_lo.amin(1), t_hi.amax(1))
    hit, _ = _beam_box(beam, ((lo + hi) / 2)[:, 0], ((hi - lo) / 2)[:, 0])
    assert per_ray.any(1).sum() > 300 and (~per_ray.any(1)).sum() > 300
    assert hit[per_ray.any(1)].all()
    assert hit.float().mean() < 0.9                                         # and it does cull
    one = _beam(o[:, 0], o[:, 0], inv[:, 0], inv[:, 0], t_lo[:, 0], t_hi[:, 0])
    single, _ = _beam_box(one, ((lo + hi) / 2)[:, 0], ((hi - lo) / 2)[:, 0], True)
    ok = (d[:, 0] != 0).all(1)                                              # (zero components: kept, see _beam)
    assert torch.equal(single[ok], per_ray[ok, 0]) and single[per_ray[:, 0]].all()


def test_bvh_ties_go_to_the_lower_face_id():
    """Two copies of the same triangle (ids 1 and 3 among others): every ray reports face 1."""
    v = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5], [6, 5, 5], [5, 6, 5]], dtype=torch.float64)
    mesh = Mesh(v, torch.tensor([[3, 4, 5], [0, 1, 2], [3, 5, 4], [0, 2, 1]]))
    o = torch.tensor([[0.2, 0.2, 1.0], [0.1, 0.3, -2.0]], dtype=torch.float64)
    d = torch.tensor([[0.0, 0, -1], [0, 0, 1]], dtype=torch.float64)
    assert BVH(mesh).intersect(o, d).face_id.tolist() == [1, 1]


def test_float32_and_float64_agree():
    m64 = icosphere(3, dtype=torch.float64)
    m32 = Mesh(m64.verts.float(), m64.faces)
    o, d = random_rays(2000, seed=3, spread=0.8)
    h64 = BVH(m64).intersect(o, d)
    h32 = BVH(m32).intersect(o.float(), d.float())
    assert h32.t.dtype == torch.float32
    assert (h32.face_id == h64.face_id).float().mean() > 0.99
    assert torch.equal(h32.hit, h64.hit)                                    # nothing close to the silhouette here
    same = (h32.face_id == h64.face_id) & h64.hit
    assert torch.allclose(h32.t[same].double(), h64.t[same], rtol=1e-5)


@pytest.mark.parametrize("scale", [1e-4, 1e4])
def test_bvh_at_tiny_and_huge_scales(scale):
    mesh = icosphere(2, dtype=torch.float64)
    mesh = Mesh(mesh.verts * scale + 3 * scale, mesh.faces)
    o, d = random_rays(300, seed=4, spread=0.7)
    o = o * scale + 3 * scale
    _, face, t = brute_force(intersect_triangles, o, d, mesh.verts[mesh.faces])
    hits = BVH(mesh).intersect(o, d)
    assert torch.equal(hits.face_id, face) and (face >= 0).sum() > 50
    assert torch.allclose(hits.t[face >= 0], t[face >= 0], rtol=1e-12, atol=0)


def test_empty_scene_and_bad_inputs():
    empty = SimpleNamespace(verts=torch.zeros(3, 3), faces=torch.zeros(0, 3, dtype=torch.int64))
    bvh = BVH(empty)
    hits = bvh.intersect(torch.zeros(5, 3), torch.ones(5, 3))
    assert (hits.face_id == -1).all() and torch.isinf(hits.t).all()
    cam = Camera.look_at((0.0, 0.0, 3.0), fov_y=40.0, width=6, height=4)
    frags = raycast(empty, cam)
    assert frags.shape == (4, 6) and (frags.face_id == -1).all() and torch.isinf(frags.depth).all()
    assert visible(torch.zeros(2, 3), torch.ones(3), bvh).all()
    good = BVH(icosphere(1))
    with pytest.raises(ValueError):
        good.intersect(torch.zeros(4, 3), torch.zeros(4, 2))
    with pytest.raises(ValueError):
        good.intersect(torch.zeros(4, 3), torch.ones(4, 3), t_min=torch.zeros(3))
    with pytest.raises(ValueError):
        good.intersect(torch.full((1, 3), math.nan), torch.ones(1, 3))
    with pytest.raises(ValueError):
        BVH(SimpleNamespace(verts=torch.zeros(3, 2), faces=torch.zeros(1, 3, dtype=torch.int64)))
    with pytest.raises(ValueError):
        visible(torch.zeros(4, 3), torch.zeros(3, 3), good)
    with pytest.raises(ValueError):
        visible(torch.zeros(4, 2), torch.zeros(3), good)
    with pytest.raises(ValueError):
        raycast(icosphere(1), cam, bvh=BVH(icosphere(2)))


# --------------------------------------------------------------------------------- raycast vs rasterize

def near_edge(frags_a, frags_b, mesh, camera, tol=1e-3):
    """(H, W) bool: pixel centres within ``tol`` px of an edge of either face the two fragments name there."""
    H, W = camera.height, camera.width
    xy, _ = camera.project(mesh.verts.double())
    out = torch.zeros(H * W, dtype=torch.bool)
    i, j = torch.meshgrid(torch.arange(H), torch.arange(W), indexing="ij")
    p = torch.stack([j.reshape(-1) + 0.5, i.reshape(-1) + 0.5], 1).double()
    for f in (frags_a.face_id.reshape(-1), frags_b.face_id.reshape(-1)):
        ok = f >= 0
        tri = xy[mesh.faces[f.clamp_min(0)]]                                # (P, 3, 2)
        for k in range(3):
            a, b = tri[:, k], tri[:, (k + 1) % 3]
            e = b - a
            s = (((p - a) * e).sum(1) / (e * e).sum(1).clamp_min(1e-300)).clamp(0, 1)
            dist = (p - a - s[:, None] * e).norm(dim=1)
            out |= ok & (dist < tol)
    return out.view(H, W)


def cameras(size=48, dtype=torch.float64):
    return {
        "perspective": Camera.look_at((0.3, 0.4, 2.6), (0.0, 0.05, 0.0), fov_y=45.0, width=size, height=size - 8,
                                      dtype=dtype),
        "orthographic": Camera.look_at((2.0, 1.0, 2.5), (0.0, 0.0, 0.0), ortho_height=2.4, width=size,
                                       height=size + 4, dtype=dtype),
    }


def assert_agrees(mesh, camera):
    a, b = raycast(mesh, camera), rasterize(mesh, camera)
    for f in (a.face_id, a.bary, a.depth):
        assert not torch.isnan(f).any()
    differ = (a.face_id != b.face_id) & ~near_edge(a, b, mesh, camera)
    both = (a.face_id >= 0) & (b.face_id >= 0)
    tie = both & ((a.depth - b.depth).abs() <= 1e-9 * b.depth.abs())
    assert not (differ & ~tie).any(), f"{int((differ & ~tie).sum())} pixels differ"
    assert (a.face_id >= 0).sum() > 50
    same = (a.face_id == b.face_id) & both
    assert torch.allclose(a.depth[same], b.depth[same], rtol=1e-5, atol=0)
    assert torch.allclose(a.bary[same], b.bary[same], rtol=1e-5, atol=1e-6)
    assert torch.isinf(a.depth[a.face_id < 0]).all()
    return a


@pytest.mark.parametrize("kind", ["perspective", "orthographic"])
@pytest.mark.parametrize("model", ["icosphere", "teapot"])
def test_raycast_agrees_with_rasterize(kind, model):
    mesh = icosphere(3) if model == "icosphere" else teapot(6)
    assert_agrees(mesh, cameras()[kind])


def test_raycast_is_differentiable_like_rasterize():
    mesh = icosphere(2, dtype=torch.float64)
    verts = mesh.verts.clone().requires_grad_(True)
    frags = raycast(Mesh(verts, mesh.faces), cameras(16)["perspective"])
    frags.depth[frags.face_id >= 0].sum().backward()
    assert verts.grad is not None and verts.grad.abs().sum() > 0 and torch.isfinite(verts.grad).all()


def test_raycast_near_far_and_camera_inside_bounds():
    """A camera inside a box (inside the BVH's root bounds) sees its walls; near and far planes clip."""
    room = cube(4.0, dtype=torch.float64)
    cam = Camera.look_at((0.3, 0.2, 0.5), (1.0, -0.3, -2.0), fov_y=80.0, width=40, height=30,
                         dtype=torch.float64)
    a = assert_agrees(room, cam)
    assert (a.face_id >= 0).all()
    clipped = Camera(cam.K, cam.R, cam.t, 40, 30, near=0.1, far=2.0)
    c = assert_agrees(room, clipped)
    assert (c.face_id < 0).any() and (c.depth[c.face_id >= 0] <= 2.0).all()
    sphere = icosphere(3, dtype=torch.float64)                             # the near plane cuts a sphere
    assert_agrees(sphere, Camera.look_at((0.0, 0.0, 1.5), fov_y=60.0, width=40, height=40, near=0.8,
                                         dtype=torch.float64))


@pytest.mark.parametrize("scale", [1e-4, 1e4])
def test_raycast_at_tiny_and_huge_scales(scale):
    m = icosphere(3)
    mesh = Mesh(m.verts * scale, m.faces)
    cam = Camera.look_at((0.3 * scale, 0.4 * scale, 2.6 * scale), (0.0, 0.0, 0.0), fov_y=45.0, width=40,
                         height=40, near=0.1 * scale, far=100 * scale)
    assert_agrees(mesh, cam)


# ------------------------------------------------------------------------------------------ shadow rays

def test_light_inside_a_closed_mesh_is_blocked_everywhere():
    bvh = BVH(icosphere(2, dtype=torch.float64))
    g = torch.Generator().manual_seed(5)
    d = torch.randn(300, 3, generator=g, dtype=torch.float64)
    points = 1.5 * d / d.norm(dim=1, keepdim=True)
    assert not visible(points, torch.zeros(3), bvh).any()
    assert not visible(points, torch.tensor([0.1, -0.2, 0.3]), bvh).any()
    disk = disk_light_samples([0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 0.5, 300, grid=3)
    assert (visible(points, disk, bvh) == 0).all()
    # and from outside, a light on the same side is seen
    top = torch.tensor([[0.3, 1.5, 0.0], [-0.2, 2.0, 0.1]], dtype=torch.float64)
    assert visible(top, torch.tensor([0.0, 5.0, 0.0]), bvh).all()


def test_points_on_the_surface_do_not_shadow_themselves():
    for dtype in (torch.float32, torch.float64):
        mesh = icosphere(3, dtype=dtype)
        bvh = BVH(mesh)
        tris = mesh.verts[mesh.faces]
        points = tris.mean(1)                                               # one point on every face
        lit = (points[:, 1] > 0.3)                                          # faces well toward the light
        light = torch.tensor([0.0, 10.0, 0.0], dtype=dtype)
        assert visible(points[lit], light, bvh).all()
        assert visible(points[lit], torch.tensor([0.0, -1.0, 0.0], dtype=dtype), bvh, directional=True).all()
        # with the geometric normals the far side is shadowed by its own surface
        normals = mesh.face_normals()
        far_side = points[:, 1] < -0.3
        assert not visible(points[far_side], light, bvh, normals=normals[far_side]).any()
        assert visible(points[lit], light, bvh, normals=normals[lit]).all()


def test_hard_and_soft_shadows_under_a_sphere():
    bvh = BVH(icosphere(3, dtype=torch.float64))
    ground = torch.tensor([[0.0, -2.0, 0.0], [1.2, -2.0, 0.0], [3.0, -2.0, 0.0]], dtype=torch.float64)
    down = torch.tensor([0.0, -1.0, 0.0], dtype=torch.float64)
    assert visible(ground, down, bvh, directional=True).tolist() == [False, True, True]
    assert visible(ground, torch.tensor([0.0, 4.0, 0.0]), bvh).tolist() == [False, False, True]
    rect = rectangle_light_samples([-1.0, 4.0, -1.0], [2.0, 0.0, 0.0], [0.0, 0.0, 2.0], 3, grid=6, seed=7)
    assert rect.shape == (3, 36, 3) and (rect[..., 1] == 4).all()
    frac = visible(ground, rect, bvh)
    assert frac.dtype == torch.float64 and float(frac[0]) == 0.0 and float(frac[2]) == 1.0
    assert 0 < float(frac[1]) < 1                                            # the penumbra
    again = visible(ground, rectangle_light_samples([-1.0, 4.0, -1.0], [2.0, 0.0, 0.0], [0.0, 0.0, 2.0], 3,
                                                    grid=6, seed=7), bvh)
    assert torch.equal(frac, again)                                         # seeded
    disk = disk_light_samples([0.0, 4.0, 0.0], [0.0, -1.0, 0.0], 1.0, 3, grid=6, seed=1)
    r = (disk - torch.tensor([0.0, 4.0, 0.0])).norm(dim=-1)
    assert (r <= 1 + 1e-6).all() and (disk[..., 1] - 4).abs().max() < 1e-6
    fd = visible(ground, disk, bvh)
    assert float(fd[0]) == 0.0 and float(fd[2]) == 1.0 and 0 < float(fd[1]) < 1
