"""What the fits of lecture 10 share: their histories and results, the views they train and judge on, the
silhouettes and self-intersections they are measured by, and the loops' helpers (progress bars, schedules,
snapshots).

Every loop is seeded, shows a ``tqdm.auto`` progress bar (silenced by ``progress=False`` or the
environment variable ``TQDM_DISABLE=1``), and returns a result whose ``.history`` holds the loss at every
step and snapshots at chosen steps, so a notebook can plot the curve and animate the fit.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import torch

from . import losses
from ..camera import Camera
from ..mesh import Mesh
from ..raster import rasterize
from ..nmr import nmr_rasterize
from ..soft import soft_rasterize
from ..tensors import _check_count, _check_real

__all__ = ["FitHistory", "SilhouetteFit", "CameraFit", "circle_views", "sphere_views", "hard_silhouettes",
           "held_out_iou", "self_intersections", "start_verts"]

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
    from ..discontinuities import _intersecting_faces
    from ..boundary import _weld
    from ..intersect import intersect_triangles
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


def _background3(background, like):
    bg = torch.as_tensor(background, dtype=like.dtype, device=like.device)
    return bg.expand(3) if bg.dim() == 0 else bg
