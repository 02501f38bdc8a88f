"""A light recovered from its shadows: the direction of a directional light fitted to one image (lecture 12).

The image model is ``shadow_gradients.shadowed_coverage`` (flat colours, hard shadows, box-filtered exactly);
the loss is the mean squared difference to the target image, both blurred by a Gaussian of ``blur`` pixels
that shrinks to 0 over the fit (coarse to fine: a shadow that misses its target entirely has a zero
gradient, since sliding it over empty floor changes nothing; blurred, the two overlap). The light is a free
3-vector, normalised where it is used (the image depends on its direction only), stepped by Adam; its
gradient comes from ``shadow_image_gradient`` with ``method`` "exact" or "reynolds" (the boundary term of the
shadow edges), the weights being the loss's derivative with respect to the image.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from .gradients import _check_scene, shadow_image_gradient, shadowed_coverage
from ..tensors import as_tensor, unit

__all__ = ["LightFitSettings", "LightFit", "angle_between", "fit_light_direction"]


@dataclass(frozen=True)
class LightFitSettings:
    """steps: Adam steps; lr: its step size (the light is a unit vector, so about radians); blur: the
    Gaussian's standard deviation (pixels) at the start, falling linearly to 0 at ``sharp_from`` of the
    steps; method: "exact" or "reynolds"."""
    steps: int = 80
    lr: float = 0.03
    blur: float = 2.0
    sharp_from: float = 0.6
    method: str = "exact"


@dataclass
class LightFit:
    """light: (3,) the fitted direction (unit); losses, angles: per step (angles in degrees to ``truth`` when
    it was given, else empty)."""
    light: torch.Tensor
    losses: list = field(default_factory=list)
    angles: list = field(default_factory=list)


def angle_between(a, b) -> float:
    """The angle between two directions (3,), in degrees."""
    a, b = as_tensor(a, dtype=torch.float64), as_tensor(b, dtype=torch.float64)
    c = float(a @ b / (a.norm() * b.norm()))
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def _blur(image, sigma):
    """(H, W, 3) blurred by a separable Gaussian of ``sigma`` pixels (zero padding); sigma 0: unchanged."""
    if sigma <= 0:
        return image
    r = max(1, int(3 * sigma + 0.5))
    x = torch.arange(-r, r + 1, dtype=image.dtype, device=image.device)
    k = torch.exp(-0.5 * (x / sigma) ** 2)
    k = k / k.sum()
    m = image.permute(2, 0, 1)[:, None]                                     # (3, 1, H, W)
    m = torch.nn.functional.conv2d(m, k.view(1, 1, 1, -1), padding=(0, r))
    m = torch.nn.functional.conv2d(m, k.view(1, 1, -1, 1), padding=(r, 0))
    return m[:, 0].permute(1, 2, 0)


def fit_light_direction(mesh, camera, face_colors, target, init, *, ambient=0.3, background=(0.0, 0.0, 0.0),
                        settings: LightFitSettings = LightFitSettings(), truth=None, progress: bool = False):
    """Fit the direction a light travels so that ``shadowed_coverage`` matches ``target`` (H, W, 3).

    mesh, camera, face_colors (F, 3), ambient, background: as ``shadowed_coverage``; init: (3,) the starting
    direction; truth: (3,) optional, to record the angle to it each step. Returns a ``LightFit``."""
    if settings.method not in ("exact", "reynolds"):
        raise ValueError(f"settings.method must be 'exact' or 'reynolds', got {settings.method!r}")
    if not (isinstance(settings.steps, int) and settings.steps > 0):
        raise ValueError(f"settings.steps must be a positive integer, got {settings.steps!r}")
    verts, _, d = _check_scene(mesh, init)
    target = as_tensor(target, dtype=torch.float64, name="target")
    if target.shape != (camera.height, camera.width, 3):
        raise ValueError(f"target must have shape (H, W, 3) = ({camera.height}, {camera.width}, 3), "
                         f"got {tuple(target.shape)}")
    if not torch.isfinite(target).all():
        raise ValueError("target contains NaN or inf")
    light = unit(d.detach().double()).clone().requires_grad_()
    opt = torch.optim.Adam([light], lr=settings.lr)
    fit = LightFit(light.detach().clone())
    steps = range(settings.steps)
    if progress:
        from tqdm.auto import tqdm
        steps = tqdm(steps, desc="light fit")
    for step in steps:
        sigma = settings.blur * max(0.0, 1 - step / max(1, settings.sharp_from * settings.steps))
        with torch.no_grad():
            image = shadowed_coverage(mesh, camera, face_colors, light, ambient, background).double()
        image = image.requires_grad_()
        loss = ((_blur(image, sigma) - _blur(target, sigma)) ** 2).mean()
        weights, = torch.autograd.grad(loss, image)                        # d loss / d image, (H, W, 3)
        g, = shadow_image_gradient(mesh, camera, face_colors, light.detach(), weights, method=settings.method,
                                   ambient=ambient, background=background, wrt=("light",))
        opt.zero_grad()
        light.grad = g.to(light.dtype)
        opt.step()
        with torch.no_grad():
            light /= light.norm()                                           # stay a unit vector
        fit.losses.append(float(loss.detach()))
        if truth is not None:
            fit.angles.append(angle_between(light.detach(), truth))
    fit.light = light.detach().clone()
    return fit
