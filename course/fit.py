"""Optimisation loops for inverse rendering (lecture 10): a mesh from silhouettes, a camera from an image.

Every loop is seeded, shows a ``tqdm.auto`` progress bar (silenced by ``progress=False`` or the
environment variable ``TQDM_DISABLE=1``), and returns a result whose ``.history`` holds the loss at every
step and snapshots at chosen steps, so a notebook can plot the curve and animate the fit.

**A mesh from silhouettes** (Kato et al. 2018, "optimizing mesh to match a projection";
``fit_silhouettes``). The target silhouettes are the *hard* rasterizer's coverage masks of the target
mesh (0 / 1 per pixel centre, back faces kept, so an open mesh such as the teapot shows no holes). The
fitted mesh is a closed, welded icosphere (``models.icosphere``) moved by a per-vertex offset, the only
parameter, optimised with Adam. Each step renders the current mesh from every training view with a
differentiable rasterizer, soft rasterization (``method="soft"``, Liu et al. 2019) or the Neural 3D Mesh
Renderer's approximate gradient (``method="nmr"``), and minimises

    L = Σ_views L_sl(ŝ, s) / N  +  smoothness · L_sm  +  laplacian · L_lap  +  edge_length · L_edge

(``course.losses``: Kato et al.'s IoU loss, their smoothness loss, the uniform Laplacian and the
edge-length variance). The metric is the mean IoU of hard renders of the fitted and target meshes over
held-out views (``sphere_views``: a Fibonacci spiral, disjoint from the training ring), at the training
resolution.

**A camera from one image** (``fit_camera``). Intrinsics known; the pose is parameterised about the start
camera, object-centred: the world is first turned about the point ``target`` by ``Q = exp([ω]ₓ)``
(axis-angle ω in world axes, starting at 0, so no singularity near the start, unlike Euler angles), then
seen by the start camera, then shifted by ``s`` in camera space:
``x_cam = R_start (target + Q (x - target)) + t_start + s``, i.e. ``R = R_start Q``. Turning ω orbits the
camera about the object (the silhouette changes shape but stays put), and ``s`` moves the image; with
the rotation about the camera's own centre instead (``R_start exp([ω]ₓ)``, centre free) a silhouette fit
from 30° away stalls in a local minimum that re-centres the image by turning the camera in place
(measured: the error grew from 30° to 35°). The loss is the IoU loss on a silhouette reference (H, W) or the
L2 loss on a colour reference (H, W, C). Errors are the geodesic rotation angle in degrees and
``|c - c_ref| / |c_ref - target|`` in percent of the reference's viewing distance.

Five gradients drive the same loop (``CAMERA_METHODS``): soft rasterization and NMR (lecture 08), the hard
rasterizer with plain autograd (zero: the camera never moves), and lecture 09's boundary integral of the
box-filtered image, exactly (``"reynolds"``) or by ``"edge_sampling"``. ``camera_problem()`` builds the
comparison of lecture 10: the teapot, shaded by a light fixed in the world (``shaded_face_colors``: flat
colours that do not depend on the camera), a reference camera, and a start 30° away about the world's
vertical axis.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import torch

from . import losses, models
from .camera import Camera, axis_angle_to_matrix
from .mesh import Mesh
from .raster import rasterize
from .nmr import nmr_rasterize
from .soft import soft_rasterize
from .tensors import _check_count, _check_real, _check_shape, as_tensor

__all__ = ["FitHistory", "SilhouetteFit", "CameraFit", "circle_views", "sphere_views", "hard_silhouettes",
           "held_out_iou", "fit_silhouettes", "fit_mesh_from_silhouettes", "CAMERA_METHODS", "shaded_face_colors",
           "camera_problem", "fit_camera", "rotation_error", "center_error", "self_intersections", "ImageFit",
           "fit_mesh_from_images", "ShadedData", "shaded_data", "shaded_images", "held_out_psnr", "coverage_masks",
           "GRADIENTS", "SKY"]

_METHODS = ("soft", "nmr")


# ------------------------------------------------------------------------------------------ histories

@dataclass
class FitHistory:
    """What a loop recorded. ``loss``: one float per step (the total loss *before* that step's update);
    ``snapshot_steps``: the steps at which ``snapshots`` were taken (step k is the state before update k;
    step ``steps`` is the final state); ``snapshots``: detached copies (vertices (V, 3) for a mesh fit,
    rendered images (H, W) or (H, W, C) for a camera fit); ``metrics``: named series, one value per step
    (``steps`` or ``steps + 1`` entries, e.g. the rotation error of a camera fit) or one per snapshot
    (``len(snapshot_steps)`` entries, e.g. a held-out PSNR measured only at snapshots); ``viz.fit.plot_history``
    tells them apart by length."""
    loss: list = field(default_factory=list)
    snapshot_steps: list = field(default_factory=list)
    snapshots: list = field(default_factory=list)
    metrics: dict = field(default_factory=dict)


@dataclass
class SilhouetteFit:
    """``mesh``: the fitted Mesh (target's world frame); ``history``; ``start_iou`` / ``iou``: the held-out
    mean IoU of the start sphere and of the result; ``per_view_iou``: (N,) the result's held-out IoUs."""
    mesh: Mesh
    history: FitHistory
    start_iou: float
    iou: float
    per_view_iou: torch.Tensor


@dataclass
class CameraFit:
    """``camera``: the fitted Camera; ``history`` (metrics ``"rotation_deg"`` and ``"center_pct"`` per step
    when a reference camera was given); the final errors, or None without a reference camera."""
    camera: Camera
    history: FitHistory
    rotation_error_deg: float | None = None
    center_error_pct: float | None = None


# ---------------------------------------------------------------------------------------------- views

def circle_views(n: int, *, distance: float = 3.0, elevations=(25.0, -25.0), size: int = 64, fov_y: float = 40.0,
                 target=(0.0, 0.0, 0.0), dtype=None, device=None) -> list:
    """``n`` cameras looking at ``target``, azimuths evenly spaced over 360°, elevations (degrees) taking turns
    from ``elevations`` (so 8 views alternate above and below). size: the square image's side in pixels."""
    n = _check_count(n, "n")
    distance = _check_real(distance, "distance", low=0, low_open=True)
    elevations = _check_elevations(elevations)
    cams = []
    for k in range(n):
        az, el = 2 * math.pi * k / n, math.radians(elevations[k % len(elevations)])
        eye = (distance * math.cos(el) * math.sin(az), distance * math.sin(el), distance * math.cos(el) * math.cos(az))
        cams.append(_look(eye, target, size, fov_y, dtype, device))
    return cams


def sphere_views(n: int = 16, *, distance: float = 3.0, size: int = 64, fov_y: float = 40.0, target=(0.0, 0.0, 0.0),
                 offset: float = 0.3, dtype=None, device=None) -> list:
    """``n`` cameras spread evenly over the sphere (a Fibonacci spiral, offset by half a step so that no view
    coincides with a ``circle_views`` view): the held-out views."""
    n = _check_count(n, "n")
    distance = _check_real(distance, "distance", low=0, low_open=True)
    offset = _check_real(offset, "offset")
    golden = math.pi * (3 - math.sqrt(5))
    cams = []
    for k in range(n):
        y = 1 - 2 * (k + 0.5) / n
        r = math.sqrt(max(0.0, 1 - y * y))
        az = golden * k + offset
        cams.append(_look((distance * r * math.sin(az), distance * y, distance * r * math.cos(az)), target, size,
                          fov_y, dtype, device))
    return cams


def _check_elevations(elevations) -> list:
    """A non-empty sequence of elevations in degrees, each in (-90, 90)."""
    if isinstance(elevations, (int, float)) or not hasattr(elevations, "__len__") or len(elevations) == 0:
        raise ValueError(f"elevations must be a non-empty sequence of angles in degrees, got {elevations!r}")
    return [_check_real(e, "elevations", low=-90, high=90, low_open=True, high_open=True) for e in elevations]


def _check_cameras(cameras, name: str = "cameras") -> list:
    if not isinstance(cameras, (list, tuple)) or len(cameras) == 0 or not all(isinstance(c, Camera) for c in cameras):
        raise ValueError(f"{name} must be a non-empty list of Camera")
    return list(cameras)


def _look(eye, target, size, fov_y, dtype, device):
    # up = +y, unless the view is (nearly) vertical: then +z
    d = [e - t for e, t in zip(eye, target)]
    horizontal = math.hypot(d[0], d[2]) / max(math.sqrt(sum(x * x for x in d)), 1e-12)
    up = (0.0, 1.0, 0.0) if horizontal > 1e-3 else (0.0, 0.0, 1.0)
    return Camera.look_at(eye, target, up, fov_y=fov_y, width=size, height=size,
                          dtype=dtype or torch.float32, device=device)


def hard_silhouettes(mesh, cameras) -> torch.Tensor:
    """(N, H, W) 0 / 1 coverage of the hard rasterizer (back faces kept), one per camera; no gradient."""
    cameras = _check_cameras(cameras)
    if len({(c.height, c.width) for c in cameras}) != 1:
        raise ValueError("all cameras must have the same image size")
    with torch.no_grad():
        return torch.stack([rasterize(mesh, c, cull_backfaces=False).mask.to(mesh.verts.dtype) for c in cameras])


def held_out_iou(mesh, target_mesh, cameras) -> torch.Tensor:
    """(N,) ``losses.iou`` of the hard silhouettes of ``mesh`` and ``target_mesh`` from each camera."""
    return losses.iou(hard_silhouettes(mesh, cameras), hard_silhouettes(target_mesh, cameras).to(mesh.verts.dtype))


def self_intersections(mesh) -> torch.Tensor:
    """(K, 2) pairs of faces (f < g) of ``mesh`` that cross each other and share no vertex position: where a
    fit without a regulariser has folded through itself.

    Candidates come from ``discontinuities._intersecting_faces`` (a grid, then each face having corners on both
    sides of the other's plane, conservative); a pair counts when an edge of one, as a segment, passes
    through the other (the watertight ray-triangle test with the edge as the ray, 0 <= t <= 1).
    """
    from .discontinuities import _intersecting_faces
    from .boundary import _weld
    from .intersect import intersect_triangles
    if not isinstance(mesh, Mesh):
        raise ValueError(f"mesh must be a Mesh, got {type(mesh).__name__}")
    verts, faces = mesh.verts.detach(), mesh.faces
    f, g = _intersecting_faces(verts, faces, _weld(verts))
    if f.numel() == 0:
        return torch.zeros(0, 2, dtype=torch.int64, device=faces.device)
    crossing = torch.zeros(f.shape, dtype=torch.bool, device=faces.device)
    for a, b in ((f, g), (g, f)):                                          # edges of a through triangle b
        tri = verts[faces[b]]
        for k in range(3):
            p, q = verts[faces[a, k]], verts[faces[a, (k + 1) % 3]]
            t, _, hit = intersect_triangles(p, q - p, tri)
            crossing |= hit & (t >= 0) & (t <= 1)
    pairs = torch.stack([torch.minimum(f, g), torch.maximum(f, g)], 1)[crossing]
    return torch.unique(pairs, dim=0)


# ------------------------------------------------------------------------------------------ helpers

def _progress(total, progress, desc):
    from tqdm.auto import tqdm
    disable = (not progress) or os.environ.get("TQDM_DISABLE", "").lower() not in ("", "0", "false")
    return tqdm(total=total, desc=desc, disable=disable, leave=False)


def _check_common(steps, lr, method, snapshot_every):
    if isinstance(steps, bool) or not (isinstance(steps, int) and steps >= 0):
        raise ValueError(f"steps must be a non-negative integer, got {steps!r}")
    if isinstance(lr, bool) or not (isinstance(lr, (int, float)) and math.isfinite(lr) and lr > 0):
        raise ValueError(f"lr must be a positive finite number, got {lr!r}")
    if method not in _METHODS:
        raise ValueError(f"method must be one of {_METHODS}, got {method!r}")
    if snapshot_every is not None and (isinstance(snapshot_every, bool) or
                                       not (isinstance(snapshot_every, int) and snapshot_every >= 1)):
        raise ValueError(f"snapshot_every must be a positive integer or None, got {snapshot_every!r}")


def _silhouettes(mesh, cameras, method, sigma):
    """(N, H, W) the silhouettes of the views: soft, all in one call (a camera batch); NMR, one by one."""
    if method == "soft":
        return soft_rasterize(mesh, cameras, mode="silhouette", sigma=sigma, cull_backfaces=False)
    return torch.stack([nmr_rasterize(mesh, c, cull_backfaces=False) for c in cameras])


def start_verts(start, seed) -> tuple:
    """(verts (V, 3), faces (F, 3)) of the Mesh ``start`` with a small seeded jitter (2e-3 of its radius about
    the origin, uniform per coordinate): the starting shape of every silhouette fit, so runs with one seed are
    identical and the symmetric sphere does not sit exactly on a tie."""
    gen = torch.Generator(device="cpu").manual_seed(_check_count(seed, "seed", minimum=0))
    base = start.verts.detach()
    scale = float(base.norm(dim=1).max())
    jitter = (torch.rand(base.shape, generator=gen, dtype=torch.float64) - 0.5).to(dtype=base.dtype,
                                                                                  device=base.device)
    return base + 2e-3 * scale * jitter, start.faces


def _schedule(start, end, steps):
    """steps + 1 values from start to end, geometrically (all ``start`` when end is None)."""
    for name, v in (("sigma", start), ("sigma_end", end)):
        if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a positive finite number, got {v!r}")
    if start is None:
        raise ValueError("sigma must be a positive finite number, got None")
    if end is None or steps == 0:
        return [float(start)] * (steps + 1)
    return [float(start) * (end / start) ** (k / steps) for k in range(steps + 1)]


def _snap_due(step, steps, snapshot_every):
    return snapshot_every is not None and (step % snapshot_every == 0 or step == steps)


# --------------------------------------------------------------------------------- mesh from silhouettes

def fit_silhouettes(target_mesh, cameras, *, steps: int = 200, method: str = "soft", lr: float = 0.01,
                    smoothness: float = 0.0005, laplacian: float = 0.0, edge_length: float = 0.0,
                    sigma: float = 3e-4, sigma_end: float | None = 3e-5, lr_end: float = 1.0,
                    seed: int = 0, start=None, subdivisions: int = 3,
                    radius: float = 0.5, held_out=None, snapshot_every: int | None = 10,
                    progress: bool = True, optimizer: str = "adam", lam: float = 20.0) -> SilhouetteFit:
    """Deform a sphere so that its silhouettes from ``cameras`` match those of ``target_mesh``.

    Args:
        target_mesh: a Mesh (``verts`` (V, 3), ``faces`` (F, 3)); only its hard silhouettes are used.
        cameras: a non-empty list of ``Camera`` (the training views), all of one image size; for ``"soft"``
            also of one near, far and projection (each step renders them in one call, a camera batch).
        steps: Adam steps. method: ``"soft"`` (soft rasterization, sharpness ``sigma`` in NDC units, see
            ``course.soft``) or ``"nmr"`` (hard forward, Kato et al.'s approximate gradient).
        lr: Adam's learning rate on the per-vertex offset (world units); ``lr_end``: it decays
            exponentially to this fraction of itself by the last step (1: constant).
        sigma, sigma_end: soft rasterization's sharpness, annealed geometrically from ``sigma`` to
            ``sigma_end`` (None: constant). Blurred silhouettes pull the sphere from afar, sharp ones pin the
            detail: on the teapot, 3e-4 → 3e-5 reaches held-out IoU 0.925 where a constant 3e-4 stops at 0.880.
        smoothness, laplacian, edge_length: weights of ``losses.smoothness_loss`` (Kato et al.),
            ``losses.laplacian_loss`` (uniform) and ``losses.edge_length_loss``; 0 turns a term off.
            The silhouette term is the IoU loss averaged over views.
        seed: seeds the small random jitter added to the start (1e-3 of the radius), so runs with one seed
            are identical and different seeds differ.
        start: a Mesh to deform instead of the sphere (it should be closed and welded), or None for
            ``models.icosphere(subdivisions, radius)``.
        held_out: cameras for the metric, or None for ``sphere_views(16)`` at the training image size.
        snapshot_every: keep the vertices every this many steps (and the last); None: none.
        progress: show a tqdm bar (``TQDM_DISABLE=1`` also hides it).
        optimizer: ``"adam"`` (Adam on a per-vertex offset) or ``"large_steps"`` (Nicolet et al.: the vertices
            as u = (I + λL) v, stepped by ``large_steps.UniformAdam`` with learning rate ``lr``; ``lam`` is λ).

    Returns a ``SilhouetteFit``; ``history.loss`` has ``steps`` entries, ``history.metrics["iou_loss"]`` the
    silhouette term alone.
    """
    _check_common(steps, lr, method, snapshot_every)
    if not isinstance(cameras, (list, tuple)) or len(cameras) == 0 or not all(isinstance(c, Camera) for c in cameras):
        raise ValueError("cameras must be a non-empty list of Camera")
    if len({(c.height, c.width) for c in cameras}) != 1:
        raise ValueError("all cameras must have the same image size")
    if not isinstance(target_mesh, Mesh):
        raise ValueError(f"target_mesh must be a Mesh, got {type(target_mesh).__name__}")
    for name, w in (("smoothness", smoothness), ("laplacian", laplacian), ("edge_length", edge_length)):
        if not (isinstance(w, (int, float)) and math.isfinite(w) and w >= 0):
            raise ValueError(f"{name} must be a non-negative number, got {w!r}")
    if not (isinstance(sigma, (int, float)) and math.isfinite(sigma) and sigma > 0):
        raise ValueError(f"sigma must be a positive finite number, got {sigma!r}")
    dtype, device = target_mesh.verts.dtype, target_mesh.verts.device
    if start is None:
        start = models.icosphere(subdivisions, radius, dtype=dtype, device=device)
    elif not isinstance(start, Mesh):
        raise ValueError(f"start must be a Mesh or None, got {type(start).__name__}")
    H, W = cameras[0].height, cameras[0].width
    if held_out is None:
        held_out = sphere_views(16, size=W, dtype=cameras[0].dtype, device=device) if H == W else None
        if held_out is None:
            raise ValueError("non-square training images: pass held_out cameras")

    base, faces = start_verts(start, seed)
    base = base.to(dtype)
    targets = hard_silhouettes(target_mesh, cameras).to(dtype)              # (N, H, W)
    if optimizer not in ("adam", "large_steps"):
        raise ValueError(f'optimizer must be "adam" or "large_steps", got {optimizer!r}')
    if optimizer == "large_steps":
        from .large_steps import Parameterization, UniformAdam
        param = Parameterization(base, faces, lam)
        opt = UniformAdam([param.u], lr=lr)
        current = param.verts
    else:
        offset = torch.zeros_like(base, requires_grad=True)
        opt = torch.optim.Adam([offset], lr=lr)
        current = lambda: base + offset                                     # noqa: E731
    sched = torch.optim.lr_scheduler.ExponentialLR(opt, gamma=lr_end ** (1 / max(steps, 1)))
    sigmas = _schedule(sigma, sigma_end, steps)
    history = FitHistory(metrics={"iou_loss": []})
    start_iou = held_out_iou(Mesh(base, faces), target_mesh, held_out).mean()

    bar = _progress(steps, progress, f"fit_silhouettes ({method})")
    for step in range(steps + 1):
        verts = current()
        if _snap_due(step, steps, snapshot_every):
            history.snapshot_steps.append(step)
            history.snapshots.append(verts.detach().clone())
        if step == steps:
            break
        mesh = Mesh(verts, faces)
        pred = _silhouettes(mesh, cameras, method, sigmas[step])           # (N, H, W)
        sil = losses.silhouette_iou_loss(pred.clamp(0, 1), targets, reduction="mean")
        loss = sil
        if smoothness:
            loss = loss + smoothness * losses.smoothness_loss(verts, faces)
        if laplacian:
            loss = loss + laplacian * losses.laplacian_loss(verts, faces)
        if edge_length:
            loss = loss + edge_length * losses.edge_length_loss(verts, faces)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        history.loss.append(float(loss.detach()))
        history.metrics["iou_loss"].append(float(sil.detach()))
        bar.update(1)
        bar.set_postfix(loss=f"{history.loss[-1]:.4f}")
    bar.close()
    fitted = Mesh(current().detach(), faces)
    per_view = held_out_iou(fitted, target_mesh, held_out)
    return SilhouetteFit(fitted, history, float(start_iou), float(per_view.mean()), per_view)


def fit_mesh_from_silhouettes(target_mesh, *, n_views: int = 8, seed: int = 0, size: int = 64, steps: int = 300,
                              method: str = "soft", layout: str = "sphere", progress: bool = True,
                              **kwargs) -> SilhouetteFit:
    """The issue's entry point: ``fit_silhouettes`` from ``n_views`` training views at distance 3 with a 40°
    field of view, ``size`` x ``size`` pixels, held out on ``sphere_views(16, size=size)``. layout:
    ``"sphere"``: ``sphere_views(n_views, offset=1.9)`` (spread over the sphere; never at a held-out view,
    since the spirals' heights differ), or ``"ring"``: ``circle_views(n_views)`` (alternating ±25°)."""
    if layout not in ("sphere", "ring"):
        raise ValueError(f'layout must be "sphere" or "ring", got {layout!r}')
    if not isinstance(target_mesh, Mesh):
        raise ValueError(f"target_mesh must be a Mesh, got {type(target_mesh).__name__}")
    n_views = _check_count(n_views, "n_views")
    like = dict(size=size, dtype=target_mesh.verts.dtype, device=target_mesh.verts.device)
    cams = sphere_views(n_views, offset=1.9, **like) if layout == "sphere" else circle_views(n_views, **like)
    return fit_silhouettes(target_mesh, cams, steps=steps, method=method, seed=seed, progress=progress, **kwargs)


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
    from .antialias import supersample
    from .coverage import exact_coverage
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
    from .antialias import supersample
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
    from .coverage import exact_coverage
    from .visibility import image_gradient
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


# ------------------------------------------------------------------------------------ camera from image

def rotation_error(R1, R2) -> float:
    """Geodesic angle between two rotation matrices (3, 3), in degrees."""
    R1, R2 = as_tensor(R1, name="R1").detach().double(), as_tensor(R2, name="R2").detach().double()
    _check_shape(R1, (3, 3), "R1"), _check_shape(R2, (3, 3), "R2")
    c = ((torch.trace(R1.T @ R2.to(R1.device)) - 1) / 2).clamp(-1, 1)
    return math.degrees(float(torch.acos(c)))


def center_error(camera, reference, target=(0.0, 0.0, 0.0)) -> float:
    """``|c - c_ref| / |c_ref - target|`` in percent: camera-centre error relative to the viewing distance."""
    for name, cam in (("camera", camera), ("reference", reference)):
        if not isinstance(cam, Camera):
            raise TypeError(f"{name} must be a Camera, got {type(cam).__name__}")
    c, c_ref = camera.eye.detach().double(), reference.eye.detach().double()
    tgt = torch.as_tensor(target, dtype=torch.float64, device=c.device)
    return 100 * float((c - c_ref).norm() / (c_ref - tgt).norm())


CAMERA_METHODS = ("soft", "nmr", "hard", "reynolds", "edge_sampling")


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


def camera_problem(mesh=None, *, size: int = 64, degrees: float = 30.0, axis=(0.0, 1.0, 0.0),
                   eye=(1.5, 1.0, 2.5), fov_y: float = 40.0, shaded: bool = True, textured: bool = False):
    """The camera fit of lecture 10 and ``bench fit``: (mesh, face_colors, reference_camera, start_camera,
    reference_image).

    mesh: None for ``models.teapot(4)`` in float64 (with its checker texture). The reference camera sits at
    ``eye`` looking at the origin; the start is the reference camera orbited by ``degrees`` about ``axis``
    through the origin (world +y by default, which is not the view axis), looking at the origin again.
    shaded: the reference is the exact box-filtered image (``coverage.exact_coverage``) of
    ``shaded_face_colors`` on a black background, (H, W, 3); otherwise its silhouette, (H, W), and face_colors
    is None. textured: the reference is the course's full pipeline instead, ``render(scene).image`` (H, W, 3)
    of ``scene = Scene(mesh, reference_camera, lights=default_lights())`` (texture, Phong shading, white
    background), and the second item is that Scene, what ``fit_camera(scene, image, start)`` takes.
    """
    from .coverage import exact_coverage
    if mesh is None:
        mesh = models.teapot(4, dtype=torch.float64)
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a Mesh or None, got {type(mesh).__name__}")
    dtype, device = mesh.verts.dtype, mesh.verts.device
    ref_cam = Camera.look_at(eye, fov_y=fov_y, width=size, height=size, dtype=dtype, device=device)
    a = as_tensor(axis, dtype=dtype, device=device, name="axis")
    _check_shape(a, (3,), "axis")
    if float(a.norm()) == 0:
        raise ValueError("axis must be a non-zero vector (the axis the start camera is orbited about)")
    Q = axis_angle_to_matrix(a / a.norm() * math.radians(_check_real(degrees, "degrees")))
    start = Camera.look_at(Q @ ref_cam.eye, fov_y=fov_y, width=size, height=size, dtype=dtype, device=device)
    if textured:
        from .render import Scene, default_lights, render
        if mesh.texture is None:
            raise ValueError("textured=True needs a mesh with a texture and uvs (models.teapot has both)")
        scene = Scene(mesh, ref_cam, lights=default_lights())
        with torch.no_grad():
            return mesh, scene, ref_cam, start, render(scene).image
    colors = shaded_face_colors(mesh) if shaded else torch.ones(mesh.faces.shape[0], 3, dtype=dtype, device=device)
    with torch.no_grad():
        image = exact_coverage(mesh, ref_cam, colors, (0.0, 0.0, 0.0))
    if not shaded:
        return mesh, None, ref_cam, start, image[..., 0].clamp(0, 1)          # rounding: 1 + 1e-15
    return mesh, colors, ref_cam, start, image


SEARCH_AXES = ((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))   # the start's own y, x, z axes: pan, tilt, roll
OVERSAMPLE = 4          # a pyramid level h x w is rendered at up to 4h x 4w pixels and averaged down to it
SIGMA_PX = (0.15, 0.05)  # soft rasterization's default σ in px² of the reference (σ = 4 σ_px / W²), annealed
                        # geometrically from the first to the second over the steps
MIN_LEVEL = 12          # the pyramid's coarsest images are at least this many pixels a side
SILHOUETTE_SIGMA = (1e-3, 3e-5)   # a silhouette's σ, annealed (NDC): its IoU needs the blur to pull from afar


def _render_for_camera(mesh, camera, method, sigma, face_colors, background, gamma=1e-2, scene=None,
                       settings=None):
    """The image a method renders: soft, or the hard one (hard, NMR), or the box-filtered one (Reynolds, edge
    sampling), whose gradient ``_boundary_backward`` supplies instead of autograd. With a ``scene`` (and its
    ``settings``), ``render()``'s own pipeline draws it: ``_render_scene``."""
    if scene is not None:
        return _render_scene(scene, settings, camera, method, sigma, gamma)
    if method in ("reynolds", "edge_sampling"):
        from .coverage import exact_coverage
        colors = face_colors if face_colors is not None else mesh.verts.new_ones(mesh.faces.shape[0], 3)
        with torch.inference_mode():                                        # no graph at all: 15 % faster here
            image = exact_coverage(mesh, _detached(camera), colors, _background3(background, mesh.verts))
        image = image.clone()                                               # an ordinary tensor again
        return image if face_colors is not None else image[..., 0]
    if face_colors is None:
        if method == "soft":
            return soft_rasterize(mesh, camera, mode="silhouette", sigma=sigma, cull_backfaces=False)
        if method == "hard":
            return rasterize(mesh, camera, cull_backfaces=False).mask.to(mesh.verts.dtype)
        return nmr_rasterize(mesh, camera, cull_backfaces=False)
    if method == "soft":                                                    # alpha: no fattening (soft_rasterize)
        return soft_rasterize(mesh, camera, mode="color", sigma=sigma, gamma=gamma, face_colors=face_colors,
                              background=background, cull_backfaces=True, blend="alpha")
    if method == "hard":
        with torch.no_grad():
            return nmr_rasterize(mesh, _detached(camera), face_colors=face_colors, background=background,
                                 cull_backfaces=True)
    return nmr_rasterize(mesh, camera, face_colors=face_colors, background=background, cull_backfaces=True)


def _render_scene(scene, settings, camera, method, sigma, gamma):
    """(H, W, 3) ``render()`` of the scene's meshes, lights, materials and background seen by ``camera``, with
    the reference's settings, its visibility replaced by the method's: ``"soft"`` (``visibility="soft"``:
    Gouraud or flat lighting, the texture read per pixel and face, blended with ``soft_blend="alpha"``, back
    faces culled), ``"nmr"`` (the hard image, NMR's gradient) or ``"hard"`` (the hard image, no gradient)."""
    from dataclasses import replace
    from .render import Scene, render
    if method == "soft":
        settings = replace(settings, visibility="soft", sigma=sigma, gamma=gamma, soft_blend="alpha",
                           cull_backfaces=True, antialias="none", return_depth=False, return_normals=False,
                           return_silhouette=False)
    elif method == "nmr":
        settings = replace(settings, visibility="nmr", antialias="none")
    else:
        settings, camera = replace(settings, visibility="hard"), _detached(camera)
    return render(Scene(scene.meshes, camera, scene.lights, scene.background, scene.materials), settings).image


def _detached(camera):
    return Camera(camera.K.detach(), camera.R.detach(), camera.t.detach(), camera.width, camera.height,
                  camera.near, camera.far, camera.orthographic)


def _background3(background, like):
    bg = torch.as_tensor(background, dtype=like.dtype, device=like.device)
    return bg.expand(3) if bg.dim() == 0 else bg


def _boundary_backward(loss_of, image, mesh, camera, method, face_colors, background, generator, samples):
    """Backpropagate ``loss_of(image)`` into the camera's R and t by the boundary integral of lecture 09
    (``visibility.image_gradient``, method ``"reynolds"`` or ``"edge_sampling"``): dL/dimage are the weights,
    the boundary term turns them into dL/dR and dL/dt, and autograd carries those on into the pose."""
    from .visibility import image_gradient
    leaf = image.detach().requires_grad_(True)
    loss = loss_of(leaf)
    (weights,) = torch.autograd.grad(loss, leaf)
    colors = face_colors if face_colors is not None else mesh.verts.new_ones(mesh.faces.shape[0], 3)
    if face_colors is None:                                                  # a silhouette: channel 0 of (H, W, 3)
        weights = torch.stack([weights, torch.zeros_like(weights), torch.zeros_like(weights)], dim=-1)
    options = {"generator": generator, "samples": samples} if method == "edge_sampling" else {}
    gR, gt = image_gradient(mesh, _detached(camera), colors, weights, method=method,
                            background=_background3(background, mesh.verts), wrt=("R", "t"), **options)
    pairs = [(x, g.to(x.dtype)) for x, g in ((camera.R, gR), (camera.t, gt)) if x.requires_grad]
    if pairs:
        torch.autograd.backward([x for x, _ in pairs], [g for _, g in pairs])
    return loss.detach()


def _pyramid(H, W, levels):
    """[(h, w)] the image sizes of the loss, coarsest first: H x W halved up to ``levels - 1`` times, none with
    a side below ``MIN_LEVEL`` pixels (a smaller teapot is a blob whose loss says nothing)."""
    sizes = [(round(H / 2 ** k), round(W / 2 ** k)) for k in reversed(range(levels))]
    return [s for s in sizes if min(s) >= MIN_LEVEL] or [(H, W)]


def _area(image, size):
    """(h, w) or (h, w, C): ``image`` (H, W) or (H, W, C) averaged over the pixels each coarse pixel covers
    (the box filter of ``adaptive_avg_pool2d``); differentiable; unchanged when it already has that size."""
    if tuple(image.shape[:2]) == tuple(size):
        return image
    x = image[None, None] if image.dim() == 2 else image.permute(2, 0, 1)[None]
    y = torch.nn.functional.adaptive_avg_pool2d(x, size)[0]
    return y[0] if image.dim() == 2 else y.permute(1, 2, 0)


def _scaled(camera, h, w):
    """``camera`` seeing the same view on an h x w image (K's rows scaled; differentiable in R and t)."""
    scale = torch.tensor([[w / camera.width], [h / camera.height], [1.0]], dtype=camera.K.dtype,
                         device=camera.K.device)
    return Camera(camera.K * scale, camera.R, camera.t, w, h, camera.near, camera.far)


def _orbit(camera, axis_cam, degrees, target):
    """``camera`` orbited about the point ``target`` by ``degrees`` about its own axis ``axis_cam`` (camera
    coordinates): R = R Q, with Q the turn about that axis in world coordinates."""
    R, t = camera.R.detach(), camera.t.detach()
    Q = axis_angle_to_matrix(R.T @ torch.tensor(axis_cam, dtype=R.dtype, device=R.device) * math.radians(degrees))
    return Camera(camera.K.detach(), R @ Q, R @ (target - Q @ target) + t, camera.width, camera.height,
                  camera.near, camera.far)


def _candidate_starts(camera, starts, spread, target):
    """The ``starts`` cameras a fit searches from: ``camera``, then ``camera`` orbited about ``target`` by
    +``spread`` and -``spread`` degrees about its y, x and z axes in turn (pan, tilt, roll)."""
    cameras = [camera]
    for axis in SEARCH_AXES:
        cameras += [_orbit(camera, axis, spread, target), _orbit(camera, axis, -spread, target)]
    return cameras[:starts]


@dataclass
class _Path:
    """One start's path: the pose about its start camera (ω: the orbit about ``target``, axis-angle in world
    axes; s: a camera-space shift; both 0 at the start), Adam on them, and what it recorded."""
    start: Camera
    omega: torch.Tensor
    shift: torch.Tensor
    opt: torch.optim.Optimizer
    sched: object
    history: FitHistory

    def camera(self, target, h, w) -> Camera:
        """x_cam = R_start (target + Q (x - target)) + t_start + s, Q = exp([ω]ₓ), on an h x w image."""
        Q = axis_angle_to_matrix(self.omega)
        R0, t0 = self.start.R.detach(), self.start.t.detach()
        cam = Camera(self.start.K.detach(), R0 @ Q, R0 @ (target - Q @ target) + t0 + self.shift,
                     self.start.width, self.start.height, self.start.near, self.start.far)
        return cam if (h, w) == (cam.height, cam.width) else _scaled(cam, h, w)


def _new_path(start, lr, lr_position, decay, metrics) -> _Path:
    dtype, device = start.R.dtype, start.R.device
    omega = torch.zeros(3, dtype=dtype, device=device, requires_grad=True)
    shift = torch.zeros(3, dtype=dtype, device=device, requires_grad=True)
    opt = torch.optim.Adam([{"params": [omega], "lr": lr}, {"params": [shift], "lr": lr_position}])
    sched = torch.optim.lr_scheduler.ExponentialLR(opt, gamma=decay)
    return _Path(start, omega, shift, opt, sched, FitHistory(metrics={k: [] for k in metrics}))


@dataclass
class _CameraProblem:
    """What every step of a camera fit needs: the renderer's arguments, the reference at each pyramid level,
    the level and σ of each step, the loss, and the optional true camera."""
    mesh: object
    scene: object
    settings: object
    method: str
    face_colors: object
    background: object
    gamma: float
    refs: list                  # the reference averaged down to each level, coarsest first
    sizes: list                 # (h, w) of each level
    level_of: list              # the level of each step
    sigmas: list                # soft rasterization's σ at each step (NDC)
    target: torch.Tensor
    reference_camera: object
    generator: torch.Generator
    samples: int
    supersample: int = 1        # samples per pixel side of the full-size image

    def render_size(self, level):
        """The size rendered for a level: ``OVERSAMPLE`` times its own, at most ``supersample`` times the
        reference's; the level's own for the boundary methods (their image is already box-filtered, exactly)."""
        (h, w), (H, W) = self.sizes[level], self.sizes[-1]
        if self.method in ("reynolds", "edge_sampling"):
            return h, w
        f = min(self.supersample, OVERSAMPLE * h / H)
        return max(1, round(H * f)), max(1, round(W * f))

    def render(self, camera, step):
        return _render_for_camera(self.mesh, camera, self.method, self.sigmas[step], self.face_colors,
                                  self.background, self.gamma, self.scene, self.settings)

    def loss(self, image, level):
        small, ref = _area(image, self.sizes[level]), self.refs[level]
        if ref.dim() == 2:
            return losses.silhouette_iou_loss(small.clamp(0, 1), ref)
        return losses.l2_loss(small, ref)


def _fit_step(problem, path, step, snapshot_every, steps) -> float:
    """One Adam step of a path at its pyramid level (or, at ``step == steps``, only the final records)."""
    level = problem.level_of[step]
    cam = path.camera(problem.target, *problem.render_size(level))
    if problem.reference_camera is not None:
        path.history.metrics["rotation_deg"].append(rotation_error(cam.R, problem.reference_camera.R))
        path.history.metrics["center_pct"].append(center_error(cam, problem.reference_camera, problem.target))
    if step == steps:
        if _snap_due(step, steps, snapshot_every):
            with torch.no_grad():
                _snapshot(problem, path, step, step)
        return math.nan
    image = problem.render(cam, step)
    if _snap_due(step, steps, snapshot_every):
        _snapshot(problem, path, step, step, image.detach())
    path.opt.zero_grad()
    if problem.method in ("reynolds", "edge_sampling"):
        loss = _boundary_backward(lambda im: problem.loss(im, level), image, problem.mesh, cam, problem.method,
                                  problem.face_colors, problem.background, problem.generator, problem.samples)
    else:
        loss = problem.loss(image, level)
        if loss.requires_grad:                                              # the hard image has no gradient:
            loss.backward()                                                 # Adam sees zeros and stays put
    path.opt.step()
    path.sched.step()
    path.history.loss.append(float(loss.detach()))
    return path.history.loss[-1]


def _snapshot(problem, path, step, sigma_step, image=None):
    """Keep the model's image at the reference's full size: the step's own, averaged down if supersampled, or
    rendered again as the last level renders it when the step's level drew less."""
    (H, W) = problem.sizes[-1]
    if image is None or image.shape[0] < H:
        with torch.no_grad():
            image = problem.render(path.camera(problem.target, *problem.render_size(len(problem.sizes) - 1)),
                                   sigma_step)
    path.history.snapshot_steps.append(step)
    path.history.snapshots.append(_area(image.detach(), (H, W)).clone())


def _score(problem, path, step) -> float:
    """A path's loss at the level of ``step`` without a step taken: how the search ranks its starts."""
    level = problem.level_of[step]
    with torch.no_grad():
        image = problem.render(path.camera(problem.target, *problem.render_size(level)), step)
        return float(problem.loss(image, level))


def _check_fit_camera(mesh, camera_start, method, render_settings, reference_camera, samples, lr_end, starts,
                      spread, levels, search_steps, steps):
    """The checks of ``fit_camera``'s arguments (a ValueError naming the one that is wrong)."""
    from .render import RenderSettings, Scene
    if method not in CAMERA_METHODS:
        raise ValueError(f"method must be one of {CAMERA_METHODS}, got {method!r}")
    if not (isinstance(samples, int) and samples >= 1):
        raise ValueError(f"samples must be a positive integer, got {samples!r}")
    if not (isinstance(lr_end, (int, float)) and 0 < lr_end <= 1):
        raise ValueError(f"lr_end must lie in (0, 1], got {lr_end!r}")
    if not isinstance(camera_start, Camera):
        raise ValueError(f"camera_start must be a Camera, got {type(camera_start).__name__}")
    if camera_start.orthographic:
        raise ValueError("fit_camera needs a perspective camera_start")
    if reference_camera is not None and not isinstance(reference_camera, Camera):
        raise ValueError(f"reference_camera must be a Camera or None, got {type(reference_camera).__name__}")
    if not isinstance(mesh, (Mesh, Scene)):
        raise ValueError(f"mesh must be a Mesh, or the Scene that rendered the reference, got {type(mesh).__name__}")
    if render_settings is not None and not isinstance(render_settings, RenderSettings):
        raise ValueError(f"render_settings must be a RenderSettings or None, got {type(render_settings).__name__}")
    if render_settings is not None and not isinstance(mesh, Scene):
        raise ValueError("render_settings go with a Scene: pass the Scene that rendered the reference as mesh")
    if isinstance(mesh, Scene) and method == "soft":
        _check_soft_scene(render_settings or RenderSettings())
    most = 1 + 2 * len(SEARCH_AXES)
    if starts is not None and not (isinstance(starts, int) and not isinstance(starts, bool) and 1 <= starts <= most):
        raise ValueError(f"starts must be None or an integer from 1 to {most}, got {starts!r}")
    _check_real(spread, "spread (degrees)", low=0, high=180, low_open=True)
    if levels is not None:
        _check_count(levels, "levels")
    if search_steps is not None and not (isinstance(search_steps, int) and not isinstance(search_steps, bool)
                                         and 0 <= search_steps <= steps):
        raise ValueError(f"search_steps must be None or an integer from 0 to steps ({steps}), got {search_steps!r}")


def _check_soft_scene(settings):
    """The reference's settings that soft rasterization can draw (a ValueError naming what it cannot)."""
    from .render import SOFT_SHADING
    cannot = [what for what, on in (("shadows", settings.shadows != "none"), ("a wireframe", settings.wireframe),
                                    (f"shading={settings.shading!r}", settings.shading not in SOFT_SHADING)) if on]
    if cannot:
        raise ValueError(f"fit_camera(method='soft') draws the scene by soft rasterization, which cannot draw "
                         f"{' or '.join(cannot)}: use method='nmr' (the hard image, Kato et al.'s gradient)")


def _check_reference(mesh, ref, camera_start, method, face_colors):
    """The reference image against the mesh or scene, the method and the colours."""
    from .render import Scene
    H, W = camera_start.height, camera_start.width
    if ref.dim() not in (2, 3):
        raise ValueError(f"reference_image must be (H, W) or (H, W, C), got shape {tuple(ref.shape)}")
    if tuple(ref.shape[:2]) != (H, W):
        raise ValueError(f"reference_image must be {H}x{W} like camera_start, got {tuple(ref.shape[:2])}")
    if not torch.isfinite(ref).all():
        raise ValueError("reference_image contains NaN or inf")
    if isinstance(mesh, Scene):
        if method in ("reynolds", "edge_sampling"):
            raise ValueError(f"method {method!r} differentiates flat face colours (coverage.exact_coverage), not a "
                             "Scene's textures and lights: pass the Mesh with face_colors that do not depend on the "
                             "camera, e.g. course.fit.shaded_face_colors(mesh), and a reference drawn with them "
                             "(course.fit.camera_problem())")
        if face_colors is not None:
            raise ValueError("a Scene brings its own colours (textures, lights, materials): give no face_colors")
        if ref.dim() != 3 or ref.shape[2] != 3:
            raise ValueError(f"a Scene's reference is render(scene).image, (H, W, 3), got shape {tuple(ref.shape)}")
        return
    if ref.dim() == 2 and face_colors is not None:
        raise ValueError("a silhouette reference (H, W) takes no face_colors")
    if ref.dim() == 2 and (ref.min() < 0 or ref.max() > 1):
        raise ValueError("a silhouette reference must hold values in [0, 1]")
    if ref.dim() == 3 and face_colors is None:
        hint = " (the flat colours the boundary methods differentiate)" if method in ("reynolds", "edge_sampling") \
            else ", or pass the Scene that rendered it as mesh: fit_camera(scene, render(scene).image, start)"
        raise ValueError(f"a colour reference (H, W, C) needs face_colors (F, C), e.g. "
                         f"course.fit.shaded_face_colors(mesh){hint}")


def fit_camera(mesh, reference_image, camera_start, *, steps: int = 200, method: str = "soft", lr: float | None = None,
               lr_position: float | None = None, sigma: float | None = None, sigma_end: float | None = None,
               lr_end: float = 0.1, gamma: float = 1e-2, face_colors=None, background=0.0,
               reference_camera=None, target=(0.0, 0.0, 0.0), samples: int = 4000, seed: int = 0,
               snapshot_every: int | None = 10, progress: bool = True, render_settings=None,
               starts: int | None = None, spread: float = 30.0, levels: int | None = None,
               search_steps: int | None = None, supersample: int | None = None) -> CameraFit:
    """Recover a camera pose from one reference image of a known mesh, intrinsics known.

    The reference is a silhouette, an image of flat face colours (``face_colors``, e.g. ``camera_problem()``'s),
    or an image of the course's full pipeline, ``render(scene).image`` of a textured, lit mesh: then pass that
    ``Scene`` as ``mesh`` (its camera is ignored: it is what the fit looks for) and the ``RenderSettings`` it
    was rendered with, and every step renders the scene with ``render()`` itself, the method's visibility in
    place of the z-buffer (``"soft"``: the texture read per pixel and face, times the lighting)::

        scene = Scene(teapot, camera, lights=default_lights())
        fit = fit_camera(scene, render(scene).image, start)

    Three choices make the default fit robust to starts far from the answer (measured on the teapot
    from 12 poses, starts 30-45° away about random axes, flat and textured references: at 96² every fit
    within 2° and 2 % of the distance; at 64² all but the views whose bias, below, exceeds 2 %):

    * **several starts** (``starts``): the start and the start orbited about ``target`` by ±``spread``
      degrees about its own y, x and z axes each run the first ``search_steps`` steps (the coarse half of the
      pyramid); the one with the lowest loss there goes on alone. One start can stall in a view that looks
      alike (the former defaults missed 2° / 2 % from 9 of 20 starts at 96², 13 of 20 at 64²; the pyramid
      with one start, 4 of 16);
    * **a pyramid of image sizes** (``levels``): the loss compares the images averaged down to H/8, H/4,
      H/2 and H (none under ``MIN_LEVEL`` pixels), an equal share of the steps each, coarse to fine. A coarse
      level sees the whole object move, and each level is rendered at up to ``OVERSAMPLE`` times its size
      and averaged down: the blur is a box filter of sharp images, whose minimum stays at the answer, so the
      search can rank the starts by it (a blur by σ fattens a mesh of small faces, and ranked them wrongly);
    * **soft rasterization composited by its silhouette** (``soft_rasterize(..., blend="alpha")``, back faces
      culled), σ annealed from 0.15 to 0.05 px² of the reference (``SIGMA_PX``), the model image made like
      the reference (``supersample``): the paper's softmax, with the background in it, fattens the object at
      γ = 1e-2 and put the camera 1-4 % of its distance too far. What bias is left is under a pixel: the
      probabilistic OR dips to 3/4 on every edge between faces, which thins a mesh of small faces (up to
      2.6 % of the distance at 64², 1.4 % at 96²).

    Args:
        mesh: the Mesh seen in the reference, or the ``course.render.Scene`` that rendered it.
        reference_image: (H, W) silhouette in [0, 1] (IoU loss) or (H, W, C) colours (L2 loss): flat colours
            (needs ``face_colors``) or ``render(scene).image`` (needs the Scene as ``mesh``), the size of
            ``camera_start``'s image.
        camera_start: the initial ``Camera``; K, image size, near and far are kept.
        steps: Adam steps of the path that is returned, the search's included. method: one of
            ``CAMERA_METHODS``, the gradient that drives the pose: ``"soft"`` (soft rasterization),
            ``"nmr"`` (hard image, Kato et al.'s approximate gradient), ``"hard"`` (the hard image and
            autograd: zero gradient, the pose never moves; there for comparison), ``"reynolds"`` /
            ``"edge_sampling"`` (the box-filtered image ``coverage.exact_coverage`` and its gradient by
            lecture 09's boundary integral, exact or from ``samples`` random edge points drawn with ``seed``;
            their faces are flat-coloured, so a colour reference needs face colours that do not depend on the
            camera, ``shaded_face_colors``: a Scene is refused with an error saying so).
        lr: Adam's learning rate on the axis-angle ω (radians), the orbit about ``target``; None: 0.03 with a
            pyramid (0.02 left a textured 64² view stuck 17° off), 0.02 on one size (the former loop's).
        lr_position: Adam's learning rate on the camera-space shift s (world units); None: ``lr`` times
            the start's distance to ``target``.
        sigma, sigma_end: soft rasterization's sharpness (NDC units: ``σ_px = σ W² / 4`` px²), annealed
            geometrically over the steps (``sigma_end=None``: constant). None: ``SIGMA_PX`` for colours,
            ``SILHOUETTE_SIGMA`` for a silhouette (whose IoU loss needs the blur to pull from afar).
        gamma: soft rasterization's depth-softmax temperature for a colour reference (between faces only: the
            background is composited by the silhouette).
        lr_end: both learning rates decay exponentially to this fraction of their start by the last step.
        face_colors: (F, C) flat colours for a colour reference of a Mesh (None: silhouette). background: that
            reference's background (a Scene brings its own). render_settings: the ``RenderSettings`` the
            Scene's reference was rendered with (None: the defaults); soft rasterization shades ``"phong"`` as
            Gouraud, culls back faces, and cannot draw shadows or a wireframe (use ``method="nmr"``).
        reference_camera: the true camera, if known: the errors are then recorded per step and at the end.
        target: (3,) the orbit's pivot, and the point the centre error's distance is measured to.
        samples: edge sampling's points per step. seed: seeds edge sampling (the other methods draw no
            random numbers).
        snapshot_every: keep the rendered image (full size) every this many steps (and the last); None: none.
        starts: how many starts to search from, 1 to 7; None: 7 for a colour reference with ``"soft"`` or
            ``"nmr"``, else 1 (mirrored views have alike silhouettes, the hard image never moves, and a
            boundary method's step costs a hundred soft ones). spread: their angle from the start (degrees).
        levels: the most sizes in the pyramid (1: the full size only; None: 4 for ``"soft"`` and ``"nmr"``,
            else 1, the loop of lecture 10's comparison). search_steps: the steps every start runs before the
            best goes on (None: those of the coarse half of the pyramid; 0 without a search).
        supersample: samples per pixel side of the model's full-size image (``_supersample``; None: 2 for
            face colours, box-filtered like ``exact_coverage``'s, and for an antialiased Scene, else 1).

    Returns a ``CameraFit`` of the path that won; ``history.loss`` has ``steps`` entries and starts where that
    path started (``camera_start``, or the orbit of it the search chose), on the coarsest level.
    """
    _check_common(steps, 0.02 if lr is None else lr, "soft", snapshot_every)
    _check_fit_camera(mesh, camera_start, method, render_settings, reference_camera, samples, lr_end, starts, spread,
                      levels, search_steps, steps)
    from .render import RenderSettings
    scene = None if isinstance(mesh, Mesh) else mesh
    first = mesh if scene is None else scene.meshes[0]
    dtype, device = first.verts.dtype, first.verts.device
    ref = torch.as_tensor(reference_image).to(dtype=dtype, device=device)
    _check_reference(mesh, ref, camera_start, method, face_colors)
    if starts is None:
        starts = 7 if ref.dim() == 3 and method in ("soft", "nmr") else 1
    if levels is None:
        levels = 4 if method in ("soft", "nmr") else 1
    sizes = _pyramid(camera_start.height, camera_start.width, levels)
    if lr is None:
        lr = 0.03 if len(sizes) > 1 else 0.02
    if search_steps is None:
        search_steps = steps * (len(sizes) // 2) // len(sizes) if starts > 1 else 0
    tgt = torch.as_tensor(target, dtype=dtype, device=device)
    start = Camera(camera_start.K.detach().to(dtype), camera_start.R.detach().to(dtype),
                   camera_start.t.detach().to(dtype), camera_start.width, camera_start.height, camera_start.near,
                   camera_start.far)
    if lr_position is None:
        lr_position = lr * float((start.eye - tgt).norm())
    level_of = [min(k * len(sizes) // max(steps, 1), len(sizes) - 1) for k in range(steps)] + [len(sizes) - 1]
    problem = _CameraProblem(
        mesh=first if scene is None else None, scene=scene, settings=render_settings or RenderSettings(),
        method=method, face_colors=face_colors, background=background, gamma=gamma,
        refs=[_area(ref, s) for s in sizes], sizes=sizes, level_of=level_of, sigmas=[], target=tgt,
        reference_camera=reference_camera, samples=samples,
        generator=torch.Generator(device="cpu").manual_seed(_check_count(seed, "seed", minimum=0)))
    problem.sigmas = _sigmas(problem, sigma, sigma_end, steps)
    problem.supersample = _supersample(supersample, scene, problem.settings, face_colors)
    metrics = ("rotation_deg", "center_pct") if reference_camera is not None else ()
    decay = lr_end ** (1 / max(steps, 1))
    paths = [_new_path(c, lr, lr_position, decay, metrics) for c in _candidate_starts(start, starts, spread, tgt)]
    bar = _progress(len(paths) * search_steps + steps - search_steps, progress, f"fit_camera ({method})")
    for path in paths:                                                      # the search: every start, coarse
        for step in range(search_steps):
            _fit_step(problem, path, step, snapshot_every, steps)
            bar.update(1)
    best = min(paths, key=lambda p: _score(problem, p, max(search_steps - 1, 0))) if len(paths) > 1 else paths[0]
    for step in range(search_steps, steps + 1):                             # the winner, on to the full size
        loss = _fit_step(problem, best, step, snapshot_every, steps)
        if step < steps:
            bar.update(1)
            bar.set_postfix(loss=f"{loss:.4f}")
    bar.close()
    final = _detached(best.camera(tgt, *sizes[-1]))
    if reference_camera is None:
        return CameraFit(final, best.history)
    return CameraFit(final, best.history, rotation_error(final.R, reference_camera.R),
                     center_error(final, reference_camera, tgt))


def _supersample(supersample, scene, settings, face_colors) -> int:
    """Samples per pixel side of the model's full-size image: made the way the reference was. None: 2 for face
    colours (the course's flat references are box-filtered, ``coverage.exact_coverage``: 2 x 2 samples
    average them much as the box does) and for a Scene rendered with antialiasing; 1 for a Scene without
    (``render()`` samples pixel centres) and for silhouettes."""
    if supersample is not None:
        if isinstance(supersample, bool) or not isinstance(supersample, int) or not 1 <= supersample <= 4:
            raise ValueError(f"supersample must be None or an integer from 1 to 4, got {supersample!r}")
        return supersample
    if scene is not None:
        return 1 if settings.antialias == "none" else 2
    return 2 if face_colors is not None else 1


def _sigmas(problem, sigma, sigma_end, steps):
    """σ (NDC) at each step: ``sigma`` annealed to ``sigma_end`` if given; by default, for a silhouette
    ``SILHOUETTE_SIGMA`` annealed the same way, for colours ``SIGMA_PX`` px² at the width the step's level
    renders."""
    if sigma is None and problem.refs[0].dim() == 2:
        sigma, sigma_end = SILHOUETTE_SIGMA
    if sigma is not None:
        return _schedule(sigma, sigma_end, steps)
    W = problem.sizes[-1][1]
    return _schedule(4 * SIGMA_PX[0] / W ** 2, 4 * SIGMA_PX[1] / W ** 2, steps)
