"""Soft rasterization and NMR's approximate gradient: a dense oracle, gradcheck, the hard limit, the rule by
hand, and stress cases (extreme σ and γ, degenerate triangles, the near plane)."""
import math

import pytest
import torch

from course.camera import Camera
from course.mesh import Mesh
from course.models import icosphere
from course.raster import rasterize
from course.nmr import nmr_image, nmr_rasterize
from course.soft import soft_rasterize


def ortho8(width=8, height=8, dtype=torch.float64):
    """One world unit per pixel, world (0, 0) at the image centre, looking down -z."""
    return Camera.look_at((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), ortho_height=height, width=width, height=height,
                          dtype=dtype)


def screen_mesh(points_xy, faces, z=0.0, size=8, dtype=torch.float64):
    """A mesh given in the screen coordinates of ``ortho8`` (x right, y down); z: world z (toward the eye)."""
    zs = z if isinstance(z, (list, tuple)) else [z] * len(points_xy)
    return Mesh(torch.tensor([[x - size / 2, size / 2 - y, zz] for (x, y), zz in zip(points_xy, zs)],
                             dtype=dtype), faces)


def persp(size=12, dtype=torch.float64, eye=(0.3, -0.2, 3.0)):
    return Camera.look_at(eye, (0.0, 0.0, 0.0), fov_y=40.0, width=size, height=size, near=0.5, far=10.0,
                          dtype=dtype)


def two_triangles(dtype=torch.float64):
    """Two overlapping triangles at different depths (the second nearer the camera at z = +3)."""
    verts = torch.tensor([[-0.8, -0.6, 0.0], [0.7, -0.5, 0.1], [-0.1, 0.8, -0.1],
                          [-0.2, -0.7, 0.5], [0.9, 0.2, 0.4], [0.1, 0.6, 0.6]], dtype=dtype)
    return Mesh(verts, torch.tensor([[0, 1, 2], [3, 4, 5]]))


def small_sphere(dtype=torch.float32):
    return icosphere(1, radius=1.0, dtype=dtype)


# ------------------------------------------------------------------------------------- a dense oracle

def dense_soft(mesh, camera, sigma, gamma, eps=1e-3, face_colors=None, vertex_colors=None, bg=0.0, cut=None,
               z_of="inverse"):
    """The paper's formulas for every (pixel, face), no culling, float64: the reference soft_rasterize
    must match (faces all in front of the near plane, no back-face culling). cut: None, or drop the pairs
    with D < cut (the absolute cut-off); z_of: "inverse" or "linear" depth (z = (far - depth) / (far - near))."""
    W, H = camera.width, camera.height
    xy, depth = camera.project(mesh.verts)
    tri = xy[mesh.faces].double()                                          # (F, 3, 2)
    q = (depth if camera.orthographic else 1 / depth)[mesh.faces].double()
    ys, xs = torch.meshgrid(torch.arange(H) + 0.5, torch.arange(W) + 0.5, indexing="ij")
    p = torch.stack([xs.flatten(), ys.flatten()], 1).double()[:, None, :]  # (P, 1, 2)
    d2, cross = [], []
    for k in range(3):
        a, b = tri[None, :, k], tri[None, :, (k + 1) % 3]                  # (1, F, 2)
        e, w = b - a, p - a
        t = ((w * e).sum(-1) / (e * e).sum(-1)).clamp(0, 1)
        d2.append(((w - t[..., None] * e) ** 2).sum(-1))
        cross.append(e[..., 0] * w[..., 1] - e[..., 1] * w[..., 0])        # (P, F)
    d2 = torch.stack(d2).amin(0)
    area = sum(cross)
    bary = torch.stack([cross[1], cross[2], cross[0]], -1) / area[..., None]
    inside = (bary > 0).all(-1)
    x = torch.where(inside, d2, -d2) / (sigma * W * W / 4)                 # d_ndc = 2 d_px / W
    D = torch.sigmoid(x)
    if cut is not None:
        D = torch.where(D < cut, 0.0, D)
    if face_colors is None and vertex_colors is None:
        return (1 - (1 - D).prod(1)).view(H, W)
    b = bary.clamp(0, 1)
    b = b / b.sum(-1, keepdim=True)
    qp = (b * q[None]).sum(-1)
    n, f = camera.near, camera.far
    if camera.orthographic or z_of == "linear":
        z = (f - (qp if camera.orthographic else 1 / qp)) / (f - n)
    else:
        z = (qp - 1 / f) / (1 / n - 1 / f)
    w = D * torch.exp(z / gamma)                                           # (P, F): fine for moderate γ
    w_bg = math.exp(eps / gamma)
    if face_colors is not None:
        c = face_colors.double()[None].expand(w.shape[0], -1, -1)         # (P, F, C)
    else:
        pc = b if camera.orthographic else b * q[None]
        pc = pc / pc.sum(-1, keepdim=True)
        c = (pc[..., None] * vertex_colors.double()[mesh.faces][None]).sum(2)
    img = ((w[..., None] * c).sum(1) + w_bg * bg) / (w.sum(1) + w_bg)[:, None]
    return img.view(H, W, -1)


@pytest.mark.parametrize("camera", [persp(), ortho8(12, 10)], ids=["perspective", "orthographic"])
def test_matches_the_dense_formulas(camera):
    mesh = two_triangles() if not camera.orthographic else screen_mesh(
        [(1.3, 1.2), (10.1, 2.4), (2.2, 8.7), (5.5, 0.5), (11.0, 9.0), (3.0, 6.0)], [[0, 1, 2], [3, 4, 5]],
        z=[0.0, 0.0, 0.0, 1.0, 1.5, 1.2])
    fc = torch.tensor([[0.9, 0.2, 0.1], [0.1, 0.3, 0.8]], dtype=torch.float64)
    vc = torch.rand(6, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    kw = dict(sigma=3e-3, threshold=1e-14, cull_backfaces=False)
    sil = soft_rasterize(mesh, camera, **kw)
    assert torch.allclose(sil, dense_soft(mesh, camera, 3e-3, 1.0), atol=1e-10)
    for gamma in (0.05, 0.5):
        img = soft_rasterize(mesh, camera, mode="color", gamma=gamma, face_colors=fc, background=0.25, **kw)
        ref = dense_soft(mesh, camera, 3e-3, gamma, face_colors=fc, bg=0.25)
        assert torch.allclose(img, ref, atol=1e-10)
        img = soft_rasterize(mesh, camera, mode="color", gamma=gamma, vertex_colors=vc, **kw)
        assert torch.allclose(img, dense_soft(mesh, camera, 3e-3, gamma, vertex_colors=vc), atol=1e-10)


@pytest.mark.parametrize("camera", [persp(), ortho8(12, 10)], ids=["perspective", "orthographic"])
def test_the_absolute_cutoff_drops_exactly_the_pairs_below_the_threshold(camera):
    """cutoff="absolute" (the reference SoftRas code's): the dense formulas with every D < threshold set to 0,
    in silhouette and colour modes; unlike the relative cut-off, it changes the image at tiny γ."""
    mesh = two_triangles() if not camera.orthographic else screen_mesh(
        [(1.3, 1.2), (10.1, 2.4), (2.2, 8.7), (5.5, 0.5), (11.0, 9.0), (3.0, 6.0)], [[0, 1, 2], [3, 4, 5]],
        z=[0.0, 0.0, 0.0, 1.0, 1.5, 1.2])
    fc = torch.tensor([[0.9, 0.2, 0.1], [0.1, 0.3, 0.8]], dtype=torch.float64)
    sigma, thr = 3e-2, 1e-2
    kw = dict(sigma=sigma, threshold=thr, cull_backfaces=False, cutoff="absolute")
    sil = soft_rasterize(mesh, camera, **kw)
    assert torch.allclose(sil, dense_soft(mesh, camera, sigma, 1.0, cut=thr), atol=1e-12)
    assert not torch.allclose(sil, dense_soft(mesh, camera, sigma, 1.0), atol=1e-4)   # some pairs are cut
    for gamma in (0.5, 1e-2):
        img = soft_rasterize(mesh, camera, mode="color", gamma=gamma, face_colors=fc, background=0.25, **kw)
        assert torch.allclose(img, dense_soft(mesh, camera, sigma, gamma, face_colors=fc, bg=0.25, cut=thr),
                              atol=1e-12)
    rel = soft_rasterize(mesh, camera, mode="color", gamma=1e-2, face_colors=fc, background=0.25,
                         **dict(kw, cutoff="relative"))
    assert (rel - img).abs().max() > 0.1                                   # the relative cut keeps the far pairs


@pytest.mark.parametrize("vertex", [False, True], ids=["face colours", "vertex colours"])
def test_linear_depth_matches_the_dense_formulas(vertex):
    """depth="linear": z = (far - depth) / (far - near) with the perspective-correct depth at the pixel, as in
    the reference SoftRas code and PyTorch3D; it differs from the default inverse depth."""
    mesh, camera = two_triangles(), persp()
    colours = dict(vertex_colors=torch.rand(6, 3, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
                   ) if vertex else dict(face_colors=torch.tensor([[0.9, 0.2, 0.1], [0.1, 0.3, 0.8]],
                                                                  dtype=torch.float64))
    for gamma in (0.05, 0.005):
        img = soft_rasterize(mesh, camera, mode="color", sigma=3e-3, gamma=gamma, threshold=1e-14,
                             cull_backfaces=False, depth="linear", **colours)
        ref = dense_soft(mesh, camera, 3e-3, gamma, z_of="linear", **colours)
        assert torch.allclose(img, ref, atol=1e-10)
        inverse = dense_soft(mesh, camera, 3e-3, gamma, **colours)
        assert (img - inverse).abs().max() > 1e-3
    cut = soft_rasterize(mesh, camera, mode="color", sigma=3e-3, gamma=0.005, threshold=1e-3, cull_backfaces=False,
                         depth="linear", cutoff="absolute", **colours)
    assert torch.allclose(cut, dense_soft(mesh, camera, 3e-3, 0.005, z_of="linear", cut=1e-3, **colours),
                          atol=1e-12)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("cutoff, depth", [("absolute", "inverse"), ("relative", "linear"), ("absolute", "linear")])
def test_the_reference_options_give_finite_gradients(dtype, cutoff, depth):
    mesh, camera = small_sphere(dtype), persp(24, dtype=dtype)
    verts = mesh.verts.clone().requires_grad_()
    colours = torch.rand(mesh.faces.shape[0], 3, generator=torch.Generator().manual_seed(3), dtype=dtype)
    for mode, kw in (("silhouette", {}), ("color", dict(face_colors=colours, gamma=1e-4))):
        image = soft_rasterize(Mesh(verts, mesh.faces), camera, mode=mode, sigma=1e-3, cutoff=cutoff, depth=depth,
                               **kw)
        grad, = torch.autograd.grad((image * torch.linspace(-1, 1, image.numel(), dtype=dtype).view(image.shape)).sum(),
                                    verts)
        assert torch.isfinite(image).all() and torch.isfinite(grad).all() and grad.abs().sum() > 0


def test_culling_error_stays_bounded_as_gamma_shrinks():
    """The culled image differs from the uncut one by at most about threshold per face, at any γ, because
    culling weighs the sigmoid with its softmax factor (a sigmoid-only cull would lose the nearer face)."""
    mesh, camera = two_triangles(), persp(16)
    fc = torch.tensor([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], dtype=torch.float64)
    for gamma in (1e-1, 1e-3, 1e-5):
        kw = dict(mode="color", sigma=1e-3, gamma=gamma, face_colors=fc, cull_backfaces=False)
        full = soft_rasterize(mesh, camera, threshold=1e-15, **kw)
        cut = soft_rasterize(mesh, camera, threshold=1e-4, **kw)
        assert (full - cut).abs().max() <= 3e-4


# ------------------------------------------------------------------------------------------ gradcheck

def _edge_gap(mesh, camera):
    """Where gradcheck could meet a kink: the smallest distance from a pixel centre to an edge (the sign
    flips there), and, for centres inside a face, the smallest gap between the distances to its nearest and
    second-nearest edges (the min switches there: the medial axis). Outside a face the distance to it is
    smooth (C¹), so ties between two edges meeting at the nearest vertex are no kink."""
    xy, _ = camera.project(mesh.verts.detach())
    tri = xy[mesh.faces]
    W, H = camera.width, camera.height
    ys, xs = torch.meshgrid(torch.arange(H) + 0.5, torch.arange(W) + 0.5, indexing="ij")
    p = torch.stack([xs.flatten(), ys.flatten()], 1).double()[:, None, :]
    d, cross = [], []
    for k in range(3):
        a, b = tri[None, :, k], tri[None, :, (k + 1) % 3]
        e, w = b - a, p - a
        t = ((w * e).sum(-1) / (e * e).sum(-1)).clamp(0, 1)
        d.append(((w - t[..., None] * e) ** 2).sum(-1).sqrt())
        cross.append(e[..., 0] * w[..., 1] - e[..., 1] * w[..., 0])
    area = sum(cross)
    inside = torch.stack([c * area > 0 for c in cross]).all(0)             # (P, F)
    d = torch.stack(d, -1).sort(-1).values                                 # (P, F, 3)
    return float((d[..., 1] - d[..., 0])[inside].min()), float(d[..., 0].min())


@pytest.mark.parametrize("mode", ["silhouette", "face colours", "vertex colours"])
def test_gradcheck_at_smooth_points(mode):
    """float64 gradcheck w.r.t. verts, colours, K, R and t. The points are smooth: the threshold is tiny
    (1e-20, so the cut is far below gradcheck's tolerance), and the asserts below check that no pixel centre
    lies within 1e-3 px of an edge or of a tie between two edges (the kinks of distance-to-triangle)."""
    cam = persp(7)
    mesh = two_triangles()
    gap, nearest = _edge_gap(mesh, cam)
    assert gap > 1e-3 and nearest > 1e-3
    n = 2 if mode == "face colours" else 6
    colors = torch.rand(n, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)

    def f(verts, colors, K, R, t):
        camera = Camera(K, R, t, 7, 7, near=0.5, far=10.0)
        kw = dict(sigma=2e-2, threshold=1e-20, cull_backfaces=False)
        if mode == "silhouette":
            return soft_rasterize(Mesh(verts, mesh.faces), camera, **kw)
        key = "face_colors" if mode == "face colours" else "vertex_colors"
        return soft_rasterize(Mesh(verts, mesh.faces), camera, mode="color", gamma=0.1, **{key: colors}, **kw)

    args = [x.clone().requires_grad_() for x in (mesh.verts, colors, cam.K, cam.R, cam.t)]
    assert torch.autograd.gradcheck(f, args, atol=1e-7, rtol=1e-5)


# --------------------------------------------------------------------------------------- stress cases

@pytest.mark.parametrize("sigma", [1e-7, 1e-2])
@pytest.mark.parametrize("gamma", [1e-5, 1.0])
def test_float32_extremes_are_finite(sigma, gamma):
    mesh, cam = small_sphere(), persp(24, torch.float32, eye=(0.0, 0.0, 3.0))
    verts = mesh.verts.clone().requires_grad_()
    K = cam.K.clone().requires_grad_()
    camera = Camera(K, cam.R, cam.t, 24, 24, near=0.5, far=10.0)
    fc = torch.rand(mesh.faces.shape[0], 3, generator=torch.Generator().manual_seed(2)).requires_grad_()
    w = torch.randn(24, 24, 3, generator=torch.Generator().manual_seed(3))
    sil = soft_rasterize(Mesh(verts, mesh.faces), camera, sigma=sigma)
    img = soft_rasterize(Mesh(verts, mesh.faces), camera, mode="color", sigma=sigma, gamma=gamma, face_colors=fc)
    assert sil.dtype == img.dtype == torch.float32
    assert torch.isfinite(sil).all() and torch.isfinite(img).all()
    assert sil.min() >= 0 and sil.max() <= 1 and img.min() >= 0 and img.max() <= 1 + 1e-6
    ((sil[..., None] * w).sum() + (img * w).sum()).backward()
    for g in (verts.grad, K.grad, fc.grad):
        assert torch.isfinite(g).all()
    assert verts.grad.abs().sum() > 0


def _finite_grads(mesh, camera, **kw):
    verts = mesh.verts.clone().requires_grad_()
    m = Mesh(verts, mesh.faces)
    w = torch.randn(camera.height, camera.width, generator=torch.Generator().manual_seed(4), dtype=verts.dtype)
    total = (soft_rasterize(m, camera, cull_backfaces=False, **kw) * w).sum()
    fc = torch.ones(mesh.faces.shape[0], 3, dtype=verts.dtype)
    total = total + (soft_rasterize(m, camera, mode="color", face_colors=fc, gamma=1e-3, cull_backfaces=False,
                                    **kw) * w[..., None]).sum()
    total = total + (nmr_rasterize(m, camera, cull_backfaces=False) * w).sum()
    total.backward()
    assert torch.isfinite(total) and torch.isfinite(verts.grad).all()
    return verts.grad


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_degenerate_and_special_triangles_give_finite_gradients(dtype):
    cam = ortho8(dtype=dtype)
    cases = {
        "collinear": [(1.0, 1.0), (4.0, 4.0), (7.0, 7.0)],
        "point": [(3.3, 3.3)] * 3,
        "on pixel centres": [(1.5, 1.5), (6.5, 1.5), (1.5, 6.5)],
        "on pixel corners": [(1.0, 1.0), (6.0, 1.0), (1.0, 6.0)],
        "sliver": [(1.0, 1.0), (7.0, 1.0 + 1e-6), (4.0, 1.0)],
    }
    for name, pts in cases.items():
        _finite_grads(screen_mesh(pts, [[0, 1, 2]], dtype=dtype), cam, sigma=1e-3)
    # edge-on: a perspective camera looking along the triangle's plane
    edge_on = Mesh(torch.tensor([[-1.0, 0.0, -1.0], [1.0, 0.0, -1.0], [0.0, 0.0, 1.0]], dtype=dtype), [[0, 1, 2]])
    cam = Camera.look_at((0.0, 0.0, 4.0), (0.0, 0.0, 0.0), fov_y=40.0, width=8, height=8, dtype=dtype)
    _finite_grads(edge_on, cam, sigma=1e-3)


def test_triangles_crossing_the_near_plane():
    """Clipped at the near plane (z = 0.5), not dropped: the visible part shows, gradients stay finite,
    also for a vertex exactly in the camera's plane (z = 0) of a face behind the camera."""
    cam = persp(12, eye=(0.0, 0.0, 3.0))
    mesh = Mesh(torch.tensor([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 0.5, 3.5],       # crosses
                              [-0.5, 0.5, 4.0], [0.5, 0.5, 4.0], [0.0, 1.0, 3.0]],        # behind the camera
                             dtype=torch.float64), [[0, 1, 2], [3, 4, 5]])
    grad = _finite_grads(mesh, cam, sigma=1e-3)
    assert grad[:3].abs().sum() > 0 and grad[3:].abs().sum() == 0
    sil = soft_rasterize(mesh, cam, sigma=1e-5, cull_backfaces=False)
    hard = rasterize(mesh, cam).mask.double()
    assert (sil - hard).abs().mean() < 0.05


# ------------------------------------------------------------------------------------ limits of σ and γ

def _far_from_edges(mesh, camera, margin=1.0):
    """(H, W) bool: pixel centres farther than ``margin`` pixels from every projected edge."""
    xy, _ = camera.project(mesh.verts.detach())
    tri = xy[mesh.faces].double()
    W, H = camera.width, camera.height
    ys, xs = torch.meshgrid(torch.arange(H) + 0.5, torch.arange(W) + 0.5, indexing="ij")
    p = torch.stack([xs.flatten(), ys.flatten()], 1).double()[:, None, :]
    far = torch.ones(H * W, dtype=torch.bool)
    for k in range(3):
        a, b = tri[None, :, k], tri[None, :, (k + 1) % 3]
        e, w = b - a, p - a
        t = ((w * e).sum(-1) / (e * e).sum(-1)).clamp(0, 1)
        far &= (((w - t[..., None] * e) ** 2).sum(-1) > margin ** 2).all(1)
    return far.view(H, W)


@pytest.mark.parametrize("camera", [persp(24), ortho8(24, 24)], ids=["perspective", "orthographic"])
def test_hard_limit_along_sigma_equal_gamma_squared(camera):
    """With σ = γ² → 0 the colour image tends to the hard rasterizer's at pixels farther than one pixel
    from every edge; the measured error shrinks and ends below 1e-6."""
    mesh = two_triangles()
    if camera.orthographic:
        mesh = Mesh(mesh.verts * torch.tensor([10.0, 10.0, 1.0], dtype=torch.float64), mesh.faces)
    fc = torch.tensor([[0.9, 0.2, 0.1], [0.1, 0.3, 0.8]], dtype=torch.float64)
    frags = rasterize(mesh, camera)
    hard = torch.where(frags.mask[..., None], fc[frags.face_id.clamp(min=0)], torch.zeros(3, dtype=torch.float64))
    far = _far_from_edges(mesh, camera)
    assert far.sum() > 100 and frags.mask[far].any() and (~frags.mask[far]).any()
    errors = []
    for gamma in (3e-2, 3e-3, 3e-4):
        img = soft_rasterize(mesh, camera, mode="color", sigma=gamma ** 2, gamma=gamma, face_colors=fc,
                             cull_backfaces=False)
        errors.append(float((img - hard)[far].abs().max()))
    assert errors[0] > errors[1] > errors[2] and errors[2] < 1e-6, errors


def test_tiny_gamma_fattens_the_silhouette():
    """At fixed σ, a tiny γ lets a face several pixels outside a pixel outweigh the background."""
    cam = ortho8(16, 16)
    mesh = screen_mesh([(4.0, 4.0), (12.0, 4.0), (4.0, 12.0)], [[0, 1, 2]], z=1.0, size=16)
    fc = torch.ones(1, 3, dtype=torch.float64)
    probe = (12, 12)                                                       # centre (12.5, 12.5): 5.3 px outside
    colours = [float(soft_rasterize(mesh, cam, mode="color", sigma=1e-3, gamma=g, face_colors=fc,
                                    cull_backfaces=False)[probe][0]) for g in (1e-1, 1e-2, 1e-5)]
    assert colours[0] < 1e-3 and colours[2] > 0.99, colours
    sil = soft_rasterize(mesh, cam, sigma=1e-3, cull_backfaces=False)
    assert sil[probe] < 1e-3                                               # the silhouette has no γ


# ----------------------------------------------------------------------------------- NMR by hand

def _nmr_grad(mesh, camera, d_image, **kw):
    verts = mesh.verts.clone().requires_grad_()
    img = nmr_rasterize(Mesh(verts, mesh.faces), camera, cull_backfaces=False, **kw)
    img.backward(d_image)
    return img.detach(), verts.grad


def test_nmr_gradient_by_hand():
    """One triangle on an 8×8 orthographic grid (screen x = world x + 4, screen y = 4 - world y). Screen
    vertices v0 = (1, 1), v1 = (7, 1), v2 = (1, 7): the hypotenuse v1→v2 is x + y = 8."""
    cam = ortho8()
    mesh = screen_mesh([(1.0, 1.0), (7.0, 1.0), (1.0, 7.0)], [[0, 1, 2]])
    sil, _ = _nmr_grad(mesh, cam, torch.zeros(8, 8))
    # Pixel (row 2, col 6): centre (6.5, 2.5), outside (6.5 + 2.5 = 9 > 8), silhouette 0.
    assert sil[2, 6] == 0 and sil[2, 2] == 1
    d = torch.zeros(8, 8)
    d[2, 6] = -1.0                                                         # the loss wants the pixel covered
    _, g = _nmr_grad(mesh, cam, d)
    # Row y = 2.5 crosses the hypotenuse at x = 5.5; the pixel is δ = 1 to the right. Weight of v1 on the
    # edge at that row: s1 = (2.5 - 7) / (1 - 7) = 0.75, of v2: 0.25. Moving v1 right by δ/s1 = 4/3 covers
    # the pixel, δI = +1: ∂L/∂x1 = δᴾ δI / δx = -1 / (4/3) = -0.75; v2: -1 / (1 / 0.25) = -0.25.
    # Column x = 6.5 crosses the hypotenuse at y = 1.5, δ = 1 downward: s1 = (6.5 - 1) / (7 - 1) = 11/12,
    # s2 = 1/12: ∂L/∂y1 = -11/12 and ∂L/∂y2 = -1/12 (screen y); world y = 4 - screen y flips the sign.
    expected = torch.tensor([[0.0, 0.0, 0.0], [-0.75, 11 / 12, 0.0], [-0.25, 1 / 12, 0.0]], dtype=torch.float64)
    assert torch.allclose(g, expected, atol=1e-12)
    # the sign rule: δᴾ δI >= 0 gives nothing (covering the pixel would raise the loss)
    _, g = _nmr_grad(mesh, cam, -d)
    assert g.abs().max() == 0


def test_nmr_inside_pixel_sums_both_directions():
    """Pixel (row 2, col 2), centre (2.5, 2.5), inside; δᴾ = +1: the loss wants it uncovered (δI = -1).
    Row 2.5 is bounded by the left edge v2→v0 at x = 1 (δ = 1.5) and the hypotenuse at x = 5.5 (δ = -3);
    column 2.5 by v0→v1 at y = 1 (δ = 1.5) and the hypotenuse at y = 5.5 (δ = -3)."""
    cam = ortho8()
    mesh = screen_mesh([(1.0, 1.0), (7.0, 1.0), (1.0, 7.0)], [[0, 1, 2]])
    d = torch.zeros(8, 8)
    d[2, 2] = 1.0
    _, g = _nmr_grad(mesh, cam, d)
    # left edge v2→v0 at row 2.5: s0 = (2.5 - 7) / (1 - 7) = 0.75, s2 = 0.25; the edge moves +x by 1.5:
    #   ∂L/∂x0 = -1 / (1.5 / 0.75) = -0.5, ∂L/∂x2 = -1 / (1.5 / 0.25) = -1/6
    # hypotenuse at row 2.5 (s1 = 0.75, s2 = 0.25), moves -x by 3: ∂L/∂x1 = -1 / (-3 / 0.75) = +0.25,
    #   ∂L/∂x2 += +1/12;  so x: v0 -0.5, v1 +0.25, v2 -1/6 + 1/12 = -1/12
    # column 2.5: the top edge v0→v1 at y = 1 (s0 = 0.75, s1 = 0.25, δ = +1.5): ∂L/∂y0 = -0.5, ∂L/∂y1 = -1/6;
    #   the hypotenuse at y = 5.5 (s1 = 0.25, s2 = 0.75, δ = -3): ∂L/∂y1 += +1/12, ∂L/∂y2 = +0.25;
    #   so screen y: v0 -0.5, v1 -1/12, v2 +0.25, and world y = 4 - screen y flips the sign
    expected = torch.tensor([[-0.5, 0.5, 0.0], [0.25, 1 / 12, 0.0], [-1 / 12, -0.25, 0.0]], dtype=torch.float64)
    assert torch.allclose(g, expected, atol=1e-12)


def test_nmr_floor_reach_and_nonlinearity():
    cam = ortho8()
    thin = screen_mesh([(1.0, 1.0), (7.3, 1.0), (1.0, 7.3)], [[0, 1, 2]])   # hypotenuse x + y = 8.3
    d = torch.zeros(8, 8)
    d[2, 5] = 1.0                                       # centre (5.5, 2.5), inside, 0.3 px from the hypotenuse
    # row 2.5: v1's weight s1 = 4.8 / 6.3, the edge must move by δ = -0.3, so v1 by δ / s1 = -0.39 px:
    # floored at min_step = 0.5, ∂L/∂x1 = δᴾ δI / δx = (1)(-1) / (-0.5) = 2; with min_step = 0.1, s1 / 0.3
    assert float(_nmr_grad(thin, cam, d)[1][1, 0]) == pytest.approx(2.0, abs=1e-12)
    assert float(_nmr_grad(thin, cam, d, min_step=0.1)[1][1, 0]) == pytest.approx(4.8 / 6.3 / 0.3, abs=1e-12)
    mesh = screen_mesh([(1.0, 1.0), (7.0, 1.0), (1.0, 7.0)], [[0, 1, 2]])
    far = torch.zeros(8, 8)
    far[2, 0] = -1.0                                    # centre 0.5 px left of the left edge x = 1
    _, g_near = _nmr_grad(mesh, cam, far, reach=1.0)
    _, g_none = _nmr_grad(mesh, cam, far, reach=0.25)
    assert g_near.abs().sum() > 0 and g_none.abs().sum() == 0
    # not linear: the sign rule keeps a term for g1 and drops it for g1 + g2 when they cancel its sign
    g1, g2 = torch.zeros(8, 8), torch.zeros(8, 8)
    g1[2, 6], g2[2, 6] = -1.0, 2.0
    a = _nmr_grad(mesh, cam, g1)[1] + _nmr_grad(mesh, cam, g2)[1]
    b = _nmr_grad(mesh, cam, g1 + g2)[1]
    assert not torch.allclose(a, b)


def test_nmr_colour_and_occlusion():
    """Colour mode: δI is the face colour minus what the pixel shows; a face behind the visible surface
    gets no covering gradient there."""
    cam = ortho8()
    mesh = screen_mesh([(1.0, 1.0), (5.0, 1.0), (1.0, 5.0), (4.0, 0.0), (8.0, 0.0), (8.0, 8.0)],
                       [[0, 2, 1], [3, 5, 4]], z=[0.0, 0.0, 0.0, 1.0, 1.0, 1.0])   # the second is nearer
    fc = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)
    verts = mesh.verts.clone().requires_grad_()
    colors = fc.clone().requires_grad_()
    img = nmr_rasterize(Mesh(verts, mesh.faces), cam, face_colors=colors, cull_backfaces=False)
    assert torch.equal(img[2, 1], fc[0]) and torch.equal(img[1, 6], fc[1]) and torch.equal(img[7, 0], torch.zeros(3))
    d = torch.zeros(8, 8, 3, dtype=torch.float64)
    d[1, 5, 0] = -1.0                                   # wants red at (5.5, 1.5), which shows the nearer blue face
    img.backward(d)
    assert verts.grad[:3].abs().sum() == 0             # red is behind blue there: no covering gradient
    assert colors.grad[1, 0] == -1.0                    # the colour's own gradient passes through


# ------------------------------------------------------------------------------- camera and input checks

@pytest.mark.parametrize("method", ["soft", "nmr"])
@pytest.mark.parametrize("orthographic", [False, True])
def test_gradients_reach_the_camera(method, orthographic):
    mesh = small_sphere(torch.float64)
    base = ortho8(16, 16) if orthographic else persp(16, eye=(0.0, 0.0, 3.0))
    if orthographic:
        base = Camera.look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), ortho_height=3.0, width=16, height=16,
                              dtype=torch.float64)
    K, R, t = (x.clone().requires_grad_() for x in (base.K, base.R, base.t))
    cam = Camera(K, R, t, 16, 16, near=base.near, far=base.far, orthographic=orthographic)
    target = torch.zeros(16, 16, dtype=torch.float64)
    target[4:12, 5:13] = 1.0
    img = soft_rasterize(mesh, cam, sigma=1e-3) if method == "soft" else nmr_rasterize(mesh, cam)
    ((img - target) ** 2).sum().backward()
    for g in (K.grad, R.grad, t.grad):
        assert torch.isfinite(g).all() and g.abs().sum() > 0
    assert K.grad[0, 0] != 0                                                # the focal length


def test_dtype_is_kept():
    mesh, cam = small_sphere(torch.float64), persp(8, eye=(0.0, 0.0, 3.0))
    assert soft_rasterize(mesh, cam).dtype == torch.float64
    assert nmr_rasterize(mesh, cam).dtype == torch.float64


def test_bad_input_raises_clear_errors():
    mesh, cam = small_sphere(), persp(8, torch.float32, eye=(0.0, 0.0, 3.0))
    F, V = mesh.faces.shape[0], mesh.verts.shape[0]
    cases = [
        (dict(sigma=0.0), "sigma"), (dict(sigma=-1.0), "sigma"), (dict(gamma=float("nan")), "gamma"),
        (dict(threshold=0.0), "threshold"), (dict(threshold=1.0), "threshold"), (dict(mode="rgb"), "mode"),
        (dict(mode="color"), "exactly one"),
        (dict(mode="color", face_colors=torch.ones(F + 1, 3)), "face_colors"),
        (dict(mode="color", vertex_colors=torch.ones(V, 3), face_colors=torch.ones(F, 3)), "exactly one"),
        (dict(mode="color", vertex_colors=torch.ones(V - 1, 3)), "vertex_colors"), (dict(eps=2.0), "eps"),
    ]
    for kw, match in cases:
        with pytest.raises(ValueError, match=match):
            soft_rasterize(mesh, cam, **kw)
    with pytest.raises(ValueError, match="verts"):
        soft_rasterize(type("NotAMesh", (), {"verts": torch.ones(3, 2), "faces": mesh.faces})(), cam)
    with pytest.raises(ValueError, match="face_colors"):
        nmr_rasterize(mesh, cam, face_colors=torch.ones(F - 1, 3))
    with pytest.raises(ValueError, match="min_step"):
        nmr_rasterize(mesh, cam, min_step=0.0)
    with pytest.raises(ValueError, match="image"):
        nmr_image(torch.zeros(8, 7, 1), mesh, cam, torch.zeros(8, 8, dtype=torch.int64))


def test_bench_soft_rows():
    from course.bench.soft import bench_soft, format_table
    rows = bench_soft(sizes=(16,), sigmas=(1e-3,), thresholds=(1e-4,), gammas=(1e-2,), repeat=1, out=lambda s: None)
    assert [(r["image"], r["method"]) for r in rows] == [(i, m) for i in ("silhouette", "shaded")
                                                         for m in ("hard", "NMR", "soft")]
    hard, nmr = rows[0], rows[1]
    assert hard["rmse"] == nmr["rmse"] > 0                                  # the same forward image
    assert all(r["fwd_ms"] > 0 and r["fwd_bwd_ms"] > 0 for r in rows)
    assert "soft" in format_table(rows)


# --------------------------------------------------------------------- chunked work: the same results

def _soft_grads(mesh, camera, mode, cull, **kw):
    """The image and the gradients of a fixed loss w.r.t. verts (and the colours in colour mode)."""
    verts = mesh.verts.clone().requires_grad_()
    fc = torch.rand(mesh.faces.shape[0], 3, generator=torch.Generator().manual_seed(5),
                    dtype=torch.float64).requires_grad_()
    w = torch.randn(camera.height, camera.width, 3, generator=torch.Generator().manual_seed(6), dtype=torch.float64)
    if mode == "silhouette":
        img = soft_rasterize(Mesh(verts, mesh.faces), camera, cull_backfaces=cull, **kw)
        (img * w[..., 0]).sum().backward()
        return img.detach(), verts.grad, None
    img = soft_rasterize(Mesh(verts, mesh.faces), camera, mode="color", face_colors=fc, cull_backfaces=cull, **kw)
    (img * w).sum().backward()
    return img.detach(), verts.grad, fc.grad


@pytest.mark.parametrize("mode", ["silhouette", "color"])
@pytest.mark.parametrize("cull", [True, False])
def test_soft_chunks_change_nothing_but_rounding(monkeypatch, mode, cull):
    """CHUNK bounds the pairs built at once (candidates per group of faces, kept pairs per checkpoint); a tiny
    CHUNK (hundreds of groups, the survivors pruned many times) gives the same image and gradients as one
    chunk, which is the unchunked computation."""
    import course.soft as soft
    mesh, cam = icosphere(2, dtype=torch.float64), persp(32, eye=(0.3, 0.4, 2.6))
    kw = dict(sigma=1e-3, gamma=1e-3)
    monkeypatch.setattr(soft, "CHUNK", 1 << 30)
    whole = _soft_grads(mesh, cam, mode, cull, **kw)
    monkeypatch.setattr(soft, "CHUNK", 500)
    xy, _, _, _ = soft._screen_faces(mesh.verts, mesh.faces, cam, cull)
    radius = torch.full((xy.shape[0],), 2.0, dtype=torch.float64)
    assert len(soft._triangle_groups(xy.double(), radius, 32, 32)) > 10    # many groups really
    chunked = _soft_grads(mesh, cam, mode, cull, **kw)
    for a, b in zip(whole, chunked):
        if a is not None:
            assert torch.allclose(a, b, rtol=1e-12, atol=1e-12 * float(a.abs().max()))


def test_color_pairs_keep_exactly_the_pairs_that_matter(monkeypatch):
    """The pairs kept group by group (against the best weight so far, pruned on the way) are exactly those
    that pass the threshold against the final per-pixel best, computed here from all candidates at once."""
    import course.soft as soft
    mesh, cam = icosphere(2, dtype=torch.float64), persp(32, eye=(0.3, 0.4, 2.6))
    xy, q, _, _ = soft._screen_faces(mesh.verts, mesh.faces, cam, False)
    near = soft._nearness(q.double(), cam)
    gamma, eps, s = 1e-3, 1e-3, 4.0 / (32 * 32 * 1e-3)
    radius = ((math.log(1e4) + (near.amax(1) - eps).clamp(min=0) / gamma) / s).sqrt()
    pixel, tri = soft._candidate_pairs(xy.double(), radius, 32, 32)        # every candidate, at once
    x, b = soft._pair_terms(xy, tri, pixel, 32, s)
    nt = near[tri]
    log_w = torch.nn.functional.logsigmoid(x) + (b[0] * nt[:, 0] + b[1] * nt[:, 1] + b[2] * nt[:, 2]) / gamma
    top = torch.full((32 * 32,), eps / gamma, dtype=torch.float64).scatter_reduce(0, pixel, log_w, "amax")
    keep = log_w - top[pixel] >= math.log(1e-4)
    monkeypatch.setattr(soft, "CHUNK", 400)                                 # many groups, pruned on the way
    got = soft._color_pairs(xy, near, radius, 32, 32, s, gamma, eps, math.log(1e-4))
    assert torch.equal(got[0], pixel[keep]) and torch.equal(got[1], tri[keep]) and torch.equal(got[2], top)
    assert keep.sum() < pixel.numel() / 3                                  # most candidates are dropped


def _nmr_grads(mesh, camera, *, colour, image_colours=False, **kw):
    """The gradient w.r.t. verts (and K) of a fixed loss through nmr_rasterize (or nmr_image with vertex colours
    and no face_values: the covering colour then comes from the image)."""
    verts = mesh.verts.clone().requires_grad_()
    K = camera.K.clone().requires_grad_()
    cam = Camera(K, camera.R, camera.t, camera.width, camera.height, near=camera.near, far=camera.far,
                 orthographic=camera.orthographic)
    m = Mesh(verts, mesh.faces)
    gen = torch.Generator().manual_seed(7)
    w = torch.randn(camera.height, camera.width, 3, generator=gen, dtype=torch.float64)
    if image_colours:
        vc = torch.rand(mesh.verts.shape[0], 3, generator=gen, dtype=torch.float64)
        frags = rasterize(m, cam, cull_backfaces=kw.get("cull_backfaces", True))
        from course.raster import interpolate
        image = torch.where(frags.mask[..., None], interpolate(vc, frags, mesh.faces), torch.zeros(3).double())
        img = nmr_image(image, m, cam, frags.face_id, background=0.3, **kw)
        (img * w).sum().backward()
    elif colour:
        fc = torch.rand(mesh.faces.shape[0], 3, generator=gen, dtype=torch.float64)
        (nmr_rasterize(m, cam, face_colors=fc, background=(0.1, 0.2, 0.3), **kw) * w).sum().backward()
    else:
        (nmr_rasterize(m, cam, **kw) * w[..., 0]).sum().backward()
    return verts.grad, K.grad


@pytest.mark.parametrize("camera", [persp(40, eye=(0.3, 0.4, 2.6)), "ortho"], ids=["perspective", "orthographic"])
@pytest.mark.parametrize("kind", ["silhouette", "face colours", "image colours"])
@pytest.mark.parametrize("cull", [True, False])
def test_nmr_row_tables_agree_with_the_pixel_by_pixel_rule(monkeypatch, camera, kind, cull):
    """NMR's backward visits the pixels far beyond a span as per-row tables (ROW_TABLES) and the others pixel
    by pixel, CHUNK at a time. Forcing every pixel through the pixel-by-pixel rule in one chunk (the
    unchunked computation) or through tables and tiny chunks gives the same gradients, for reach None and a
    finite reach the tables clip."""
    import course.nmr as nmr
    if camera == "ortho":
        camera = Camera.look_at((0.3, 0.4, 3.0), (0.0, 0.0, 0.0), ortho_height=2.6, width=40, height=40,
                                dtype=torch.float64)
    mesh = icosphere(2, dtype=torch.float64)
    mesh = Mesh(mesh.verts * torch.tensor([1.0, 0.8, 1.1], dtype=torch.float64), mesh.faces)
    kw = dict(colour=kind == "face colours", image_colours=kind == "image colours", cull_backfaces=cull)
    for reach in (None, 7.5):
        monkeypatch.setattr(nmr, "CHUNK", 1 << 30)
        monkeypatch.setattr(nmr, "ROW_TABLES", math.inf)                   # never tables: the paper's loop
        ref = _nmr_grads(mesh, camera, reach=reach, **kw)
        monkeypatch.setattr(nmr, "CHUNK", 300)
        monkeypatch.setattr(nmr, "ROW_TABLES", 0.0)                        # tables whenever reach > min_step
        got = _nmr_grads(mesh, camera, reach=reach, **kw)
        for a, b in zip(ref, got):
            assert a.abs().sum() > 0
            assert torch.allclose(a, b, rtol=1e-10, atol=1e-12 * float(a.abs().max())), (reach, (a - b).abs().max())


def test_nmr_backward_matches_the_rule_on_a_larger_mesh():
    """With the default settings (reach None: row tables) the gradient equals the pixel-by-pixel rule run
    through the old code path's settings (no tables, one chunk), on a mesh where faces hide faces."""
    import course.nmr as nmr
    mesh = icosphere(3, dtype=torch.float64)
    cam = persp(64, eye=(0.5, 0.3, 2.8))
    default = _nmr_grads(mesh, cam, colour=True, cull_backfaces=False)
    old = nmr.ROW_TABLES, nmr.CHUNK
    try:
        nmr.ROW_TABLES, nmr.CHUNK = math.inf, 1 << 30
        ref = _nmr_grads(mesh, cam, colour=True, cull_backfaces=False)
    finally:
        nmr.ROW_TABLES, nmr.CHUNK = old
    for a, b in zip(ref, default):
        assert torch.allclose(a, b, rtol=1e-10, atol=1e-12 * float(a.abs().max()))


# ---------------------------------------------------------------------------------- bad input, defined

def _empty_mesh(V, dtype=torch.float64):
    """A mesh without faces (course.mesh.Mesh refuses one; any object with verts and faces is accepted)."""
    import types
    return types.SimpleNamespace(verts=torch.zeros(V, 3, dtype=dtype, requires_grad=True),
                                 faces=torch.zeros(0, 3, dtype=torch.int64))


@pytest.mark.parametrize("V", [0, 3])
def test_empty_mesh_gives_the_background_and_zero_gradients(V):
    """No faces (no vertices, or some): the background everywhere, and a backward that runs and gives 0."""
    cam = persp(8)
    bg = torch.tensor([0.1, 0.2, 0.3], dtype=torch.float64)
    renders = [(lambda m: soft_rasterize(m, cam), 0.0),
               (lambda m: soft_rasterize(m, cam, mode="color", face_colors=torch.zeros(0, 3), background=bg), bg),
               (lambda m: nmr_rasterize(m, cam), 0.0),
               (lambda m: nmr_rasterize(m, cam, face_colors=torch.zeros(0, 3), background=bg), bg),
               (lambda m: nmr_image(torch.full((8, 8, 1), 0.5), m, cam, torch.full((8, 8), -1)), 0.5)]
    for render, expected in renders:
        mesh = _empty_mesh(V)
        img = render(mesh)
        assert torch.equal(img, torch.as_tensor(expected, dtype=img.dtype).expand_as(img))
        (img * torch.randn(img.shape, dtype=img.dtype)).sum().backward()
        assert mesh.verts.grad is None or (mesh.verts.grad == 0).all()


def test_integer_colours_are_taken_as_floats():
    mesh, cam = two_triangles(), persp(12)
    ints = torch.tensor([[1, 0, 0], [0, 1, 1]])
    floats = ints.double()
    for key in ("face_colors",):
        a = soft_rasterize(mesh, cam, mode="color", gamma=0.1, sigma=1e-3, **{key: ints}, cull_backfaces=False)
        b = soft_rasterize(mesh, cam, mode="color", gamma=0.1, sigma=1e-3, **{key: floats}, cull_backfaces=False)
        assert a.dtype == torch.float64 and torch.equal(a, b)
    a = nmr_rasterize(mesh, cam, face_colors=ints, background=1, cull_backfaces=False)
    b = nmr_rasterize(mesh, cam, face_colors=floats, background=1.0, cull_backfaces=False)
    assert a.dtype == torch.float64 and torch.equal(a, b)
    # float32 colours on a float64 mesh: the image is float64, as soft_rasterize's
    assert nmr_rasterize(mesh, cam, face_colors=floats.float(), cull_backfaces=False).dtype == torch.float64


NAN, INF = float("nan"), float("inf")


@pytest.mark.parametrize("kw, match", [
    (dict(mode="color", background=(0.1, 0.2)), "background"),
    (dict(mode="color", background=torch.zeros(1, 3)), "background"),
    (dict(mode="color", background=(0.1, NAN, 0.2)), "background"),
    (dict(mode="color", face_colors=torch.full((2, 3), NAN)), "face_colors"),
    (dict(mode="color", face_colors=torch.zeros(2, 0)), "face_colors"),
    (dict(mode="color", vertex_colors=torch.full((6, 3), INF)), "vertex_colors"),
    (dict(sigma=INF), "sigma"), (dict(sigma=True), "sigma"), (dict(sigma="1e-4"), "sigma"),
    (dict(gamma=INF), "gamma"), (dict(gamma=-1e-4), "gamma"),
    (dict(threshold=NAN), "threshold"), (dict(threshold="small"), "threshold"),
    (dict(eps=NAN), "eps"), (dict(eps=-0.1), "eps"),
    (dict(mode=None), "mode"), (dict(cull_backfaces="no"), "cull_backfaces"),
    (dict(cutoff="abs"), "cutoff"), (dict(cutoff=None), "cutoff"), (dict(depth="log"), "depth"),
    (dict(mode="color", depth=1), "depth"),
])
def test_soft_rasterize_refuses_bad_input(kw, match):
    if kw.get("mode") == "color" and "face_colors" not in kw and "vertex_colors" not in kw:
        kw = dict(kw, face_colors=torch.ones(2, 3))
    with pytest.raises(ValueError, match=match):
        soft_rasterize(two_triangles(), persp(8), **kw)


def test_colours_that_are_not_numbers_are_a_type_error():
    with pytest.raises(TypeError, match="face_colors"):                     # as everywhere (course.tensors)
        soft_rasterize(two_triangles(), persp(8), mode="color", face_colors="red")
    with pytest.raises(TypeError, match="face_colors"):
        nmr_rasterize(two_triangles(), persp(8), face_colors="red")


def test_soft_rasterize_accepts_numbers_of_any_kind():
    import numpy as np
    mesh, cam = two_triangles(), persp(8)
    ref = soft_rasterize(mesh, cam, sigma=1e-3)
    for sigma in (np.float32(1e-3), np.float64(1e-3), torch.tensor(1e-3, dtype=torch.float64)):
        assert torch.allclose(soft_rasterize(mesh, cam, sigma=sigma), ref, rtol=1e-6)
    img = soft_rasterize(mesh, cam, mode="color", face_colors=torch.ones(2, 3), background=torch.tensor([0.5]))
    assert img.shape == (8, 8, 3)


@pytest.mark.parametrize("kw, match", [
    (dict(face_colors=torch.full((2, 3), NAN)), "face_colors"),
    (dict(face_colors=torch.ones(2, 3), background=(0.0, 1.0)), "background"),
    (dict(face_colors=torch.ones(2, 3), background=(0.0, NAN, 1.0)), "background"),
    (dict(background=(0.0, 1.0, 0.0)), "background"),                      # a silhouette has one channel
    (dict(min_step="0.5"), "min_step"), (dict(min_step=True), "min_step"), (dict(min_step=NAN), "min_step"),
    (dict(min_step=-1.0), "min_step"),
    (dict(reach="all"), "reach"), (dict(reach=False), "reach"), (dict(reach=-1.0), "reach"),
    (dict(reach=NAN), "reach"), (dict(cull_backfaces="no"), "cull_backfaces"),
])
def test_nmr_rasterize_refuses_bad_input(kw, match):
    with pytest.raises(ValueError, match=match):
        nmr_rasterize(two_triangles(), persp(8), **kw)


def test_nmr_reach_may_be_infinite():
    mesh, cam = two_triangles(), persp(12)
    d = torch.randn(12, 12, generator=torch.Generator().manual_seed(8), dtype=torch.float64)
    assert torch.equal(_nmr_grad(mesh, cam, d, reach=None)[1], _nmr_grad(mesh, cam, d, reach=math.inf)[1])


def test_nmr_image_refuses_bad_input():
    mesh, cam = two_triangles(), persp(8)
    frags = rasterize(mesh, cam)
    image = torch.rand(8, 8, 3, dtype=torch.float64)
    fid = frags.face_id
    cases = [
        (dict(image=image[..., :0]), ValueError, "image"),
        (dict(image=image[..., 0]), ValueError, "image"),
        (dict(image=torch.full((8, 8, 3), NAN)), ValueError, "image"),
        (dict(face_id=fid.double()), TypeError, "face_id"),
        (dict(face_id=fid.bool()), TypeError, "face_id"),
        (dict(face_id=fid[:, :7]), ValueError, "face_id"),
        (dict(face_id=torch.full((8, 8), 2)), ValueError, "face_id"),      # the mesh has 2 faces
        (dict(face_id=torch.full((8, 8), -2)), ValueError, "face_id"),
        (dict(face_values=torch.ones(2, 1)), ValueError, "face_values"),   # one channel for an RGB image
        (dict(face_values=torch.full((2, 3), NAN)), ValueError, "face_values"),
        (dict(background=(0.0, 1.0)), ValueError, "background"),
        (dict(background=INF), ValueError, "background"),
        (dict(reach="far"), ValueError, "reach"), (dict(min_step=0), ValueError, "min_step"),
    ]
    for kw, error, match in cases:
        args = dict(image=image, face_id=fid)
        args.update(kw)
        image_, face_id = args.pop("image"), args.pop("face_id")
        with pytest.raises(error, match=match):
            nmr_image(image_, mesh, cam, face_id, **args)
    # numpy face ids and int32 ids are indices too
    out = nmr_image(image, mesh, cam, fid.numpy().astype("int32"))
    assert torch.equal(out, image)


def _nmr_rule_by_loops(mesh, camera, image, face_id, g, face_values, bg, reach=math.inf, min_step=0.5):
    """NMR's rule (module docstring, ``_nmr_scan``) written as plain loops over faces, rows and pixels: the
    gradient (V, 2) w.r.t. the screen positions. Slow; tiny scenes only. No faces cross the near plane."""
    H, W = camera.height, camera.width
    xy, depth = camera.project(mesh.verts.detach())
    q = (1 / depth).tolist()
    uv = xy.tolist()
    faces = mesh.faces.tolist()
    fid = face_id.tolist()
    qmap = [[-math.inf] * W for _ in range(H)]                             # q of the visible surface
    for i in range(H):
        for j in range(W):
            if fid[i][j] >= 0:
                (x0, y0), (x1, y1), (x2, y2) = (uv[k] for k in faces[fid[i][j]])
                area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
                px, py = j + 0.5, i + 0.5
                b1 = ((px - x0) * (y2 - y0) - (x2 - x0) * (py - y0)) / area
                b2 = ((x1 - x0) * (py - y0) - (px - x0) * (y1 - y0)) / area
                qmap[i][j] = sum(b * q[k] for b, k in zip((1 - b1 - b2, b1, b2), faces[fid[i][j]]))
    out = [[0.0, 0.0] for _ in uv]
    for axis in (0, 1):                                                    # rows give x, columns give y
        n_rows, n_cols = (H, W) if axis == 0 else (W, H)
        at = (lambda a, r, c: a[r][c]) if axis == 0 else (lambda a, r, c: a[c][r])   # noqa: E731
        for f, face in enumerate(faces):
            u = [uv[k][axis] for k in face]
            v = [uv[k][1 - axis] for k in face]
            for r in range(n_rows):
                vc = r + 0.5
                cross = []                                                 # (u at the crossing, s_a, a, b)
                for k in range(3):
                    va, vb = v[k], v[(k + 1) % 3]
                    if min(va, vb) <= vc < max(va, vb):
                        s = (vc - vb) / (va - vb)
                        cross.append((u[(k + 1) % 3] + s * (u[k] - u[(k + 1) % 3]), s, face[k], face[(k + 1) % 3]))
                if len(cross) != 2:
                    continue
                left, right = sorted(cross, key=lambda c: c[0])
                ul, ur = left[0], right[0]
                # the face's q along the row: the plane through its corners
                (a0, b0), (a1, b1), (a2, b2) = ((u[k], v[k]) for k in range(3))
                det = (a1 - a0) * (b2 - b0) - (b1 - b0) * (a2 - a0)
                dqa = ((q[face[1]] - q[face[0]]) * (b2 - b0) - (q[face[2]] - q[face[0]]) * (b1 - b0)) / det
                dqb = ((q[face[2]] - q[face[0]]) * (a1 - a0) - (q[face[1]] - q[face[0]]) * (a2 - a0)) / det
                for c in range(n_cols):
                    up = c + 0.5
                    here = at(image, r, c)
                    grad = at(g, r, c)
                    terms = []                                             # (side's crossing, dI, direction)
                    if ul <= up <= ur:                                     # uncovering: either edge
                        if at(fid, r, c) != f:
                            continue
                        for side, (ue, *_rest), step in ((0, left, -1), (1, right, 1)):
                            across = (math.ceil(ue - 0.5) - 1) if side == 0 else (math.floor(ue - 0.5) + 1)
                            behind = at(image, r, across) if 0 <= across < n_cols else bg
                            terms.append((side, [x - y for x, y in zip(behind, here)], 1 - 2 * side))
                    else:                                                  # covering: the nearer edge
                        side = 0 if up < ul else 1
                        ue = (left if side == 0 else right)[0]
                        if abs(up - ue) > reach:
                            continue
                        qp = q[face[0]] + dqa * (up - a0) + dqb * (vc - b0)
                        if not (qp > at(qmap, r, c) and qp > 0):
                            continue
                        if face_values is not None:
                            colour = face_values[f]
                        else:
                            near_px = math.ceil(ue - 0.5) if side == 0 else math.floor(ue - 0.5)
                            near_px = min(max(near_px, 0), n_cols - 1)
                            if at(fid, r, near_px) != f:
                                continue
                            colour = at(image, r, near_px)
                        terms.append((side, [x - y for x, y in zip(colour, here)], 2 * side - 1))
                    for side, dI, direction in terms:
                        ue, s, va_, vb_ = left if side == 0 else right
                        dot = sum(x * y for x, y in zip(grad, dI))
                        if dot >= 0:
                            continue
                        for w, vid in ((s, va_), (1 - s, vb_)):
                            out[vid][axis] += dot * w * direction / max(abs(up - ue), min_step * w, 1e-300)
    return torch.tensor(out, dtype=torch.float64)


@pytest.mark.parametrize("with_face_values", [True, False])
@pytest.mark.parametrize("tables", [True, False])
@pytest.mark.parametrize("reach", [None, 2.5])
def test_nmr_matches_the_rule_written_as_loops(monkeypatch, with_face_values, tables, reach):
    """An oracle: NMR's rule as plain loops, on six triangles at 14 × 11 (not square) that overlap, cross the
    image border on both sides, hide behind another or lie off the image, against nmr_image's gradient (row
    tables or pixel by pixel, tiny chunks)."""
    import course.nmr as nmr
    monkeypatch.setattr(nmr, "CHUNK", 40)
    monkeypatch.setattr(nmr, "ROW_TABLES", 0.0 if tables else math.inf)
    cam = Camera.look_at((0.1, 0.2, 3.0), (0.0, 0.0, 0.0), fov_y=40.0, width=14, height=11, near=0.5, far=10.0,
                         dtype=torch.float64)
    verts = torch.tensor([[-1.6, -0.5, 0.0], [0.3, -0.7, 0.2], [-0.2, 0.6, -0.1],          # crosses the left
                          [-0.3, -0.2, 0.6], [1.9, 0.1, 0.5], [0.2, 0.75, 0.55],           # nearer, crosses right
                          [-0.6, 0.1, -0.4], [0.6, -0.5, -0.5], [0.5, 0.8, -0.45],         # behind both
                          [-0.2, -0.15, 0.5], [1.6, 0.1, 0.45], [0.2, 0.6, 0.48],          # hidden, crosses right
                          [1.5, -0.3, 0.0], [2.2, -0.2, 0.0], [1.7, 0.4, 0.1],             # off the image, right
                          [-2.2, -0.3, 0.0], [-1.5, -0.2, 0.0], [-1.7, 0.4, 0.1]],         # and left
                         dtype=torch.float64)
    mesh = Mesh(verts, [[0, 1, 2], [3, 4, 5], [6, 7, 8], [9, 10, 11], [12, 13, 14], [15, 16, 17]])
    frags = rasterize(mesh, cam)
    gen = torch.Generator().manual_seed(9)
    assert (frags.face_id == 2).sum() > 0 and (frags.face_id >= 3).sum() == 0   # the last three never show
    fv = torch.rand(6, 3, generator=gen, dtype=torch.float64)
    bg = [0.3, 0.1, 0.6]
    image = torch.where(frags.mask[..., None], fv[frags.face_id.clamp(min=0)], torch.tensor(bg, dtype=torch.float64))
    g = torch.randn(11, 14, 3, generator=gen, dtype=torch.float64)
    expected = _nmr_rule_by_loops(mesh, cam, image.tolist(), frags.face_id, g.tolist(),
                                  fv.tolist() if with_face_values else None, bg,
                                  reach=math.inf if reach is None else reach)
    screen = mesh.verts.clone().requires_grad_()
    out = nmr_image(image, Mesh(screen, mesh.faces), cam, frags.face_id, face_values=fv if with_face_values else None,
                    background=bg, cull_backfaces=False, reach=reach)
    out.backward(g)
    # the same verts gradient, from the oracle's screen gradient through the projection
    v = mesh.verts.clone().requires_grad_()
    xy, _ = cam.project(v)
    (xy * expected).sum().backward()
    assert expected.abs().sum() > 0 and (expected[:, 0] != 0).any() and (expected[:, 1] != 0).any()
    assert torch.allclose(screen.grad, v.grad, rtol=1e-10, atol=1e-10)
