"""Appearance from images (lecture 10): a UV texture, or per-vertex colours, fitted to photos of a known shape.

Shapes: V vertices, F faces, N views, H x W image, Ht x Wt texture, P covered pixels (all views together).

**Why visibility needs no special gradient here.** The geometry and the cameras are known and fixed, so
which face each pixel sees, and where on that face, never changes while we optimise. The course's own hard
rasterizer (``course.raster.rasterize``: z-buffer, top-left rule, perspective-correct barycentrics) is run
*once* per view, before the loop. What remains is a function of the appearance alone, and it is linear::

    texture:        pixel p = Σ_k w_pk T[texel_k(p)]       (bilinear: 4 texels around the pixel's uv)
    vertex colours: pixel p = Σ_k b_pk c[vertex_k(p)]      (barycentric: the 3 corners of its face)

so the loss ``mean over object pixels of |render - target|²`` is a convex quadratic and plain Adam finds
its minimum. The renders are **unlit** (``RenderSettings(shading="unlit")``: the base colour itself, no
lights): an unlit pixel *is* the texture value, so every texel a view sees gets the same gradient
strength, whereas under a light a texel on a dark, grazing part of the surface would barely move (and a
fit could trade texture against shading). Targets are made by ``course.render.render`` with that setting,
bilinear filtering and no antialiasing (``render_texture`` / ``render_vertex_colors``); the loop replays
exactly the same lookups (``sample_texture`` at the interpolated uvs, ``interpolate``'s barycentric sum) from
the cached fragments, which is bit-identical (tested) and skips the rasterization at every step: the
fast path. ``render`` itself is differentiable w.r.t. ``mesh.texture`` and ``mesh.vert_colors`` too, just
slower, since it rasterizes again each call.

**Keeping colours in [0, 1].** The texture (or the colours) is the parameter itself, projected back onto
[0, 1] after each Adam step (clamping). A sigmoid would also keep it in range, but it makes the quadratic
non-convex and can never reach exactly 0 or 1 (the teapot's white marker is exactly 1).

**What the views see.** A texel gets a gradient only if some covered pixel of some training view looks it
up with a positive bilinear weight (``seen_texels``); every other texel keeps its start value exactly (Adam
moves a parameter only after a non-zero gradient). A held-out view that reads such a texel shows the start
grey there, so every fit reports ``held_out_unseen``: the fraction of held-out object pixels that read a
texel (or a vertex colour) no training view reaches. At the defaults (8 views spread over the sphere at
256 x 256 pixels, a 256 x 256 texture) it is well under 1 %, so the held-out PSNR measures
generalisation, not luck. At 128 x 128 pixels 8 views reach only 83 % of the texels and the held-out PSNR
of a 256² texture falls to ~22 dB: each pixel pins only the four texels around one point, so the
image resolution must match the texture's.

**Vertex colours cannot show detail finer than the mesh.** Inside a triangle a vertex-coloured surface is
the linear blend of three colours; the teapot's 8 x 8 checker has edges that cut through triangles, so no
choice of vertex colours reproduces it (``fit_vertex_colors_from_images`` without ``target_colors``), while
a smooth vertex-coloured target (``smooth_vertex_colors``) is fitted almost exactly. At the defaults
(float64, 100 steps) the held-out PSNR goes from 12.4 to 41 dB for the texture, from 10.7 to 57 dB for
vertex colours on a vertex-coloured target, and from 12.4 to a plateau of 16.5 dB (reached by step 30)
for vertex colours on the textured teapot.

The metric is ``course.inverse.losses.psnr`` per held-out view over the pixels that show the object (the
geometry is known, so target and result cover the same pixels), averaged over views in dB.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from .. import models
from . import losses
from ..camera import Camera
from .common import FitHistory, _progress, _snap_due, sphere_views
from ..mesh import Mesh
from ..raster import interpolate, rasterize
from ..render import RenderSettings, Scene, render
from ..tensors import _check_count, _check_real, as_tensor
from ..textures import sample_texture

__all__ = ["TextureFit", "ColorFit", "fit_texture", "fit_vertex_colors", "fit_texture_from_images",
           "fit_vertex_colors_from_images", "smooth_vertex_colors", "render_texture", "render_vertex_colors",
           "seen_texels", "seen_vertices"]

_UNLIT = RenderSettings(shading="unlit")        # bilinear, no antialiasing, hard visibility, clamped to [0, 1]


# ------------------------------------------------------------------------------------------- results

@dataclass
class TextureFit:
    """``texture``: (Ht, Wt, 3) the fitted texture in [0, 1], detached. ``history``: loss (the MSE over
    training object pixels) per step, snapshots = the texture (Ht, Wt, 3) every ``snapshot_every`` steps,
    metrics ``"train_psnr"`` per step and ``"held_out_psnr"`` at each snapshot step. ``start_psnr`` / ``psnr``:
    mean held-out PSNR (dB) of the start and of the result; ``per_view_psnr``: (N,) the result's.
    ``seen``: (Ht, Wt) bool, the texels the training views reach; ``held_out_unseen``: the fraction of
    held-out object pixels that read an unseen texel."""
    texture: torch.Tensor
    history: FitHistory
    psnr: float
    start_psnr: float
    per_view_psnr: torch.Tensor
    seen: torch.Tensor
    held_out_unseen: float


@dataclass
class ColorFit:
    """``colors``: (V, 3) the fitted vertex colours in [0, 1], detached. ``history``: as ``TextureFit``'s, but
    snapshots are renders (H, W, 3) of the first held-out view. ``seen``: (V,) bool, the vertices whose colour
    some training pixel blends in; the other fields as in ``TextureFit``."""
    colors: torch.Tensor
    history: FitHistory
    psnr: float
    start_psnr: float
    per_view_psnr: torch.Tensor
    seen: torch.Tensor
    held_out_unseen: float


# ------------------------------------------------------------------------------------- target renders

def render_texture(mesh, cameras, texture=None, *, background=(1.0, 1.0, 1.0)) -> torch.Tensor:
    """(N, H, W, 3) unlit renders of ``mesh`` with ``texture`` (Ht, Wt, 3) (None: the mesh's own) through
    ``course.render.render``: bilinear lookups at pixel centres, no antialiasing, over ``background``.
    Differentiable w.r.t. ``texture``."""
    _check_mesh(mesh, need_uvs=True)
    cameras = _check_cameras(cameras, "cameras")
    texture = mesh.texture if texture is None else as_tensor(texture, dtype=mesh.verts.dtype, name="texture")
    if texture is None:
        raise ValueError("the mesh has no texture: pass texture (Ht, Wt, 3)")
    textured = Mesh(mesh.verts, mesh.faces, uvs=mesh.uvs, texture=texture)
    return torch.stack([render(Scene(textured, c, background=background), _UNLIT).image for c in cameras])


def render_vertex_colors(mesh, cameras, colors, *, background=(1.0, 1.0, 1.0)) -> torch.Tensor:
    """(N, H, W, 3) unlit renders of ``mesh`` coloured by ``colors`` (V, 3) (barycentric blends inside each
    face), through ``course.render.render`` like ``render_texture``. Differentiable w.r.t. ``colors``."""
    _check_mesh(mesh)
    cameras = _check_cameras(cameras, "cameras")
    coloured = Mesh(mesh.verts, mesh.faces, vert_colors=colors)
    return torch.stack([render(Scene(coloured, c, background=background), _UNLIT).image for c in cameras])


def smooth_vertex_colors(mesh, seed: int = 0, *, frequency: float = 2.0) -> torch.Tensor:
    """(V, 3) a seeded, smooth random colour field on the mesh, in [0.1, 0.9]: each channel is
    ``0.5 + 0.4 sin(k · x + φ)`` of the vertex position x, with a random direction k of length
    ``frequency`` (waves per 2π world units) and a random phase φ. A function of position, so the copies of
    a seam vertex get the same colour. The course ships no vertex-coloured model; this is its stand-in."""
    _check_mesh(mesh)
    gen = torch.Generator(device="cpu").manual_seed(_check_count(seed, "seed", minimum=0))
    frequency = _check_real(frequency, "frequency", low=0)
    k = torch.randn(3, 3, generator=gen, dtype=torch.float64)
    k = frequency * k / k.norm(dim=0, keepdim=True)                          # (3 xyz, 3 channels)
    phase = 2 * math.pi * torch.rand(3, generator=gen, dtype=torch.float64)
    x = mesh.verts.detach().to(device="cpu", dtype=torch.float64)
    return (0.5 + 0.4 * torch.sin(x @ k + phase)).to(dtype=mesh.verts.dtype, device=mesh.verts.device)


# ------------------------------------------------------------------------------------- cached views

@dataclass
class _Views:
    """What the fixed geometry looks like from a set of cameras, computed once.

    mask: (N, H, W) bool, pixels that show the object; pixel: (P,) their flat indices into N*H*W;
    corners: (P, 3) the vertex ids of each pixel's face; bary: (P, 3) its perspective-correct barycentrics;
    uv: (P, 2) its interpolated texture coordinates (None without uvs)."""
    mask: torch.Tensor
    pixel: torch.Tensor
    corners: torch.Tensor
    bary: torch.Tensor
    uv: torch.Tensor | None


def _views(mesh, cameras) -> _Views:
    with torch.no_grad():
        frags = [rasterize(mesh, c) for c in cameras]                        # cull_backfaces=False, like render()
        mask = torch.stack([f.mask for f in frags])                           # (N, H, W)
        corners = torch.cat([mesh.faces[f.face_id[f.mask]] for f in frags])   # (P, 3)
        bary = torch.cat([f.bary[f.mask] for f in frags]).to(mesh.verts.dtype)  # (P, 3)
        uv = None
        if mesh.uvs is not None:                                               # the same op render() uses
            uv = torch.cat([interpolate(mesh.uvs, f, mesh.faces)[f.mask] for f in frags])   # (P, 2)
    return _Views(mask, mask.reshape(-1).nonzero().squeeze(1), corners, bary, uv)


def _check_visible(views, name) -> None:
    """Every view must show part of the mesh: PSNR over no pixel is undefined, and such a view teaches nothing."""
    empty = (~views.mask.flatten(1).any(1)).nonzero().squeeze(1).tolist()
    if empty:
        raise ValueError(f"{name} {empty} show no part of the mesh: aim the cameras at it")


def _blend(colors, views) -> torch.Tensor:
    """(P, 3) each object pixel's colour from vertex colours (V, 3): ``interpolate`` on the cached faces."""
    P = views.corners.shape[0]
    corner = colors.index_select(0, views.corners.reshape(-1)).view(P, 3, 3)   # (P, 3 corners, 3 RGB)
    return (views.bary[:, :, None] * corner).sum(1)


def _paint(values, views, background) -> torch.Tensor:
    """(N, H, W, 3) images: ``values`` (P, 3) at the object pixels, ``background`` (N, H, W, 3) elsewhere."""
    flat = background.reshape(-1, 3).index_put((views.pixel,), values.clamp(0, 1))
    return flat.view(background.shape)


def _object_pixels(images, views) -> torch.Tensor:
    """(P, 3) the images' values at the object pixels."""
    return images.reshape(-1, 3)[views.pixel]


def _per_view_psnr(values, target, views) -> torch.Tensor:
    """(N,) ``losses.psnr`` of each view over its object pixels (values, target: (P, 3) object pixels).

    View n's object pixels are passed as one 1 x P_n image: the same number as ``losses.psnr`` of the full
    images with the object mask, without building the images."""
    counts = views.mask.sum(dim=(1, 2)).tolist()                              # P_n per view
    pairs = zip(values.clamp(0, 1).split(counts), target.split(counts))
    return torch.stack([losses.psnr(v[None], t[None]) for v, t in pairs])


def seen_texels(mesh, cameras, texture_size) -> torch.Tensor:
    """(Ht, Wt) bool: the texels that a pixel of some view looks up with a positive bilinear weight, i.e.
    the texels a texture gradient from these views can reach. texture_size: int or (Ht, Wt)."""
    _check_mesh(mesh, need_uvs=True)
    Ht, Wt = _texture_shape(texture_size)
    return _seen_texels(_views(mesh, _check_cameras(cameras, "cameras")), Ht, Wt, mesh.verts.dtype)


def _seen_texels(views, Ht, Wt, dtype) -> torch.Tensor:
    probe = torch.zeros(Ht, Wt, 1, dtype=dtype, device=views.uv.device, requires_grad=True)
    sample_texture(probe, views.uv).sum().backward()                          # d/dT Σ pixels = Σ weights
    return probe.grad[..., 0] > 0


def seen_vertices(mesh, cameras) -> torch.Tensor:
    """(V,) bool: the vertices whose colour some pixel of some view blends in with a positive weight."""
    _check_mesh(mesh)
    views = _views(mesh, _check_cameras(cameras, "cameras"))
    return _seen_vertices(views, mesh.num_verts)


def _seen_vertices(views, V) -> torch.Tensor:
    weight = torch.zeros(V, dtype=views.bary.dtype, device=views.bary.device)
    return weight.index_add(0, views.corners.reshape(-1), views.bary.reshape(-1).clamp_min(0)) > 0


# ----------------------------------------------------------------------------------------- validation

def _check_mesh(mesh, need_uvs: bool = False) -> None:
    if not isinstance(mesh, Mesh):
        raise ValueError(f"mesh must be a course.mesh.Mesh, got {type(mesh).__name__}")
    if need_uvs and mesh.uvs is None:
        raise ValueError("the mesh has no uvs: a texture needs per-vertex texture coordinates (V, 2)")


def _check_cameras(cameras, name) -> list:
    if not isinstance(cameras, (list, tuple)) or len(cameras) == 0 or not all(isinstance(c, Camera) for c in cameras):
        raise ValueError(f"{name} must be a non-empty list of Camera")
    if len({(c.height, c.width) for c in cameras}) != 1:
        raise ValueError(f"all {name} must have the same image size")
    return list(cameras)


def _check_images(images, cameras, name, dtype, device) -> torch.Tensor:
    """(N, H, W, 3) images matching ``cameras`` (one per camera, the cameras' size), finite, in [0, 1]."""
    if images is None:
        raise ValueError(f"{name} are missing: pass (N, H, W, 3) images, one per camera")
    images = as_tensor(images, dtype=dtype, device=device, name=name).detach()
    H, W = cameras[0].height, cameras[0].width
    if images.dim() != 4 or images.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (N, H, W, 3), got {tuple(images.shape)}")
    if images.shape[0] != len(cameras):
        raise ValueError(f"{name} hold {images.shape[0]} images but there are {len(cameras)} cameras")
    if tuple(images.shape[1:3]) != (H, W):
        raise ValueError(f"{name} are {tuple(images.shape[1:3])} pixels but the cameras make {(H, W)} images")
    if not torch.isfinite(images).all():
        raise ValueError(f"{name} contain NaN or inf")
    if images.min() < 0 or images.max() > 1:
        raise ValueError(f"{name} must hold colours in [0, 1], got values in "
                         f"[{float(images.min()):g}, {float(images.max()):g}]")
    return images


def _check_loop(steps, lr, snapshot_every) -> None:
    if isinstance(steps, bool) or not (isinstance(steps, int) and steps >= 0):
        raise ValueError(f"steps must be a non-negative integer, got {steps!r}")
    if isinstance(lr, bool) or not (isinstance(lr, (int, float)) and math.isfinite(lr) and lr > 0):
        raise ValueError(f"lr must be a positive finite number, got {lr!r}")
    if snapshot_every is not None and (isinstance(snapshot_every, bool) or not
                                       (isinstance(snapshot_every, int) and snapshot_every >= 1)):
        raise ValueError(f"snapshot_every must be a positive integer or None, got {snapshot_every!r}")


def _texture_shape(texture_size) -> tuple:
    size = (texture_size, texture_size) if isinstance(texture_size, int) else tuple(texture_size)
    if len(size) != 2 or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 1 for s in size):
        raise ValueError(f"texture_size must be a positive int or (Ht, Wt), got {texture_size!r}")
    return size


def _start(init, shape, seed, dtype, device, name) -> torch.Tensor:
    """The start value: ``"grey"`` (0.5 everywhere), ``"random"`` (seeded uniform in [0, 1]) or a tensor."""
    if isinstance(init, str):
        if init == "grey":
            return torch.full(shape, 0.5, dtype=dtype, device=device)
        if init == "random":
            gen = torch.Generator(device="cpu").manual_seed(_check_count(seed, "seed", minimum=0))
            return torch.rand(shape, generator=gen, dtype=torch.float64).to(dtype=dtype, device=device)
        raise ValueError(f'init must be "grey", "random" or a {name} tensor {shape}, got {init!r}')
    start = as_tensor(init, dtype=dtype, device=device, name="init").detach().clone()
    if tuple(start.shape) != tuple(shape):
        raise ValueError(f"init must have shape {tuple(shape)} ({name}), got {tuple(start.shape)}")
    if not torch.isfinite(start).all() or start.min() < 0 or start.max() > 1:
        raise ValueError("init must hold finite colours in [0, 1]")
    return start


def _held_out(cameras, held_out, held_out_images, dtype, device):
    """The metric's cameras and images: the held-out ones, or the training ones when none are given."""
    if held_out is None:
        if held_out_images is not None:
            raise ValueError("held_out_images need their cameras: pass held_out too")
        return None
    held_out = _check_cameras(held_out, "held_out")
    return held_out, _check_images(held_out_images, held_out, "held_out_images", dtype, device)


# ------------------------------------------------------------------------------------------ the loop

def _fit(param, render_pixels, train, target, test, test_target, snapshot, *, steps, lr,
         snapshot_every, progress, desc):
    """Adam on ``param`` (projected onto [0, 1] after each step) against the MSE over training object pixels.

    render_pixels(param, views) -> (P, 3); target, test_target: (P, 3) object pixels of the training and
    test views; snapshot(param) -> what the history keeps. Returns (history, start per-view PSNR)."""
    history = FitHistory(metrics={"train_psnr": [], "held_out_psnr": []})
    start = _per_view_psnr(render_pixels(param.detach(), test), test_target, test)
    opt = torch.optim.Adam([param], lr=lr)
    bar = _progress(steps, progress, desc)
    for step in range(steps + 1):
        if _snap_due(step, steps, snapshot_every):
            with torch.no_grad():
                history.snapshot_steps.append(step)
                history.snapshots.append(snapshot(param.detach()))
                history.metrics["held_out_psnr"].append(
                    float(_per_view_psnr(render_pixels(param, test), test_target, test).mean()))
        if step == steps:
            break
        loss = (render_pixels(param, train) - target).pow(2).mean()           # MSE over object pixels
        opt.zero_grad()
        loss.backward()
        opt.step()
        with torch.no_grad():
            param.clamp_(0, 1)                                                # project back onto [0, 1]
        history.loss.append(float(loss.detach()))
        history.metrics["train_psnr"].append(-10 * math.log10(history.loss[-1]) if history.loss[-1] > 0 else math.inf)
        bar.update(1)
        bar.set_postfix(loss=f"{history.loss[-1]:.2e}")
    bar.close()
    return history, start


def fit_texture(mesh, images, cameras, *, texture_size=256, steps: int = 100, lr: float = 0.05, seed: int = 0,
                init="grey", held_out=None, held_out_images=None, snapshot_every: int | None = 10,
                progress: bool = True) -> TextureFit:
    """Fit a UV texture so that unlit renders of ``mesh`` match ``images`` seen from ``cameras``.

    Args:
        mesh: a Mesh with ``uvs`` (V, 2); its geometry is fixed, its own texture (if any) is not used.
        images: (N, H, W, 3) target colours in [0, 1], one per camera (unlit renders, see
            ``render_texture``); only the pixels that show the mesh count.
        cameras: N ``Camera``, all of one image size H x W.
        texture_size: int or (Ht, Wt), the fitted texture's size (ignored when ``init`` is a tensor).
        steps: Adam steps. lr: Adam's learning rate (colour units per step, roughly).
        seed: seeds ``init="random"``; the loop itself draws no random numbers.
        init: ``"grey"`` (0.5 everywhere), ``"random"`` (seeded uniform) or a (Ht, Wt, 3) tensor in [0, 1].
        held_out, held_out_images: cameras and their (N', H', W', 3) images for the metric; None: the
            metric is taken on the training views (then it is no held-out check).
        snapshot_every: keep the texture every this many steps (and the last); None: none.
        progress: show a tqdm bar (``TQDM_DISABLE=1`` also hides it).

    Returns a ``TextureFit`` (texture in the mesh's dtype and device).
    """
    _check_mesh(mesh, need_uvs=True)
    _check_loop(steps, lr, snapshot_every)
    cameras = _check_cameras(cameras, "cameras")
    dtype, device = mesh.verts.dtype, mesh.verts.device
    images = _check_images(images, cameras, "images", dtype, device)
    test = _held_out(cameras, held_out, held_out_images, dtype, device)
    shape = (*_texture_shape(texture_size), 3)
    if isinstance(init, torch.Tensor):                                        # its own size wins
        if init.dim() != 3 or init.shape[-1] != 3:
            raise ValueError(f"init must be a (Ht, Wt, 3) texture, got shape {tuple(init.shape)}")
        shape = tuple(init.shape)
    texture = _start(init, shape, seed, dtype, device, "(Ht, Wt, 3)").requires_grad_(True)
    train = _views(mesh, cameras)
    test_cams, test_images = test if test is not None else (cameras, images)
    test_views = train if test is None else _views(mesh, test_cams)
    _check_visible(train, "training views")
    _check_visible(test_views, "held-out views")

    def lookup(tex, views):
        return sample_texture(tex, views.uv)                                  # (P, 3) bilinear, as render() does

    history, start = _fit(texture, lookup, train, _object_pixels(images, train), test_views,
                          _object_pixels(test_images, test_views), lambda t: t.clone(),
                          steps=steps, lr=lr, snapshot_every=snapshot_every, progress=progress,
                          desc="fit_texture")
    texture = texture.detach()
    per_view = _per_view_psnr(lookup(texture, test_views), _object_pixels(test_images, test_views), test_views)
    seen = _seen_texels(train, shape[0], shape[1], dtype)
    unseen = sample_texture((~seen).to(dtype)[..., None], test_views.uv)[:, 0] > 0   # (P',) reads one
    return TextureFit(texture, history, float(per_view.mean()), float(start.mean()), per_view, seen,
                      float(unseen.to(torch.float64).mean()))


def fit_vertex_colors(mesh, images, cameras, *, steps: int = 100, lr: float = 0.05, seed: int = 0, init="grey",
                      held_out=None, held_out_images=None, snapshot_every: int | None = 10,
                      progress: bool = True) -> ColorFit:
    """Fit per-vertex colours (V, 3) so that unlit renders of ``mesh`` match ``images`` from ``cameras``.

    The arguments are ``fit_texture``'s (``init``: ``"grey"``, ``"random"`` or a (V, 3) tensor); the mesh's
    own colours, uvs and texture are not used. Snapshots are renders of the first held-out view (the first
    training view without held-out cameras), over that view's target background.
    """
    _check_mesh(mesh)
    _check_loop(steps, lr, snapshot_every)
    cameras = _check_cameras(cameras, "cameras")
    dtype, device = mesh.verts.dtype, mesh.verts.device
    images = _check_images(images, cameras, "images", dtype, device)
    test = _held_out(cameras, held_out, held_out_images, dtype, device)
    colors = _start(init, (mesh.num_verts, 3), seed, dtype, device, "(V, 3)").requires_grad_(True)
    train = _views(mesh, cameras)
    test_cams, test_images = test if test is not None else (cameras, images)
    test_views = train if test is None else _views(mesh, test_cams)
    _check_visible(train, "training views")
    _check_visible(test_views, "held-out views")
    first = _views(mesh, test_cams[:1])

    def snapshot(c):
        return _paint(_blend(c, first), first, test_images[:1].clone())[0]   # (H, W, 3)

    history, start = _fit(colors, _blend, train, _object_pixels(images, train), test_views,
                          _object_pixels(test_images, test_views), snapshot,
                          steps=steps, lr=lr, snapshot_every=snapshot_every, progress=progress,
                          desc="fit_vertex_colors")
    colors = colors.detach()
    per_view = _per_view_psnr(_blend(colors, test_views), _object_pixels(test_images, test_views), test_views)
    seen = _seen_vertices(train, mesh.num_verts)
    unseen = _blend((~seen).to(dtype)[:, None].expand(-1, 3), test_views)[:, 0] > 0
    return ColorFit(colors, history, float(per_view.mean()), float(start.mean()), per_view, seen,
                    float(unseen.to(torch.float64).mean()))


# -------------------------------------------------------------------------------------- entry points

def _entry_views(mesh, n_views, size):
    if isinstance(n_views, bool) or not (isinstance(n_views, int) and n_views >= 1):
        raise ValueError(f"n_views must be a positive integer, got {n_views!r}")
    if isinstance(size, bool) or not (isinstance(size, int) and size >= 1):
        raise ValueError(f"size must be a positive integer (pixels), got {size!r}")
    like = dict(size=size, dtype=mesh.verts.dtype, device=mesh.verts.device)
    return sphere_views(n_views, offset=1.9, **like), sphere_views(16, **like)


def fit_texture_from_images(mesh=None, *, n_views: int = 8, seed: int = 0, size: int = 256, steps: int = 100,
                            lr: float = 0.05, texture_size=None, init="grey", snapshot_every: int | None = 10,
                            progress: bool = True) -> TextureFit:
    """The issue's entry point: recover a textured mesh's texture from ``n_views`` unlit renders of it.

    mesh: a Mesh with uvs and a texture (None: ``models.teapot(dtype=torch.float64)``, its 256 x 256 checker).
    Training views: ``sphere_views(n_views, offset=1.9)``, spread over the sphere; held out:
    ``sphere_views(16)`` (a different spiral, so no view is shared); all ``size`` x ``size`` pixels at
    distance 3 with a 40° field of view. The fit starts from flat grey; texture_size None: the mesh's own
    texture's size. The other arguments go to ``fit_texture``.
    """
    mesh = models.teapot(dtype=torch.float64) if mesh is None else mesh
    _check_mesh(mesh, need_uvs=True)
    if mesh.texture is None:
        raise ValueError("the mesh has no texture to render targets from")
    train, held_out = _entry_views(mesh, n_views, size)
    texture_size = tuple(mesh.texture.shape[:2]) if texture_size is None else texture_size
    return fit_texture(mesh, render_texture(mesh, train), train, texture_size=texture_size, steps=steps, lr=lr,
                       seed=seed, init=init, held_out=held_out, held_out_images=render_texture(mesh, held_out),
                       snapshot_every=snapshot_every, progress=progress)


def fit_vertex_colors_from_images(mesh=None, target_colors=None, *, n_views: int = 8, seed: int = 0,
                                  size: int = 256, steps: int = 100, lr: float = 0.05, init="grey",
                                  snapshot_every: int | None = 10, progress: bool = True) -> ColorFit:
    """Fit vertex colours to ``n_views`` unlit renders of a target, with the views of ``fit_texture_from_images``.

    mesh: None for ``models.teapot(dtype=torch.float64)``. target_colors: (V, 3) in [0, 1]: the target is
    the mesh coloured by them (try ``smooth_vertex_colors(mesh, seed)``); exactly representable, so the fit
    should reach a high PSNR. None: the target is the mesh's own *texture* (the teapot's 8 x 8 checker),
    whose edges cut through triangles: vertex colours can only blur it, and the PSNR plateaus far below a
    texture fit's. The other arguments go to ``fit_vertex_colors``.
    """
    mesh = models.teapot(dtype=torch.float64) if mesh is None else mesh
    _check_mesh(mesh)
    train, held_out = _entry_views(mesh, n_views, size)
    if target_colors is None:
        if mesh.texture is None or mesh.uvs is None:
            raise ValueError("target_colors is None, so the target is the mesh's texture, but it has none")
        images, held_out_images = render_texture(mesh, train), render_texture(mesh, held_out)
    else:
        target_colors = as_tensor(target_colors, dtype=mesh.verts.dtype, device=mesh.verts.device,
                                  name="target_colors")
        if tuple(target_colors.shape) != (mesh.num_verts, 3):
            raise ValueError(f"target_colors must have shape ({mesh.num_verts}, 3), got {tuple(target_colors.shape)}")
        if not torch.isfinite(target_colors).all() or target_colors.min() < 0 or target_colors.max() > 1:
            raise ValueError("target_colors must hold finite colours in [0, 1]")
        images = render_vertex_colors(mesh, train, target_colors)
        held_out_images = render_vertex_colors(mesh, held_out, target_colors)
    return fit_vertex_colors(mesh, images, train, steps=steps, lr=lr, seed=seed, init=init, held_out=held_out,
                             held_out_images=held_out_images, snapshot_every=snapshot_every, progress=progress)
