"""Visibility gradients (course.visibility): every method against the exact gradient of the box-filtered image."""
import math

import pytest
import torch

from course.camera import Camera
from course.mesh import Mesh, join_meshes
from course.models import icosphere
from course.visibility import PARAMETERS, image_gradient

ALL = ("verts", "R", "t", "focal", "colors")


def problem(kind="sphere", ortho=False, size=(32, 40), seed=0):
    """Scenes where the exact gradient exists (no vertex on a pixel border, no symmetric edge on one: the
    camera is off-axis), with flat random colours and random weights."""
    if kind == "sphere":
        mesh = icosphere(1, dtype=torch.float64)
    else:                                                                   # two spheres
        a, b = icosphere(2, dtype=torch.float64), icosphere(2, dtype=torch.float64)
        shift = torch.tensor([0.5, 0.3, 1.9 if kind == "occlusion" else 1.0], dtype=torch.float64)
        mesh = join_meshes([a, Mesh(b.verts * 0.6 + shift, b.faces)])      # "intersect": they cross
    H, W = size
    if ortho:
        cam = Camera.look_at((0.3, 0.4, 3.0), (0.0, 0.0, 0.0), ortho_height=3.0, width=W, height=H,
                             dtype=torch.float64)
    else:
        cam = Camera.look_at((0.3, 0.4, 3.0), (0.0, 0.0, 0.0), fov_y=50.0, width=W, height=H, dtype=torch.float64)
    g = torch.Generator().manual_seed(seed)
    colors = torch.rand(mesh.faces.shape[0], 3, generator=g, dtype=torch.float64)
    weights = torch.randn(H, W, 3, generator=g, dtype=torch.float64)
    return mesh, cam, colors, weights


def rel(a, b):
    return float((a - b).norm() / b.norm().clamp_min(1e-300))


@pytest.mark.parametrize("kind, ortho", [("sphere", False), ("occlusion", False), ("occlusion", True),
                                         ("intersect", False), ("intersect", True)])
def test_reynolds_equals_the_exact_gradient(kind, ortho):
    """Flat colours: the boundary integral is exact with one point per piece of edge once the pieces are cut
    where visibility can change (pixel borders, other edges, intersection lines), so the two agree to
    rounding (float64: 1e-12 leaves room for sums over thousands of terms)."""
    mesh, cam, colors, weights = problem(kind, ortho)
    exact = image_gradient(mesh, cam, colors, weights, method="exact", background=(0.2, 0.1, 0.3), wrt=ALL)
    reyn = image_gradient(mesh, cam, colors, weights, method="reynolds", background=(0.2, 0.1, 0.3), wrt=ALL)
    for name, x, y in zip(ALL, reyn, exact):
        assert y.abs().sum() > 0, name
        assert rel(x, y) < 1e-12, (name, rel(x, y))
    two = image_gradient(mesh, cam, colors, weights, method="reynolds", order=2, background=(0.2, 0.1, 0.3))
    assert rel(two, exact[0]) < 1e-12


@pytest.mark.parametrize("ortho", [False, True])
def test_affine_colours_need_two_points_per_piece(ortho):
    """Vertex colours interpolated affinely on screen: the interior term (autograd under fixed pieces) plus the
    boundary term, whose integrand (colour jump × normal speed) is a product of two linear functions along a
    piece of edge: exact with 2 Gauss points, not with 1 (the midpoint rule misses the quadratic part)."""
    mesh, cam, _, weights = problem("intersect", ortho)
    colors = torch.rand(mesh.verts.shape[0], 3, generator=torch.Generator().manual_seed(4), dtype=torch.float64)
    exact = image_gradient(mesh, cam, colors, weights, method="exact", model="affine", wrt=ALL)
    two = image_gradient(mesh, cam, colors, weights, method="reynolds", model="affine", order=2, wrt=ALL)
    one = image_gradient(mesh, cam, colors, weights, method="reynolds", model="affine", order=1)
    for name, x, y in zip(ALL, two, exact):
        assert y.abs().sum() > 0 and rel(x, y) < 1e-12, (name, rel(x, y))
    assert rel(one, exact[0]) > 1e-4
    fd = image_gradient(mesh, cam, colors, weights, method="finite_differences", model="affine", step=1e-6,
                        vertices=[3, 50, 300])
    assert rel(fd[[3, 50, 300]], exact[0][[3, 50, 300]]) < 1e-6
    es = image_gradient(mesh, cam, colors, weights, method="edge_sampling", model="affine", samples=4000)
    assert torch.isfinite(es).all() and float((es * exact[0]).sum()) > 0


def teapot_problem(size=20, resolution=3):
    """The Utah teapot, an open surface with every awkward configuration: the spout and handle pass into the
    body (intersection lines; faces of the spout whose edges are all shared still cross the body), the lid
    floats in the rim, and the poles and uv seams hold copies of one vertex a few ulps apart (the patches
    are evaluated separately). The vertices in the plane z = 0 are moved by ~1e-3 (seam copies together):
    there the spout's seam edge passes exactly through the body's, a degenerate point where the autograd of
    ``exact_coverage`` is off (~1e-4 of those vertices' gradients; central differences agree with Reynolds)."""
    from course.boundary import _weld
    from course.models import teapot
    mesh = teapot(resolution, dtype=torch.float64)
    weld = _weld(mesh.verts)
    g = torch.Generator().manual_seed(0)
    noise = 1e-3 * torch.randn(int(weld.max()) + 1, generator=g, dtype=torch.float64)[weld]
    verts = mesh.verts.clone()
    seam = verts[:, 2] == 0
    verts[seam, 2] += noise[seam]
    cam = Camera.look_at((2.6, 1.0, 1.35), fov_y=40.0, width=size, height=size, dtype=torch.float64)
    colors = torch.rand(mesh.faces.shape[0], 3, generator=g, dtype=torch.float64)
    weights = torch.randn(size, size, 3, generator=g, dtype=torch.float64)
    return Mesh(verts, mesh.faces), cam, colors, weights


def test_reynolds_equals_the_exact_gradient_on_the_teapot():
    """Regression: each of these once cost the teapot percents. (1) Positions a few ulps apart were two
    vertices, so the edges of a pole fan looked like an open crack, counted in full from both sides; (2) a
    face all of whose edges were merged into its neighbours' copies was left out of the intersection lines;
    (3) an intersection line ends on the edge of its face, and rounding put the crossing just outside it,
    so the edge was not cut where it passes under the other face; (4) on a piece of edge ~1e-5 px long next
    to a vertex, the z-buffer was asked 1e-6 px beside it, across a thin wedge of face. The gradients of the
    seam copies of a vertex are compared summed: they move together (each method may credit either copy)."""
    from course.discontinuities import _intersecting_faces
    from course.boundary import _weld
    mesh, cam, colors, weights = teapot_problem()
    weld = _weld(mesh.verts)
    distinct = lambda v: torch.unique(v, dim=0).shape[0]
    assert distinct(torch.round(mesh.verts * 1e6)) < distinct(mesh.verts)         # copies a few ulps apart
    assert _intersecting_faces(mesh.verts, mesh.faces, weld)[0].numel() > 0       # the spout crosses the body
    exact = image_gradient(mesh, cam, colors, weights, method="exact", background=(0.2, 0.1, 0.3), wrt=ALL)
    reyn = image_gradient(mesh, cam, colors, weights, method="reynolds", background=(0.2, 0.1, 0.3), wrt=ALL)
    welded = lambda g: torch.zeros(int(weld.max()) + 1, 3, dtype=g.dtype).index_add_(0, weld, g)
    assert rel(welded(reyn[0]), welded(exact[0])) < 1e-9, rel(welded(reyn[0]), welded(exact[0]))
    for name, x, y in zip(ALL[1:], reyn[1:], exact[1:]):
        assert y.abs().sum() > 0 and rel(x, y) < 1e-9, (name, rel(x, y))


def test_weld_merges_positions_a_few_ulps_apart_only():
    """One id per position up to ~1e-9 of the mesh's size, wherever the points sit on the welding grid (a
    pair straddling a cell border included); points 1e-6 apart stay two."""
    from course.boundary import _weld
    p = torch.tensor([0.3, 0.7, 0.1], dtype=torch.float64)
    q = torch.full((3,), 0.25, dtype=torch.float64)                         # on a border of the cells (h = 1e-9)
    verts = torch.stack([torch.zeros(3, dtype=torch.float64), torch.ones(3, dtype=torch.float64), p,
                         torch.nextafter(p, torch.ones(3, dtype=torch.float64)), p + 1e-6, q - 1e-13, q + 1e-13])
    w = _weld(verts)
    assert w[2] == w[3] and w[5] == w[6]
    assert len({int(w[k]) for k in (0, 1, 2, 4, 5)}) == 5
    assert torch.equal(_weld(verts[:1]), torch.zeros(1, dtype=torch.int64))


def test_back_faces_are_skipped_only_when_they_cannot_show():
    """A closed sphere seen from outside: back faces are skipped (they never show). Turned inside out, or with
    the camera inside, or opened up, the back faces show and are kept; Reynolds equals exact every time."""
    from course.boundary import _back_faces_hidden
    from course.visibility import _Problem
    sphere = icosphere(1, dtype=torch.float64)
    inverted = Mesh(sphere.verts, sphere.faces[:, [0, 2, 1]])
    opened = Mesh(sphere.verts, sphere.faces[1:])
    outside = Camera.look_at((0.3, 0.4, 3.0), (0.0, 0.0, 0.0), fov_y=50.0, width=24, height=20, dtype=torch.float64)
    inside = Camera.look_at((0.1, 0.05, 0.2), (0.5, 0.3, -1.0), fov_y=70.0, width=24, height=20, near=0.05,
                            dtype=torch.float64)
    g = torch.Generator().manual_seed(3)
    for mesh, cam, hidden in ((sphere, outside, True), (inverted, outside, False), (opened, outside, False),
                              (sphere, inside, False)):
        colors = torch.rand(mesh.faces.shape[0], 3, generator=g, dtype=torch.float64)
        weights = torch.randn(20, 24, 3, generator=g, dtype=torch.float64)
        prob = _Problem(mesh, cam, colors, weights, (0.0, 0.0, 0.0), "flat")
        assert _back_faces_hidden(prob, prob.weld) == hidden
        exact = image_gradient(mesh, cam, colors, weights, method="exact")
        reyn = image_gradient(mesh, cam, colors, weights, method="reynolds")
        assert exact.abs().sum() > 0 and rel(reyn, exact) < 1e-12, rel(reyn, exact)


def test_finite_differences_match_exact_and_their_step_trade_off():
    """Central differences: truncation error O(h²) for large h, round-off O(eps / h) for small h; in float64
    h = 1e-6 lands between the two (error ~1e-7 here), in float32 no step gets close."""
    mesh, cam, colors, weights = problem()
    exact = image_gradient(mesh, cam, colors, weights, method="exact")
    vertices = [0, 5, 11]
    sub = lambda g: g[vertices]
    fd = image_gradient(mesh, cam, colors, weights, method="finite_differences", step=1e-6, vertices=vertices)
    assert torch.isnan(fd[1]).all() and not torch.isnan(sub(fd)).any()   # the others: not computed
    assert rel(sub(fd), sub(exact)) < 1e-5
    big = image_gradient(mesh, cam, colors, weights, method="finite_differences", step=1e-2, vertices=vertices)
    assert rel(sub(big), sub(exact)) > 10 * rel(sub(fd), sub(exact))
    f32 = image_gradient(mesh, cam, colors, weights, method="finite_differences", step=1e-6, vertices=vertices,
                         dtype=torch.float32)
    assert rel(sub(f32).double(), sub(exact)) > 1e-2                      # round-off: eps32 / h ~ 0.1
    fwd = image_gradient(mesh, cam, colors, weights, method="finite_differences", step=1e-6, scheme="forward",
                         vertices=vertices)
    assert rel(sub(fwd), sub(exact)) < 1e-3
    t, = image_gradient(mesh, cam, colors, weights, method="finite_differences", step=1e-6, wrt=("t",))
    t_exact, = image_gradient(mesh, cam, colors, weights, method="exact", wrt=("t",))
    assert rel(t, t_exact) < 1e-5


def test_edge_sampling_is_unbiased_and_its_error_falls_like_one_over_sqrt_samples():
    """With a fixed seed per run: the mean over runs approaches the exact gradient, and the RMS error at 16x
    the samples is about 4x smaller (between 2.5x and 6.5x allows for the spread of 12 runs)."""
    mesh, cam, colors, weights = problem()
    exact = image_gradient(mesh, cam, colors, weights, method="exact")

    def runs(n, k=12):
        return torch.stack([image_gradient(mesh, cam, colors, weights, method="edge_sampling", samples=n, seed=s)
                            for s in range(k)])

    few, many = runs(500), runs(8000)
    rms = lambda g: float(((g - exact) ** 2).sum((1, 2)).mean().sqrt())
    ratio = rms(few) / rms(many)
    assert 2.5 < ratio < 6.5, ratio
    # unbiased: the mean of 12 runs is off by about the error of one run / sqrt(12); allow 2x that
    assert float((many.mean(0) - exact).norm()) < 2 * rms(many) / math.sqrt(12)
    again = image_gradient(mesh, cam, colors, weights, method="edge_sampling", samples=500, seed=0)
    assert torch.equal(again, few[0])                                      # seeded


def test_nmr_and_soft_give_finite_gradients_of_their_own_images():
    mesh, cam, colors, weights = problem()
    exact = image_gradient(mesh, cam, colors, weights, method="exact")
    for method, opts in (("nmr", {}), ("soft", dict(sigma=1e-4, gamma=1e-2))):
        g = image_gradient(mesh, cam, colors, weights, method=method, **opts)
        assert torch.isfinite(g).all() and g.abs().sum() > 0
        cos = float((g * exact).sum() / (g.norm() * exact.norm()))
        assert cos > 0.3, (method, cos)                                   # related, not equal


def test_degenerate_inputs_give_finite_gradients():
    """A zero-area face, an edge-on face, a vertex exactly on a pixel centre and one on a pixel corner, and a
    face crossing the near plane."""
    v = torch.tensor([[-0.5, -0.4, 0.0], [0.6, -0.3, 0.0], [0.0, 0.5, 0.0],        # an ordinary face
                      [0.1, 0.1, 0.2], [0.2, 0.2, 0.2], [0.3, 0.3, 0.2],           # zero area (collinear)
                      [0.0, -0.2, 0.1], [0.0, 0.3, 0.1], [0.0, 0.0, 0.6],          # edge-on (in x = 0)
                      [-0.3, 0.2, 2.7], [0.3, 0.25, 2.7], [0.0, -0.3, 3.5]],       # crosses the near plane
                     dtype=torch.float64)
    mesh = Mesh(v, torch.arange(12).view(4, 3))
    cam = Camera.look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov_y=50.0, width=16, height=16, near=0.5,
                         dtype=torch.float64)
    # move vertex 0 onto a pixel centre and vertex 1 onto a pixel corner
    for k, target in ((0, (4.5, 11.5)), (1, (12.0, 11.0))):
        xy, z = cam.project(v[k:k + 1])
        K = cam.K
        v[k, 0] += (target[0] - float(xy[0, 0])) * float(z[0]) / float(K[0, 0])
        v[k, 1] -= (target[1] - float(xy[0, 1])) * float(z[0]) / float(K[1, 1])
    mesh = Mesh(v, torch.arange(12).view(4, 3))
    g = torch.Generator().manual_seed(1)
    colors = torch.rand(4, 3, generator=g, dtype=torch.float64)
    weights = torch.randn(16, 16, 3, generator=g, dtype=torch.float64)
    for method, opts in (("exact", {}), ("reynolds", {}), ("edge_sampling", dict(samples=2000)),
                         ("finite_differences", dict(step=1e-6)), ("soft", {}), ("nmr", {})):
        out = image_gradient(mesh, cam, colors, weights, method=method, wrt=ALL, **opts)
        for name, x in zip(ALL, out):
            assert torch.isfinite(x).all(), (method, name)


def test_bad_inputs_are_named():
    mesh, cam, colors, weights = problem()
    with pytest.raises(ValueError, match="method"):
        image_gradient(mesh, cam, colors, weights, method="magic")
    with pytest.raises(ValueError, match="wrt"):
        image_gradient(mesh, cam, colors, weights, method="exact", wrt=("verts", "zoom"))
    with pytest.raises(ValueError, match="colors"):
        image_gradient(mesh, cam, colors[:-1], weights, method="exact")
    with pytest.raises(ValueError, match="weights"):
        image_gradient(mesh, cam, colors, weights[:-1], method="exact")
    with pytest.raises(ValueError, match="model"):
        image_gradient(mesh, cam, colors, weights, method="exact", model="smooth")
    with pytest.raises(ValueError, match="vertex"):
        image_gradient(mesh, cam, colors, weights, method="exact", model="affine")     # (F, 3) given
    with pytest.raises(ValueError, match="vertices"):
        image_gradient(mesh, cam, colors, weights, method="finite_differences", vertices=[10**6])
    with pytest.raises(ValueError, match="NaN"):
        image_gradient(mesh, cam, colors * math.nan, weights, method="exact")
    with pytest.raises(ValueError, match="scheme"):
        image_gradient(mesh, cam, colors, weights, method="finite_differences", scheme="sideways")
    with pytest.raises(TypeError, match="unexpected"):
        image_gradient(mesh, cam, colors, weights, method="reynolds", samples=10)
    assert PARAMETERS == ALL


@pytest.mark.parametrize("options, match", [
    (dict(method="reynolds", order=2.5), "order must be a positive integer"),  # was taken as 2
    (dict(method="reynolds", order=0), "order"), (dict(method="reynolds", order=-2), "order"),
    (dict(method="reynolds", order=True), "order"),
    (dict(method="exact", dtype="float"), "dtype"),                         # was a RuntimeError about devices
    (dict(method="exact", dtype=torch.int64), "dtype"),
    (dict(method="edge_sampling", samples=10.0), "samples"), (dict(method="edge_sampling", samples=0), "samples"),
    (dict(method="edge_sampling", seed="a"), "seed"), (dict(method="edge_sampling", generator=3), "generator"),
    (dict(method="finite_differences", step=0.0), "step"), (dict(method="finite_differences", step="1e-3"), "step"),
    (dict(method="finite_differences", vertices=[1.5]), "vertices"),
    (dict(method="exact", wrt="verts"), "wrt"), (dict(method="exact", wrt=("verts", "verts")), "wrt"),
    (dict(method=3), "method"),
])
def test_bad_options_are_refused_by_name(options, match):
    mesh, cam, colors, weights = problem(size=(8, 8))
    with pytest.raises((ValueError, TypeError), match=match):
        image_gradient(mesh, cam, colors, weights, **options)


@pytest.mark.parametrize("method", ["exact", "finite_differences", "reynolds", "edge_sampling", "reparameterization",
                                    "nmr", "soft"])
def test_a_mesh_without_faces_has_zero_gradient(method):
    """Nothing drawn, nothing to move: every method returns zeros of the right shapes (NMR used to raise an
    IndexError)."""

    class NoFaces:
        verts = torch.zeros(3, 3, dtype=torch.float64)
        faces = torch.zeros(0, 3, dtype=torch.int64)

    cam = Camera.look_at((0.3, 0.2, 3.0), (0.0, 0.0, 0.0), fov_y=40, width=8, height=8, dtype=torch.float64)
    grads = image_gradient(NoFaces(), cam, torch.zeros(0, 3), torch.ones(8, 8, 3), method=method, wrt=("verts", "t"))
    assert [tuple(g.shape) for g in grads] == [(3, 3), (3,)]
    assert all(float(g.abs().sum()) == 0 for g in grads)
