"""The antialiasing benchmark: ``python -m course bench aa [--scenes ...] [--plot FILE] [--repeat N]``.

Run time against error for every way of filtering a pixel, on three scenes, against the exact box-filtered
image (``exact_coverage`` in float64) as the reference::

    S4 flat      icosphere, 1,280 faces, 256²; random flat face colours: every edge is a discontinuity
    S1 sil       icosphere, 20,480 faces, 512²; its silhouette: only the outline is a discontinuity
    occlusion    two intersecting icospheres (1,280 faces each, one in front of the other), 256²,
                 random flat colours: occlusion edges, an intersection line, long silhouettes

Methods: one sample per pixel (``none``); supersampling 2×2, 4×4, 8×8 on a regular grid and stratified
jittered (``ss``, ``ss-jit``); adaptive supersampling at the same k (``adaptive``, ``adaptive-jit``); and
``exact``. The error is the RMSE over all pixels and channels. The target pairs are also timed side by side
(adaptive 4×4 against full 4×4; exact against 8×8), and the adaptive sampler's sample face ids are checked
against the full sampler's. A last table renders a smooth-shaded (Phong) sphere with ``render()`` and
reports how far adaptive supersampling, which keeps one sample in the interior, lands from full
supersampling there.
"""
from __future__ import annotations


import torch

from ..camera import Camera
from ..mesh import Mesh, join_meshes
from ..models import icosphere
from .raster import scene as raster_scene
from .timing import time_it, time_side_by_side

__all__ = ["SCENES", "aa_scene", "measure", "bench_aa", "plot_pareto", "smooth_shading", "add_arguments", "run"]

REPEAT = 3               # timed runs per measurement (these take seconds each)
DESCRIPTION = "antialiasing: none, supersampling, adaptive, exact coverage — time against RMSE to the exact image"

SCENES = ("S4 flat", "S1 sil", "occlusion")
KS = (2, 4, 8)


def aa_scene(name: str, dtype=torch.float32):
    """(mesh, camera, face_colors (F, 3)) of a benchmark scene, colours seeded."""
    g = torch.Generator().manual_seed(0)
    if name == "S4 flat":
        mesh, cam = raster_scene("S4", dtype=dtype)
        return mesh, cam, torch.rand(mesh.faces.shape[0], 3, generator=g, dtype=dtype)
    if name == "S1 sil":
        mesh, cam = raster_scene("S1", dtype=dtype)
        return mesh, cam, torch.ones(mesh.faces.shape[0], 3, dtype=dtype)
    if name == "occlusion":
        big = icosphere(3, radius=1.0, dtype=dtype)
        small = icosphere(3, radius=0.6, dtype=dtype)
        small = Mesh(small.verts + torch.tensor([0.75, 0.35, 0.6], dtype=dtype), small.faces)
        mesh = join_meshes([big, small])
        cam = Camera.look_at((0.3, 0.2, 3.2), (0.2, 0.1, 0.0), fov_y=40.0, width=256, height=256)
        cam = cam.to(dtype=dtype)
        return mesh, cam, torch.rand(mesh.faces.shape[0], 3, generator=g, dtype=dtype)
    raise ValueError(f"unknown scene {name!r}; choose from {', '.join(SCENES)}")


def _methods(mesh, cam, colors):
    """name -> (family, k, function returning the (H, W, 3) image)."""
    from ..antialias import adaptive_supersample, flat_colors, supersample
    from ..raster import rasterize
    bg = torch.zeros(3, dtype=colors.dtype)
    out = {"none": ("none", 1, lambda: flat_colors(rasterize(mesh, cam).face_id, colors, bg))}
    for k in KS:
        out[f"ss {k}x{k}"] = ("ss", k, lambda k=k: supersample(mesh, cam, colors, k))
        out[f"ss-jit {k}x{k}"] = ("ss-jit", k, lambda k=k: supersample(mesh, cam, colors, k, jitter=True))
        out[f"adaptive {k}x{k}"] = ("adaptive", k, lambda k=k: adaptive_supersample(mesh, cam, colors, k)[0])
        out[f"adaptive-jit {k}x{k}"] = ("adaptive-jit", k,
                                        lambda k=k: adaptive_supersample(mesh, cam, colors, k, jitter=True)[0])
    return out


def measure(name: str, repeat: int = 3, scene=None) -> list[dict]:
    """Time and RMSE to the exact image of every method on one scene. Rows: scene, method, family, k, ms,
    rmse (exact's own time is reported; its rmse is 0 by definition). scene: (mesh, camera, face_colors)
    to measure instead of the named benchmark scene (``name`` then only labels the rows)."""
    from ..coverage import exact_coverage
    mesh, cam, colors = aa_scene(name) if scene is None else scene
    mesh64, cam64, colors64 = mesh.to(dtype=torch.float64), cam.to(dtype=torch.float64), colors.double()
    reference = exact_coverage(mesh64, cam64, colors64)
    rows = [dict(scene=name, method="exact", family="exact", k=0, rmse=0.0,
                 ms=time_it(lambda: exact_coverage(mesh64, cam64, colors64), max(1, repeat // 2), warmup=0))]
    for method, (family, k, fn) in _methods(mesh, cam, colors).items():
        image = fn().double()
        rmse = float(((image - reference) ** 2).mean().sqrt())
        rows.append(dict(scene=name, method=method, family=family, k=k, rmse=rmse, ms=time_it(fn, repeat)))
    return rows


def _targets(repeat: int) -> list[dict]:
    """The issue's targets, each pair timed side by side: adaptive 4x4 against full 4x4 (S1 silhouette, S4
    flat colours; with a check that the sample face ids agree), exact float64 against 8x8 supersampling."""
    from ..antialias import adaptive_supersample, sample_fragments, supersample
    from ..coverage import exact_coverage
    rows = []
    for name in ("S1 sil", "S4 flat"):
        mesh, cam, colors = aa_scene(name)
        full = supersample(mesh, cam, colors, 4)
        adaptive, marked = adaptive_supersample(mesh, cam, colors, 4)
        pix = marked.reshape(-1).nonzero().squeeze(1)
        same_ids = bool(torch.equal(sample_fragments(mesh, cam, 4, pixels=pix).face_id,
                                    sample_fragments(mesh, cam, 4).face_id[pix]))
        ms_a, ms_f = time_side_by_side([lambda: adaptive_supersample(mesh, cam, colors, 4),
                                        lambda: supersample(mesh, cam, colors, 4)], repeat)
        rows.append(dict(target=f"{name}: adaptive 4x4 vs full 4x4", ms_a=ms_a, ms_b=ms_f, ratio=ms_f / ms_a,
                         note=f"{int(marked.sum())} of {marked.numel()} px refined; ids equal: {same_ids}; "
                              f"pixels equal: {bool(torch.equal(full, adaptive))}"))
    for name in ("S4 flat", "occlusion"):
        mesh, cam, colors = aa_scene(name)
        m64, c64, col64 = mesh.to(dtype=torch.float64), cam.to(dtype=torch.float64), colors.double()
        ms_e, ms_s = time_side_by_side([lambda: exact_coverage(m64, c64, col64),
                                        lambda: supersample(mesh, cam, colors, 8)], max(1, repeat // 2))
        rows.append(dict(target=f"{name}: exact (float64) vs ss 8x8", ms_a=ms_e, ms_b=ms_s, ratio=ms_e / ms_s,
                         note="exact / ss8 (target: at most 10)"))
    return rows


def smooth_shading(repeat: int = 3, size: int = 256) -> list[dict]:
    """render() of a Phong-shaded icosphere: none, adaptive k and full k against full 8x8 supersampling."""
    from ..render import RenderSettings, Scene, default_lights, render
    mesh, cam = raster_scene("S4")
    sc = Scene(mesh, cam, lights=default_lights(), background=(0.0, 0.0, 0.0))
    ref = render(sc, RenderSettings(antialias="supersample", samples=8)).image.double()
    rows = []
    cases = [("none", RenderSettings())]
    for k in (2, 4):
        cases += [(f"adaptive {k}x{k}", RenderSettings(antialias="adaptive", samples=k)),
                  (f"ss {k}x{k}", RenderSettings(antialias="supersample", samples=k))]
    images = {name: render(sc, s).image.double() for name, s in cases}
    times = time_side_by_side([lambda s=s: render(sc, s) for _, s in cases], repeat)
    for (name, _), ms in zip(cases, times):
        k = name.split()[-1] if " " in name else ""
        twin = images.get(f"ss {k}") if name.startswith("adaptive") else None
        rows.append(dict(method=name, ms=ms, rmse_ss8=float(((images[name] - ref) ** 2).mean().sqrt()),
                         vs_full=None if twin is None else float((images[name] - twin).abs().max())))
    return rows


def plot_pareto(rows, path=None, ax=None):
    """Log-log Pareto plot, one panel per scene: time (ms) against RMSE to the exact image, a line per
    family; the exact method's time as a dashed vertical line (its error is zero). Returns the figure."""
    import matplotlib.pyplot as plt
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    if ax is None:
        fig, axes = plt.subplots(1, len(scenes), figsize=(4.6 * len(scenes), 3.9), squeeze=False)
        axes = axes[0]
    else:
        axes, fig = [ax] if len(scenes) == 1 else ax, (ax if not hasattr(ax, "figure") else ax.figure)
    styles = {"none": ("k", "o"), "ss": ("C0", "s"), "ss-jit": ("C1", "D"), "adaptive": ("C2", "^"),
              "adaptive-jit": ("C3", "v")}
    for a, name in zip(axes, scenes):
        mine = [r for r in rows if r["scene"] == name]
        for family, (color, marker) in styles.items():
            pts = sorted((r for r in mine if r["family"] == family), key=lambda r: r["k"])
            if pts:
                a.plot([r["ms"] for r in pts], [max(r["rmse"], 1e-12) for r in pts], marker=marker, color=color,
                       label=family)
                below = family.startswith("adaptive")                       # often on top of ss's points
                for r in pts:
                    if r["k"] > 1:
                        a.annotate(f"{r['k']}²", (r["ms"], r["rmse"]), fontsize=7, xytext=(3, -9 if below else 3),
                                   textcoords="offset points")
        exact = [r for r in mine if r["family"] == "exact"]
        if exact:
            a.axvline(exact[0]["ms"], color="0.3", ls="--", lw=1, label="exact (RMSE 0)")
        a.set_xscale("log")
        a.set_yscale("log")
        a.xaxis.set_minor_formatter(plt.NullFormatter())                     # decade labels only
        a.yaxis.set_minor_formatter(plt.NullFormatter())
        a.set_xlabel("time (ms)")
        a.set_ylabel("RMSE to the exact image")
        a.set_title(name)
        a.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    if path:
        fig.savefig(path, dpi=110)
    return fig


def bench_aa(names=SCENES, repeat: int = 3, plot: str | None = "aa_pareto.png", out=print) -> dict:
    """The whole benchmark: the per-scene table, the side-by-side targets, smooth shading, and the plot."""
    rows = [r for name in names for r in measure(name, repeat)]
    head = f"{'scene':<11}{'method':<20}{'ms':>10}{'RMSE':>12}"
    lines = [head, "-" * len(head)]
    lines += [f"{r['scene']:<11}{r['method']:<20}{r['ms']:>10.1f}{r['rmse']:>12.2e}" for r in rows]
    out("\n".join(lines))
    targets = _targets(repeat)
    out("\ntargets, timed side by side (ms):")
    for t in targets:
        out(f"  {t['target']:<40} {t['ms_a']:>9.1f} vs {t['ms_b']:>9.1f}   ratio {t['ratio']:.2f}   {t['note']}")
    smooth = smooth_shading(repeat)
    out("\nsmooth shading (render(), Phong, S4 sphere), against full 8x8:")
    for r in smooth:
        vs = "" if r["vs_full"] is None else f"   max |adaptive - full| {r['vs_full']:.3e}"
        out(f"  {r['method']:<14}{r['ms']:>9.1f} ms   RMSE {r['rmse_ss8']:.2e}{vs}")
    if plot:
        plot_pareto(rows, plot)
        out(f"\nPareto plot written to {plot}")
    return dict(rows=rows, targets=targets, smooth=smooth)


def add_arguments(parser) -> None:
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=SCENES, metavar="SCENE",
                        help=f"scenes to run (default all: {', '.join(SCENES)})")
    parser.add_argument("--plot", default="aa_pareto.png", help="where to save the Pareto plot ('' for none)")


def run(args) -> list[dict]:
    return bench_aa(args.scenes, args.repeat, args.plot or None)
