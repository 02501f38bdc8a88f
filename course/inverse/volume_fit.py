"""A density grid fitted to shaded images (lecture 15): the teapot's 12 views of lecture 10, volume-rendered.

``fit_density_grid(data)`` fits a ``resolution``³ grid of density and colour filling the box [-1, 1]³ (the
teapot fits the unit sphere) to lecture 10's training images (``ShadedData``) with NeRF's quadrature
(``course.volume.render_volume``, trilinear, ``samples`` steps a ray), one random view a step, Adam on the L1
image difference. The density is ``scale · softplus(raw)`` (non-negative, ``scale`` per unit length) and the
colour ``sigmoid(raw)``. No regulariser: what the views do not constrain (inside, behind, between) stays where
the optimiser leaves it, floaters included. Reported as ``fit_gaussians`` does: the
held-out PSNR over the 16 views and the steps' time.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import torch

from ..volume import render_volume
from . import losses

__all__ = ["GridFit", "fit_density_grid"]


@dataclass
class GridFit:
    """``density`` (R, R, R) and ``colors`` (R, R, R, 3) of the fitted grid over ``lo``..``hi``; held-out PSNR of
    the start and the result (dB); ``psnr_curve`` [(step, PSNR)]; ``seconds`` the steps' wall time."""
    density: torch.Tensor
    colors: torch.Tensor
    lo: torch.Tensor
    hi: torch.Tensor
    start_psnr: float
    psnr: float
    psnr_curve: list = field(default_factory=list)
    seconds: float = 0.0


def _psnr(density, colors, lo, hi, cameras, images, background, samples):
    bg = torch.as_tensor(background, dtype=torch.float64)
    with torch.no_grad():
        return float(torch.stack([losses.psnr(render_volume(density, colors, lo, hi, c, samples, bg).clamp(0, 1),
                                              t.to(torch.float64)) for c, t in zip(cameras, images)]).mean())


def fit_density_grid(data, *, resolution: int = 32, steps: int = 300, samples: int = 64, lr: float = 0.1,
                     scale: float = 10.0, seed: int = 0, eval_every: int = 100, progress: bool = False) -> GridFit:
    """Fit a density grid to ``data``'s training images (module docstring); evaluate on its held-out views."""
    R = int(resolution)
    g = torch.Generator().manual_seed(int(seed))
    bg = torch.as_tensor(data.background, dtype=torch.float64)
    lo, hi = torch.full((3,), -1.0, dtype=torch.float64), torch.full((3,), 1.0, dtype=torch.float64)
    raw_density = torch.full((R, R, R), -2.0, dtype=torch.float64, requires_grad=True)
    raw_colors = torch.zeros(R, R, R, 3, dtype=torch.float64, requires_grad=True)
    opt = torch.optim.Adam([raw_density, raw_colors], lr=lr)

    def fields():
        return scale * torch.nn.functional.softplus(raw_density), torch.sigmoid(raw_colors)
    held = (data.held_out, data.held_out_images, data.background, samples)
    start = _psnr(*[f.detach() for f in fields()], lo, hi, *held)
    curve, seconds = [], 0.0
    for step in range(int(steps)):
        t0 = time.perf_counter()
        k = int(torch.randint(len(data.cameras), (1,), generator=g))
        opt.zero_grad()
        image = render_volume(*fields(), lo, hi, data.cameras[k], samples, bg)
        (image - data.targets[k].to(torch.float64)).abs().mean().backward()
        opt.step()
        seconds += time.perf_counter() - t0
        if eval_every and (step + 1) % eval_every == 0:
            curve.append((step + 1, _psnr(*[f.detach() for f in fields()], lo, hi, *held)))
            if progress:
                print(f"step {step + 1}: held-out PSNR {curve[-1][1]:.2f} dB, {seconds:.0f} s", flush=True)
    density, colors = (f.detach() for f in fields())
    return GridFit(density, colors, lo, hi, start, _psnr(density, colors, lo, hi, *held), curve, seconds)
