"""Silhouette fitting with learned views (lecture 10): where should the cameras look?

``course.inverse.fit_silhouettes`` fits a sphere to a target's silhouettes from cameras fixed in advance,
usually a ring (``circle_views``: 8 views alternating ±25° of elevation). The ring never looks from above
or below, so whatever only shows there (a teapot's lid, a torus's hole) is never corrected. MVTN (Hamdi,
Giancola and Ghanem 2021, "MVTN: Multi-View Transformation Network for 3D Shape Recognition") makes the
views *parameters*, learned along with the task through a differentiable renderer. This module is a light
version of that idea for reconstruction: each of the N views is an azimuth and an elevation on a sphere of
fixed radius around the target, looking at its centre, and the views move while the shape is fitted.

**The views' objective: seek the worst error (an active, adversarial choice).** MVTN learns views that
*minimise* its loss, which is right for recognition, where the loss is the task. For reconstruction it is
not: views minimising the silhouette loss run away from the mistakes (a view where the current fit already
matches is a perfect score), so the training loss drops while the shape stays wrong. Here the views do the
opposite. With θ the shape and φ the views, both play one game on

    J(θ, φ) = L_sil(θ, φ) + reg(θ) - separation · P(φ)

    shape:  θ ← θ - Adam(∂J/∂θ)          (descent: match the silhouettes)
    views:  φ ← φ + Adam(∂J/∂φ)          (ascent: look where the silhouettes differ most)

``L_sil`` is Kato et al.'s IoU loss averaged over the views (``losses.silhouette_iou_loss``) and ``reg`` the
smoothness loss, as in ``fit_silhouettes``. Ascent moves each view towards where the fit is worst, the
shape then fixes that error, and the view moves on: an active-vision loop that keeps spending the view
budget on the mistakes. It needs ``∂L_sil/∂φ``, and the loss depends on the view through *both* images:
the fit's silhouette and the target's. So the target is rendered, like the fit, with soft rasterization
at the current views (the target's hard silhouette would be a step function of the view, with no
gradient). This assumes the target can be seen from any view on demand: a 3D target (MVTN's input is a
3D shape) or a camera one can steer, not a fixed set of photographs.

**MVTN's own scheme: views that minimise the task's loss** (``view_objective="task"``). In MVTN the views feed
a classifier and are trained on the classifier's loss: the views serve the task, they are not scored by how
well they match. For reconstruction the task is the shape, so the views here descend a measure of the shape,
not of the silhouettes at the views: the chamfer distance T (``chamfer_distance``) from the shape *after its
next step* to ``task_points`` points on the target's surface (``surface_points``; the target is a 3D shape, as
MVTN's input is). The shape's step θ' = θ - lr ∂L_sil/∂θ depends on the views through the silhouettes it is
computed from, so

    views:  φ ← φ - Adam(∂T(θ'(φ))/∂φ + separation · ∂P/∂φ)       (a one-step look-ahead, as in DARTS)

which needs the mixed second derivative ∂²L_sil/∂θ∂φ times ∇T(θ'): taken, as DARTS does, as a finite difference
of two first derivatives (``_task_view_gradient``): a view step costs about three ordinary steps. The views move toward where the next silhouette step would most
improve the 3D shape. The shape itself still sees only the silhouettes.

**Keeping views apart.** Ascent alone sends every view to the single worst direction (they collapse, and N
views see what one would). ``P(φ) = Σ_{i<j} max(0, c_min - |uᵢ - uⱼ|)²`` with uᵢ the unit viewing
directions and ``c_min = 2 sin(min_separation / 2)`` the chord of the angle ``min_separation``
(``default_separation``: 57° for 8 views): zero while views are at least that far apart, so they are
otherwise free, and a spring pushing them apart below it.
Elevations are clamped to ±``max_elevation`` (80° by default) after each step, so the look-at frame with
+y up stays defined.

**Cost.** A view step renders the target too (soft, with a gradient), and after the views move the
targets are rendered again; to keep that affordable the views move every ``view_every`` steps and the
targets stay cached in between. With ``learn_views=False`` the views are ``circle_views(n_views)`` and never
move, the targets are rendered once, and the loop is otherwise the same (the same soft targets, the same
losses, sigma, seed and steps), so the two differ only in the views. Both start from those ring views.

The metric is ``fit.held_out_iou`` over ``sphere_views(16)``, as for ``fit_silhouettes``.

**Measured** (defaults: 8 views, 64 × 64, 200 steps, seed 0; held-out mean IoU, start sphere → fit):

    target    ring (fixed)    learned, "worst"    learned, "best" (MVTN-style)
    teapot    0.663 → 0.901   0.932               0.912
    cube      0.341 → 0.940   0.953               0.933
    torus     0.160 → 0.840   0.768               0.837

``"task"`` was measured at lecture 10's size only (4 views, 32 × 32, 60 steps, seed 0): 0.867 on the ring,
0.891 with the views learned on the task loss (0.86 ascending, 0.87 descending the silhouette loss), at about
three times the ring's time.

On the teapot one view climbs to the clamp (80°, the lid, seen by no ring view) and three drop near the
equator (the spout's and handle's profiles); the worst held-out view rises from 0.855 to 0.874. The torus
is where seeking the worst error fails, and it shows why: the torus is symmetric about its axis and its
mid-plane, so a view's azimuth and the sign of its elevation change nothing, and all 8 views see the same
target silhouette, at ±25° on the ring and at ±45° after learning. At ±45° the hole shows through, an error
a sphere-shaped (genus 0) mesh can never fix: the adversary stays on the irreducible error (the ascent has
no notion of what the shape *can* fix) while the profile seen from the equator goes unsupervised: the
held-out views nearest the equator fall from 0.87 to 0.57-0.73 across the settings we tried. "best"
views barely move on the torus (the ring's score) and lose on the cube. Learning the views also costs
more: the target is rendered with a gradient on every view step and again after it (1.25-1.5 times the
ring's CPU time per run).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from .. import models
from . import losses
from ..camera import Camera, intrinsics_from_fov, look_at
from .common import FitHistory, _check_common, _progress, _snap_due, held_out_iou, sphere_views, start_verts
from ..mesh import Mesh
from ..soft import soft_rasterize
from ..tensors import _check_count, _check_dtype, _check_finite, _check_real, as_tensor

__all__ = ["ViewFit", "view_camera", "ring_angles", "view_directions", "separation_penalty", "default_separation",
           "surface_points", "chamfer_distance", "fit_with_learned_views"]


@dataclass
class ViewFit:
    """``mesh``: the fitted Mesh (target's world frame); ``history`` (``metrics``: ``"iou_loss"``, the
    silhouette term, and ``"azimuth_deg"`` / ``"elevation_deg"``, the N views used at each step, lists of N
    floats, one list per step, like ``loss``); ``cameras``: the N final views; ``azimuth_deg`` /
    ``elevation_deg``: (N,) float64, their angles; ``start_iou`` / ``iou``: held-out mean IoU of the start
    sphere and of the result; ``per_view_iou``: (16,) the result's held-out IoUs."""
    mesh: Mesh
    history: FitHistory
    cameras: list
    azimuth_deg: torch.Tensor
    elevation_deg: torch.Tensor
    start_iou: float
    iou: float
    per_view_iou: torch.Tensor


# ---------------------------------------------------------------------------------------------- views

def view_directions(angles) -> torch.Tensor:
    """Unit vectors from the target to each eye. angles: (N, 2) radians, (azimuth, elevation). Returns (N, 3):
    ``(cos e sin a, sin e, cos e cos a)``, the convention of ``fit.circle_views`` (azimuth 0 looks from +z,
    azimuth 90° from +x, elevation 90° from +y above)."""
    angles = as_tensor(angles, name="angles")
    if angles.dim() != 2 or angles.shape[1] != 2:
        raise ValueError(f"angles must have shape (N, 2), (azimuth, elevation) in radians, got {tuple(angles.shape)}")
    _check_finite(angles, "angles")
    az, el = angles[:, 0], angles[:, 1]
    return torch.stack([torch.cos(el) * torch.sin(az), torch.sin(el), torch.cos(el) * torch.cos(az)], -1)


def view_camera(azimuth, elevation, *, distance: float = 3.0, size: int = 64, fov_y: float = 40.0,
                target=(0.0, 0.0, 0.0)) -> Camera:
    """A camera at ``distance`` from ``target``, looking at it from (azimuth, elevation) in radians, +y up.

    azimuth, elevation: 0-d tensors (or floats); the camera's R and t are differentiable in them
    (``camera.look_at`` is plain torch), so a silhouette rendered by ``soft_rasterize`` through this camera
    has a gradient with respect to the view. Same cameras as ``fit.circle_views`` at the same angles.
    Undefined straight above or below (|elevation| = 90°): keep elevations inside (-90°, 90°).
    """
    az = azimuth if isinstance(azimuth, torch.Tensor) else as_tensor(azimuth, name="azimuth")
    if az.numel() != 1 or az.is_complex() or az.dtype == torch.bool:
        raise ValueError(f"azimuth must be one angle (a float or 0-d tensor), got shape {tuple(az.shape)}")
    if not isinstance(elevation, torch.Tensor):
        _check_real(elevation, "elevation")
    dtype = az.dtype if az.is_floating_point() else torch.get_default_dtype()
    angles = torch.stack([az.to(dtype), torch.as_tensor(elevation, dtype=dtype, device=az.device)])[None]
    center = torch.as_tensor(target, dtype=dtype, device=az.device)
    eye = center + distance * view_directions(angles)[0]
    R, t = look_at(eye, center, (0.0, 1.0, 0.0))
    K = intrinsics_from_fov(fov_y, size, size, dtype=dtype, device=az.device)
    return Camera(K, R, t, size, size)


def ring_angles(n: int, *, elevations=(25.0, -25.0), dtype=torch.float64, device=None) -> torch.Tensor:
    """(n, 2) radians: the (azimuth, elevation) of ``fit.circle_views(n)``, azimuths 360°/n apart, elevations
    taking turns from ``elevations`` (degrees). The start (and, unlearned, the whole run) of the views."""
    from .common import _check_elevations
    n, dtype = _check_count(n, "n"), _check_dtype(dtype)
    elevations = _check_elevations(elevations)
    k = torch.arange(n, dtype=dtype, device=device)
    el = torch.tensor([math.radians(elevations[i % len(elevations)]) for i in range(n)], dtype=dtype, device=device)
    return torch.stack([2 * math.pi * k / n, el], -1)


def separation_penalty(angles, min_separation_deg: float) -> torch.Tensor:
    """``Σ_{i<j} max(0, c_min - |uᵢ - uⱼ|)²``: zero while every two views are ``min_separation_deg`` apart.

    angles: (N, 2) radians. uᵢ = ``view_directions(angles)``; ``c_min = 2 sin(min_separation / 2)`` is the
    chord between two unit vectors that far apart (chords, not angles: ``acos`` has an infinite slope at
    0°, the chord's gradient stays finite). A hinge, so views farther apart feel no force at all.
    """
    min_separation_deg = _check_real(min_separation_deg, "min_separation_deg", low=0, high=180)
    u = view_directions(angles)                                            # (N, 3)
    i, j = torch.triu_indices(len(u), len(u), 1, device=u.device)           # every pair once
    chord = (u[i] - u[j]).pow(2).sum(-1).clamp(min=1e-12).sqrt()           # (pairs,) finite gradient at 0
    c_min = 2 * math.sin(math.radians(min_separation_deg) / 2)
    return (c_min - chord).clamp(min=0).pow(2).sum()


def default_separation(n: int) -> float:
    """0.8 · √(4π / n) in degrees (at most 180): each of n views owns 4π / n of the sphere, a cap about
    √(4π / n) radians across, and may come 20% closer than that to another (57° for 8 views, which the
    ring of ``circle_views(8)``, 66° apart at the closest, already satisfies)."""
    n = _check_count(n, "n")
    return min(180.0, 0.8 * math.degrees(math.sqrt(4 * math.pi / n)))


def surface_points(mesh, n: int = 2000, seed: int = 0) -> torch.Tensor:
    """(n, 3) points on ``mesh``'s surface, uniform by area (a face drawn with probability proportional to its
    area, then a uniform point in it), seeded: the 3D target the ``"task"`` views' loss measures against."""
    n = _check_count(n, "n")
    g = torch.Generator(device="cpu").manual_seed(_check_count(seed, "seed", minimum=0))
    v, f = mesh.verts.detach(), mesh.faces
    tri = v[f]                                                               # (F, 3, 3)
    area = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], dim=-1).norm(dim=-1)
    pick = torch.multinomial(area.double().cpu(), n, replacement=True, generator=g).to(f.device)
    r = torch.rand(n, 2, generator=g, dtype=torch.float64).to(dtype=v.dtype, device=v.device)
    s = r[:, 0].sqrt()                                                       # uniform in the triangle
    w = torch.stack([1 - s, s * (1 - r[:, 1]), s * r[:, 1]], -1)             # (n, 3) barycentrics
    return (w[:, :, None] * tri[pick]).sum(1)


def chamfer_distance(points, target_points) -> torch.Tensor:
    """Mean squared distance from each of ``points`` (N, 3) to the nearest of ``target_points`` (M, 3), plus the
    same the other way: 0 only when each set lies on the other."""
    d = torch.cdist(points, target_points).pow(2)                           # (N, M)
    return d.min(1).values.mean() + d.min(0).values.mean()


def _degrees(angles) -> tuple[list, list]:
    a = torch.rad2deg(angles.detach().double())
    return a[:, 0].tolist(), a[:, 1].tolist()


# ------------------------------------------------------------------------------------------- the fit

def _check_views(n_views, size, view_lr, view_every, separation, min_separation_deg, max_elevation_deg,
                 distance, smoothness, sigma, radius, held_out):
    if isinstance(n_views, bool) or not (isinstance(n_views, int) and n_views >= 1):
        raise ValueError(f"n_views must be a positive integer, got {n_views!r}")
    if isinstance(size, bool) or not (isinstance(size, int) and size >= 4):
        raise ValueError(f"size must be an integer >= 4 (pixels), got {size!r}")
    if isinstance(view_every, bool) or not (isinstance(view_every, int) and view_every >= 1):
        raise ValueError(f"view_every must be a positive integer, got {view_every!r}")
    for name, v in (("view_lr", view_lr), ("distance", distance), ("sigma", sigma), ("radius", radius)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a positive finite number, got {v!r}")
    for name, v in (("separation", separation), ("smoothness", smoothness)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise ValueError(f"{name} must be a non-negative number, got {v!r}")
    if min_separation_deg is not None and not (isinstance(min_separation_deg, (int, float))
                                               and 0 <= min_separation_deg <= 180):
        raise ValueError(f"min_separation_deg must be in [0, 180] degrees, got {min_separation_deg!r}")
    if not (isinstance(max_elevation_deg, (int, float)) and 0 < max_elevation_deg < 90):
        raise ValueError(f"max_elevation_deg must be in (0, 90) degrees, got {max_elevation_deg!r}")
    if held_out is not None and not (isinstance(held_out, (list, tuple)) and len(held_out) > 0
                                     and all(isinstance(c, Camera) for c in held_out)):
        raise ValueError("held_out must be None or a non-empty list of Camera")


def _silhouettes(mesh, cameras, sigma):
    """(N, H, W) soft silhouettes, back faces kept (an open target such as the teapot shows no holes)."""
    return torch.stack([soft_rasterize(mesh, c, mode="silhouette", sigma=sigma, cull_backfaces=False)
                        for c in cameras]).clamp(0, 1)


def _task_view_gradient(target_mesh, faces, verts, d_verts, angles, cam, sigma, lr, points) -> torch.Tensor:
    """(N, 2) dT/dφ for ``view_objective="task"``: T = ``chamfer_distance(θ', points)`` of the shape after its next
    step θ' = θ - lr ∂L/∂θ (``d_verts``: ∂L/∂θ at the current views). θ' depends on the views φ through ∂L/∂θ, so

        dT/dφ = -lr (∂²L/∂φ∂θ) u,   u = ∇T(θ')
              ≈ -lr [∂L/∂φ(θ + εu) - ∂L/∂φ(θ - εu)] / 2ε,    ε = 0.001 / |u|

    the finite difference DARTS (Liu, Simonyan and Yang 2019) uses for the same product (with a smaller ε: at
    0.01 / |u| the vertices move about a soft edge's width and the difference is 30% off): two first derivatives,
    which soft rasterization gives exactly, instead of a second derivative through it (``course.soft`` holds the
    closest point on an edge fixed in its derivative: exact to first order only). L here is the silhouette
    term; the smoothness term does not depend on φ."""
    ahead = (verts - lr * d_verts).requires_grad_(True)
    (u,) = torch.autograd.grad(chamfer_distance(ahead, points), ahead)
    eps = 1e-3 / max(float(u.norm()), 1e-12)                             # 3e-4 relative to central differences
    cameras = cam(angles)                                                    # a graph in φ
    targets = _silhouettes(target_mesh, cameras, sigma)
    sil = [losses.silhouette_iou_loss(_silhouettes(Mesh(verts + sign * eps * u, faces), cameras, sigma), targets,
                                      reduction="mean") for sign in (1.0, -1.0)]
    (slope,) = torch.autograd.grad(sil[0] - sil[1], angles)                 # ∂L/∂φ(θ + εu) - ∂L/∂φ(θ - εu)
    return -lr * slope / (2 * eps)


def fit_with_learned_views(target_mesh, *, n_views: int = 8, seed: int = 0, learn_views: bool = True,
                           size: int = 64, steps: int = 200, lr: float = 0.01, view_lr: float = 0.05,
                           view_every: int = 4, view_objective: str = "worst", task_points: int = 2000,
                           separation: float = 10.0,
                           min_separation_deg: float | None = None, max_elevation_deg: float = 80.0,
                           smoothness: float = 0.0005, sigma: float = 3e-4,
                           distance: float = 3.0, fov_y: float = 40.0, subdivisions: int = 3,
                           radius: float = 0.5, held_out=None, snapshot_every: int | None = 10,
                           progress: bool = True) -> ViewFit:
    """Fit an icosphere to ``target_mesh``'s silhouettes while the views move to where the fit is worst.

    Args:
        target_mesh: a Mesh, centred near the origin (the views look at ``(0, 0, 0)``) and inside the view.
        n_views: N, the number of training views. They start at ``circle_views(N)`` (ring, ±25°).
        seed: seeds the start's jitter, as in ``fit_silhouettes``; runs with one seed are identical.
        learn_views: True: the views ascend the silhouette loss (see the module docstring); False: they
            stay on the ring, the baseline, with the loop otherwise the same.
        size: the square images' side in pixels. steps: Adam steps on the shape.
        lr: Adam's learning rate on the per-vertex offset (world units).
        view_lr: Adam's learning rate on the (N, 2) view angles (radians: 0.05 ≈ 3° per view step).
        view_every: the views move (and the targets are re-rendered) every this many steps.
        view_objective: ``"worst"``: the views ascend the silhouette loss (seek the worst fit, the default);
            ``"best"``: they descend it (kept to show why that fails here); ``"task"``: MVTN's scheme, the views
            descend the task's loss, the chamfer distance of the shape after its next step to points on the
            target's surface (see the module docstring).
        task_points: the number of target surface points for ``"task"`` (``surface_points``, seeded by seed).
        separation, min_separation_deg: the weight and the angle (degrees) of the hinge
            ``separation_penalty``; None: ``default_separation(n_views)`` (57° for 8 views).
        max_elevation_deg: elevations are clamped to ± this after each view step.
        smoothness: weight of Kato et al.'s smoothness loss. sigma: soft rasterization's sharpness (NDC).
        distance, fov_y: every view's distance to the origin and vertical field of view (degrees).
        subdivisions, radius: the start icosphere. held_out: cameras for the metric, or None for
            ``sphere_views(16)`` at ``size``, ``distance`` and ``fov_y``.
        snapshot_every: keep the vertices every this many steps (and the last); None: none.
        progress: show a tqdm bar (``TQDM_DISABLE=1`` also hides it).

    Returns a ``ViewFit``. Both the fit's and the target's silhouettes are soft renders at sharpness
    ``sigma`` (the same blur on both sides); the metric uses hard ones.
    """
    _check_common(steps, lr, "soft", snapshot_every)
    _check_views(n_views, size, view_lr, view_every, separation, min_separation_deg, max_elevation_deg,
                 distance, smoothness, sigma, radius, held_out)
    if not isinstance(target_mesh, Mesh):
        raise ValueError(f"target_mesh must be a Mesh, got {type(target_mesh).__name__}")
    if view_objective not in ("worst", "best", "task"):
        raise ValueError(f'view_objective must be "worst", "best" or "task", got {view_objective!r}')
    task_points = _check_count(task_points, "task_points")
    if not isinstance(learn_views, bool):
        raise ValueError(f"learn_views must be True or False, got {learn_views!r}")
    dtype, device = target_mesh.verts.dtype, target_mesh.verts.device
    if min_separation_deg is None:
        min_separation_deg = default_separation(n_views)
    if held_out is None:
        held_out = sphere_views(16, distance=distance, size=size, fov_y=fov_y, dtype=dtype, device=device)
    cam = lambda a: [view_camera(az, el, distance=distance, size=size, fov_y=fov_y) for az, el in a]

    base, faces = start_verts(models.icosphere(subdivisions, radius, dtype=dtype, device=device), seed)
    offset = torch.zeros_like(base, requires_grad=True)
    angles = ring_angles(n_views, dtype=dtype, device=device).requires_grad_(learn_views)   # (N, 2)
    opt = torch.optim.Adam([offset], lr=lr)
    ascend = view_objective == "worst"                                     # views: maximise J, or minimise
    task = view_objective == "task" and learn_views                         # views: minimise the task loss
    points = surface_points(target_mesh, task_points, seed) if task else None
    opt_views = torch.optim.Adam([angles], lr=view_lr, maximize=ascend) if learn_views else None
    max_el = math.radians(max_elevation_deg)
    history = FitHistory(metrics={"iou_loss": [], "azimuth_deg": [], "elevation_deg": []})
    start_iou = held_out_iou(Mesh(base, faces), target_mesh, held_out).mean()
    targets = None                                                           # (N, H, W) cached, detached

    bar = _progress(steps, progress, "fit_with_learned_views" if learn_views else "fit (ring views)")
    for step in range(steps + 1):
        verts = base + offset
        if _snap_due(step, steps, snapshot_every):
            history.snapshot_steps.append(step)
            history.snapshots.append(verts.detach().clone())
        if step == steps:
            break
        view_step = learn_views and step % view_every == 0
        graph = view_step and not task                                       # "task": φ's graph in the helper
        cameras = cam(angles if graph else angles.detach())                 # R, t carry φ's graph on view steps
        if graph:
            targets = _silhouettes(target_mesh, cameras, sigma)             # differentiable in φ
        elif targets is None:
            with torch.no_grad():
                targets = _silhouettes(target_mesh, cameras, sigma)
        pred = _silhouettes(Mesh(verts, faces), cameras, sigma)              # (N, H, W)
        sil = losses.silhouette_iou_loss(pred, targets, reduction="mean")
        loss = sil + smoothness * losses.smoothness_loss(verts, faces) if smoothness else sil
        objective = loss
        if graph:                                                            # -P when ascending, +P descending
            objective = loss + (-1 if ascend else 1) * separation * separation_penalty(angles, min_separation_deg)
        opt.zero_grad()
        if view_step:
            opt_views.zero_grad()
        objective.backward()
        if view_step and task:                                               # MVTN: the views serve the task
            grad = _task_view_gradient(target_mesh, faces, verts.detach(), offset.grad, angles, cam, sigma, lr, points)
            angles.grad = grad + torch.autograd.grad(separation * separation_penalty(angles, min_separation_deg),
                                                     angles)[0]
        opt.step()                                                           # shape: descent on J
        history.loss.append(float(loss.detach()))
        history.metrics["iou_loss"].append(float(sil.detach()))
        az, el = _degrees(angles)
        history.metrics["azimuth_deg"].append(az)
        history.metrics["elevation_deg"].append(el)
        if view_step:
            opt_views.step()                                                 # views: ascent (or descent) on J
            with torch.no_grad():
                angles[:, 1].clamp_(-max_el, max_el)
                angles[:, 0].remainder_(2 * math.pi)                         # azimuth in [0, 2π)
            targets = None                                                   # the views moved: render anew
        bar.update(1)
        bar.set_postfix(loss=f"{history.loss[-1]:.4f}")
    bar.close()
    fitted = Mesh((base + offset).detach(), faces)
    per_view = held_out_iou(fitted, target_mesh, held_out)
    final = cam(angles.detach())
    az, el = torch.rad2deg(angles.detach().double()).unbind(1)
    return ViewFit(fitted, history, final, az, el, float(start_iou), float(per_view.mean()), per_view)
