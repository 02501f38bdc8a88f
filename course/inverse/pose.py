"""A camera from one image (lecture 10; ``fit_camera``).

Intrinsics known; the pose is parameterised about the start
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
from dataclasses import dataclass

import torch

from .. import models
from . import losses
from ..camera import Camera, axis_angle_to_matrix
from ..mesh import Mesh
from ..raster import rasterize
from ..nmr import nmr_rasterize
from ..soft import soft_rasterize
from .common import _background3, CameraFit, _check_common, FitHistory, _progress, _schedule, _snap_due
from .shaded import shaded_face_colors
from ..tensors import _check_count, _check_real, _check_shape, as_tensor

__all__ = ["CAMERA_METHODS", "camera_problem", "fit_camera", "rotation_error", "center_error"]

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
    from ..coverage import exact_coverage
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
        from ..render import Scene, default_lights, render
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
        from ..coverage import exact_coverage
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
    from ..render import Scene, render
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



def _boundary_backward(loss_of, image, mesh, camera, method, face_colors, background, generator, samples):
    """Backpropagate ``loss_of(image)`` into the camera's R and t by the boundary integral of lecture 09
    (``visibility.image_gradient``, method ``"reynolds"`` or ``"edge_sampling"``): dL/dimage are the weights,
    the boundary term turns them into dL/dR and dL/dt, and autograd carries those on into the pose."""
    from ..visibility import image_gradient
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
    from ..render import RenderSettings, Scene
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
    from ..render import SOFT_SHADING
    cannot = [what for what, on in (("shadows", settings.shadows != "none"), ("a wireframe", settings.wireframe),
                                    (f"shading={settings.shading!r}", settings.shading not in SOFT_SHADING)) if on]
    if cannot:
        raise ValueError(f"fit_camera(method='soft') draws the scene by soft rasterization, which cannot draw "
                         f"{' or '.join(cannot)}: use method='nmr' (the hard image, Kato et al.'s gradient)")


def _check_reference(mesh, ref, camera_start, method, face_colors):
    """The reference image against the mesh or scene, the method and the colours."""
    from ..render import Scene
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
                             "camera, e.g. course.inverse.shaded_face_colors(mesh), and a reference drawn with them "
                             "(course.inverse.camera_problem())")
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
                         f"course.inverse.shaded_face_colors(mesh){hint}")


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
    from ..render import RenderSettings
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
