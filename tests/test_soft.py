"""Soft rasterization and NMR's approximate gradient: a dense oracle, gradcheck, the hard limit, the rule by
hand, and stress cases (extreme σ and γ, degenerate triangles, the near plane)."""
import math

import pytest
import torch

from course.camera import Camera
from course.mesh import Mesh
from course.models import icosphere
from course.raster import rasterize
from course.soft import nmr_image, nmr_rasterize, soft_rasterize


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

def dense_soft(mesh, camera, sigma, gamma, eps=1e-3, face_colors=None, vertex_colors=None, bg=0.0):
    """The paper's formulas for every (pixel, face), no culling, float64: the reference soft_rasterize
    must match (faces all in front of the near plane, no back-face culling)."""
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
    if face_colors is None and vertex_colors is None:
        return (1 - (1 - D).prod(1)).view(H, W)
    b = bary.clamp(0, 1)
    b = b / b.sum(-1, keepdim=True)
    qp = (b * q[None]).sum(-1)
    n, f = camera.near, camera.far
    z = (f - qp) / (f - n) if camera.orthographic else (qp - 1 / f) / (1 / n - 1 / f)
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
