"""Exact pixel coverage against an independent reference: scanlines solved exactly, integrated in y.

The reference never clips a polygon. Along one horizontal scanline every quantity that decides visibility
is linear in x: the three signed volumes ``d(x) · (v_k × v_k+1)`` that say whether the pixel ray hits a
camera-space triangle (pinhole camera), or the 2D edge functions of the ray's origin (orthographic), the
ray's 1/z (or z) at the hit, and so the near and far tests. So each face covers an x-interval of the
scanline, and the nearest face changes only at interval ends and where two faces' depths cross: between
those breakpoints one face is visible, found by its depth at the midpoint (ties → lower face id). That
integral over x is exact; the integral over y uses the midpoint rule on ``ROWS`` scanlines per pixel row,
whose error is O(1/ROWS²) where the visible widths kink (they are piecewise linear in y).
"""
import math
from types import SimpleNamespace

import pytest
import torch

import course.coverage as coverage
from course.camera import Camera, look_at
from course.coverage import (clip_polygon, exact_coverage, halfplane_pixel_area, polygon_area,
                             visible_regions)
from course.mesh import Mesh
from course.models import teapot
from course.raster import rasterize

D = torch.float64
ROWS = 600                                  # reference scanlines per pixel row
TOL = 2e-5                                  # exact vs reference, per pixel and channel


# ------------------------------------------------------------------------------------------ the reference

def reference(mesh, camera, colors, background=(0.0, 0.0, 0.0), rows=ROWS):
    """(H, W, 3) float64: the box-filtered image, exact per scanline, midpoint rule in y."""
    K, R, t = (x.detach().to(D) for x in (camera.K, camera.R, camera.t))
    tri = (mesh.verts.detach().to(D) @ R.T + t)[mesh.faces]                # (F, 3, 3) camera space
    colors = torch.as_tensor(colors, dtype=D)
    bg = torch.as_tensor(background, dtype=D)
    H, W, F = camera.height, camera.width, tri.shape[0]
    v0, v1, v2 = tri.unbind(1)
    normal = torch.linalg.cross(v1 - v0, v2 - v0)
    det = (normal * v0).sum(-1)                                             # N · v0 = det(v0, v1, v2)
    Kinv = torch.linalg.inv(K)
    out = torch.zeros(H, W, 3, dtype=D)
    for i in range(H):
        y = i + (torch.arange(rows, dtype=D) + 0.5) / rows                  # (S,) scanlines
        x = torch.arange(W + 1, dtype=D)                                    # pixel borders
        p = torch.stack(torch.broadcast_tensors(x[None], y[:, None], torch.ones(1, dtype=D)), -1)  # (S, W+1, 3)
        d = p @ Kinv.T                                                      # ray direction or origin
        cons, near_n = [], None
        if camera.orthographic:
            area = normal[:, 2]
            ok = area != 0
            for a, b in ((v0, v1), (v1, v2), (v2, v0)):                     # 2D edge functions
                e = (b - a)[:, 0] * (d[..., 1:2] - a[:, 1]) - (b - a)[:, 1] * (d[..., 0:1] - a[:, 0])
                cons.append(torch.sign(area) * e)
            z = (det - normal[:, 0] * d[..., 0:1] - normal[:, 1] * d[..., 1:2]) / torch.where(ok, area, 1.0)
            cons += [camera.far - z, z - camera.near]
            near_n = -z                                                     # (S, W+1, F) larger is nearer
        else:
            ok = det != 0
            for a, b in ((v0, v1), (v1, v2), (v2, v0)):                     # signed volumes
                cons.append(torch.sign(det) * (d @ torch.linalg.cross(a, b).T))
            inv_z = (d @ normal.T) / torch.where(ok, det, 1.0)
            cons += [inv_z - 1 / camera.far, 1 / camera.near - inv_z]
            near_n = inv_z
        c = torch.stack(cons, -1)                                           # (S, W+1, F, 5)
        ca, cb = c[:, :-1], c[:, 1:]                                        # at x = j and j + 1
        slope = cb - ca
        root = -ca / torch.where(slope == 0, torch.ones_like(slope), slope)
        lo = torch.where(slope > 0, root, torch.where((slope == 0) & (ca < 0), 2.0, 0.0)).clamp(0, 2)
        hi = torch.where(slope < 0, root, torch.where((slope == 0) & (ca < 0), -1.0, 1.0)).clamp(-1, 1)
        lo, hi = lo.amax(-1), hi.amin(-1)                                   # (S, W, F) the covered t-interval
        valid = (hi > lo) & ok
        na, nb = near_n[:, :-1], near_n[:, 1:]
        dna, dnb = na[..., :, None] - na[..., None, :], nb[..., :, None] - nb[..., None, :]
        den = dna - dnb
        cross = (dna / torch.where(den == 0, torch.ones_like(den), den)).flatten(-2)   # depth crossings
        zero_one = torch.tensor([0.0, 1.0], dtype=D).expand(*lo.shape[:2], 2)
        bp = torch.cat([zero_one, lo, hi, cross], -1).nan_to_num(0).clamp(0, 1).sort(-1).values
        mid, width = (bp[..., 1:] + bp[..., :-1]) / 2, bp[..., 1:] - bp[..., :-1]   # (S, W, B)
        n_mid = na[..., None, :] + mid[..., None] * (nb - na)[..., None, :]        # (S, W, B, F)
        inside = valid[..., None, :] & (lo[..., None, :] <= mid[..., None]) & (mid[..., None] <= hi[..., None, :])
        score = torch.where(inside, n_mid, torch.tensor(-math.inf, dtype=D))
        best = score.argmax(-1)                                             # first maximum: the lower id
        colour = torch.where(inside.any(-1)[..., None], colors[best], bg)
        out[i] = (width[..., None] * colour).sum(-2).mean(0)
    return out


# --------------------------------------------------------------------------------------------- scenes

def pinhole(W=6, H=6, f=6.0, near=0.1, far=100.0):
    """R = I, t = 0: camera space is world space (OpenCV axes: x right, y down, z forward)."""
    K = torch.tensor([[f, 0, W / 2], [0, f, H / 2], [0, 0, 1]], dtype=D)
    return Camera(K, torch.eye(3, dtype=D), torch.zeros(3, dtype=D), W, H, near=near, far=far)


def ortho(W=6, H=6, near=0.0, far=100.0):
    """Orthographic with K = I and R = I, t = 0: screen (x, y) is camera (x, y); pixel corners are integers."""
    return Camera(torch.eye(3, dtype=D), torch.eye(3, dtype=D), torch.zeros(3, dtype=D), W, H,
                  near=near, far=far, orthographic=True)


def mesh_of(*tris):
    """Triangles given as lists of three (x, y, z) camera-space points."""
    verts = torch.tensor([p for t in tris for p in t], dtype=D)
    return Mesh(verts, torch.arange(verts.shape[0]).view(-1, 3))


def distinct(F):
    g = torch.Generator().manual_seed(F)
    return 0.1 + 0.8 * torch.rand(F, 3, generator=g, dtype=D)


SCENES = {
    # a near triangle in front of a farther one (pinhole)
    "occlusion": (pinhole, [[(-0.6, -0.5, 2.0), (0.7, -0.3, 2.0), (-0.1, 0.6, 2.0)],
                            [(-0.2, -0.7, 1.3), (0.5, 0.2, 1.3), (-0.45, 0.35, 1.3)]]),
    # a sliver between pixel centres: it covers no centre (rasterize sees nothing)
    "sliver": (ortho, [[(0.6, 0.55, 1.0), (5.4, 0.62, 1.0), (5.45, 0.7, 1.0)]]),
    # smaller than a pixel, between the centres
    "tiny": (ortho, [[(2.55, 2.6, 1.0), (2.95, 2.62, 1.0), (2.7, 2.93, 1.0)]]),
    # larger than the image, and a second one crossing it
    "huge": (ortho, [[(-40.0, -30.0, 2.0), (50.0, -20.0, 2.0), (-10.0, 60.0, 2.0)],
                     [(-9.0, 1.3, 1.0), (20.0, 3.9, 1.5), (-3.0, 30.0, 1.2)]]),
    # every vertex exactly on a pixel corner, edges along pixel borders
    "corners": (ortho, [[(1.0, 1.0, 1.0), (5.0, 1.0, 1.0), (1.0, 5.0, 1.0)],
                        [(2.0, 2.0, 0.5), (4.0, 2.0, 0.5), (4.0, 4.0, 0.5)]]),
    # one vertex behind the camera: clipped at z = near into a quad (and one into a triangle)
    "near": (pinhole, [[(-0.8, -0.6, 1.5), (0.9, -0.2, 1.5), (0.2, 0.5, -0.5)],
                       [(-0.5, 0.5, 0.05), (0.6, 0.6, 0.05), (0.0, -0.2, 1.0)]]),
    # clockwise on screen (a back face): still drawn
    "back": (pinhole, [[(-0.6, -0.5, 2.0), (-0.1, 0.6, 2.0), (0.7, -0.3, 2.0)]]),
    # a large tilted triangle whose centroid is farther than a small one it hides
    "tilted": (pinhole, [[(-1.0, -1.0, 1.0), (1.2, -0.9, 1.05), (0.0, 1.2, 9.0)],
                         [(-0.3, -0.9, 3.0), (0.3, -0.85, 3.0), (0.0, -0.6, 3.0)]]),
    # two triangles passing through each other
    "intersecting": (pinhole, [[(-0.7, -0.5, 1.5), (0.8, -0.4, 2.5), (0.0, 0.7, 2.0)],
                               [(-0.6, 0.4, 2.4), (0.7, 0.5, 1.4), (0.1, -0.7, 2.0)]]),
    # three triangles each over the next: no depth order of whole faces exists
    "cyclic": (ortho, [[(0.3, 1.0, 1.0), (5.7, 1.2, 3.0), (5.5, 2.4, 3.0)],
                       [(4.8, 0.4, 1.0), (3.0, 5.6, 3.0), (2.0, 5.3, 3.0)],
                       [(1.6, 5.2, 1.0), (0.2, 0.6, 3.0), (1.3, 0.4, 3.0)]]),
    # the far plane cuts a tilted triangle (pinhole, far = 3)
    "far": (lambda: pinhole(far=3.0), [[(-0.8, -0.7, 1.5), (0.9, -0.5, 1.8), (0.0, 0.8, 6.0)]]),
    "far_ortho": (lambda: ortho(far=3.0), [[(0.4, 0.5, 1.0), (5.6, 1.5, 2.0), (2.5, 5.5, 6.0)],
                                           [(0.5, 4.5, 4.0), (5.5, 4.8, 4.0), (3.0, 0.3, 1.5)]]),
}


@pytest.mark.parametrize("name", sorted(SCENES))
def test_matches_reference(name):
    make_camera, tris = SCENES[name]
    camera, mesh = make_camera(), mesh_of(*tris)
    colors = distinct(len(tris))
    bg = (0.05, 0.1, 0.15)
    exact = exact_coverage(mesh, camera, colors, bg)
    ref = reference(mesh, camera, colors, bg)
    assert exact.shape == (camera.height, camera.width, 3) and exact.dtype == D
    err = (exact - ref).abs().max().item()
    assert err < TOL, f"{name}: max |exact - reference| = {err:.2e}"


def test_reference_sanity():
    """The reference itself, on a case checked by hand: the half-plane x + y <= 6 over a 4 x 4 image."""
    camera = ortho(4, 4)
    mesh = mesh_of([(-1.0, -1.0, 1.0), (7.0, -1.0, 1.0), (-1.0, 7.0, 1.0)])   # x + y <= 6
    ref = reference(mesh, camera, [[1.0, 1.0, 1.0]], rows=50)
    expect = torch.tensor([[1, 1, 1, 1], [1, 1, 1, 1], [1, 1, 1, 0.5], [1, 1, 0.5, 0]], dtype=D)
    assert torch.allclose(ref[..., 0], expect, atol=1e-12)


def test_sliver_and_tiny_triangle_are_seen_where_centres_miss_them():
    for name in ("sliver", "tiny"):
        make_camera, tris = SCENES[name]
        camera, mesh = make_camera(), mesh_of(*tris)
        assert not rasterize(mesh, camera).mask.any()                      # no pixel centre is covered
        cov = exact_coverage(mesh, camera, torch.ones(1, 3, dtype=D))[..., 0]
        xy = torch.tensor(tris[0], dtype=D)[:, :2]
        assert cov.sum().item() == pytest.approx(abs(polygon_area(xy).item()), abs=1e-12)


def test_single_triangle_sum_is_its_screen_area():
    camera = pinhole(8, 8, f=7.0)
    tri = [(-0.5, -0.45, 2.0), (0.55, -0.3, 2.6), (-0.1, 0.5, 1.7)]
    cov = exact_coverage(mesh_of(tri), camera, torch.ones(1, 3, dtype=D))[..., 0]
    p = torch.tensor(tri, dtype=D)
    screen = p[:, :2] / p[:, 2:] * 7.0 + 4.0                               # by hand: x = f X / Z + c
    assert screen.min() > 0 and screen.max() < 8
    by_hand = 0.5 * abs(((screen[1] - screen[0])[0] * (screen[2] - screen[0])[1]
                         - (screen[1] - screen[0])[1] * (screen[2] - screen[0])[0]).item())
    assert cov.sum().item() == pytest.approx(by_hand, rel=1e-12)
    assert cov.max() <= 1 + 1e-12 and cov.min() >= 0


def test_tilted_triangle_hides_the_small_one_despite_its_centroid():
    make_camera, tris = SCENES["tilted"]
    small_z, big = 3.0, torch.tensor(tris[0])
    assert big[:, 2].mean() > small_z                                      # painter's order would draw it last
    alone = exact_coverage(mesh_of(tris[1]), make_camera(), torch.ones(1, 3, dtype=D))
    assert alone.sum() > 0.9                                                # it is in view
    colors = torch.tensor([[1.0, 0, 0], [0, 1.0, 0]], dtype=D)
    img = exact_coverage(mesh_of(*tris), make_camera(), colors)
    assert img[..., 1].max() < 1e-12                                        # the small (green) face never shows


def test_coplanar_tie_goes_to_the_lower_face_id():
    a = [(0.5, 0.5, 1.0), (5.5, 0.7, 1.0), (1.0, 5.5, 1.0)]
    b = [(5.5, 5.4, 1.0), (0.6, 4.0, 1.0), (4.8, 0.3, 1.0)]
    colors = torch.tensor([[1.0, 0, 0], [0, 0, 1.0]], dtype=D)
    for tris in ((a, b), (b, a)):
        img = exact_coverage(mesh_of(*tris), ortho(), colors)
        assert (img - reference(mesh_of(*tris), ortho(), colors)).abs().max() < TOL
    first = exact_coverage(mesh_of(a, b), ortho(), colors)
    assert first[..., 0].sum() == pytest.approx(abs(polygon_area(torch.tensor(a, dtype=D)[:, :2]).item()), abs=1e-9)
    b_area = abs(polygon_area(torch.tensor(b, dtype=D)[:, :2]).item())
    assert first[..., 2].sum() < b_area - 1                                 # b loses the overlap


def test_far_plane_clips():
    make_camera, tris = SCENES["far"]
    camera, mesh = make_camera(), mesh_of(*tris)
    ones = torch.ones(1, 3, dtype=D)
    clipped = exact_coverage(mesh, camera, ones)[..., 0].sum()
    whole = exact_coverage(mesh, pinhole(far=100.0), ones)[..., 0].sum()
    assert clipped < whole - 0.5


def test_teapot_total_coverage_matches_dense_supersampling():
    """The teapot's spout and handle pass into its body; at low resolution many faces share a pixel."""
    mesh = teapot(3, dtype=D)
    R, t = look_at(torch.tensor([2.2, 1.3, 2.6], dtype=D), torch.zeros(3, dtype=D))
    K = torch.tensor([[14.0, 0, 6.0], [0, 14.0, 5.0], [0, 0, 1]], dtype=D)
    camera = Camera(K, R, t, 12, 10)
    F = mesh.faces.shape[0]
    colors = distinct(F)
    exact = exact_coverage(mesh, camera, colors)
    cov = exact_coverage(mesh, camera, torch.ones(F, 3, dtype=D))[..., 0]
    n = 24
    g = (torch.arange(n, dtype=D) + 0.5) / n
    offsets = torch.stack(torch.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    fid = rasterize(mesh, camera, samples=offsets).face_id                 # (H*W, S)
    dense_cov = (fid >= 0).to(D).mean(1).view(10, 12)
    dense = torch.where((fid >= 0)[..., None], colors[fid.clamp(min=0)], 0.0).mean(1).view(10, 12, 3)
    assert cov.min() >= -1e-12 and cov.max() <= 1 + 1e-9
    assert cov.sum().item() == pytest.approx(dense_cov.sum().item(), abs=0.05)
    assert (cov - dense_cov).abs().max() < 0.05 and (exact - dense).abs().max() < 0.05
    assert ((exact - dense) ** 2).mean().sqrt() < 0.01


# ------------------------------------------------------------------------------------------ primitives

def test_polygon_area_sign_and_clip():
    cw_on_screen = torch.tensor([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]], dtype=D)   # right, then down
    assert polygon_area(cw_on_screen).item() == 0.5
    assert polygon_area(cw_on_screen.flip(0)).item() == -0.5
    square = torch.tensor([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]], dtype=D)
    half = clip_polygon(square, torch.tensor([-1.0, 0.0, 0.5], dtype=D))      # x <= 0.5
    assert polygon_area(half).item() == pytest.approx(1.0)
    assert clip_polygon(square, torch.tensor([1.0, 0.0, 5.0], dtype=D)).shape == (4, 2)
    assert clip_polygon(square, torch.tensor([1.0, 0.0, -5.0], dtype=D)).shape == (0, 2)


def test_halfplane_pixel_area():
    assert halfplane_pixel_area(torch.tensor([1.0, 0.0, -3.25], dtype=D), 3, 7).item() == pytest.approx(0.75)
    assert halfplane_pixel_area(torch.tensor([0.0, -1.0, 7.5], dtype=D), 3, 7).item() == pytest.approx(0.5)
    # the diagonal x + y >= col + row + 1 cuts the square in half; a line far away covers all or nothing
    assert halfplane_pixel_area(torch.tensor([1.0, 1.0, -11.0], dtype=D), 3, 7).item() == pytest.approx(0.5)
    assert halfplane_pixel_area(torch.tensor([1.0, 1.0, 50.0], dtype=D), 3, 7).item() == pytest.approx(1.0)
    assert halfplane_pixel_area(torch.tensor([1.0, 1.0, -50.0], dtype=D), 3, 7).item() == 0.0
    # random lines against the area of the covered part integrated exactly in x, midpoint in y
    g = torch.Generator().manual_seed(3)
    for _ in range(20):
        a, b = torch.randn(2, generator=g, dtype=D)
        c = -(a * (2 + torch.rand(1, generator=g, dtype=D)) + b * (5 + torch.rand(1, generator=g, dtype=D)))
        y = 5 + (torch.arange(4000, dtype=D) + 0.5) / 4000
        x0 = -(b * y + c) / a                                               # a x + b y + c = 0
        width = torch.where(a > 0, 3 - x0, x0 - 2).clamp(0, 1)
        got = halfplane_pixel_area(torch.stack([a, b, c[0]]), 2, 5).item()
        assert got == pytest.approx(width.mean().item(), abs=1e-6)


def test_vectorised_clipping_agrees_with_the_teaching_version():
    g = torch.Generator().manual_seed(5)
    N, n = 40, 6
    ang = torch.sort(torch.rand(N, n, generator=g, dtype=D) * 2 * math.pi, 1).values
    poly = torch.stack([ang.cos(), -ang.sin()], -1) * (0.5 + torch.rand(N, 1, 1, generator=g, dtype=D))
    count = torch.randint(3, n + 1, (N,), generator=g)
    poly = torch.where(torch.arange(n)[None, :, None] < count[:, None, None], poly,
                       poly.gather(1, (count - 1)[:, None, None].expand(-1, n, 2)))   # pad with the last vertex
    line = torch.randn(N, 3, generator=g, dtype=D) * torch.tensor([1.0, 1.0, 0.5], dtype=D)
    s = poly[..., 0] * line[:, :1] + poly[..., 1] * line[:, 1:2] + line[:, 2:]
    out, out_count = coverage._clip_rows(poly, count, s)
    for r in range(N):
        want = clip_polygon(poly[r, :count[r]], line[r])
        assert out_count[r].item() == want.shape[0]
        assert torch.allclose(out[r, :out_count[r]], want, atol=1e-14)
        assert coverage._areas(out[r:r + 1]).item() == pytest.approx(polygon_area(want).item(), abs=1e-14)


def test_regions_are_the_image():
    make_camera, tris = SCENES["cyclic"]
    camera, mesh = make_camera(), mesh_of(*tris)
    regions = visible_regions(mesh, camera)
    areas = torch.stack([polygon_area(v[:c]) for v, c in zip(regions.image_verts(camera.width), regions.count)])
    assert torch.allclose(areas, regions.area, atol=1e-12) and (regions.area > 0).all()
    per_pixel = torch.zeros(camera.height * camera.width, dtype=D).index_add(0, regions.pixel, regions.area)
    assert per_pixel.max() <= 1 + 1e-12
    colors = distinct(3)
    img = torch.zeros(camera.height * camera.width, 3, dtype=D).index_add(
        0, regions.pixel, regions.area[:, None] * colors[regions.face])
    assert torch.allclose(img.view(6, 6, 3), exact_coverage(mesh, camera, colors), atol=1e-14)


def test_chunks_give_the_same_image(monkeypatch):
    make_camera, tris = SCENES["intersecting"]
    mesh, camera, colors = mesh_of(*tris), make_camera(), distinct(2)
    whole = exact_coverage(mesh, camera, colors)
    monkeypatch.setattr(coverage, "CHUNK", 3)
    assert torch.allclose(exact_coverage(mesh, camera, colors), whole, atol=1e-14)


# ------------------------------------------------------------------------------- precision, gradients

def test_float32_agrees_with_float64():
    for name in ("intersecting", "occlusion", "cyclic", "near", "corners"):
        make_camera, tris = SCENES[name]
        camera, mesh = make_camera(), mesh_of(*tris)
        colors = distinct(len(tris))
        ref = exact_coverage(mesh, camera, colors)
        m32 = Mesh(mesh.verts.float(), mesh.faces)
        got = exact_coverage(m32, camera.to(dtype=torch.float32), colors.float())
        assert got.dtype == torch.float32
        assert (got.double() - ref).abs().max() < 1e-5, name
    mixed = exact_coverage(Mesh(mesh.verts.float(), mesh.faces), camera.to(dtype=torch.float32), colors)
    assert mixed.dtype == torch.float64                                    # promote(verts, camera, colours)


def _scene_for_gradients():
    """Two intersecting triangles and a third in front, moved off the pixel borders (a vertex on a border is
    a kink: there central differences average two one-sided derivatives)."""
    tris = SCENES["intersecting"][1] + [[(-0.3, -0.2, 1.2), (0.25, -0.1, 1.25), (0.0, 0.3, 1.3)]]
    mesh = mesh_of(*tris)
    return Mesh(mesh.verts + torch.tensor([0.0123, 0.0071, 0.0], dtype=D), mesh.faces), distinct(3)


def _central_difference(fn, x, eps=1e-6):
    grad = torch.zeros_like(x)
    flat = grad.view(-1)
    for k in range(x.numel()):
        xp, xm = x.clone(), x.clone()
        xp.view(-1)[k] += eps
        xm.view(-1)[k] -= eps
        flat[k] = (fn(xp) - fn(xm)) / (2 * eps)
    return grad


def test_gradients_match_central_differences():
    mesh, colors = _scene_for_gradients()
    camera = pinhole()
    w = torch.rand(6, 6, 3, generator=torch.Generator().manual_seed(1), dtype=D)   # a random loss direction

    def loss(verts=mesh.verts, cols=colors, t=camera.t, K=camera.K):
        cam = Camera(K, camera.R, t, 6, 6, near=camera.near, far=camera.far)
        return (w * exact_coverage(Mesh(verts, mesh.faces), cam, cols)).sum()

    for name, x in (("verts", mesh.verts), ("cols", colors), ("t", camera.t), ("K", camera.K)):
        x = x.clone().requires_grad_(True)
        (auto,) = torch.autograd.grad(loss(**{name: x}), x)
        numeric = _central_difference(lambda v: loss(**{name: v}).item(), x.detach())
        assert torch.allclose(auto, numeric, atol=1e-6, rtol=1e-5), (name, (auto - numeric).abs().max())


def test_gradients_finite_at_kinks():
    # vertices exactly on pixel corners, edges exactly along pixel borders, a vertex on the near plane
    mesh = mesh_of(*SCENES["corners"][1])
    verts = mesh.verts.clone().requires_grad_(True)
    img = exact_coverage(Mesh(verts, mesh.faces), ortho(), distinct(2))
    (g,) = torch.autograd.grad((img * torch.arange(108, dtype=D).view(6, 6, 3)).sum(), verts)
    assert torch.isfinite(g).all() and g.abs().sum() > 0
    # a vertex exactly at z = near, one projecting onto the pixel corner (3, 3)
    mesh = mesh_of([(-0.5, -0.5, 1.0), (0.5, -0.5, 1.0), (0.0, 0.5, 0.1)],
                   [(0.0, 0.0, 1.0), (1.0, 0.0, 1.0), (0.0, 1.0, 1.0)])
    verts = mesh.verts.clone().requires_grad_(True)
    K = pinhole().K.clone().requires_grad_(True)
    cam = Camera(K, torch.eye(3, dtype=D), torch.zeros(3, dtype=D), 6, 6, near=0.1)
    img = exact_coverage(Mesh(verts, mesh.faces), cam, distinct(2))
    gv, gk = torch.autograd.grad(img.sum() + img[2, 3].sum(), (verts, K))
    assert torch.isfinite(gv).all() and torch.isfinite(gk).all()
    # an edge-on face (its plane passes through the eye) beside a face it touches
    mesh = mesh_of([(0.0, -0.5, 1.0), (0.0, 0.5, 1.0), (0.0, 0.0, 2.0)],
                   [(0.0, -0.5, 1.0), (0.4, 0.3, 1.2), (0.0, 0.5, 1.0)])
    verts = mesh.verts.clone().requires_grad_(True)
    img = exact_coverage(Mesh(verts, mesh.faces), pinhole(), distinct(2))
    (gv,) = torch.autograd.grad(img.sum(), verts)
    assert torch.isfinite(img).all() and torch.isfinite(gv).all()


def _teapot_for_gradients():
    """teapot(3) at 24 px: its lid fan, shared edges and the spout crossing the body at z = 0 put many piece
    vertices exactly on clipping lines (lecture 09's benchmark scene)."""
    mesh = teapot(3, dtype=D)
    g = torch.Generator().manual_seed(0)
    colors = torch.rand(mesh.faces.shape[0], 3, generator=g, dtype=D)
    camera = Camera.look_at((2.6, 1.0, 1.35), fov_y=40, width=24, height=24, dtype=D)
    w = torch.randn(24, 24, 3, generator=g, dtype=D)
    return mesh, colors, camera, w


def test_teapot_gradients_match_central_differences():
    # Regression: a piece edge lying on the clipping line (a shared lid edge, seen from both of its faces)
    # was split at t = noise / noise, leaving slivers of area 1e-17 with O(1) derivatives: vertex 253 got
    # (0.94, -8.78, 2.47) for (-0.16, -3.48, 1.90). Vertex 366 sits on the z = 0 seam (4 copies) where three
    # lines meet (its z moved by 0.7 under a fix that kept such vertices unclipped); the copies move
    # together, so their gradients are summed (welded).
    mesh, colors, camera, w = _teapot_for_gradients()
    verts = mesh.verts.clone().requires_grad_(True)
    (auto,) = torch.autograd.grad((w * exact_coverage(Mesh(verts, mesh.faces), camera, colors)).sum(), verts)

    def loss(v):
        return (w * exact_coverage(Mesh(v, mesh.faces), camera, colors)).sum().item()

    h = 1e-6
    for i, axes in ((253, (0, 1, 2)), (366, (2,))):
        copies = (mesh.verts - mesh.verts[i]).norm(dim=1) < 1e-9
        for axis in axes:
            step = torch.zeros_like(mesh.verts)
            step[copies, axis] = h
            numeric = (loss(mesh.verts + step) - loss(mesh.verts - step)) / (2 * h)
            assert auto[copies, axis].sum().item() == pytest.approx(numeric, abs=2e-5, rel=1e-5), (i, axis)


def test_hidden_sliver_has_no_gradient():
    # Regression: in pixel (row 9, column 14) face 119 lies behind the teapot's lid; it used to keep a piece of
    # area 2e-17 along the lid edge 259-291 whose area gradient had norm 4 (its true derivative is 0).
    mesh, _, camera, _ = _teapot_for_gradients()
    verts = mesh.verts.clone().requires_grad_(True)
    regions = visible_regions(Mesh(verts, mesh.faces), camera)
    mine = (regions.pixel == 9 * 24 + 14) & (regions.face == 119)
    area = regions.area[mine].sum()
    assert abs(area.item()) < 1e-12
    if area.requires_grad:
        (g,) = torch.autograd.grad(area, verts, retain_graph=True)
        assert g.abs().max().item() < 1e-9
    # and no piece anywhere has a vertex whose derivative is a ratio of rounding errors
    (g,) = torch.autograd.grad((regions.area * torch.linspace(-1, 1, regions.area.numel(), dtype=D)).sum(), verts)
    assert torch.isfinite(g).all()


def test_clip_rows_edge_on_the_line_splits_at_its_start():
    # the bottom edge lies on the line y = 0, its two ends with rounding noise of opposite signs: split at
    # t = noise / noise, the piece below the line got a derivative of 1e16; now it is split at its start
    poly = torch.tensor([[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]], dtype=D, requires_grad=True)
    s = poly[..., 1] + torch.tensor([[1e-17, -1e-17, 0.0, 0.0]], dtype=D)
    below, n = coverage._clip_rows(poly, torch.tensor([4]), -s, tol=1e-12)   # the part y <= 0: area 0
    above, m = coverage._clip_rows(poly, torch.tensor([4]), s, tol=1e-12)
    assert torch.equal(below[0, 0], poly[0, 0].detach()) and n.item() == 3 and m.item() == 5
    (g,) = torch.autograd.grad(coverage._areas(below).sum(), poly, retain_graph=True)
    assert torch.isfinite(g).all() and g.abs().max().item() <= 1.0
    (both,) = torch.autograd.grad(coverage._areas(below).sum() + coverage._areas(above).sum(), poly)
    (whole,) = torch.autograd.grad(coverage._areas(poly).sum(), poly)          # the two parts tile the square
    assert torch.allclose(both, whole, atol=1e-12)


# ------------------------------------------------------------------------------------------- bad input

def test_bad_input():
    mesh, camera = mesh_of(*SCENES["occlusion"][1]), pinhole()
    with pytest.raises(ValueError, match=r"face_colors must have shape \(F, 3\)"):
        exact_coverage(mesh, camera, torch.ones(2, 4))
    with pytest.raises(ValueError, match=r"face_colors must have shape \(F, 3\)"):
        exact_coverage(mesh, camera, torch.ones(3, 3))
    with pytest.raises(ValueError, match="face_colors contains NaN"):
        exact_coverage(mesh, camera, torch.tensor([[0.0, float("nan"), 0], [0, 0, 0]]))
    with pytest.raises(ValueError, match=r"background must have shape \(3,\)"):
        exact_coverage(mesh, camera, torch.ones(2, 3), background=(0.0, 0.0))
    with pytest.raises(ValueError, match="background contains NaN"):
        exact_coverage(mesh, camera, torch.ones(2, 3), background=(0.0, float("nan"), 0.0))
    bad = SimpleNamespace(verts=torch.tensor([[0.0, 0, 1], [1, 0, 1], [0, float("nan"), 1]]),
                          faces=torch.tensor([[0, 1, 2]]))
    with pytest.raises(ValueError, match="NaN"):
        exact_coverage(bad, camera, torch.ones(1, 3))
    with pytest.raises(TypeError, match="camera"):
        exact_coverage(mesh, "camera", torch.ones(2, 3))


def test_empty_scene_is_background():
    camera = pinhole(4, 3)
    behind = mesh_of([(-1.0, -1.0, -2.0), (1.0, -1.0, -2.0), (0.0, 1.0, -2.0)])
    img = exact_coverage(behind, camera, torch.ones(1, 3, dtype=D), background=(0.25, 0.5, 0.75))
    assert torch.equal(img, torch.tensor([0.25, 0.5, 0.75], dtype=D).expand(3, 4, 3))
