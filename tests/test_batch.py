"""Camera batches (one mesh, a list of N cameras): soft_rasterize, exact_coverage and the boundary gradient of
visibility.image_gradient render or differentiate every view in one call, and each view's result must be the
one its own call gives: images and gradients to rounding in float64, to float32's resolution in float32.
The scenes are small (spheres of 320 or 80 faces, three 20 x 16 views, one of them with the sphere through its
near plane) and the chunks are made tiny where they matter, so that a chunk or a group of triangles holds pairs of
several views: a term that leaked into another view's pixels would show."""
import pytest
import torch

from course import coverage, soft
from course.camera import Camera
from course.coverage import exact_coverage
from course.mesh import Mesh, join_meshes
from course.models import icosphere
from course.soft import soft_rasterize
from course.visibility import image_gradient

EYES = ((0.3, 0.4, 3.0), (2.5, -0.6, 1.2), (-0.3, 0.9, 1.0))   # the last: the sphere crosses its near plane


def cameras(dtype=torch.float64, eyes=EYES, width=20, height=16, far=10.0):
    return [Camera.look_at(eye, (0.0, 0.0, 0.0), fov_y=45.0, width=width, height=height, near=0.5, far=far,
                           dtype=dtype) for eye in eyes]


def sphere(dtype=torch.float64):
    return icosphere(2, dtype=dtype)


def rel(a, b):
    return float((a - b).norm() / b.norm().clamp_min(1e-300))


def test_the_scene_clips_one_view_at_its_near_plane():
    mesh, cams = sphere(), cameras()
    depth = [cam.to_camera(mesh.verts)[:, 2] for cam in cams]
    assert all(float(d.min()) > cams[0].near for d in depth[:2])
    assert float(depth[2].min()) < cams[0].near < float(depth[2].max())


# ------------------------------------------------------------------------------------------ soft_rasterize

def _soft_inputs(kind, dtype, gen):
    """The colour arguments of one kind of soft image, those that can take a gradient as leaves."""
    F, V = 320, 162
    rand = lambda *shape: torch.rand(*shape, generator=gen, dtype=torch.float64).to(dtype)   # noqa: E731
    if kind == "silhouette":
        return dict(mode="silhouette", sigma=1e-3), {}
    if kind in ("faces", "alpha"):
        leaves = dict(face_colors=rand(F, 3).requires_grad_())
        return dict(mode="color", sigma=1e-3, gamma=1e-2, background=(0.2, 0.4, 0.8),
                    blend="alpha" if kind == "alpha" else "softmax"), leaves
    if kind == "vertices":
        leaves = dict(vertex_colors=rand(V, 3).requires_grad_())
        return dict(mode="color", sigma=3e-4, gamma=1e-3, background=0.5), leaves
    leaves = dict(texture=rand(5, 4, 3).requires_grad_(), face_colors=rand(F, 3).requires_grad_(),
                  specular=(0.1 * rand(F, 3)).requires_grad_())
    return dict(mode="color", sigma=1e-3, gamma=1e-2, uvs=rand(V, 2), background=(0.0, 0.1, 0.2)), leaves


def _soft_both(kind, dtype, cull=False):
    """(one-by-one, batched): each the images (N, H, W[, C]) and the gradients of a weighted sum w.r.t. verts,
    the colour leaves and every camera's K, R and t."""
    gen = torch.Generator().manual_seed(2)
    mesh = sphere(dtype)
    options, leaves = _soft_inputs(kind, dtype, gen)
    out = []
    for batched in (False, True):
        verts = mesh.verts.clone().requires_grad_()
        poses = [[c.K.clone().requires_grad_(), c.R.clone().requires_grad_(), c.t.clone().requires_grad_()]
                 for c in cameras(dtype)]
        cams = [Camera(K, R, t, 20, 16, near=0.5, far=10.0) for K, R, t in poses]
        m = Mesh(verts, mesh.faces)
        kw = dict(options, cull_backfaces=cull, **leaves)
        image = soft_rasterize(m, cams, **kw) if batched else torch.stack([soft_rasterize(m, c, **kw) for c in cams])
        w = torch.randn(image.shape, generator=torch.Generator().manual_seed(5), dtype=torch.float64).to(dtype)
        wrt = [verts, *leaves.values(), *(x for pose in poses for x in pose)]
        out.append((image.detach(), torch.autograd.grad((w * image).sum(), wrt)))
    return out


@pytest.mark.parametrize("kind", ["silhouette", "faces", "alpha", "vertices", "texture"])
@pytest.mark.parametrize("cull", [False, True])
def test_soft_batch_equals_one_by_one_float64(kind, cull, monkeypatch):
    """Silhouettes, face and vertex colours, alpha blending, textures; with and without culling. CHUNK is tiny:
    groups of triangles, the pairs kept and the colour sums' chunks all mix several views."""
    monkeypatch.setattr(soft, "CHUNK", 300)
    (one, g_one), (batch, g_batch) = _soft_both(kind, torch.float64, cull)
    assert batch.shape[:3] == (3, 16, 20) and batch.shape == one.shape
    assert (one[2] != one[0]).any() and one.amax() > 0.5                   # three different, non-empty views
    assert torch.allclose(batch, one, rtol=0, atol=1e-12), float((batch - one).abs().max())
    assert all(b.abs().sum() > 0 for b in g_one[:-3])                     # culled, view 2 sees a hole: its K,
    for a, b in zip(g_batch, g_one):                                        # R and t may get none
        assert rel(a, b) < 1e-12, rel(a, b)


@pytest.mark.parametrize("kind", ["silhouette", "faces", "texture"])
def test_soft_batch_equals_one_by_one_float32(kind):
    (one, g_one), (batch, g_batch) = _soft_both(kind, torch.float32)
    assert batch.dtype == torch.float32
    # 32 float32 ulps at 1: the batched sums run in another order, and with another thread count (2.1e-6 seen)
    assert torch.allclose(batch, one, rtol=0, atol=32 * 2.0 ** -23), float((batch - one).abs().max())
    for a, b in zip(g_batch, g_one):
        assert a.dtype == torch.float32 and rel(a, b) < 1e-5, rel(a, b)


def test_soft_batch_gradients_reach_every_camera():
    """d/dR and d/dt of each view come from that view alone: a weight on view 1 only moves camera 1."""
    verts = sphere().verts.clone().requires_grad_()
    poses = [[c.R.clone().requires_grad_(), c.t.clone().requires_grad_()] for c in cameras()]
    cams = [Camera(c.K, R, t, 20, 16, near=0.5, far=10.0) for c, (R, t) in zip(cameras(), poses)]
    image = soft_rasterize(Mesh(verts, sphere().faces), cams, sigma=1e-3)
    grads = torch.autograd.grad(image[1].sum(), [verts] + [x for pose in poses for x in pose], allow_unused=True)
    assert grads[0].abs().sum() > 0
    assert [g is not None and g.abs().sum() > 0 for g in grads[1:]] == [False, False, True, True, False, False]


def test_one_camera_in_a_list_is_a_batch_of_one():
    mesh, cam = sphere(), cameras()[0]
    single = soft_rasterize(mesh, cam, sigma=1e-3)
    assert single.shape == (16, 20)
    assert torch.equal(soft_rasterize(mesh, [cam], sigma=1e-3), single[None])
    colors = torch.rand(320, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    image = exact_coverage(mesh, cam, colors)
    assert image.shape == (16, 20, 3) and torch.equal(exact_coverage(mesh, (cam,), colors), image[None])


# ------------------------------------------------------------------------------------------ exact_coverage

@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_exact_coverage_batch_equals_one_by_one(dtype, monkeypatch):
    """Images, and the gradients w.r.t. the colours and the vertices (the decisions then taken on the shifted
    copy), in chunks of 800 pairs (on an 80-face sphere the views plan 721, 758 and 485): the first two chunks
    hold the end of one view and the start of the next. Then colours of one key: quiet pixels in every view."""
    monkeypatch.setattr(coverage, "CHUNK", 800)
    mesh, cams = icosphere(1, dtype=dtype), cameras(dtype)
    colors = torch.rand(80, 3, generator=torch.Generator().manual_seed(1), dtype=dtype)
    w = torch.randn(3, 16, 20, 3, generator=torch.Generator().manual_seed(4), dtype=torch.float64).to(dtype)
    out = []
    for batched in (False, True):
        verts, c = mesh.verts.clone().requires_grad_(), colors.clone().requires_grad_()
        m = Mesh(verts, mesh.faces)
        image = exact_coverage(m, cams, c) if batched else torch.stack([exact_coverage(m, cam, c) for cam in cams])
        out.append((image.detach(), torch.autograd.grad((w * image).sum(), (verts, c))))
    (one, g_one), (batch, g_batch) = out
    tol = 1e-14 if dtype == torch.float64 else 1e-6
    assert batch.shape == (3, 16, 20, 3) and torch.allclose(batch, one, rtol=0, atol=tol)
    for a, b in zip(g_batch, g_one):
        assert b.abs().sum() > 0 and rel(a, b) < 100 * tol, rel(a, b)
    with torch.no_grad():                                                   # colours of one key: skipped pixels
        plain = torch.ones(80, 3, dtype=dtype) * torch.tensor([0.9, 0.5, 0.1], dtype=dtype)
        assert torch.allclose(exact_coverage(mesh, cams, plain, (0.2, 0.4, 0.8)),
                              torch.stack([exact_coverage(mesh, cam, plain, (0.2, 0.4, 0.8)) for cam in cams]),
                              rtol=0, atol=tol)


# ------------------------------------------------------------------------------------- boundary gradients

def crossing_spheres():
    """Two spheres that pass through each other: their intersection line is a boundary too."""
    a, b = icosphere(2, dtype=torch.float64), icosphere(1, dtype=torch.float64)
    return join_meshes([a, Mesh(b.verts * 0.6 + torch.tensor([0.5, 0.3, 0.9], dtype=torch.float64), b.faces)])


def _boundary_problem():
    mesh = crossing_spheres()
    gen = torch.Generator().manual_seed(3)
    colors = torch.rand(mesh.faces.shape[0], 3, generator=gen, dtype=torch.float64)
    weights = torch.randn(3, 16, 20, 3, generator=gen, dtype=torch.float64)
    return mesh, cameras(), colors, weights


def test_reynolds_batch_is_the_sum_of_the_views():
    mesh, cams, colors, weights = _boundary_problem()
    wrt = ("verts", "R", "t", "focal", "colors")
    batch = image_gradient(mesh, cams, colors, weights, method="reynolds", wrt=wrt)
    one = [image_gradient(mesh, c, colors, w, method="reynolds", wrt=wrt) for c, w in zip(cams, weights)]
    for k, name in enumerate(wrt):
        views = [o[k] for o in one]
        ref = sum(views) if name in ("verts", "colors") else torch.stack(views)
        assert batch[k].shape == ref.shape and ref.abs().sum() > 0
        assert rel(batch[k], ref) < 1e-10, (name, rel(batch[k], ref))
    verts_only = image_gradient(mesh, tuple(cams), colors, weights, method="reynolds")
    assert torch.equal(verts_only, batch[0])


def test_edge_sampling_batch_is_seeded_and_unbiased():
    """The batch draws ``samples`` points a view from one generator, view after view: exactly the sum of the
    calls per view that hand that generator on (each of them unbiased, ``tests/test_visibility.py``). Same seed,
    same gradient. And the mean over 16 seeds is Reynolds': M |mean - reynolds|² over the sum of the entries'
    variances is about 1 (chi-square-like; a bias of a few standard errors would put it far above 3)."""
    mesh, cams, colors, weights = _boundary_problem()
    run = lambda seed: image_gradient(mesh, cams, colors, weights, method="edge_sampling", samples=300,
                                      seed=seed)                            # noqa: E731
    first = run(0)
    assert torch.equal(first, run(0)) and not torch.equal(first, run(1))
    g = torch.Generator().manual_seed(0)
    views = [image_gradient(mesh, c, colors, w, method="edge_sampling", samples=300, generator=g)
             for c, w in zip(cams, weights)]
    assert rel(first, sum(views)) < 1e-12, rel(first, sum(views))
    reynolds = image_gradient(mesh, cams, colors, weights, method="reynolds")
    runs = torch.stack([first] + [run(seed) for seed in range(1, 16)])
    ratio = 16 * ((runs.mean(0) - reynolds) ** 2).sum() / runs.var(0).sum()
    assert 0.2 < float(ratio) < 3, float(ratio)


# ---------------------------------------------------------------------------------------------- refusals

def test_batches_that_cannot_be_one_call_are_refused():
    mesh, cams = sphere(), cameras()
    colors = torch.rand(320, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    small = cameras(width=12, height=16)[0]
    for call in (lambda c: soft_rasterize(mesh, c), lambda c: exact_coverage(mesh, c, colors),
                 lambda c: image_gradient(mesh, c, colors, torch.zeros(len(c), 16, 20, 3), method="reynolds")):
        with pytest.raises(ValueError, match=r"one image size: cameras\[0\] is 20x16, cameras\[3\] is 12x16"):
            call(cams + [small])
        with pytest.raises(ValueError, match="cameras is empty"):
            call([])
        with pytest.raises(TypeError, match=r"cameras\[1\] must be a course.camera.Camera"):
            call([cams[0], "camera"])
    far = cameras(far=20.0)[0]
    for call in (lambda: soft_rasterize(mesh, [cams[0], far]), lambda: exact_coverage(mesh, [cams[0], far], colors)):
        with pytest.raises(ValueError, match=r"must share far: cameras\[0\] has far=10.0, cameras\[1\] has far=20.0"):
            call()
    with pytest.raises(ValueError, match=r"weights must have shape \(N, H, W, 3\) = \(3, 16, 20, 3\)"):
        image_gradient(mesh, cams, colors, torch.zeros(16, 20, 3), method="reynolds")
    with pytest.raises(ValueError, match="a camera batch takes method 'reynolds' or 'edge_sampling'"):
        image_gradient(mesh, cams, colors, torch.zeros(3, 16, 20, 3), method="exact")
