"""The shadow-art benchmark (lecture 12): ``python -m course bench shadow-art [--targets star T L]
[--methods exact reynolds vsm] [--size N] [--steps K] [--figure PNG] [--gif DIR]``.

A flat disc above the floor deformed until its shadow matches a target outline (``course.shadows.art``: the
camera sees the floor and the shadow only), once per target and gradient:

* ``exact``: autograd through the exact shadowed image (``shadow_gradients.shadowed_coverage``);
* ``reynolds``: the boundary term of the shadow's edges (``shadow_image_gradient(method="reynolds")``);
* ``vsm``: autograd through a variance shadow map drawn smoothly (``prefiltered_shadows.shadow_map_image``).

Each fit runs ``fit_shadow_art``'s default settings (``--steps`` to change the number of steps) and is timed
once, after a one-step warm-up of each method on a tiny scene (the compiled kernels' cold start): the wall time
of the whole fit, the exact image's IoU at every step included (``--repeat`` runs it more times and reports
the median). Metric: the shadow IoU against the target (``shadow_iou``, from the exact images in float64)
of the start disc and of the result; the fits are deterministic, so only the time varies.
``--figure`` saves the first target's fits side by side (``shadow_art_figure``), ``--gif`` a GIF per fit.
"""
from __future__ import annotations

import statistics
from dataclasses import replace
from pathlib import Path

from ..shadows.art import (METHODS, TARGETS, ShadowArtSettings, fit_shadow_art, save_shadow_art_gif,
                          shadow_art_figure, shadow_art_problem)

__all__ = ["bench_shadow_art", "add_arguments", "run"]

REPEAT = 1
DESCRIPTION = ("shadow art: a disc's shadow fitted to a star (and letters) by the exact gradient, Reynolds and "
               "variance shadow maps: steps, time, shadow IoU")


def bench_shadow_art(targets=("star",), methods=METHODS, size: int = 48, steps: int | None = None,
                     repeat: int = REPEAT, figure=None, gif=None) -> list[dict]:
    """Rows: target, method, steps, seconds (median over ``repeat`` fits), start_iou, iou. Prints a table."""
    settings = ShadowArtSettings() if steps is None else replace(ShadowArtSettings(), steps=steps)
    for method in methods:                                                  # the kernels' cold start: not timed
        fit_shadow_art(shadow_art_problem("star", 16, vertices=4), method=method,
                       settings=replace(settings, steps=1))
    rows = []
    print(f"shadow art, {size}x{size} px, float64; {settings.steps} Adam steps, coarse to fine")
    print(f"{'target':<7} {'method':<9} {'steps':>5} {'seconds':>8} {'start IoU':>10} {'final IoU':>10}")
    for target in targets:
        problem = shadow_art_problem(target, size)
        fits = []
        for method in methods:
            runs = [fit_shadow_art(problem, method=method, settings=settings, frames=12 if gif else 0)
                    for _ in range(max(1, repeat))]
            fit = runs[0]
            fits.append(fit)
            row = dict(target=target, method=method, steps=settings.steps,
                       seconds=statistics.median(r.seconds for r in runs), start_iou=fit.start_iou, iou=fit.iou)
            rows.append(row)
            print(f"{target:<7} {method:<9} {row['steps']:>5} {row['seconds']:>8.1f} {row['start_iou']:>10.3f} "
                  f"{row['iou']:>10.3f}", flush=True)
            if gif:
                path = save_shadow_art_gif(problem, fit, Path(gif) / f"shadow_art_{target}_{method}.gif")
                print(f"  GIF written to {path}")
        if figure and target == targets[0]:
            import matplotlib.pyplot as plt
            fig = shadow_art_figure(problem, fits)
            fig.savefig(figure, dpi=110)
            plt.close(fig)
            print(f"figure written to {figure}")
    return rows


def add_arguments(parser) -> None:
    parser.add_argument("--targets", nargs="+", choices=TARGETS, default=["star"], help="target outlines")
    parser.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS), help="gradients")
    parser.add_argument("--size", type=int, default=48, help="camera image size (pixels per side)")
    parser.add_argument("--steps", type=int, default=None, help="Adam steps (default: fit_shadow_art's)")
    parser.add_argument("--figure", default="", help="where to save the first target's figure ('' for none)")
    parser.add_argument("--gif", default="", help="a folder for a GIF of each fit ('' for none)")


def run(args) -> list[dict]:
    return bench_shadow_art(tuple(args.targets), tuple(args.methods), args.size, args.steps, args.repeat,
                            args.figure or None, args.gif or None)
