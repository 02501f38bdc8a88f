"""The shadow benchmark: ``python -m course bench shadows [--resolutions ...] [--size N] [--plot FILE]``.

Shadow maps against ray-traced shadows, as time against error, on the teapot (``course.models.teapot``) over a
ground plane (``course.models.plane``, side 4, moved to the pot's base), seen from a fixed camera
(``Camera.look_at``); everything in float64. The receivers are the surface points seen by the camera's pixels
(``raycast``), with their faces' geometric normals turned toward the camera; errors are over the receivers that
face the light (the others are dark whatever the shadow says).

* **Hard shadows**, a directional light: ``shadow_map`` + ``shadow_factor`` at resolutions 256 to 4096, with
  ``pcf=1`` and ``pcf=3``, against ``visible(..., directional=True, normals=...)``, the ray-traced reference.
  Error: the mean |factor - reference| (for pcf=1 the fraction of receivers that disagree); the fraction that
  disagree (|difference| > 0.5) is reported too. Times: both passes (the map and the lookups); the
  ray-traced shadow's own time includes building its BVH.
* **Soft shadows**, a rectangular area light (a ceiling panel facing the pot): N shadow maps
  (``area_shadow_factor`` with ``area_light_samples``, one spot map per sample, ``--area-resolution``) and N
  shadow rays per point (``visible`` with (points, N, 3) samples from ``rectangle_light_samples``), N = 1, 4, 16,
  64, against ray tracing with ``--reference-samples`` (256) samples. Error: mean |fraction visible -
  reference| over ``--area-points`` receivers (a fixed subset, to keep the reference cheap).

It prints a table and writes a log-log Pareto plot (time against error, a line per method; the hard reference,
error 0, as a dashed vertical line).
"""
from __future__ import annotations

import math

import torch

from ..camera import Camera
from ..mesh import join_meshes, Mesh
from ..models import plane, teapot
from ..raytrace import BVH, raycast, rectangle_light_samples, visible
from ..shading import DirectionalLight
from ..shadows.maps import area_light_samples, area_shadow_factor, shadow_factor, shadow_map
from .timing import time_it

__all__ = ["shadow_scene", "receivers", "measure_hard", "measure_area", "bench_shadows", "plot_pareto",
           "add_arguments", "run"]

REPEAT = 3               # timed runs per measurement (these take seconds each)
DESCRIPTION = "shadow maps (resolution, PCF, area lights) against ray-traced shadows: time against error"

RESOLUTIONS = (256, 512, 1024, 2048, 4096)
SAMPLES = (1, 4, 16, 64)
SUN = (-0.5, -1.0, -0.35)                                                   # the way the light travels
PANEL = dict(center=(1.2, 2.6, 0.8), normal=(-0.35, -1.0, -0.25), size=1.0)  # the area light


def shadow_scene(size: int = 256, dtype=torch.float64):
    """(mesh, camera): the teapot on a ground plane of side 4 touching its base, a fixed camera."""
    pot = teapot(dtype=dtype)
    ground = plane(4.0, dtype=dtype)
    ground = Mesh(ground.verts + torch.tensor([0.0, float(pot.verts[:, 1].min()), 0.0], dtype=dtype), ground.faces)
    mesh = join_meshes([Mesh(pot.verts, pot.faces), ground])
    cam = Camera.look_at((2.4, 2.0, 3.2), (0.0, -0.3, 0.0), fov_y=40.0, width=size, height=size, dtype=dtype)
    return mesh, cam


def receivers(mesh, camera, bvh=None):
    """World points (N, 3) seen by the camera's pixels and their faces' normals (N, 3), toward the camera."""
    frags = raycast(mesh, camera, bvh=bvh)
    face = frags.face_id.reshape(-1)
    hit = face >= 0
    f = face[hit]
    bary = frags.bary.reshape(-1, 3)[hit].to(mesh.verts.dtype)
    tri = mesh.verts.detach()[mesh.faces[f]]                                # (N, 3, 3)
    pts = (bary[:, :, None] * tri).sum(1)
    n = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n = torch.nn.functional.normalize(n, dim=1)
    eye = camera.eye.to(n.dtype)
    n = torch.where(((eye - pts) * n).sum(1, keepdim=True) < 0, -n, n)
    return pts, n


def _err(f, ref, mask):
    diff = (f.double() - ref.double()).abs()[mask]
    return float(diff.mean()), float((diff > 0.5).double().mean())


def measure_hard(mesh, cam, resolutions=RESOLUTIONS, pcfs=(1, 3), repeat: int = 3) -> list[dict]:
    """Directional light: shadow maps (each resolution and pcf) against the ray-traced shadow."""
    bvh = BVH(mesh)
    pts, n = receivers(mesh, cam, bvh)
    sun = torch.tensor(SUN, dtype=pts.dtype)
    facing = (n @ -sun) > 0
    ref = visible(pts, sun, bvh, directional=True, normals=n).double()
    ms = time_it(lambda: visible(pts, sun, BVH(mesh), directional=True, normals=n), repeat)
    rows = [dict(case="hard", method="ray traced", param=1, ms=ms, error=0.0, disagree=0.0,
                 points=int(facing.sum()))]
    light = DirectionalLight(direction=SUN)
    for k in pcfs:
        for res in resolutions:
            def fn(res=res, k=k):
                return shadow_factor(pts, n, shadow_map(mesh, light, res), pcf=k)
            err, dis = _err(fn(), ref, facing)
            rows.append(dict(case="hard", method=f"map pcf{k}", param=res, ms=time_it(fn, repeat, warmup=0),
                             error=err, disagree=dis, points=int(facing.sum())))
    return rows


def measure_area(mesh, cam, samples=SAMPLES, n_points: int = 4096, reference_samples: int = 256,
                 resolution: int = 512, repeat: int = 1) -> list[dict]:
    """Rectangle light: N shadow maps and N shadow rays per point against a ray-traced reference."""
    bvh = BVH(mesh)
    pts, n = receivers(mesh, cam, bvh)
    c = torch.tensor(PANEL["center"], dtype=pts.dtype)
    ln = torch.nn.functional.normalize(torch.tensor(PANEL["normal"], dtype=pts.dtype), dim=0)
    facing = ((c - pts) * n).sum(1) > 0
    idx = facing.nonzero().squeeze(1)
    idx = idx[torch.linspace(0, idx.numel() - 1, min(n_points, idx.numel())).round().long()]
    pts, n = pts[idx], n[idx]
    # the rectangle as corner + u e1 + v e2, with the axes area_light_samples uses
    helper = torch.tensor((1.0, 0.0, 0.0) if abs(float(ln[0])) < 0.9 else (0.0, 1.0, 0.0), dtype=pts.dtype)
    u = torch.nn.functional.normalize(helper - (helper @ ln) * ln, dim=0)
    v = torch.linalg.cross(ln, u)
    s = PANEL["size"]
    corner, e1, e2 = c - 0.5 * s * u - 0.5 * s * v, s * u, s * v
    g = math.isqrt(reference_samples)
    ref = visible(pts, rectangle_light_samples(corner, e1, e2, pts.shape[0], g, seed=1), bvh, normals=n)
    rows = []
    for N in samples:
        grid = math.isqrt(N)
        def rays(grid=grid):
            return visible(pts, rectangle_light_samples(corner, e1, e2, pts.shape[0], grid), BVH(mesh), normals=n)
        smp = area_light_samples("rectangle", c, ln, s, N, u_axis=u, dtype=pts.dtype)
        def maps(smp=smp):
            return area_shadow_factor(pts, n, mesh, smp, resolution=resolution, light_normal=ln)
        for method, fn in (("shadow rays", rays), (f"shadow maps {resolution}", maps)):
            rows.append(dict(case="area", method=method, param=N, ms=time_it(fn, repeat, warmup=0),
                             error=_err(fn(), ref, torch.ones_like(ref, dtype=torch.bool))[0], disagree=None,
                             points=pts.shape[0]))
    rows.append(dict(case="area", method=f"reference ({g * g} rays)", param=g * g, ms=time_it(
        lambda: visible(pts, rectangle_light_samples(corner, e1, e2, pts.shape[0], g, seed=1), bvh, normals=n),
        1, warmup=0), error=0.0, disagree=None, points=pts.shape[0]))
    return rows


def plot_pareto(rows, path=None):
    """Log-log: time (ms) against error, a line per method, a panel per case (hard, area)."""
    import matplotlib.pyplot as plt
    cases = list(dict.fromkeys(r["case"] for r in rows))
    fig, axes = plt.subplots(1, len(cases), figsize=(5.2 * len(cases), 4.0), squeeze=False)
    for a, case in zip(axes[0], cases):
        mine = [r for r in rows if r["case"] == case]
        for i, method in enumerate(dict.fromkeys(r["method"] for r in mine)):
            pts = sorted((r for r in mine if r["method"] == method), key=lambda r: r["param"])
            if all(r["error"] == 0 for r in pts):
                a.axvline(pts[0]["ms"], color="0.3", ls="--", lw=1, label=f"{method} (reference, error 0)")
                continue
            a.plot([r["ms"] for r in pts], [max(r["error"], 1e-6) for r in pts], marker="os^v"[i % 4],
                   color=f"C{i}", label=method)
            for r in pts:
                a.annotate(str(r["param"]), (r["ms"], max(r["error"], 1e-6)), fontsize=7, xytext=(3, 3),
                           textcoords="offset points")
        a.set_xscale("log")
        a.set_yscale("log")
        a.set_xlabel("time (ms)")
        a.set_ylabel("mean |shadow - ray-traced reference|")
        a.set_title("directional light (map resolution)" if case == "hard" else "rectangle light (N samples)")
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=7)
    fig.tight_layout()
    if path:
        fig.savefig(path, dpi=110)
    return fig


def bench_shadows(resolutions=RESOLUTIONS, size: int = 256, repeat: int = 3, samples=SAMPLES,
                  area_points: int = 4096, reference_samples: int = 256, area_resolution: int = 512,
                  plot: str | None = "shadows_pareto.png", out=print) -> list[dict]:
    mesh, cam = shadow_scene(size)
    rows = measure_hard(mesh, cam, resolutions, repeat=repeat)
    rows += measure_area(mesh, cam, samples, area_points, reference_samples, area_resolution,
                         repeat=max(1, repeat // 3))
    out(f"teapot over a ground plane, {mesh.num_faces:,} faces, float64; camera {size}²")
    head = f"{'case':<6}{'method':<24}{'res / N':>8}{'points':>8}{'ms':>10}{'error':>11}{'disagree':>10}"
    lines = [head, "-" * len(head)]
    for r in rows:
        dis = f"{100 * r['disagree']:>9.2f}%" if r["disagree"] is not None else f"{'-':>10}"
        lines.append(f"{r['case']:<6}{r['method']:<24}{r['param']:>8}{r['points']:>8}{r['ms']:>10.1f}"
                     f"{r['error']:>11.2e}{dis}")
    out("\n".join(lines))
    out("error: mean |shadow factor - ray-traced reference| over the receivers facing the light; disagree: "
        "fraction of them with |difference| > 0.5")
    if plot:
        plot_pareto(rows, plot)
        out(f"\nPareto plot written to {plot}")
    return rows


def add_arguments(parser) -> None:
    parser.add_argument("--resolutions", nargs="+", type=int, default=list(RESOLUTIONS),
                        help="shadow-map resolutions (texels per side)")
    parser.add_argument("--size", type=int, default=256, help="camera image size (receiver pixels)")
    parser.add_argument("--samples", nargs="+", type=int, default=list(SAMPLES),
                        help="area light: N shadow maps / shadow rays per point (squares)")
    parser.add_argument("--area-points", type=int, default=4096, help="area light: receivers measured")
    parser.add_argument("--reference-samples", type=int, default=256, help="area light: reference rays per point")
    parser.add_argument("--area-resolution", type=int, default=512, help="area light: each shadow map's resolution")
    parser.add_argument("--plot", default="shadows_pareto.png", help="where to save the Pareto plot ('' for none)")


def run(args) -> list[dict]:
    return bench_shadows(args.resolutions, args.size, args.repeat, args.samples, args.area_points,
                         args.reference_samples, args.area_resolution, args.plot or None)
