"""The shadow-gradient benchmark: ``python -m course bench shadow-gradients [--size N] [--plot FILE]``.

The gradient of ``L = Σ weights ⊙ image`` w.r.t. the occluder's vertices and the light's direction, on
``shadow_scene("floor_view")`` (the camera sees the floor and the shadow, not the occluder: every such
gradient is the shadow's), in float64, by

* ``exact``: autograd through the split mesh and exact coverage (``shadow_gradients``): the reference;
* ``finite_differences`` (central, step 1e-6), ``reynolds`` (the boundary term of the split mesh) and
  ``edge_sampling`` (``--samples``);
* ``vsm``: a variance shadow map drawn smoothly (``prefiltered_shadows.shadow_map_image``), at map
  resolutions ``--resolutions`` and pre-filter widths ``--blurs`` (texels), the camera shading 4 × 4 points
  per pixel: the Worchel-Alexa route, a gradient at a shadow map's cost, of a slightly different image.

Error: ``|g - g_exact| / |g_exact|`` over the 12 numbers (9 vertex coordinates, 3 of the light); for ``vsm``
also the mean |image - exact image|. Time: forward and backward, median of ``--repeat`` runs. It prints a
table and writes a log-log Pareto plot (time against gradient error, a line per method; exact as a dashed
vertical line).
"""
from __future__ import annotations

import torch

from ..mesh import Mesh
from ..shadows.prefiltered import shadow_map_image
from ..shadows.gradients import shadow_image_gradient, shadow_scene, shadowed_coverage
from .timing import time_it

__all__ = ["measure", "bench_shadow_gradients", "plot_pareto", "add_arguments", "run"]

REPEAT = 3
DESCRIPTION = ("shadow gradients: exact, finite differences, Reynolds, edge sampling and variance shadow maps "
               "against the exact gradient: time against error")
RESOLUTIONS = (32, 64, 128, 256)
BLURS = (0.5, 1.0, 2.0)
OCCLUDER = slice(3, 6)                                                      # the occluder's vertices


def _problem(size):
    mesh, cam, colors, light = shadow_scene("floor_view", size)
    w = torch.rand(size, size, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    return mesh, cam, colors, light, w


def _flat(g_verts, g_light):
    return torch.cat([g_verts[OCCLUDER].reshape(-1), g_light.reshape(-1)])


def _vsm_gradient(mesh, cam, colors, light, w, resolution, blur):
    verts = mesh.verts.clone().requires_grad_()
    d = light.clone().requires_grad_()
    image = shadow_map_image(Mesh(verts, mesh.faces), cam, colors, d, resolution=resolution, blur=blur,
                             supersample=4, region=mesh.verts[OCCLUDER])
    (image * w).sum().backward()
    return image.detach(), _flat(verts.grad, d.grad)


def measure(size: int = 32, repeat: int = REPEAT, resolutions=RESOLUTIONS, blurs=BLURS, samples=(1000, 10000)):
    """Rows: method, param, ms (forward + backward), error (relative, of the gradient), image_error (vsm)."""
    mesh, cam, colors, light, w = _problem(size)
    args = (mesh, cam, colors, light, w)
    grad = lambda method, **o: _flat(*shadow_image_gradient(*args, method=method, wrt=("verts", "light"), **o))
    reference = grad("exact")
    exact_image = shadowed_coverage(mesh, cam, colors, light)
    err = lambda g: float((g - reference).norm() / reference.norm())
    rows = [dict(method="exact", param="-", ms=time_it(lambda: grad("exact"), repeat), error=0.0)]
    fd_rows = list(range(3, 6))                                             # the occluder only: its entries
    fd = lambda: _flat(*shadow_image_gradient(*args, method="finite_differences", wrt=("verts", "light"),
                                              vertices=fd_rows))
    rows.append(dict(method="finite_differences", param="h=1e-6", ms=time_it(fd, 1, warmup=0), error=err(fd())))
    rows.append(dict(method="reynolds", param="order 1", ms=time_it(lambda: grad("reynolds"), repeat),
                     error=err(grad("reynolds"))))
    for n in samples:
        rows.append(dict(method="edge_sampling", param=n,
                         ms=time_it(lambda: grad("edge_sampling", samples=n, seed=1), repeat),
                         error=err(grad("edge_sampling", samples=n, seed=1))))
    for blur in blurs:
        for res in resolutions:
            image, g = _vsm_gradient(*args, res, blur)
            ms = time_it(lambda: _vsm_gradient(*args, res, blur), repeat)
            rows.append(dict(method=f"vsm blur {blur:g}", param=res, ms=ms, error=err(g),
                             image_error=float((image - exact_image).abs().mean())))
    return rows


def plot_pareto(rows, path=None):
    """Log-log: time (ms) against the gradient's relative error, a line per method."""
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.0, 4.2))
    for i, method in enumerate(dict.fromkeys(r["method"] for r in rows)):
        pts = [r for r in rows if r["method"] == method]
        if method == "exact":
            ax.axvline(pts[0]["ms"], color="0.3", ls="--", lw=1, label="exact (reference, error 0)")
            continue
        ax.plot([r["ms"] for r in pts], [max(r["error"], 1e-12) for r in pts], marker="os^vD<>"[i % 7],
                color=f"C{i}", label=method)
        for r in pts:
            ax.annotate(str(r["param"]), (r["ms"], max(r["error"], 1e-12)), fontsize=7, xytext=(3, 3),
                        textcoords="offset points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time, forward + backward (ms)")
    ax.set_ylabel("|g - g_exact| / |g_exact|")
    ax.set_title("shadow gradients: occluder vertices and light direction")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    if path:
        fig.savefig(path, dpi=110)
    return fig


def bench_shadow_gradients(size=32, repeat=REPEAT, resolutions=RESOLUTIONS, blurs=BLURS, samples=(1000, 10000),
                           plot=None):
    rows = measure(size, repeat, resolutions, blurs, samples)
    print(f"floor_view scene, {size}x{size} px, float64; gradient w.r.t. the occluder's vertices and the light")
    print(f"{'method':<20} {'param':>9} {'ms':>10} {'grad error':>11} {'image error':>12}")
    for r in rows:
        image = f"{r['image_error']:.2e}" if "image_error" in r else "-"
        print(f"{r['method']:<20} {str(r['param']):>9} {r['ms']:>10.1f} {r['error']:>11.2e} {image:>12}")
    if plot:
        plot_pareto(rows, plot)
        print(f"Pareto plot written to {plot}")
    return rows


def add_arguments(parser) -> None:
    parser.add_argument("--size", type=int, default=32, help="camera image size (pixels per side)")
    parser.add_argument("--resolutions", nargs="+", type=int, default=list(RESOLUTIONS),
                        help="variance shadow map resolutions (texels per side)")
    parser.add_argument("--blurs", nargs="+", type=float, default=list(BLURS),
                        help="the shadow map's Gaussian pre-filter (texels)")
    parser.add_argument("--samples", nargs="+", type=int, default=[1000, 10000], help="edge sampling's samples")
    parser.add_argument("--plot", default="", help="where to save the Pareto plot ('' for none)")


def run(args) -> list[dict]:
    return bench_shadow_gradients(args.size, args.repeat, args.resolutions, args.blurs, args.samples,
                                  args.plot or None)
