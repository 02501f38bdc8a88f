"""The second image model (course.coverage_affine): vertex colours interpolated affinely in screen space,
box-filtered exactly. Checked against exact_coverage (equal vertex colours), dense supersampling of the
affine colour field, perspective-correct interpolation under an orthographic camera, and gradcheck."""
import pytest
import torch

from course.camera import Camera
from course.coverage import exact_coverage
from course.coverage_affine import (affine_color_at, affine_pieces, exact_affine_coverage, iter_affine_pieces,
                                    polygon_centroids)
from course.mesh import Mesh
from course.raster import interpolate, rasterize

D = torch.float64
BG = (0.2, 0.1, 0.3)


def scene(ortho=False, H=7, W=9, seed=0, shared=False):
    """Three triangles, each with its own vertices: a large one at the back, a smaller one in front of it
    (occlusion), and one passing through the large one (an intersection line), seen off-axis so that no
    vertex or edge sits on a pixel border. Random vertex colours in [0, 1]."""
    verts = torch.tensor([[-1.0, -0.9, 0.0], [1.1, -0.7, 0.05], [0.1, 1.0, -0.1],       # back
                          [-0.6, -0.3, 0.6], [0.3, -0.5, 0.5], [-0.3, 0.55, 0.7],        # in front
                          [0.05, 0.1, -0.6], [0.9, -0.2, 0.6], [0.45, 0.8, 0.4]], dtype=D)  # crosses the back one
    faces = torch.tensor([[0, 1, 2], [3, 4, 5], [6, 7, 8]])
    if ortho:
        cam = Camera.look_at((0.3, 0.4, 3.0), (0.02, 0.01, 0.0), ortho_height=2.0, width=W, height=H, dtype=D)
    else:
        cam = Camera.look_at((0.3, 0.4, 3.0), (0.02, 0.01, 0.0), fov_y=38.0, width=W, height=H, dtype=D)
    g = torch.Generator().manual_seed(seed)
    colors = torch.rand(verts.shape[0], 3, generator=g, dtype=D)
    return Mesh(verts, faces), cam, colors


def grid(n):
    """(n², 2) offsets of an n × n regular grid of sample points (cell midpoints) in the unit square."""
    s = (torch.arange(n, dtype=D) + 0.5) / n
    y, x = torch.meshgrid(s, s, indexing="ij")
    return torch.stack([x.reshape(-1), y.reshape(-1)], -1)


def supersample_affine(mesh, cam, colors, n, background=BG):
    """(H, W, C) the mean over n × n samples per pixel of the screen-affine colour of the visible face
    (face ids from the sample rasterizer, screen barycentrics computed here), background where none; and
    the sample fragments (H W, n²)."""
    H, W = cam.height, cam.width
    off = grid(n)
    frag = rasterize(mesh, cam, samples=off)                                # (H W, S)
    face = frag.face_id
    pix = torch.arange(H * W)[:, None]
    x, y = (pix % W) + off[None, :, 0], (pix // W) + off[None, :, 1]        # (P, S)
    xy, _ = cam.project(mesh.verts)
    hit = face >= 0
    tri = xy[mesh.faces[face[hit]]]                                         # (M, 3, 2)
    p = torch.stack([x[hit], y[hit]], -1)

    def cross(a, b):
        return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    a2 = cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    b1 = cross(p - tri[:, 0], tri[:, 2] - tri[:, 0]) / a2
    b2 = cross(tri[:, 1] - tri[:, 0], p - tri[:, 0]) / a2
    c = colors[mesh.faces[face[hit]]]
    value = torch.zeros(*face.shape, colors.shape[1], dtype=D)
    value[hit] = (1 - b1 - b2)[:, None] * c[:, 0] + b1[:, None] * c[:, 1] + b2[:, None] * c[:, 2]
    value[~hit] = torch.as_tensor(background, dtype=D)
    return value.mean(1).view(H, W, -1), frag


# ------------------------------------------------------------------------------------------- (1) flat case

@pytest.mark.parametrize("ortho", [False, True])
def test_equal_vertex_colours_give_exact_coverage(ortho):
    """Equal colours at a face's three vertices: the field is constant on the face, so the image is the
    flat model's; the centroid only enters through b1 (c1 - c0) + b2 (c2 - c0) = 0, so agreement is to rounding."""
    mesh, cam, _ = scene(ortho, H=12, W=15)
    face_colors = torch.rand(3, 3, generator=torch.Generator().manual_seed(1), dtype=D)
    vcol = face_colors.repeat_interleave(3, 0)                              # faces own vertices 3f..3f+2
    a = exact_affine_coverage(mesh, cam, vcol, BG)
    b = exact_coverage(mesh, cam, face_colors, BG)
    assert a.shape == (12, 15, 3) and a.dtype == D
    assert (a - b).abs().max() < 1e-12


# --------------------------------------------------------------------------------------- (2) supersampling

def test_matches_supersampling_and_error_shrinks_with_the_spacing():
    """Midpoint samples on an n × n grid integrate an affine field exactly within a cell; only the cells a
    discontinuity (an edge, an occlusion boundary, the intersection line) crosses are wrong, each by at most
    h² · |jump| with h = 1/n and |jump| <= 1 here (colours and background in [0, 1]). A straight segment
    inside a pixel (length <= √2) crosses at most |Δx|/h + |Δy|/h + 1 <= 2/h + 1 cells, so errs by at most
    2h + h². In this scene at most 3 triangle edges cross any one pixel, plus the intersection line: the
    error is at most 4 (2h + h²) < 9h per pixel and channel, asserted for n = 16, 32, 64 (the observed
    error is far smaller, ~4e-4 at n = 64: few cells are cut, and their errors partly cancel). The mean
    error must also fall with h: at least 1.6x per doubling (2x on average; regular grids alias, so the
    ratio of one doubling can stray)."""
    mesh, cam, colors = scene()
    exact = exact_affine_coverage(mesh, cam, colors, BG)
    errors = {}
    for n in (16, 32, 64):
        ref, frag = supersample_affine(mesh, cam, colors, n)
        err = (ref - exact).abs()
        assert err.max() < 9.0 / n, (n, float(err.max()))
        errors[n] = float(err.mean())
    assert errors[16] > 1.6 * errors[32] > 1.6 ** 2 * errors[64], errors
    # a pixel whose samples all see one face (no discontinuity): the midpoint rule is exact, so rounding
    one = frag.face_id
    one = ((one == one[:, :1]).all(1) & (one[:, 0] >= 0)).view(cam.height, cam.width)
    assert one.any() and err.amax(-1)[one].amin() < 1e-12
    # and the model is not perspective-correct: supersampled ``interpolate`` (1/z weights) is far off
    val = interpolate(colors, frag, mesh.faces)
    val = torch.where(frag.face_id[..., None] >= 0, val, torch.tensor(BG, dtype=D)).mean(1).view_as(exact)
    assert (val - exact).abs().max() > 20 * err.max()


# ----------------------------------------------------------------------------------- (3) orthographic

def test_orthographic_equals_perspective_correct_interpolation():
    """Under an orthographic camera depth does not divide, so ``interpolate`` (perspective-correct) gives the
    screen-affine colour: its supersampled mean converges to the exact image with the same O(h) bound as
    above (9h per pixel). Includes a face crossing the near plane (allowed orthographically: clipped, still exact)."""
    mesh, cam, colors = scene(ortho=True)
    n = 64
    frag = rasterize(mesh, cam, samples=grid(n))
    val = interpolate(colors, frag, mesh.faces)                             # (P, S, 3)
    val = torch.where(frag.face_id[..., None] >= 0, val, torch.tensor(BG, dtype=D))
    ref = val.mean(1).view(cam.height, cam.width, 3)
    exact = exact_affine_coverage(mesh, cam, colors, BG)
    assert (ref - exact).abs().max() < 9.0 / n
    assert (ref - exact).abs().mean() < 0.5 / n
    # the near plane through a face: z_cam of the third face spans [2.4, 3.6] here; put near at 3.0
    near_cam = Camera(cam.K, cam.R, cam.t, cam.width, cam.height, near=3.0, far=100.0, orthographic=True)
    frag = rasterize(mesh, near_cam, samples=grid(n))
    assert (frag.face_id >= 0).any()
    val = interpolate(colors, frag, mesh.faces)
    val = torch.where(frag.face_id[..., None] >= 0, val, torch.tensor(BG, dtype=D))
    exact = exact_affine_coverage(mesh, near_cam, colors, BG)
    assert (val.mean(1).view(cam.height, cam.width, 3) - exact).abs().max() < 9.0 / n


def test_float32_and_pieces_helper():
    """float32 keeps its dtype and agrees with float64 to float32 rounding; the pieces helper reproduces the
    image as Σ area · affine_color_at(centroid)."""
    mesh, cam, colors = scene()
    exact = exact_affine_coverage(mesh, cam, colors, BG)
    m32 = Mesh(mesh.verts.float(), mesh.faces)
    c32 = Camera(cam.K.float(), cam.R.float(), cam.t.float(), cam.width, cam.height)
    img32 = exact_affine_coverage(m32, c32, colors.float(), BG)
    assert img32.dtype == torch.float32 and (img32.double() - exact).abs().max() < 1e-5
    p = affine_pieces(mesh, cam)
    assert sum(q.pixel.numel() for q in iter_affine_pieces(mesh, cam)) == p.pixel.numel()
    col = affine_color_at(mesh, cam, colors, p.face, p.centroid, pixel=p.pixel)
    col2 = affine_color_at(mesh, cam, colors, p.face, p.image_centroid(cam.width))
    assert (col - col2).abs().max() < 1e-12
    img = torch.zeros(cam.height * cam.width, 3, dtype=D).index_add(0, p.pixel, p.area[:, None] * col)
    cov = torch.zeros(cam.height * cam.width, dtype=D).index_add(0, p.pixel, p.area)
    img = img + (1 - cov)[:, None] * torch.tensor(BG, dtype=D)
    assert (img.view_as(exact) - exact).abs().max() < 1e-12


def test_polygon_centroids():
    """The unit square, a triangle, a padded triangle, and a degenerate (collinear) polygon: the vertex mean."""
    poly = torch.tensor([[[0, 0], [1, 0], [1, 1], [0, 1]],
                         [[0, 0], [0.9, 0], [0, 0.6], [0, 0.6]],
                         [[0.1, 0.1], [0.5, 0.5], [0.9, 0.9], [0.9, 0.9]]], dtype=D, requires_grad=True)
    c = polygon_centroids(poly, torch.tensor([4, 3, 3]))
    expect = torch.tensor([[0.5, 0.5], [0.3, 0.2], [0.5, 0.5]], dtype=D)
    assert (c - expect).abs().max() < 1e-15
    c.sum().backward()
    assert torch.isfinite(poly.grad).all()


# ------------------------------------------------------------------------------------------ (4) gradcheck

def test_gradcheck():
    """Float64 gradcheck w.r.t. the vertex colours, three vertex positions (one per face) and the camera's t
    at a generic configuration: no vertex within 1e-3 px of a pixel border, so a 1e-6 step never changes
    the arrangement of pieces and the image is smooth (rational) there."""
    mesh, cam, colors = scene(H=6, W=7)
    xy, _ = cam.project(mesh.verts)
    frac = xy - xy.floor()
    assert ((frac > 1e-3) & (frac < 1 - 1e-3)).all()
    idx = torch.tensor([1, 3, 8])
    faces = mesh.faces

    def f(moved, vcol, t):
        verts = mesh.verts.index_put((idx,), moved)
        camera = Camera(cam.K, cam.R, t, cam.width, cam.height)
        return exact_affine_coverage(Mesh(verts, faces), camera, vcol, BG)

    moved, vcol, t = (x.clone().requires_grad_() for x in (mesh.verts[idx], colors, cam.t))
    # every entry of the Jacobian w.r.t. positions and t; all three inputs in fast mode (a random projection)
    assert torch.autograd.gradcheck(lambda m, t: f(m, colors, t), (moved, t), eps=1e-6, atol=1e-6, rtol=1e-5)
    assert torch.autograd.gradcheck(f, (moved, vcol, t), eps=1e-6, atol=1e-6, rtol=1e-5, fast_mode=True)


# --------------------------------------------------------------------------------- (5) degenerate faces

def test_degenerate_faces_have_finite_values_and_gradients():
    """A zero-area face (collinear vertices), a face with a repeated vertex, an edge-on face (its plane holds
    the eye), and a sliver, beside a normal one: the image and every gradient stay finite."""
    mesh, cam, colors = scene(H=6, W=7)
    eye = -cam.R.T @ cam.t
    extra = torch.stack([
        torch.tensor([-0.5, -0.5, 0.3], dtype=D), torch.tensor([0.0, 0.0, 0.3], dtype=D),
        torch.tensor([0.5, 0.5, 0.3], dtype=D),                                          # collinear
        torch.tensor([0.2, -0.4, 0.8], dtype=D), torch.tensor([0.2, -0.4, 0.8], dtype=D),
        torch.tensor([-0.3, 0.4, 0.8], dtype=D),                                         # repeated vertex
        torch.tensor([-0.4, 0.2, 0.2], dtype=D), torch.tensor([0.6, -0.1, 0.2], dtype=D),
        0.5 * (torch.tensor([-0.4, 0.2, 0.2], dtype=D) + eye),                           # edge-on
        torch.tensor([-0.7, -0.6, 0.9], dtype=D), torch.tensor([0.7, 0.6, 0.9], dtype=D),
        torch.tensor([0.7, 0.6 + 1e-9, 0.9], dtype=D) + 1e-9,                            # a sliver
    ])
    verts = torch.cat([mesh.verts, extra]).requires_grad_()
    faces = torch.cat([mesh.faces, 9 + torch.arange(12).view(4, 3)])
    vcol = torch.rand(verts.shape[0], 3, generator=torch.Generator().manual_seed(3), dtype=D).requires_grad_()
    pieces = affine_pieces(Mesh(verts, faces), cam)
    assert (pieces.face == 6).any() and pieces.area[pieces.face == 6].max() < 1e-6   # the sliver is visible
    img = exact_affine_coverage(Mesh(verts, faces), cam, vcol, BG)
    assert torch.isfinite(img).all()
    (img * torch.randn(img.shape, generator=torch.Generator().manual_seed(4), dtype=D)).sum().backward()
    assert torch.isfinite(verts.grad).all() and torch.isfinite(vcol.grad).all()
    assert verts.grad[:9].abs().sum() > 0


# ----------------------------------------------------------------------------------------- (6) bad inputs

def test_bad_inputs_raise_clear_errors():
    mesh, cam, colors = scene()
    with pytest.raises(ValueError, match=r"vertex_colors must have shape \(V, C\)"):
        exact_affine_coverage(mesh, cam, colors[:, 0])
    with pytest.raises(ValueError, match=r"V = 9"):
        exact_affine_coverage(mesh, cam, colors[:5])
    bad = colors.clone()
    bad[2, 1] = float("nan")
    with pytest.raises(ValueError, match="vertex_colors contains NaN"):
        exact_affine_coverage(mesh, cam, bad)
    with pytest.raises(ValueError, match=r"background must have shape \(C,\)"):
        exact_affine_coverage(mesh, cam, colors, (0.0, 0.0))
    with pytest.raises(ValueError, match="background contains NaN"):
        exact_affine_coverage(mesh, cam, colors, (0.0, float("nan"), 0.0))
    verts = mesh.verts.clone()
    verts[0, 0] = float("inf")
    with pytest.raises(ValueError, match="NaN or inf"):
        exact_affine_coverage(Mesh(verts, mesh.faces), cam, colors)
    with pytest.raises(ValueError, match="points"):
        affine_color_at(mesh, cam, colors, torch.tensor([0, 1]), torch.zeros(3, 2, dtype=D))
    with pytest.raises(ValueError, match="face ids"):
        affine_color_at(mesh, cam, colors, torch.tensor([0, 3]), torch.zeros(2, 2, dtype=D))
    # one channel, scalar background
    grey = exact_affine_coverage(mesh, cam, colors[:, :1], 0.5)
    assert grey.shape == (cam.height, cam.width, 1)


def test_near_plane_crossing():
    """Perspective: a visible face crossing the near plane raises, naming the problem; the same face hidden
    or outside the image does not."""
    mesh, cam, colors = scene()
    z = cam.to_camera(mesh.verts)[:, 2]
    near = 2.7                      # through the third face only (the second lies wholly before it: clipped away)
    assert z[:3].min() > near and z[3:6].max() < near and z[6:9].min() < near < z[6:9].max()
    near_cam = Camera(cam.K, cam.R, cam.t, cam.width, cam.height, near=near)
    with pytest.raises(ValueError, match="face 2 is visible and crosses the near plane"):
        exact_affine_coverage(mesh, near_cam, colors)
    with pytest.raises(ValueError, match="crosses the near plane"):
        affine_color_at(mesh, near_cam, colors, torch.tensor([2]), torch.zeros(1, 2, dtype=D))
    # the face moved out of view sideways: no visible piece, no error, and the other faces are unchanged
    verts = mesh.verts.clone()
    verts[6:9, 0] += 20.0
    img = exact_affine_coverage(Mesh(verts, mesh.faces), near_cam, colors, BG)
    ref = exact_affine_coverage(Mesh(mesh.verts[:6], mesh.faces[:2]), near_cam, colors[:6], BG)
    assert torch.isfinite(img).all() and (img - ref).abs().max() < 1e-14
