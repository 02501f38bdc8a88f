"""The penumbra-gradient benchmark: ``python -m course bench penumbra [--seeds N] [--plot FILE]``.

The gradient of ``Σ weights · F(points)`` (F the form factor of a square area light, 144 receivers on the floor
across the penumbra) with respect to the occluders' vertices, on ``penumbra_scene("square")`` and
``("overlap")``, in float64, by every estimator of ``course.shadows.penumbra``: exact (the reference),
shadow rays with autograd only, shadow rays plus edge sampling of the silhouettes seen from each point, finite
differences of the shadow-ray estimate (the same random numbers at both ends) and the variance shadow map
averaged over a grid of points on the light.

For each estimator and budget, over ``--seeds`` seeds: the **bias** ``|mean g - g_exact| / |g_exact|`` (the
mean over seeds; what remains of it for an unbiased estimator is the mean's noise, about sd / √seeds), the
**spread** ``sqrt(mean |g - mean g|²) / |g_exact|`` (one run's noise), the **error** of one run
``mean |g - g_exact| / |g_exact|``, and the median time of one gradient (forward and backward, ms). It prints
a table and writes a log-log plot (time against one run's error, a line per estimator).
"""
from __future__ import annotations

import math

import torch

from ..shadows.penumbra import penumbra_gradient, penumbra_scene
from .timing import time_it

__all__ = ["measure", "bench_penumbra", "plot_pareto", "add_arguments", "run", "CONFIGS"]

REPEAT = 1
DESCRIPTION = ("penumbra gradients of an area light: exact, shadow rays, edge sampling, finite differences and "
               "variance shadow maps against the exact gradient: bias, spread and time")
SCENES = ("square", "overlap")
# (method, label, keyword arguments of penumbra_gradient)
CONFIGS = (
    ("shadow_rays", "S=64", dict(samples=64)),
    ("shadow_rays", "S=1024", dict(samples=1024)),
    ("edge_sampling", "S=64 M=64", dict(samples=64, edge_samples=64)),
    ("edge_sampling", "S=64 M=256", dict(samples=64, edge_samples=256)),
    ("edge_sampling", "S=64 M=1024", dict(samples=64, edge_samples=1024)),
    ("finite_differences", "S=256 h=1e-2", dict(samples=256, step=1e-2)),
    ("finite_differences", "S=1024 h=1e-2", dict(samples=1024, step=1e-2)),
    ("finite_differences", "S=1024 h=1e-3", dict(samples=1024, step=1e-3)),
    ("vsm", "3x3 R=64", dict(grid=3, resolution=64)),
    ("vsm", "3x3 R=128", dict(grid=3, resolution=128)),
    ("vsm", "5x5 R=128", dict(grid=5, resolution=128)),
)


def measure(scenes=SCENES, seeds: int = 5, n: int = 12, repeat: int = REPEAT, configs=CONFIGS):
    """Rows: scene, method, param, ms, bias, spread, error (module docstring)."""
    rows = []
    for name in scenes:
        scene = penumbra_scene(name, n)
        exact = penumbra_gradient(scene, "exact")
        scale = float(exact.norm())
        rows.append(dict(scene=name, method="exact", param="-", ms=time_it(lambda: penumbra_gradient(scene), 3),
                         bias=0.0, spread=0.0, error=0.0))
        for method, label, kwargs in configs:
            runs = [penumbra_gradient(scene, method, seed=s, **kwargs) for s in range(seeds)]
            G = torch.stack(runs)
            mean = G.mean(0)
            spread = math.sqrt(float(((G - mean) ** 2).sum((1, 2)).mean())) / scale
            error = sum(float((g - exact).norm()) for g in runs) / (len(runs) * scale)
            ms = time_it(lambda: penumbra_gradient(scene, method, seed=seeds, **kwargs), repeat, warmup=0)
            rows.append(dict(scene=name, method=method, param=label, ms=ms,
                             bias=float((mean - exact).norm()) / scale, spread=spread, error=error))
    return rows


def plot_pareto(rows, path=None):
    """Log-log: time (ms) against one run's relative error, a line per estimator and scene."""
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    methods = list(dict.fromkeys(r["method"] for r in rows if r["method"] != "exact"))
    for s, scene in enumerate(dict.fromkeys(r["scene"] for r in rows)):
        for i, method in enumerate(methods):
            pts = [r for r in rows if r["scene"] == scene and r["method"] == method]
            ax.plot([r["ms"] for r in pts], [max(r["error"], 1e-6) for r in pts], marker="os^vD"[i % 5],
                    color=f"C{i}", ls="-" if s == 0 else ":", label=f"{method} ({scene})")
    exact = [r["ms"] for r in rows if r["method"] == "exact"]
    ax.axvline(max(exact), color="0.3", ls="--", lw=1, label="exact (reference, error 0)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time of one gradient (ms)")
    ax.set_ylabel("|g - g_exact| / |g_exact|")
    ax.set_title("penumbra gradients w.r.t. the occluders' vertices")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6)
    fig.tight_layout()
    if path:
        fig.savefig(path, dpi=110)
    return fig


def bench_penumbra(scenes=SCENES, seeds=5, n=12, repeat=REPEAT, plot=None):
    rows = measure(scenes, seeds, n, repeat)
    print(f"{n * n} receivers under a square light, float64; the gradient w.r.t. the occluders' vertices; "
          f"{seeds} seeds")
    print(f"{'scene':<8} {'method':<19} {'param':>14} {'ms':>9} {'bias':>9} {'spread':>9} {'error':>9}")
    for r in rows:
        print(f"{r['scene']:<8} {r['method']:<19} {r['param']:>14} {r['ms']:>9.1f} {r['bias']:>9.2e} "
              f"{r['spread']:>9.2e} {r['error']:>9.2e}")
    if plot:
        plot_pareto(rows, plot)
        print(f"plot written to {plot}")
    return rows


def add_arguments(parser) -> None:
    parser.add_argument("--seeds", type=int, default=5, help="seeds per estimator (bias and spread over them)")
    parser.add_argument("--points", type=int, default=12, help="receivers per side of the floor's grid")
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    parser.add_argument("--plot", default="", help="where to save the plot ('' for none)")


def run(args) -> list[dict]:
    return bench_penumbra(args.scenes, args.seeds, args.points, args.repeat, args.plot or None)
