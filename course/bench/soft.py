"""The differentiable-rasterization benchmark: ``python -m course bench soft [--sizes 64 256] [--sigmas ...]
[--thresholds ...] [--gammas ...]``.

On S4's icosphere (``course.bench.raster.scene("S4")``, 1,280 faces, seen at 64² and 256², back faces
culled), for the silhouette and for a shaded image (flat face colours ``0.5 + 0.5 n``, n the face normal):

* **hard**: ``rasterize`` and the image built from its face ids. Its forward+backward backpropagates a
  fixed loss through the differentiable barycentrics and depth (the only gradient it has: none reaches
  the silhouette).
* **NMR**: ``nmr_rasterize`` (Kato et al. 2018), the same image with the approximate gradient, reach the
  whole row (the paper's). Its backward is not linear in the incoming gradient, so the loss is fixed:
  ``Σ w · I`` with seeded weights w.
* **soft**: ``soft_rasterize`` (Liu et al. 2019) at each σ and threshold (and γ for the shaded image).

Times are medians (ms) of the forward and of forward+backward, timed side by side; ``× hard`` is
forward+backward over the hard rasterizer's forward. The error is the image's RMSE and largest difference
to the exact box-filtered image (``course.coverage.exact_coverage``, the area of each pixel each face
covers). The soft image differs from it by design (σ blurs, γ fattens); the hard image shows the aliasing.
"""
from __future__ import annotations

import torch

from ..camera import Camera
from ..coverage import exact_coverage
from ..mesh import Mesh
from ..raster import rasterize
from ..nmr import nmr_rasterize
from ..soft import soft_rasterize
from .raster import scene
from .timing import time_side_by_side

__all__ = ["soft_scene", "bench_soft", "format_table", "add_arguments", "run"]

REPEAT = 3               # timed runs per measurement (the slow settings take a second or more)
DESCRIPTION = "hard, NMR and soft rasterization of S4 at 64² and 256²: forward and backward time, image error"

SIZES = (64, 256)
SIGMAS = (1e-5, 1e-4, 1e-3)
THRESHOLDS = (1e-2, 1e-4, 1e-6)
GAMMAS = (1e-2, 1e-4)


def soft_scene(size: int, dtype=torch.float32):
    """S4's icosphere and camera at ``size``² (same field of view), and its flat face colours (F, 3)."""
    mesh, cam = scene("S4", dtype=dtype)
    camera = Camera(cam.K * torch.tensor([[size / cam.width], [size / cam.height], [1.0]], dtype=dtype),
                    cam.R, cam.t, size, size, near=cam.near, far=cam.far)
    return mesh, camera, 0.5 + 0.5 * mesh.face_normals()


def _methods(mesh, camera, colors, shaded, sigmas, thresholds, gammas):
    """(label dict, forward function returning the image) for every method of one table block."""
    bg = torch.zeros(3, dtype=colors.dtype)

    def hard():
        frags = rasterize(mesh, camera, cull_backfaces=True)
        if not shaded:
            return frags.mask.to(colors.dtype)
        return torch.where(frags.mask[..., None], colors[frags.face_id.clamp(min=0)], bg)

    out = [(dict(method="hard"), hard),
           (dict(method="NMR"), lambda: nmr_rasterize(mesh, camera, face_colors=colors if shaded else None))]
    for sigma in sigmas:
        for thr in thresholds:
            for gamma in (gammas if shaded else (None,)):
                kw = dict(sigma=sigma, threshold=thr, cull_backfaces=True)
                if shaded:
                    kw.update(mode="color", gamma=gamma, face_colors=colors)
                out.append((dict(method="soft", sigma=sigma, gamma=gamma, threshold=thr),
                            lambda kw=kw: soft_rasterize(mesh, camera, **kw)))
    return out


def _backward(fn, weights, hard: bool):
    """One forward and backward of a fixed loss ``Σ w · I``; the hard rasterizer's ``fn`` returns its
    fragments, and its loss goes through their barycentrics and depth."""
    if hard:
        frags = fn()
        loss = (frags.bary * weights).sum() + torch.where(frags.mask, frags.depth, 0.0).sum()
    else:
        img = fn()
        loss = (img * (weights if img.dim() == 3 else weights[..., 0])).sum()
    loss.backward()


def bench_soft(sizes=SIZES, sigmas=SIGMAS, thresholds=THRESHOLDS, gammas=GAMMAS, repeat: int = REPEAT,
               out=print) -> list[dict]:
    """Time and image error of every method; returns one row (dict) per (size, image, method, setting)."""
    rows = []
    for size in sizes:
        base, camera, colors = soft_scene(size)
        leaf = base.verts.clone().requires_grad_()
        mesh = Mesh(leaf, base.faces)
        weights = torch.randn(size, size, 3, generator=torch.Generator().manual_seed(0))
        for shaded in (False, True):
            with torch.no_grad():
                ref = exact_coverage(base, camera, colors if shaded else torch.ones_like(colors))
            ref = ref if shaded else ref[..., 0]
            methods = _methods(mesh, camera, colors, shaded, sigmas, thresholds, gammas)
            fwd = [_no_grad(fn) for _, fn in methods]
            fb = [lambda fn=fn: _backward(fn, weights, False) for _, fn in methods[1:]]
            fb = [lambda: _backward(lambda: rasterize(mesh, camera, cull_backfaces=True), weights, True)] + fb
            times = time_side_by_side(fwd + fb, repeat)
            n = len(methods)
            hard_ms = times[0]
            for k, (label, fn) in enumerate(methods):
                with torch.no_grad():
                    diff = (fn().double() - ref.double()).abs()
                rows.append(dict(size=size, image="shaded" if shaded else "silhouette", **label,
                                 fwd_ms=times[k], fwd_bwd_ms=times[n + k], x_hard=times[n + k] / hard_ms,
                                 rmse=float(diff.pow(2).mean().sqrt()), max_err=float(diff.max())))
    out(format_table(rows))
    return rows


def _no_grad(fn):
    def run():
        with torch.no_grad():
            return fn()
    return run


def format_table(rows) -> str:
    head = (f"{'size':>7}{'image':>11}{'method':>7}{'sigma':>8}{'gamma':>8}{'thresh':>8}{'fwd ms':>9}"
            f"{'fwd+bwd':>9}{'x hard':>8}{'RMSE':>9}{'max err':>9}")
    lines = [head, "-" * len(head)]
    fmt = lambda v: f"{v:>8.0e}" if v is not None else f"{'':>8}"          # noqa: E731
    for r in rows:
        lines.append(f"{str(r['size']) + '²':>7}{r['image']:>11}{r['method']:>7}{fmt(r.get('sigma'))}"
                     f"{fmt(r.get('gamma'))}{fmt(r.get('threshold'))}{r['fwd_ms']:>9.1f}{r['fwd_bwd_ms']:>9.1f}"
                     f"{r['x_hard']:>8.1f}{r['rmse']:>9.4f}{r['max_err']:>9.3f}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------- the command's options

def add_arguments(parser) -> None:
    """The options of ``python -m course bench soft``."""
    parser.add_argument("--sizes", nargs="+", type=int, default=list(SIZES), help="image sizes (default 64 256)")
    parser.add_argument("--sigmas", nargs="+", type=float, default=list(SIGMAS), help="σ, NDC units")
    parser.add_argument("--thresholds", nargs="+", type=float, default=list(THRESHOLDS))
    parser.add_argument("--gammas", nargs="+", type=float, default=list(GAMMAS), help="γ of the shaded image")


def run(args) -> list[dict]:
    return bench_soft(args.sizes, args.sigmas, args.thresholds, args.gammas, args.repeat)
