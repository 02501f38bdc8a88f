"""Supersampling through the one rasterizer, and adaptive supersampling (lecture 05).

The adaptive sampler must give the full sampler's sample face ids and pixel values to the last bit on
piecewise-constant images, and its detector must find discontinuities that one sample per pixel cannot see.
"""
import math

import pytest
import torch

from course import antialias as aa
from course.camera import Camera, intrinsics_from_fov, look_at
from course.mesh import Mesh, join_meshes
from course.models import icosphere, teapot
from course.raster import pixel_triangle_pairs, rasterize
from course.render import frame_camera

# every test runs on the compiled kernels and on the torch path (tests/conftest.py)
pytestmark = pytest.mark.usefixtures("both_backends")


def ortho_camera(W, H, dtype=torch.float64):
    """Orthographic camera looking down +z: world (x, y) = pixel (x, y), depth = world z."""
    K = torch.tensor([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1]], dtype=dtype)
    return Camera(K, torch.eye(3, dtype=dtype), torch.zeros(3, dtype=dtype), W, H, near=0.1, far=100.0,
                  orthographic=True)


def tris(*triangles, z=5.0):
    """A mesh of separate screen-space triangles (pixel coordinates) at depth z for ``ortho_camera``."""
    verts, faces = [], []
    for k, tri in enumerate(triangles):
        for x, y, *zz in tri:
            verts.append([x, y, zz[0] if zz else z])
        faces.append([3 * k, 3 * k + 1, 3 * k + 2])
    return Mesh(torch.tensor(verts, dtype=torch.float64), torch.tensor(faces))


def sphere_scene(size=48, subdivisions=2):
    mesh = icosphere(subdivisions, dtype=torch.float64)
    R, t = look_at((0.4, 0.3, 3.0), (0, 0, 0))
    K = intrinsics_from_fov(40.0, size, size, dtype=torch.float64)
    return mesh, Camera(K, R, t, size, size)


def two_spheres(size=40):
    a = icosphere(2, radius=1.0, dtype=torch.float64)
    b = icosphere(2, radius=0.7, dtype=torch.float64)
    b = Mesh(b.verts + torch.tensor([0.9, 0.2, 0.6], dtype=torch.float64), b.faces)
    mesh = join_meshes([a, b])
    return mesh, frame_camera(mesh, width=size, height=size).to(dtype=torch.float64)


# ----------------------------------------------------------------------------------------- the samples

def test_regular_offsets_are_the_grid_cell_centres():
    o = aa.regular_offsets(2)
    assert torch.equal(o, torch.tensor([[0.25, 0.25], [0.75, 0.25], [0.25, 0.75], [0.75, 0.75]], dtype=torch.float64))


def test_jitter_is_stratified_deterministic_and_independent_of_the_other_pixels():
    k, pix = 4, torch.tensor([0, 7, 123456, 5])
    o = aa.jittered_offsets(k, pix, seed=3)
    assert o.shape == (4, 16, 2)
    cell = torch.floor(o * k)
    assert torch.equal(cell, torch.floor(aa.regular_offsets(k) * k).expand_as(cell))   # one per stratum
    assert torch.equal(aa.jittered_offsets(k, pix[1:3], seed=3), o[1:3])               # a subset: same samples
    assert not torch.equal(aa.jittered_offsets(k, pix, seed=4), o)
    assert (o >= 0).all() and (o < 1).all()
    assert o[:, :, 0].std() > 0.2                                                      # not all at cell centres


def test_sample_rasterizer_matches_a_finer_scan_line_image():
    """k x k regular samples per pixel are the pixel centres of the image k times finer."""
    mesh, cam = sphere_scene(32)
    k = 4
    frags = aa.sample_fragments(mesh, cam, k)
    K = cam.K.clone()
    K[:2] *= k
    fine = rasterize(mesh, Camera(K, cam.R, cam.t, 32 * k, 32 * k, near=cam.near, far=cam.far))
    ids = fine.face_id.view(32, k, 32, k).permute(0, 2, 1, 3).reshape(32 * 32, k * k)
    assert (ids != frags.face_id).sum() <= 2                                # equal except within rounding of an edge
    hit = (ids == frags.face_id) & (ids >= 0)
    d_fine = fine.depth.view(32, k, 32, k).permute(0, 2, 1, 3).reshape(32 * 32, k * k)
    torch.testing.assert_close(frags.depth[hit], d_fine[hit], rtol=1e-12, atol=0)


@pytest.mark.parametrize("jitter", [False, True])
def test_a_subset_of_pixels_gets_bit_identical_samples(jitter):
    mesh, cam = sphere_scene(40)
    full = aa.sample_fragments(mesh, cam, 3, jitter=jitter, seed=1)
    pix = torch.randperm(40 * 40, generator=torch.Generator().manual_seed(0))[:300].sort().values
    part = aa.sample_fragments(mesh, cam, 3, jitter=jitter, seed=1, pixels=pix)
    assert torch.equal(part.face_id, full.face_id[pix])
    assert torch.equal(part.depth, full.depth[pix])
    assert torch.equal(part.bary, full.bary[pix])


def test_samples_are_watertight_on_shared_edges():
    """Two triangles sharing a diagonal: every sample is covered exactly once (no gaps, no double hits)."""
    mesh = tris([(0.3, 0.2), (7.7, 0.6), (0.1, 7.9)], [(7.7, 0.6), (7.6, 7.7), (0.1, 7.9)])
    cam = ortho_camera(8, 8)
    for k in (2, 3, 8):
        f = aa.sample_fragments(mesh, cam, k)
        both = rasterize(mesh, cam, samples=aa.regular_offsets(k))
        assert torch.equal(f.face_id, both.face_id)
    # a sample exactly on the shared edge: the edge from (0, 8) to (8, 0) passes through pixel corners
    mesh = tris([(0, 0), (8, 0), (0, 8)], [(8, 0), (8, 8), (0, 8)])
    f = rasterize(mesh, cam, samples=torch.tensor([[0.0, 0.0], [0.5, 0.5]]))
    assert (f.face_id >= 0).all()                                           # covered once, by one of the two


def test_sample_fragments_are_differentiable():
    mesh, cam = sphere_scene(12, 1)
    verts = mesh.verts.clone().requires_grad_(True)
    frags = rasterize(Mesh(verts, mesh.faces), cam, samples=aa.regular_offsets(2))
    loss = frags.depth[torch.isfinite(frags.depth)].sum() + frags.bary.sum()
    loss.backward()
    assert torch.isfinite(verts.grad).all() and verts.grad.abs().sum() > 0


def test_bad_sample_arguments_are_named():
    mesh, cam = sphere_scene(8, 0)
    with pytest.raises(ValueError, match="samples must have shape"):
        rasterize(mesh, cam, samples=torch.zeros(4, 3))
    with pytest.raises(ValueError, match=r"lie in \[0, 1\]"):
        rasterize(mesh, cam, samples=torch.tensor([[0.5, 1.5]]))
    with pytest.raises(ValueError, match="more than once"):
        rasterize(mesh, cam, pixels=torch.tensor([1, 1]))
    with pytest.raises(ValueError, match=r"pixel indices must lie"):
        rasterize(mesh, cam, pixels=torch.tensor([64]))
    with pytest.raises(ValueError, match=r"mask must have shape"):
        rasterize(mesh, cam, pixels=torch.ones(4, 4, dtype=torch.bool))
    with pytest.raises(ValueError, match="positive int"):
        aa.regular_offsets(0)
    with pytest.raises(ValueError, match=r"face_colors must have shape \(F, 3\)"):
        aa.supersample(mesh, cam, torch.ones(3), 2)


# ------------------------------------------------------------------------- the pixels a triangle touches

def _touches(tri, col, row, eps=1e-9):
    """Independent test: do the closed triangle and the closed square [col, col+1] x [row, row+1] meet?
    Separating axes: the two box axes and the three edge normals."""
    sq = torch.tensor([[col, row], [col + 1, row], [col + 1, row + 1], [col, row + 1]], dtype=torch.float64)
    axes = [torch.tensor([1.0, 0.0], dtype=torch.float64), torch.tensor([0.0, 1.0], dtype=torch.float64)]
    for k in range(3):
        e = tri[(k + 1) % 3] - tri[k]
        axes.append(torch.stack([-e[1], e[0]]))
    for ax in axes:
        a, b = tri @ ax, sq @ ax
        if a.max() < b.min() - eps or b.max() < a.min() - eps:
            return False
    return True


def test_pixel_triangle_pairs_finds_every_touched_pixel():
    g = torch.Generator().manual_seed(0)
    W = H = 9
    tri = torch.rand(40, 3, 2, generator=g, dtype=torch.float64) * 11 - 1
    tri[:8, 2] = tri[:8, 1] + 1e-3 * torch.randn(8, 2, generator=g, dtype=torch.float64)   # slivers
    tri[8:12] = tri[8:12, :1] + 0.3 * torch.rand(4, 3, 2, generator=g, dtype=torch.float64)   # tiny ones
    pixel, which = pixel_triangle_pairs(tri, W, H)
    listed = set(zip(pixel.tolist(), which.tolist()))
    for t in range(tri.shape[0]):
        for p in range(W * H):
            touch = _touches(tri[t], p % W, p // W, eps=-1e-7)             # clearly overlapping
            loose = _touches(tri[t], p % W, p // W, eps=1e-6)
            if touch:
                assert (p, t) in listed, f"triangle {t} misses pixel {p}"
            if (p, t) in listed:
                assert loose, f"triangle {t} lists pixel {p} it does not touch"


def test_pixel_triangle_pairs_respects_the_mask():
    tri = torch.tensor([[[0.2, 0.2], [7.8, 0.5], [3.0, 7.5]]], dtype=torch.float64)
    all_pix, _ = pixel_triangle_pairs(tri, 8, 8)
    mask = torch.zeros(64, dtype=torch.bool)
    mask[::3] = True
    some, _ = pixel_triangle_pairs(tri, 8, 8, mask)
    assert set(some.tolist()) == {p for p in all_pix.tolist() if p % 3 == 0}


# -------------------------------------------------------------------------------------- the detector

def test_detector_finds_slivers_that_miss_every_pixel_centre():
    """A sliver lying between two rows of centres and a small triangle between four centres: one sample
    per pixel sees neither, but their pixels are marked and adaptive sampling finds them."""
    sliver = [(0.6, 2.1), (7.4, 2.3), (7.4, 2.35)]                          # thin, y in [2.1, 2.35]
    small = [(5.6, 5.6), (5.9, 5.6), (5.7, 5.9)]                            # inside pixel (5, 5), off-centre
    mesh = tris(sliver, small)
    cam = ortho_camera(8, 8)
    assert (rasterize(mesh, cam).face_id < 0).all()                         # invisible at pixel centres
    marked = aa.discontinuity_pixels(mesh, cam)
    assert marked[2, 1:8].all() and marked[5, 5]
    colors = torch.tensor([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], dtype=torch.float64)
    full = aa.supersample(mesh, cam, colors, 8)
    adaptive, _ = aa.adaptive_supersample(mesh, cam, colors, 8)
    assert full.sum() > 0 and torch.equal(adaptive, full)


def test_detector_skips_edges_between_faces_of_one_colour():
    mesh, cam = sphere_scene(48)
    silhouette = aa.discontinuity_pixels(mesh, cam)
    every_edge = aa.discontinuity_pixels(mesh, cam, torch.arange(mesh.faces.shape[0]))
    assert silhouette.sum() < 0.5 * every_edge.sum()
    assert not silhouette[24, 24]                                           # the middle of the sphere


def test_detector_marks_intersection_lines():
    """Two triangles crossing in depth, same colour: the line where they cross is a visible jump
    between them only through their colours, but as a silhouette it is not; with two colours it is."""
    a = [(1, 1, 4.0), (7, 1, 4.0), (4, 7, 6.0)]
    b = [(1, 6, 4.0), (7, 6, 4.0), (4, 0.5, 6.0)]
    mesh = tris(a, b)
    cam = ortho_camera(8, 8)
    colors = torch.tensor([[1.0, 0, 0], [0, 0, 1.0]], dtype=torch.float64)
    full = aa.supersample(mesh, cam, colors, 4)
    adaptive, marked = aa.adaptive_supersample(mesh, cam, colors, 4)
    assert torch.equal(adaptive, full)
    inner = marked[2:5, 2:6]                                                # where the two overlap
    assert inner.any()


@pytest.mark.parametrize("k", [2, 3, 4])
@pytest.mark.parametrize("jitter", [False, True])
@pytest.mark.parametrize("scene", ["sphere", "two_spheres", "near_plane", "teapot"])
def test_adaptive_equals_full_supersampling_bit_for_bit(scene, jitter, k):
    g = torch.Generator().manual_seed(1)
    if scene == "sphere":
        mesh, cam = sphere_scene(40)
    elif scene == "two_spheres":
        mesh, cam = two_spheres(40)
    elif scene == "near_plane":                                             # the camera sits inside the sphere's skin
        mesh, cam = sphere_scene(32)
        R, t = look_at((0.0, 0.0, 1.05), (0.2, 0.1, 0.0))
        cam = Camera(cam.K, R, t, 32, 32, near=0.2)
    else:
        mesh = teapot(4, dtype=torch.float64)
        cam = frame_camera(mesh, width=40, height=32).to(dtype=torch.float64)
    F = mesh.faces.shape[0]
    for colors in (torch.ones(F, 3, dtype=torch.float64), torch.rand(F, 3, generator=g, dtype=torch.float64)):
        full_frags = aa.sample_fragments(mesh, cam, k, jitter=jitter, seed=2)
        full = aa.supersample(mesh, cam, colors, k, jitter=jitter, seed=2, background=(0.2, 0.3, 0.4))
        adaptive, marked = aa.adaptive_supersample(mesh, cam, colors, k, jitter=jitter, seed=2,
                                                   background=(0.2, 0.3, 0.4))
        assert torch.equal(adaptive, full), "pixel values differ"
        pix = marked.reshape(-1).nonzero().squeeze(1)
        part = aa.sample_fragments(mesh, cam, k, jitter=jitter, seed=2, pixels=pix)
        assert torch.equal(part.face_id, full_frags.face_id[pix]), "sample face ids differ"
        # on unmarked pixels every full sample sees one colour
        col = aa.flat_colors(full_frags.face_id, colors, torch.tensor([0.2, 0.3, 0.4], dtype=torch.float64))
        rest = ~marked.reshape(-1)
        assert (col[rest] == col[rest][:, :1]).all()
        assert marked.float().mean() < 0.9


def test_resolve_does_not_depend_on_the_batch():
    v = torch.rand(50, 9, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float32) * 1e3
    assert torch.equal(aa.resolve(v)[10:13], aa.resolve(v[10:13]))
    assert torch.allclose(aa.resolve(v), v.mean(1))


def test_supersampled_silhouette_edge_approaches_the_covered_area():
    """A half-plane edge through a pixel: k x k regular samples converge to its covered area as 1/k."""
    h = 4.0 * math.tan(math.radians(30))                                   # irrational slope, inside the image
    mesh = tris([(0.0, 0.0), (4.0, 0.0), (0.0, h)])
    cam = ortho_camera(4, 4)
    ones = torch.ones(1, 3, dtype=torch.float64)
    errs = []
    for k in (2, 4, 8, 16, 32):
        img = aa.supersample(mesh, cam, ones, k)[..., 0]
        errs.append(float((img.sum() - 0.5 * 4 * h).abs()))
    assert errs[-1] < errs[0] and errs[-1] < 0.05


# ------------------------------------------------------------------------------------------- in render()

def _render_scene(shading_lights=True):
    from course.render import Scene, default_lights
    mesh, cam = two_spheres(40)
    return Scene(mesh, cam, lights=default_lights() if shading_lights else (), background=(0.1, 0.2, 0.3))


@pytest.mark.parametrize("shading", ["silhouette", "flat"])
def test_render_adaptive_equals_supersample_on_piecewise_constant_images(shading):
    from course.render import RenderSettings, render
    sc = _render_scene()
    full = render(sc, RenderSettings(shading=shading, antialias="supersample", samples=4, return_silhouette=True))
    adaptive = render(sc, RenderSettings(shading=shading, antialias="adaptive", samples=4, return_silhouette=True))
    none = render(sc, RenderSettings(shading=shading))
    assert torch.equal(adaptive.image, full.image)
    assert torch.equal(adaptive.silhouette, full.silhouette)
    assert not torch.equal(none.image, full.image)                          # it did antialias
    edge = (full.silhouette > 0) & (full.silhouette < 1)                    # partly covered pixels
    assert edge.any() and "detect_edges" in adaptive.passes and "supersample" in adaptive.passes
    assert "detect_edges" not in full.passes and "supersample" in full.passes


def test_render_adaptive_skips_the_samples_when_no_edge_crosses_a_pixel():
    """A plane filling the whole view: no silhouette, no colour change; one sample per pixel is exact."""
    from course.models import plane
    from course.render import RenderSettings, Scene, render
    mesh = plane(40.0, 4, dtype=torch.float64)
    cam = Camera.look_at((0.0, 3.0, 0.0), (0.0, 0.0, 0.0), up=(0.0, 0.0, -1.0), fov_y=40.0, width=24,
                         height=16).to(dtype=torch.float64)
    sc = Scene(mesh, cam)
    r = render(sc, RenderSettings(shading="silhouette", antialias="adaptive"))
    assert "detect_edges" in r.passes and "supersample" not in r.passes
    assert torch.equal(r.image, render(sc, RenderSettings(shading="silhouette")).image)
    r_flat = render(sc, RenderSettings(shading="flat", antialias="adaptive"))  # every edge now counts
    assert "supersample" in r_flat.passes


def test_render_antialias_with_textures_gradients_and_bad_settings():
    from course.render import RenderSettings, Scene, default_lights, render
    mesh = teapot(4, dtype=torch.float64)
    cam = frame_camera(mesh, width=32, height=24).to(dtype=torch.float64)
    verts = mesh.verts.clone().requires_grad_(True)
    sc = Scene(Mesh(verts, mesh.faces, uvs=mesh.uvs, texture=mesh.texture), cam, lights=default_lights())
    for mode in ("supersample", "adaptive"):
        r = render(sc, RenderSettings(antialias=mode, samples=2, texture_filter="trilinear", jitter=True))
        assert r.image.shape == (24, 32, 3) and torch.isfinite(r.image).all()
        r.image.sum().backward()
        assert torch.isfinite(verts.grad).all() and verts.grad.abs().sum() > 0
        verts.grad = None
    with pytest.raises(ValueError, match="antialias must be one of"):
        RenderSettings(antialias="msaa")
    with pytest.raises(ValueError, match="samples"):
        RenderSettings(antialias="supersample", samples=0)


def test_intersection_with_a_huge_face_is_found():
    """A two-triangle plane far larger than the sphere's faces cuts through it: the intersection line is a
    jump the detector must mark (huge faces skip the grid and meet every box they overlap)."""
    from course.models import plane
    sphere = icosphere(2, dtype=torch.float64)
    ground = plane(50.0, 1, dtype=torch.float64)
    mesh = join_meshes([sphere, ground])
    cam = Camera.look_at((0.5, 1.2, 3.0), (0.0, 0.0, 0.0), fov_y=40.0, width=32, height=32).to(dtype=torch.float64)
    colors = torch.ones(mesh.faces.shape[0], 3, dtype=torch.float64)
    colors[sphere.faces.shape[0]:] = torch.tensor([0.2, 0.5, 0.9], dtype=torch.float64)
    full = aa.supersample(mesh, cam, colors, 4)
    adaptive, marked = aa.adaptive_supersample(mesh, cam, colors, 4)
    assert torch.equal(adaptive, full)
    from course import discontinuities as jumps
    f, g = jumps._intersecting_faces(mesh.verts, mesh.faces, jumps._weld(mesh.verts))
    big = mesh.faces.shape[0] - 2
    assert ((f >= big) | (g >= big)).all() and f.numel() > 8                # the plane against the sphere
    assert marked.float().mean() < 0.6                                      # the line, not the whole plane
