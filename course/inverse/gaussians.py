"""Gaussians fitted to shaded images (lecture 15): the teapot's 12 views of lecture 10, splatted.

``fit_gaussians(data)`` takes lecture 10's ``ShadedData`` (the 12 training views and their exact shaded images,
the visual hull carved from their masks, the 16 held-out views) and fits N Gaussians (``course.splats``) to the
training images, one random view a step, by Adam on the L1 image difference: means, log standard deviations,
quaternions (normalised when rendering), opacities through a sigmoid, and RGB colours (the images are
flat-shaded by a light fixed in the world, so a colour per Gaussian needs no view dependence).

**Start**: ``init="hull"`` puts the means on the visual hull's surface (area-weighted), ``init="random"`` in the
ball the views look at; standard deviations 0.03, opacity ½, grey.

**Densify and prune**, Kerbl et al.'s adaptive density control in a simplified form: every ``densify_every``
steps until ``densify_until``, each Gaussian's mean positional gradient (the norm of dL/dμ, averaged over the
steps since the last densification) above ``grad_threshold`` marks it under-reconstructed: a small one
(largest standard deviation below ``split_scale``) is **cloned** (a copy in place: the two separate as they
are optimised), a large one is **split** into two drawn from itself with standard deviations ÷ 1.6; then
Gaussians with opacity below ``prune_opacity`` are **pruned**. Left out of the reference: the periodic reset of
every opacity, the gradient taken in screen space (here in world space), spherical harmonics, the Adam moments
carried over (the optimiser restarts after each densification).

Reported: the held-out PSNR (mean over the 16 views, the renders clamped to [0, 1] against the target's 4 × 4
supersampled images), the count of Gaussians, the steps' time.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import torch

from ..splats import quaternion_to_matrix, render_gaussians
from . import losses

__all__ = ["GaussianFit", "fit_gaussians", "gaussian_psnr"]


@dataclass
class GaussianFit:
    """``params``: (means, scales, rotations, opacities, colors) of the fitted Gaussians (float64, detached);
    ``start_psnr`` / ``psnr``: held-out PSNR (dB, mean over the views) of the start and the result;
    ``psnr_curve``: [(step, held-out PSNR)] every ``eval_every`` steps; ``counts``: [(step, N)] after each
    densification; ``seconds``: the steps' wall time (the evaluations not counted)."""
    params: tuple
    start_psnr: float
    psnr: float
    psnr_curve: list = field(default_factory=list)
    counts: list = field(default_factory=list)
    seconds: float = 0.0


def _activate(raw):
    means, log_scales, quats, logit_o, colors = raw
    return means, log_scales.exp(), quats / quats.norm(dim=1, keepdim=True), torch.sigmoid(logit_o), colors


def gaussian_psnr(params, cameras, images, background) -> float:
    """The mean PSNR (dB) of the Gaussians' renders (clamped to [0, 1]) against ``images`` (M, H, W, 3)."""
    bg = torch.as_tensor(background, dtype=torch.float64)
    with torch.no_grad():
        values = [losses.psnr(render_gaussians(*params, c, bg).clamp(0, 1), t.to(torch.float64))
                  for c, t in zip(cameras, images)]
    return float(torch.stack(values).mean())


def _start(data, n, init, generator):
    if init == "hull":
        if data.hull is None:
            raise ValueError("init='hull' needs data with a carved hull (shaded_data(..., hull=True))")
        tri = data.hull.verts.to(torch.float64)[data.hull.faces]
        area = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], dim=1).norm(dim=1) / 2
        f = torch.multinomial(area, n, replacement=True, generator=generator)
        u = torch.rand(n, 2, generator=generator, dtype=torch.float64)
        u = torch.where((u.sum(1) > 1)[:, None], 1 - u, u)
        means = tri[f, 0] + u[:, :1] * (tri[f, 1] - tri[f, 0]) + u[:, 1:] * (tri[f, 2] - tri[f, 0])
    elif init == "random":
        d = torch.randn(n, 3, generator=generator, dtype=torch.float64)
        means = d / d.norm(dim=1, keepdim=True) * torch.rand(n, 1, generator=generator, dtype=torch.float64) ** (1 / 3)
    else:
        raise ValueError(f"init must be 'hull' or 'random', got {init!r}")
    quats = torch.zeros(n, 4, dtype=torch.float64)
    quats[:, 0] = 1
    return [means, torch.full((n, 3), math.log(0.03), dtype=torch.float64), quats,
            torch.zeros(n, dtype=torch.float64), torch.full((n, 3), 0.5, dtype=torch.float64)]


def _optimizer(raw, lr):
    return torch.optim.Adam([{"params": [raw[0]], "lr": 2e-3 * lr}, {"params": [raw[1]], "lr": 1e-2 * lr},
                             {"params": [raw[2]], "lr": 5e-3 * lr}, {"params": [raw[3]], "lr": 5e-2 * lr},
                             {"params": [raw[4]], "lr": 1e-2 * lr}])


def _densify(raw, grad_sum, grad_count, grad_threshold, split_scale, prune_opacity, generator):
    """Clone, split and prune (module docstring); returns new leaves."""
    raw = [p.detach() for p in raw]
    mean_grad = grad_sum / grad_count.clamp_min(1)
    big = raw[1].exp().amax(1) > split_scale
    hot = mean_grad > grad_threshold
    clone, split = hot & ~big, hot & big
    new = [[p] for p in raw]
    if bool(clone.any()):
        for k in range(5):
            new[k].append(raw[k][clone])
    if bool(split.any()):
        scales = raw[1][split].exp()
        R = quaternion_to_matrix(raw[2][split] / raw[2][split].norm(dim=1, keepdim=True))
        for _ in range(2):
            offset = (R @ (torch.randn(scales.shape, generator=generator, dtype=torch.float64) * scales)[..., None])[..., 0]
            new[0].append(raw[0][split] + offset)
            new[1].append(raw[1][split] - math.log(1.6))
            for k in (2, 3, 4):
                new[k].append(raw[k][split])
        keep_old = ~split                                                   # the split ones are replaced
        new = [[parts[0][keep_old]] + parts[1:] for parts in new]
    merged = [torch.cat(parts) for parts in new]
    alive = torch.sigmoid(merged[3]) >= prune_opacity
    return [p[alive].clone().requires_grad_() for p in merged]


def fit_gaussians(data, *, n: int = 3000, steps: int = 1200, init: str = "hull", seed: int = 0, lr: float = 1.0,
                  densify_every: int = 200, densify_until: int = 800, grad_threshold: float = 2e-4,
                  split_scale: float = 0.06, prune_opacity: float = 0.005, eval_every: int = 200,
                  progress: bool = False) -> GaussianFit:
    """Fit Gaussians to ``data``'s training images (module docstring); evaluate on its held-out views.
    ``densify_every=0`` turns the adaptive density control off."""
    g = torch.Generator().manual_seed(int(seed))
    bg = torch.as_tensor(data.background, dtype=torch.float64)
    raw = [p.requires_grad_() for p in _start(data, int(n), init, g)]
    opt = _optimizer(raw, lr)
    held = (data.held_out, data.held_out_images, data.background)
    fit = GaussianFit(tuple(p.detach() for p in _activate(raw)), 0.0, 0.0)
    fit.start_psnr = gaussian_psnr(fit.params, *held)
    grad_sum = torch.zeros(raw[0].shape[0], dtype=torch.float64)
    grad_count = torch.zeros_like(grad_sum)
    seconds = 0.0
    for step in range(int(steps)):
        t0 = time.perf_counter()
        k = int(torch.randint(len(data.cameras), (1,), generator=g))
        opt.zero_grad()
        image = render_gaussians(*_activate(raw), data.cameras[k], bg)
        loss = (image - data.targets[k].to(torch.float64)).abs().mean()
        loss.backward()
        grad_sum += raw[0].grad.norm(dim=1)
        grad_count += 1
        opt.step()
        if densify_every and (step + 1) % densify_every == 0 and step + 1 <= densify_until:
            raw = _densify(raw, grad_sum, grad_count, grad_threshold, split_scale, prune_opacity, g)
            opt = _optimizer(raw, lr)
            grad_sum = torch.zeros(raw[0].shape[0], dtype=torch.float64)
            grad_count = torch.zeros_like(grad_sum)
            fit.counts.append((step + 1, raw[0].shape[0]))
        seconds += time.perf_counter() - t0
        if eval_every and (step + 1) % eval_every == 0:
            value = gaussian_psnr(tuple(p.detach() for p in _activate(raw)), *held)
            fit.psnr_curve.append((step + 1, value))
            if progress:
                print(f"step {step + 1}: {raw[0].shape[0]} Gaussians, held-out PSNR {value:.2f} dB, {seconds:.0f} s",
                      flush=True)
    fit.params = tuple(p.detach() for p in _activate(raw))
    fit.psnr = gaussian_psnr(fit.params, *held)
    fit.seconds = seconds
    return fit
