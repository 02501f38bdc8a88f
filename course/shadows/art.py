"""Shadow art: a flat occluder deformed until its shadow on the floor matches a target outline (lecture 12).

Mitra and Pauly ("Shadow Art", SIGGRAPH Asia 2009) carve a sculpture whose shadows draw given pictures; here
the smallest case of it, solved by gradient descent on the image, and a test bed for shadow gradients.

The scene (``shadow_art_problem``). A floor (one big triangle at y = 0), a flat occluder at height ``height``
(a fan: a centre vertex and N boundary vertices, a disc at the start), a directional light tilted 45° from
straight down, and an orthographic camera looking straight down at the floor where the shadow falls. The
occluder hangs off to the side, out of the camera's view, so the image is the floor and the shadow alone
(``shadow_gradients.shadow_scene("floor_view")``): every gradient of the image w.r.t. the occluder is the
shadow's. The occluder is horizontal and so is the floor, so the shadow is the occluder's outline moved along
the light: a translated copy, whatever the tilt. The target image is the exact shadowed image
(``shadowed_coverage``) of a *target* occluder with the wanted outline (a five-pointed star, or the letters T
or L), at the same height; only its image is given to the fit.

The fit (``fit_shadow_art``). The unknowns are the in-plane coordinates (x, z) of the fan's centre and of
its N boundary vertices, (N + 1) × 2 numbers; the height stays, so the occluder stays flat. The loss is

    L = mean((blur_σ(image) - blur_σ(target))²)
        + smooth · mean|Δb|² / r² + even · var(|e|) / mean(|e|)² + fold · mean(relu(m - A) / m)²,

the image term blurred coarse to fine as in ``shadow_fit`` (σ falls from ``blur`` pixels to 0 at
``sharp_from`` of the steps: a tip of the outline that misses the target's tip entirely feels no gradient, as
sliding it over bare floor changes nothing; blurred, they overlap), and three small terms that keep the
polygon a mesh: the umbrella Laplacian of the boundary ring (Δb_k = b_k - (b_{k-1} + b_{k+1}) / 2, r the
start radius; it rounds the star's tips a little), the spread of its edge lengths e (so that the vertices do
not bunch up and leave a long edge that cannot bend), and a hinge on the fan triangles' signed areas A
(``fan_areas``), below a margin m = ``FOLD_MARGIN`` r². The shadow alone cannot keep the fan from folding:
the image is the union of the triangles' shadows, and a folded fan can cast the target's shadow too (without
the hinge, the letters' fits end folded); the centre, inside the outline, casts no shadow edge, so only the
hinge moves it. The targets are star-shaped about the start's centre, so an unfolded fan can reach them.
Adam steps the (x, z), its step size falling linearly to ``lr_end`` of itself (the outline settles on the
target instead of rocking about it). The image term's gradient with respect to the occluder's vertices, by ``method``:

* ``"exact"``: autograd through ``shadowed_coverage`` (the split of the floor by the shadow and exact
  coverage: ``shadow_image_gradient(method="exact")`` computes the same thing from the loss's weights);
* ``"reynolds"``: ``shadow_image_gradient(method="reynolds")`` with ``weights = dL/dimage``: the boundary
  term of the shadow's edges on the floor, chained back through the projection along the light;
* ``"vsm"``: autograd through ``prefiltered_shadows.shadow_map_image``, a variance shadow map drawn smoothly
  (Worchel and Alexa 2023): a different, blurred image of the same scene, fitted to the same exact target.

The metric (``shadow_iou``). From the exact images in float64: the shadow fraction of each pixel,
``s = (c_floor - image) / ((1 - ambient) c_floor)`` (the box-filtered area of the pixel in shadow, in [0, 1]),
and the soft IoU ``Σ min(s, t) / Σ max(s, t)`` against the target's fraction t: 1 when the shadows agree,
deterministic, computed the same way whatever ``method`` stepped the occluder.

Cost. ``split_by_shadows`` cuts the floor by each of the occluder's N shadow triangles in turn, in Python, and
the lit pieces multiply (a 12-gon: about 330 triangles; a 20-gon: about 900, and four times slower), so the
occluder keeps a dozen boundary vertices: ``python -m course bench shadow-art`` times the three methods.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import torch

from ..camera import Camera
from ..mesh import Mesh
from .prefiltered import shadow_map_image
from .fit import _blur
from .gradients import shadow_image_gradient, shadowed_coverage

__all__ = ["TARGETS", "METHODS", "ShadowArtProblem", "ShadowArtSettings", "ShadowArtFit", "shadow_art_problem",
           "shadow_fraction", "shadow_iou", "fan_areas", "fit_shadow_art", "save_shadow_art_gif", "shadow_art_figure"]

TARGETS = ("star", "T", "L")
METHODS = ("exact", "reynolds", "vsm")
FLOOR = ((-2.5, 0.0, -2.5), (-2.5, 0.0, 9.0), (9.0, 0.0, -2.5))            # one triangle, normal up (+y)
CENTRE = 3                                                                  # the fan's centre vertex
FOLD_MARGIN = 0.02       # of the start radius squared: fan triangles with less area than this are penalised
RING = 4                                                                    # the first boundary vertex


@dataclass(frozen=True)
class ShadowArtProblem:
    """A shadow-art scene (module docstring), float64.

    mesh: the floor (face 0, vertices 0-2) and the start occluder (vertex 3 the fan's centre, vertices 4..
        its N boundary vertices counter-clockwise seen from below, faces 1..N wound facing the floor).
    camera: orthographic, straight down on the shadow; face_colors: (N + 1, 3); light: (3,) the way the light
        travels; ambient: the fraction of its colour a shadowed point keeps.
    target: (H, W, 3) the exact image (``shadowed_coverage``) of ``target_mesh``, the floor and the target
        occluder (its outline fanned around a point inside it), at the same height.
    name: the target's name; height: the occluder's height above the floor; radius: the start disc's radius.
    """
    mesh: Mesh
    camera: Camera
    face_colors: torch.Tensor
    light: torch.Tensor
    ambient: float
    target: torch.Tensor
    target_mesh: Mesh
    name: str
    height: float
    radius: float

    @property
    def floor_color(self) -> torch.Tensor:
        """(3,) the floor's colour where it is lit."""
        return self.face_colors[0]


@dataclass(frozen=True)
class ShadowArtSettings:
    """steps: Adam steps; lr: its step size (world units; a pixel is ``3 / size`` of them), falling linearly to
    ``lr_end`` times that over the steps; blur, sharp_from:
    the coarse-to-fine Gaussian (pixels at the start, 0 from ``sharp_from`` of the steps on); smooth, even,
    fold: the weights of the ring's Laplacian, its edge-length spread and the fan's fold hinge (module
    docstring); resolution, vsm_blur,
    supersample: the variance shadow map's texels per side, pre-filter (texels) and the camera's shading points
    per pixel per side (``method="vsm"`` only)."""
    steps: int = 40
    lr: float = 0.04
    lr_end: float = 0.1
    blur: float = 2.0
    sharp_from: float = 0.5
    smooth: float = 1e-3
    even: float = 1e-3
    fold: float = 1e-2
    resolution: int = 64
    vsm_blur: float = 1.0
    supersample: int = 2


@dataclass
class ShadowArtFit:
    """verts: (V, 3) the fitted scene (floor and occluder; faces as ``problem.mesh``); method; losses: the loss
    (image term and regulariser) before each step; ious: ``shadow_iou`` of the exact image before each step
    and, last, of the result (steps + 1 entries); snapshot_steps, snapshots: the exact images (H, W, 3) at
    those steps (step ``steps`` is the result); seconds: the fit's wall time."""
    verts: torch.Tensor
    method: str
    losses: list = field(default_factory=list)
    ious: list = field(default_factory=list)
    snapshot_steps: list = field(default_factory=list)
    snapshots: list = field(default_factory=list)
    seconds: float = 0.0

    @property
    def start_iou(self) -> float:
        return self.ious[0]

    @property
    def iou(self) -> float:
        return self.ious[-1]


# ------------------------------------------------------------------------------------------- the scene

def _outline(name: str) -> torch.Tensor:
    """(K, 2) the target's outline in the occluder's plane, (x, z) (x to the image's right, z down it), with a
    positive area in (x, z) (clockwise in the image, seen from above), star-shaped about the origin: the start
    disc's centre sees the whole outline, so the fan around it can become the target without folding."""
    if name == "star":                                                      # five tips, one pointing up the image
        k = torch.arange(10, dtype=torch.float64)
        r = torch.where(k % 2 == 0, 1.0, 0.42)
        a = -math.pi / 2 + k * math.pi / 5
        return torch.stack([r * a.cos(), r * a.sin()], 1)
    if name == "T":                                                         # a bar across the top, a stem down
        xz = [(-0.95, -0.25), (0.95, -0.25), (0.95, 0.25), (0.3, 0.25), (0.3, 1.3), (-0.3, 1.3), (-0.3, 0.25),
              (-0.95, 0.25)]
    else:                                                                   # "L": the origin in its corner
        xz = [(-0.3, -1.3), (0.3, -1.3), (0.3, -0.3), (1.25, -0.3), (1.25, 0.3), (-0.3, 0.3)]
    return torch.tensor(xz, dtype=torch.float64)


def _fan(ring_xz, centre_xz, height):
    """(verts (K + 4, 3), faces (K + 1, 3)): the floor and a flat fan at ``height`` around centre_xz (2,), its
    boundary ring_xz (K, 2); the fan's faces wound facing the floor (turned from the light: the split skips
    them at once)."""
    K = ring_xz.shape[0]
    y = torch.full((K + 1, 1), float(height), dtype=ring_xz.dtype)
    xz = torch.cat([centre_xz[None], ring_xz])                              # (K + 1, 2)
    occluder = torch.cat([xz[:, :1], y, xz[:, 1:]], 1)                      # (K + 1, 3)
    verts = torch.cat([torch.tensor(FLOOR, dtype=ring_xz.dtype), occluder])
    faces = [[0, 1, 2]] + [[CENTRE, RING + k, RING + (k + 1) % K] for k in range(K)]
    return verts, torch.tensor(faces, dtype=torch.int64)


def _check_int(value, name, low):
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")


def shadow_art_problem(target: str = "star", size: int = 48, *, vertices: int = 12, height: float = 3.0,
                       radius: float = 0.65, ambient: float = 0.3) -> ShadowArtProblem:
    """The shadow-art scene (module docstring) with a ``target`` among ``TARGETS`` ("star", "T", "L").

    size: the camera's image, pixels per side (it spans 3 world units: the target's shadow spans about 2);
    vertices: the start occluder's boundary vertices N (its faces, and the split's cost, grow with it); height:
    the occluders' height above the floor; radius: the start disc's (the target spans about 2 units).
    The image's centre is a fraction of a pixel off the shadow's centre: the start disc is symmetric, and a
    vertex of its shadow exactly on a pixel border would sit on a kink of the box-filtered image (the
    derivative there is one-sided, ``shadow_gradients``).
    """
    if target not in TARGETS:
        raise ValueError(f"target must be one of {', '.join(TARGETS)}, got {target!r}")
    _check_int(size, "size", 8)
    _check_int(vertices, "vertices", 3)
    for value, name in ((height, "height"), (radius, "radius")):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < 100:
            raise ValueError(f"{name} must be a positive number (world units), got {value!r}")
    if not (isinstance(ambient, (int, float)) and 0 <= ambient < 1):
        raise ValueError(f"ambient must be a number in [0, 1) (a shadow must darken the floor), got {ambient!r}")
    light = torch.tensor([1.0, -1.0, 0.15], dtype=torch.float64)            # 45° from straight down
    shift = float(height) * light / -light[1]                               # the shadow: the occluder moved by it
    pixel = 3.0 / size                                                      # world units per pixel
    look = (float(shift[0]) + 0.31 * pixel, 0.0, float(shift[2]) + 0.17 * pixel)   # off the grid: see below
    camera = Camera.look_at((look[0], 2.0, look[2]), look, up=(0.0, 0.0, -1.0), ortho_height=3.0,
                            width=size, height=size, dtype=torch.float64)   # x right, z down the image
    a = torch.arange(vertices, dtype=torch.float64) * 2 * math.pi / vertices
    disc = float(radius) * torch.stack([a.cos(), a.sin()], 1)               # (N, 2) counter-clockwise in (x, z)
    verts, faces = _fan(disc, torch.zeros(2, dtype=torch.float64), height)
    target_verts, target_faces = _fan(_outline(target), torch.zeros(2, dtype=torch.float64), height)
    grey = lambda F: torch.full((F, 3), 0.8, dtype=torch.float64)          # noqa: E731 (the floor's colour)
    target_mesh = Mesh(target_verts, target_faces)
    image = shadowed_coverage(target_mesh, camera, grey(target_faces.shape[0]), light, ambient)
    return ShadowArtProblem(Mesh(verts, faces), camera, grey(faces.shape[0]), light, float(ambient),
                            image.detach(), target_mesh, target, float(height), float(radius))


# -------------------------------------------------------------------------------------------- the metric

def shadow_fraction(problem: ShadowArtProblem, image) -> torch.Tensor:
    """(H, W) float64: the fraction of each pixel of a floor image (H, W, 3) that lies in shadow,
    ``(c_floor - image) / ((1 - ambient) c_floor)`` averaged over the channels, clipped to [0, 1]."""
    image = torch.as_tensor(image).detach().double()
    c = problem.floor_color.double()
    if image.shape != problem.target.shape:
        raise ValueError(f"image must have shape (H, W, 3) = {tuple(problem.target.shape)}, "
                         f"got {tuple(image.shape)}")
    return ((c - image) / ((1 - problem.ambient) * c)).mean(-1).clamp(0, 1)


def shadow_iou(problem: ShadowArtProblem, image) -> float:
    """The soft IoU of an exact floor image's shadow (H, W, 3) with the target's: ``Σ min(s, t) / Σ max(s, t)``
    over the pixels' shadow fractions (``shadow_fraction``). 1 for the same shadow; 1 if both are empty."""
    s, t = shadow_fraction(problem, image), shadow_fraction(problem, problem.target)
    union = float(torch.maximum(s, t).sum())
    return float(torch.minimum(s, t).sum()) / union if union > 0 else 1.0


# ----------------------------------------------------------------------------------------------- the fit

def _occluder_verts(problem: ShadowArtProblem, xz):
    """(V, 3) the scene's vertices with the occluder's centre at xz[0] and its boundary at xz[1:] (N + 1, 2)
    in the (x, z) plane; differentiable."""
    verts, _ = _fan(xz[1:], xz[0], problem.height)
    return verts


def fan_areas(xz) -> torch.Tensor:
    """(N,) the signed areas of the fan's triangles (centre xz[0], boundary xz[1:], (N + 1, 2) in (x, z)):
    positive while the outline runs counter-clockwise around the centre, negative for a folded triangle."""
    a = xz[1:] - xz[0]                                                      # (N, 2) centre to boundary
    b = a.roll(-1, 0)
    return 0.5 * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])


def _regulariser(problem: ShadowArtProblem, xz, settings: ShadowArtSettings):
    """``smooth · mean|Δb|² / r² + even · var(|e|) / mean(|e|)² + fold · mean(relu(m - A) / m)²`` of the
    occluder (N + 1, 2) (module docstring)."""
    ring = xz[1:]
    laplacian = ring - 0.5 * (ring.roll(1, 0) + ring.roll(-1, 0))          # (N, 2)
    lengths = (ring.roll(-1, 0) - ring).norm(dim=1)                        # (N,)
    m = FOLD_MARGIN * problem.radius ** 2
    return (settings.smooth * (laplacian ** 2).sum(1).mean() / problem.radius ** 2
            + settings.even * lengths.var(unbiased=False) / lengths.mean() ** 2
            + settings.fold * (torch.relu(m - fan_areas(xz)) / m).pow(2).mean())


def _image_loss(image, target, sigma):
    return ((_blur(image, sigma) - _blur(target, sigma)) ** 2).mean()


def _image_term(problem: ShadowArtProblem, verts, sigma: float, method: str, settings: ShadowArtSettings):
    """(loss, exact image (H, W, 3), d loss / d verts (V, 3)) of the blurred image term at verts (V, 3)."""
    faces, cam, colors, light, a = (problem.mesh.faces, problem.camera, problem.face_colors, problem.light,
                                    problem.ambient)
    v = verts.detach().clone().requires_grad_()
    if method == "exact":                                                   # autograd through the exact image
        image = shadowed_coverage(Mesh(v, faces), cam, colors, light, a)
        loss = _image_loss(image, problem.target, sigma)
        g, = torch.autograd.grad(loss, v)
        return loss.detach(), image.detach(), g
    with torch.no_grad():
        exact = shadowed_coverage(Mesh(v.detach(), faces), cam, colors, light, a)
    if method == "reynolds":                                                # weights = dL/dimage, boundary term
        image = exact.clone().requires_grad_()
        loss = _image_loss(image, problem.target, sigma)
        weights, = torch.autograd.grad(loss, image)                         # (H, W, 3)
        g, = shadow_image_gradient(Mesh(v.detach(), faces), cam, colors, light, weights, method="reynolds",
                                   ambient=a)
        return loss.detach(), exact, g
    image = shadow_map_image(Mesh(v, faces), cam, colors, light, a, resolution=settings.resolution,
                             blur=settings.vsm_blur, supersample=settings.supersample, region=v.detach()[CENTRE:])
    loss = _image_loss(image, problem.target, sigma)
    g, = torch.autograd.grad(loss, v)
    return loss.detach(), exact, g


def _check_settings(settings):
    if not isinstance(settings, ShadowArtSettings):
        raise ValueError(f"settings must be a ShadowArtSettings, got {type(settings).__name__}")
    _check_int(settings.steps, "settings.steps", 1)
    for name in ("lr", "lr_end", "blur", "sharp_from", "smooth", "even", "fold", "vsm_blur"):
        value = getattr(settings, name)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < math.inf:
            raise ValueError(f"settings.{name} must be a finite number >= 0, got {value!r}")
    if settings.lr <= 0:
        raise ValueError(f"settings.lr must be positive, got {settings.lr!r}")
    _check_int(settings.resolution, "settings.resolution", 8)
    _check_int(settings.supersample, "settings.supersample", 1)


def _snapshot_steps(frames, steps):
    """The steps (in 0..steps) at which to keep an image: ``frames`` of them, evenly spaced, 0 and steps."""
    _check_int(frames, "frames", 0)
    if frames == 1:
        raise ValueError("frames must be 0 (no snapshots) or at least 2 (the start and the result), got 1")
    return sorted({round(k * steps / (frames - 1)) for k in range(frames)}) if frames else []


def fit_shadow_art(problem: ShadowArtProblem, *, method: str = "exact",
                   settings: ShadowArtSettings = ShadowArtSettings(), progress: bool = False,
                   frames: int = 0) -> ShadowArtFit:
    """Deform the problem's occluder in its plane until its shadow matches ``problem.target`` (module
    docstring). method: one of ``METHODS`` ("exact", "reynolds", "vsm"); frames: 0, or how many exact images
    to keep for a GIF, evenly spaced from the start to the result; progress: a tqdm bar. Returns a
    ``ShadowArtFit``. Deterministic: the same problem and settings give the same result."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if not isinstance(problem, ShadowArtProblem):
        raise ValueError(f"problem must be a ShadowArtProblem (shadow_art_problem), got {type(problem).__name__}")
    _check_settings(settings)
    keep = _snapshot_steps(frames, settings.steps)
    start = time.perf_counter()
    xz = problem.mesh.verts[CENTRE:][:, [0, 2]].clone().requires_grad_()  # (N + 1, 2) the unknowns: (x, z)
    opt = torch.optim.Adam([xz], lr=settings.lr)
    decay = torch.optim.lr_scheduler.LambdaLR(opt, lambda k: 1 - (1 - settings.lr_end) * k / settings.steps)
    fit = ShadowArtFit(problem.mesh.verts.clone(), method)
    steps = range(settings.steps)
    if progress:
        from tqdm.auto import tqdm
        steps = tqdm(steps, desc=f"shadow art ({method})")
    for step in steps:
        sigma = settings.blur * max(0.0, 1 - step / max(1, settings.sharp_from * settings.steps))
        verts = _occluder_verts(problem, xz)                                # (V, 3), a function of xz
        loss, image, d_verts = _image_term(problem, verts, sigma, method, settings)
        reg = _regulariser(problem, xz, settings)
        opt.zero_grad()
        torch.autograd.backward([verts, reg], [d_verts, torch.ones_like(reg)])   # chain to xz (N + 1, 2)
        opt.step()
        decay.step()
        fit.losses.append(float(loss) + float(reg.detach()))
        fit.ious.append(shadow_iou(problem, image))
        if step in keep:
            fit.snapshot_steps.append(step), fit.snapshots.append(image)
    fit.verts = _occluder_verts(problem, xz.detach()).detach()
    image = shadowed_coverage(Mesh(fit.verts, problem.mesh.faces), problem.camera, problem.face_colors,
                              problem.light, problem.ambient).detach()
    fit.ious.append(shadow_iou(problem, image))
    if settings.steps in keep:
        fit.snapshot_steps.append(settings.steps), fit.snapshots.append(image)
    fit.seconds = time.perf_counter() - start
    return fit


# ------------------------------------------------------------------------------------------ the pictures

def _side_by_side(left, right, gap: int = 2):
    """(H, 2W + gap, 3): two images with a white gap between them."""
    white = torch.ones(left.shape[0], gap, 3, dtype=left.dtype)
    return torch.cat([left, white, right.to(left.dtype)], 1)


def save_shadow_art_gif(problem: ShadowArtProblem, fit: ShadowArtFit, path, *, fps: float = 8):
    """A GIF of ``fit``'s snapshots (``fit_shadow_art(..., frames=K)``), each frame the target and the fit's
    exact image side by side, labelled with the step and the IoU (``frames.save_gif``). Returns the path."""
    from ..frames import save_gif
    if not fit.snapshots:
        raise ValueError("the fit kept no snapshots: run fit_shadow_art with frames >= 2")
    frames = [_side_by_side(problem.target, s) for s in fit.snapshots]
    labels = [f"{fit.method} step {k} IoU {fit.ious[k]:.2f}" for k in fit.snapshot_steps]
    return save_gif(frames, path, fps=fps, labels=labels)


def _fan_on_screen(problem: ShadowArtProblem, verts):
    """(N + 1, 2) pixel coordinates of the occluder's shadow: its vertices (verts (V, 3), the centre first, as
    ``problem.mesh``) moved along the light to the floor (y = 0), then projected by the camera."""
    occluder = verts.detach()[CENTRE:]
    light = problem.light
    on_floor = occluder + (occluder[:, 1:2] / -light[1]) * light           # (N + 1, 3) y = 0
    pixels, _ = problem.camera.project(on_floor)
    return pixels


def shadow_art_figure(problem: ShadowArtProblem, fits, *, size: float = 2.6):
    """One row: the target, the start, each fit's result (exact images, captioned with the IoU, the fan's
    shadow drawn over them: its outline in red, its spokes faint) and the IoU per step of every fit.
    fits: a list of ``ShadowArtFit`` (e.g. exact and vsm). Returns the figure."""
    import matplotlib.pyplot as plt
    from ..frames import image_to_frame
    fits = list(fits)
    if not fits or not all(isinstance(f, ShadowArtFit) for f in fits):
        raise ValueError("fits must be a non-empty list of ShadowArtFit")
    start = shadowed_coverage(problem.mesh, problem.camera, problem.face_colors, problem.light, problem.ambient)
    panels = [("target", problem.target, "", None)]
    panels.append(("start", start, f"IoU {shadow_iou(problem, start):.3f}", problem.mesh.verts))
    for f in fits:
        image = shadowed_coverage(Mesh(f.verts, problem.mesh.faces), problem.camera, problem.face_colors,
                                  problem.light, problem.ambient)
        panels.append((f.method, image, f"IoU {f.iou:.3f}", f.verts))
    fig, axes = plt.subplots(1, len(panels) + 1, figsize=(size * (len(panels) + 1.3), size + 0.4))
    H, W = problem.camera.height, problem.camera.width
    for ax, (title, image, caption, verts) in zip(axes, panels):
        ax.imshow(image_to_frame(image.detach()), interpolation="nearest", extent=(0, W, H, 0))
        if verts is not None:                                               # pixel centres at half-integers
            p = _fan_on_screen(problem, verts).numpy()
            for q in p[1:]:
                ax.plot([p[0, 0], q[0]], [p[0, 1], q[1]], color="C3", lw=0.4, alpha=0.4)
            ring = p[list(range(1, len(p))) + [1]]
            ax.plot(ring[:, 0], ring[:, 1], color="C3", lw=0.8, marker=".", ms=2)
        ax.set_xlim(0, W), ax.set_ylim(H, 0)
        ax.set_xticks([]), ax.set_yticks([])
        ax.set_title(title)
        ax.set_xlabel(caption)
    ax = axes[-1]
    for k, f in enumerate(fits):                                            # exact and reynolds coincide
        ax.plot(range(len(f.ious)), f.ious, ("-", "--", ":", "-.")[k % 4], color=f"C{k}", label=f.method)
    ax.set_xlabel("step")
    ax.set_ylabel("shadow IoU")
    ax.set_ylim(min(f.ious[0] for f in fits) - 0.05, 1)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.suptitle(f"shadow art: a {problem.name} from a disc")
    fig.tight_layout()
    return fig
