"""A mesh from shaded images (lecture 10): the visual hull carved from the views' masks, then fitted to
flat-shaded, exactly box-filtered images (``fit_mesh_from_images``: soft or Reynolds gradients, Large Steps or
Adam), the data computed once (``shaded_data``) and shared by fits that differ only in how they fit."""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from .. import models
from . import losses
from ..mesh import Mesh
from ..soft import soft_rasterize
from .common import (_background3, _check_cameras, _check_common, FitHistory, _progress, _schedule, _snap_due,
                     hard_silhouettes, sphere_views, start_verts)
from ..tensors import _check_count, _check_real, _check_shape, as_tensor

__all__ = ["SKY", "GRADIENTS", "ImageFit", "ShadedData", "shaded_data", "fit_mesh_from_images", "shaded_images",
           "held_out_psnr", "coverage_masks", "shaded_face_colors"]

# ------------------------------------------------------------------------------------ mesh from images

SKY = (0.2, 0.4, 0.8)          # the background of shaded images: far from every shade of the teapot's orange
GRADIENTS = ("soft", "reynolds")


@dataclass
class ImageFit:
    """``mesh``: the fitted Mesh (target's world frame); ``start``: the Mesh it started from (the carved visual
    hull, or the sphere); ``history`` (``metrics["image_loss"]``: the image term per step); held-out metrics of
    the start and of the result over ``held_out`` views: ``start_iou`` / ``iou`` (hard silhouettes, mean),
    ``start_psnr`` / ``psnr`` (shaded images, dB, mean), ``per_view_iou`` (N,)."""
    mesh: Mesh
    start: Mesh
    history: FitHistory
    start_iou: float
    iou: float
    per_view_iou: torch.Tensor
    start_psnr: float
    psnr: float


def shaded_images(mesh, cameras, *, background=SKY, exact: bool = True) -> torch.Tensor:
    """(N, H, W, 3) the box-filtered images of ``mesh`` flat-shaded by ``shaded_face_colors`` (a light fixed
    in the world) on ``background``, one per camera, no gradient: exactly (``coverage.exact_coverage``; the
    targets of ``fit_mesh_from_images``) or with 4 x 4 samples per pixel (``antialias.supersample``, ten times
    faster: the held-out metric)."""
    from ..antialias import supersample
    from ..coverage import exact_coverage
    cameras = _check_cameras(cameras)
    with torch.inference_mode():                                            # no graph at all
        colors = shaded_face_colors(Mesh(mesh.verts.detach(), mesh.faces))
        bg = _background3(background, colors)
        draw = (lambda c: exact_coverage(mesh, c, colors, bg)) if exact else \
            (lambda c: supersample(mesh, c, colors, 4, background=bg))
        images = torch.stack([draw(c) for c in cameras])
    return images.clone()                                                   # an ordinary tensor again


def held_out_psnr(mesh, target_mesh, cameras, *, background=SKY) -> torch.Tensor:
    """(N,) the PSNR (dB) of ``mesh``'s shaded images against ``target_mesh``'s, 4 x 4 samples per pixel."""
    pred = shaded_images(mesh, cameras, background=background, exact=False)
    target = shaded_images(target_mesh, cameras, background=background, exact=False).to(pred.dtype)
    return torch.stack([losses.psnr(p.clamp(0, 1), t) for p, t in zip(pred, target)])


def coverage_masks(mesh, cameras) -> torch.Tensor:
    """(N, H, W) the fraction of each pixel the mesh covers (4 x 4 samples per pixel), no gradient: the masks
    ``carve.carve`` reads (fractions, not ``hard_silhouettes``' 0 / 1: the hull's surface then falls between
    pixel centres where the outline does, measured: Chamfer 0.48 % against 0.52 % on the teapot)."""
    from ..antialias import supersample
    ones = mesh.verts.new_ones(mesh.faces.shape[0], 3)
    with torch.no_grad():
        return torch.stack([supersample(mesh, c, ones, 4)[..., 0] for c in cameras])


def _reynolds_backward(image_loss, verts, faces, colors, cameras, targets, background):
    """The image term's gradient by lecture 09's exact boundary integral on the box-filtered images.
    The images are ``coverage.exact_coverage`` of every view in one call (a camera batch) with the face colours
    as autograd leaves: one pass gives the images, the loss, dL/dimage (the weights) and dL/dcolours (each
    face's weighted areas, exact: the image is linear in them); ``visibility.image_gradient(method="reynolds")``
    of the batch turns the weights into dL/dverts summed over the views (the edges' motion). Then
    ``g_v · v + g_c · c(v)`` is backpropagated, so the colours' own dependence on the vertices (the shading
    follows the normals) reaches the optimiser too. Returns the image term (a tensor)."""
    from ..coverage import exact_coverage
    from ..visibility import image_gradient
    mesh = Mesh(verts.detach(), faces)
    flat, bg = colors.detach().requires_grad_(True), _background3(background, verts)
    with torch.enable_grad():
        images = exact_coverage(mesh, cameras, flat, bg)                   # (N, H, W, 3)
        loss = sum(image_loss(image, target) for image, target in zip(images, targets))
        weights, g_colors = torch.autograd.grad(loss, (images, flat))
    g_verts = image_gradient(mesh, cameras, flat.detach(), weights, method="reynolds", background=bg)
    ((g_verts.to(verts.dtype) * verts).sum() + (g_colors * colors).sum()).backward()
    return loss.detach()


@dataclass(frozen=True)
class ShadedData:
    """What every fit of one target from shaded images starts from, computed once (``shaded_data``) so that
    fits differing only in how they fit (optimiser, gradient, steps) share it: the ``target`` Mesh, the training
    ``cameras`` and their exact shaded images ``targets`` (N, H, W, 3), the visual ``hull`` carved from their
    masks on a ``resolution``³ grid (None: not carved), the ``held_out`` cameras with the target's hard
    silhouettes ``held_out_masks`` (M, H, W) and its 4 x 4-sampled shaded images ``held_out_images``
    (M, H, W, 3), the ``background``, and the hull's own held-out IoU and PSNR (``hull_iou``, ``hull_psnr``)."""
    target: Mesh
    cameras: list
    targets: torch.Tensor
    hull: Mesh | None
    resolution: int
    held_out: list
    held_out_masks: torch.Tensor
    held_out_images: torch.Tensor
    background: tuple
    hull_iou: float | None
    hull_psnr: float | None

    def scores(self, mesh) -> tuple[torch.Tensor, float]:
        """(per-view held-out IoU (M,), mean held-out PSNR in dB) of ``mesh`` against the target."""
        iou = losses.iou(hard_silhouettes(mesh, self.held_out), self.held_out_masks.to(mesh.verts.dtype))
        pred = shaded_images(mesh, self.held_out, background=self.background, exact=False)
        psnr = torch.stack([losses.psnr(p.clamp(0, 1), t) for p, t in zip(pred, self.held_out_images.to(pred.dtype))])
        return iou, float(psnr.mean())


def shaded_data(target_mesh, *, n_views: int = 12, size: int = 64, resolution: int = 48, background=SKY,
                held_out=None, hull: bool = True) -> ShadedData:
    """The data of ``fit_mesh_from_images`` (its docstring says what each piece is), computed once: pass it as
    ``data=`` to fits of the same target that differ only in how they fit. ``hull=False`` skips the carving
    (fits that start from a sphere)."""
    from . import carve
    if not isinstance(target_mesh, Mesh):
        raise ValueError(f"target_mesh must be a Mesh, got {type(target_mesh).__name__}")
    n_views = _check_count(n_views, "n_views")
    resolution = _check_count(resolution, "resolution")
    dtype, device = target_mesh.verts.dtype, target_mesh.verts.device
    like = dict(size=_check_count(size, "size"), dtype=dtype, device=device)
    cameras = sphere_views(n_views, offset=1.9, **like)
    held_out = sphere_views(16, **like) if held_out is None else _check_cameras(held_out, "held_out")
    carved = (carve.carve(coverage_masks(target_mesh, cameras), cameras, resolution).to(device=device, dtype=dtype)
              if hull else None)
    data = ShadedData(target_mesh, cameras, shaded_images(target_mesh, cameras, background=background), carved,
                      resolution, held_out, hard_silhouettes(target_mesh, held_out),
                      shaded_images(target_mesh, held_out, background=background, exact=False),
                      tuple(background) if not torch.is_tensor(background) else background, None, None)
    if carved is None:
        return data
    iou, psnr = data.scores(carved)
    return ShadedData(**{**data.__dict__, "hull_iou": float(iou.mean()), "hull_psnr": psnr})


def fit_mesh_from_images(target_mesh, *, n_views: int = 12, seed: int = 0, size: int = 64, steps: int = 150,
                         gradient: str = "soft", optimizer: str = "large_steps", lam: float = 10.0,
                         lr: float = 0.005, start: str = "hull", resolution: int = 48, subdivisions: int = 4,
                         sigma: float = 3e-5, sigma_end: float | None = 3e-6, gamma: float = 1e-2,
                         laplacian: float = 0.0, smoothness: float = 0.0, background=SKY, held_out=None,
                         snapshot_every: int | None = 10, progress: bool = True,
                         data: ShadedData | None = None) -> ImageFit:
    """A mesh from shaded images of ``target_mesh``: carve, then fit the shading.

    The data: ``n_views`` images (``sphere_views(n_views, offset=1.9)``, ``size`` x ``size``, distance 3, 40°)
    of the target flat-shaded by a light fixed in the world (``shaded_face_colors``: the concavities show as
    shading) on a ``background`` far from every shade, box-filtered exactly (``shaded_images``), and the same
    views' coverage masks. Two stages:

    1. ``start="hull"``: the visual hull of the masks (``carve.carve``, a ``resolution``³ grid), a closed mesh
       that already has the handle's hole (seen through from the side) but none of the concavities; or
       ``start="sphere"``: ``models.icosphere(subdivisions, 0.5)``, which cannot open a hole.
    2. ``steps`` steps on the image term ``Σ_views mean (image - target)² / N`` (+ ``laplacian`` ·
       ``losses.laplacian_loss`` + ``smoothness`` · ``losses.smoothness_loss``, off by default), the face
       colours recomputed from the current normals every step (so shading moves the surface). ``gradient``:
       ``"soft"``, soft rasterization (sharpness ``sigma`` → ``sigma_end`` geometrically, depth softmax
       ``gamma``), or ``"reynolds"``: the exact box-filtered image and lecture 09's boundary gradient
       (``_reynolds_backward``; no blur, about 20 times the cost of a soft step). ``optimizer``: ``"large_steps"``
       (``large_steps.Parameterization`` with λ = ``lam`` and ``UniformAdam``, learning rate ``lr``) or
       ``"adam"`` (Adam on a per-vertex offset, learning rate ``lr``).

    The defaults (λ = 10; λ = 3 and 30 end at the same Chamfer distance and normal consistency to 0.002
    points of percent and 0.001, the larger fitting the images less closely) reach, on ``models.teapot()`` at
    64², Chamfer < 0.5 % of the diagonal, normal consistency > 0.95 and held-out IoU > 0.96 with no
    self-intersections in about a minute (``python -m course bench fit --only images``). held_out: cameras for
    the metrics (None: ``sphere_views(16)`` at ``size``). seed: the sphere start's jitter (``start_verts``; the
    hull is used as carved). resolution: the carving grid's points a side; subdivisions: the sphere's.
    data: the images, the hull and the held-out references computed once by ``shaded_data`` (its settings then
    replace ``n_views``, ``size``, ``resolution``, ``background`` and ``held_out``; the same results as without
    it). Returns an ``ImageFit``.
    """
    from . import large_steps
    _check_common(steps, lr, "soft", snapshot_every)
    if not isinstance(target_mesh, Mesh):
        raise ValueError(f"target_mesh must be a Mesh, got {type(target_mesh).__name__}")
    if gradient not in GRADIENTS:
        raise ValueError(f"gradient must be one of {GRADIENTS}, got {gradient!r}")
    if optimizer not in ("adam", "large_steps"):
        raise ValueError(f'optimizer must be "adam" or "large_steps", got {optimizer!r}')
    if start not in ("hull", "sphere"):
        raise ValueError(f'start must be "hull" or "sphere", got {start!r}')
    for name, w in (("laplacian", laplacian), ("smoothness", smoothness), ("gamma", gamma)):
        if isinstance(w, bool) or not (isinstance(w, (int, float)) and math.isfinite(w) and w >= 0):
            raise ValueError(f"{name} must be a non-negative number, got {w!r}")
    if data is None:
        data = shaded_data(target_mesh, n_views=n_views, size=size, resolution=resolution, background=background,
                           held_out=held_out, hull=start == "hull")
    elif not isinstance(data, ShadedData) or data.target is not target_mesh:
        raise ValueError("data must be shaded_data(target_mesh, ...) of this very target_mesh")
    elif start == "hull" and data.hull is None:
        raise ValueError('start="hull" needs data carved with the hull: shaded_data(..., hull=True)')
    dtype, device = target_mesh.verts.dtype, target_mesh.verts.device
    cameras, targets, background = data.cameras, data.targets, data.background        # targets: (N, H, W, 3)
    sigmas = _schedule(sigma, sigma_end, steps)
    if start == "hull":
        first = data.hull
    else:
        first = models.icosphere(subdivisions, 0.5, dtype=dtype, device=device)
    # the sphere is jittered off its symmetric tie (``start_verts``); the hull needs none, and jitter would
    # fold its smallest triangles through each other
    base, faces = start_verts(first, seed) if start == "sphere" else (first.verts, first.faces)
    if optimizer == "large_steps":
        param = large_steps.Parameterization(base, faces, lam)
        opt = large_steps.UniformAdam([param.u], lr=lr)
        current = lambda: param.verts().to(dtype)                          # noqa: E731
    else:
        offset = torch.zeros_like(base, requires_grad=True)
        opt = torch.optim.Adam([offset], lr=lr)
        current = lambda: base + offset                                     # noqa: E731

    def image_loss(image, target):
        return (image - target).square().mean() / len(cameras)

    history = FitHistory(metrics={"image_loss": []})
    bar = _progress(steps, progress, f"fit_mesh_from_images ({gradient}, {optimizer})")
    for step in range(steps + 1):
        verts = current()
        if _snap_due(step, steps, snapshot_every):
            history.snapshot_steps.append(step)
            history.snapshots.append(verts.detach().clone())
        if step == steps:
            break
        mesh = Mesh(verts, faces)
        colors = shaded_face_colors(mesh)
        regular = verts.new_zeros(())
        if laplacian:
            regular = regular + laplacian * losses.laplacian_loss(verts, faces)
        if smoothness:
            regular = regular + smoothness * losses.smoothness_loss(verts, faces)
        opt.zero_grad()
        if gradient == "soft":
            images = soft_rasterize(mesh, cameras, mode="color", sigma=sigmas[step], gamma=gamma,
                                    face_colors=colors, background=background)   # (N, H, W, 3), one call
            term = sum(image_loss(image, t) for image, t in zip(images, targets))
            (term + regular).backward()
        else:
            if regular.requires_grad:
                regular.backward(retain_graph=True)
            term = _reynolds_backward(image_loss, verts, faces, colors, cameras, targets, background)
        opt.step()
        history.loss.append(float(term.detach() + regular.detach()))
        history.metrics["image_loss"].append(float(term.detach()))
        bar.update(1)
        bar.set_postfix(loss=f"{history.loss[-1]:.5f}")
    bar.close()
    fitted, begun = Mesh(current().detach(), faces), Mesh(base, faces)
    per_view, psnr = data.scores(fitted)
    if start == "hull":                                                   # the hull's scores, computed once
        start_iou, start_psnr = data.hull_iou, data.hull_psnr
    else:
        start_views, start_psnr = data.scores(begun)
        start_iou = float(start_views.mean())
    return ImageFit(fitted, begun, history, start_iou, float(per_view.mean()), per_view, start_psnr, psnr)

def shaded_face_colors(mesh, light=(0.4, 0.8, 0.45), albedo=(0.85, 0.6, 0.35), ambient: float = 0.15) -> torch.Tensor:
    """(F, 3) flat Lambert colours ``albedo (ambient + (1 - ambient) max(0, n·l))`` under a directional light
    fixed in the world (``light`` points toward it): a shaded image whose colours do not depend on the camera,
    so every visibility method of lecture 09 can differentiate it. Differentiable in ``mesh.verts`` (a mesh fit
    from shaded images moves the shading with the surface)."""
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a Mesh, got {type(mesh).__name__}")
    n = mesh.face_normals()
    d = as_tensor(light, dtype=n.dtype, device=n.device, name="light")
    _check_shape(d, (3,), "light")
    if float(d.norm()) == 0:
        raise ValueError("light must be a non-zero direction (toward the light)")
    lam = (n @ (d / d.norm())).clamp(min=0)
    a = as_tensor(albedo, dtype=n.dtype, device=n.device, name="albedo")
    _check_shape(a, (3,), "albedo")
    ambient = _check_real(ambient, "ambient", low=0, high=1)
    return a * (ambient + (1 - ambient) * lam)[:, None]
