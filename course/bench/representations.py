"""The teapot fitted three ways: ``python -m course bench representations [--fast]``.

Lecture 10's data (``course.inverse.shaded.shaded_data``: 12 flat-shaded 64² training views of the teapot, the
visual hull carved from their masks, 16 held-out views) fitted by Gaussians (``fit_gaussians``, from the hull
and from random points), by a 32³ density grid (``fit_density_grid``) and by the mesh (``fit_mesh_from_images``,
from the hull), each with its defaults, one run each (seed 0). Per fit: steps, the fit's seconds, the held-out
PSNR (mean over the 16 views) and the worst view's, and **what it gets wrong** (``course.inverse.anatomy``):
the share of its held-out squared error on the silhouette's outline, in the gap under the lid (where the
target shows its inside), in the shading of the covered surface, in floaters and where the background shows
through the target, with those two regions' pixel counts. The shaded hull is a row too (no steps). A row's
seconds are its fit's steps (the Gaussians' and the grid's periodic evaluations left out; the mesh's wall time,
snapshots off). The data are computed once and counted in no row; the process's peak resident memory is printed at the end.
``--fast``: 4 views at 32², a few steps each (a smoke run, not a measurement).
"""
from __future__ import annotations

import resource
import time

import torch

from .. import models
from ..inverse.anatomy import error_anatomy, inside_masks
from ..inverse.gaussians import fit_gaussians
from ..inverse.shaded import fit_mesh_from_images, shaded_data, shaded_images
from ..inverse.volume_fit import fit_density_grid
from ..splats import render_gaussians
from ..volume import render_volume

__all__ = ["FITS", "measure", "bench_representations", "add_arguments", "run"]

REPEAT = 1
DESCRIPTION = ("the teapot fitted by Gaussians, a density grid and the mesh: held-out PSNR, time, and where each "
               "one's error lies (outline, the gap under the lid, shading, floaters, see-through)")
# (label, kind, keyword arguments of the fit); steps are each fit's defaults
FITS = (("Gaussians, from the hull", "gaussians", dict(init="hull")),
        ("Gaussians, from random points", "gaussians", dict(init="random")),
        ("32³ density grid", "grid", {}),
        ("mesh (soft, Large Steps), from the hull", "mesh", dict(snapshot_every=None)))
SHARES = (("outline", "edge"), ("lid gap", "inside"), ("shading", "shading"), ("floaters", "floaters"),
          ("see-through", "see-through"))


def _renders(kind, result, data):
    """(16, H, W, 3) the fit's held-out images, as its held-out PSNR renders them."""
    bg = torch.as_tensor(data.background, dtype=torch.float64)
    with torch.no_grad():
        if kind == "gaussians":
            return torch.stack([render_gaussians(*result.params, c, bg) for c in data.held_out])
        if kind == "grid":
            return torch.stack([render_volume(result.density, result.colors, result.lo, result.hi, c, 64, bg)
                                for c in data.held_out])
        return shaded_images(result, data.held_out, background=data.background, exact=False)


def measure(fast: bool = False, out=print) -> list[dict]:
    teapot = models.teapot(dtype=torch.float64)
    data = shaded_data(teapot, **(dict(n_views=4, size=32, resolution=24) if fast else {}))
    inside = inside_masks(teapot, data.held_out)
    bg = torch.as_tensor(data.background, dtype=torch.float64)
    small = dict(gaussians=dict(steps=4, n=200, densify_every=2, densify_until=4, eval_every=0),
                 grid=dict(steps=3, resolution=8, eval_every=0), mesh=dict(steps=3)) if fast else {}
    rows = []

    def row(label, steps, seconds, renders):
        a = error_anatomy(renders, data.held_out_images, data.held_out_masks, bg, inside=inside)
        r = dict(fit=label, steps=steps, seconds=seconds, psnr=sum(a["psnr"]) / len(a["psnr"]),
                 worst_view=a["worst_view"], worst_psnr=a["psnr"][a["worst_view"]],
                 floater_pixels=a["floaters"]["pixels"], see_through_pixels=a["see-through"]["pixels"],
                 inside_pixels=a["inside"]["pixels"])
        r.update({f"share_{name}": a[key]["share"] for name, key in SHARES})
        rows.append(r)
        out(f"{label}: {r['psnr']:.2f} dB held out, {seconds:.0f} s", flush=True)

    with torch.no_grad():
        hull = shaded_images(data.hull, data.held_out, background=data.background, exact=False)
    row("the carved hull (no fit)", 0, 0.0, hull)
    for label, kind, extra in FITS:
        kwargs = dict(extra, **small.get(kind, {}))
        start = time.perf_counter()
        if kind == "gaussians":
            result = fit_gaussians(data, seed=0, **kwargs)
            steps, fitted = kwargs.get("steps", 1200), result
        elif kind == "grid":
            result = fit_density_grid(data, seed=0, **kwargs)
            steps, fitted = kwargs.get("steps", 300), result
        else:
            result = fit_mesh_from_images(teapot, seed=0, progress=False, data=data, **kwargs)
            steps, fitted = kwargs.get("steps", 150), result.mesh
        seconds = getattr(result, "seconds", 0.0) or (time.perf_counter() - start)
        row(label, steps, seconds, _renders(kind, fitted, data))
    return rows


def bench_representations(fast: bool = False, out=print) -> list[dict]:
    rows = measure(fast, out)
    out("")
    out("held-out PSNR (dB), mean and worst of the 16 views; share (%) of the held-out squared error by region; "
        "pixels (all views)")
    head = f"{'fit':<40} {'steps':>5} {'s':>5} {'PSNR':>6} {'worst':>6}"
    head += "".join(f" {name:>11}" for name, _ in SHARES) + f" {'floater px':>10} {'see-thr. px':>11}"
    out(head)
    for r in rows:
        line = (f"{r['fit']:<40} {r['steps']:>5} {r['seconds']:>5.0f} {r['psnr']:>6.2f} "
                f"{r['worst_psnr']:>6.2f}")
        line += "".join(f" {100 * r['share_' + name]:>11.1f}" for name, _ in SHARES)
        line += f" {r['floater_pixels']:>10} {r['see_through_pixels']:>11}"
        out(line)
    out(f"the lid gap (the target shows its inside there: the gap under the lid, the spout's opening), off the "
        f"outline: {rows[0]['inside_pixels']} held-out pixels; the fits' worst views: "
        f"{sorted({r['worst_view'] for r in rows})}")
    out(f"peak resident memory of the process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
    return rows


def add_arguments(parser) -> None:
    parser.add_argument("--fast", action="store_true", help="a smoke run: 4 small views, a few steps a fit")


def run(args) -> list[dict]:
    return bench_representations(args.fast)
