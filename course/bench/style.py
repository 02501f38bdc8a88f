"""The style-transfer benchmark (lecture 11): ``python -m course bench style [--steps N] [--size PX] [--seeds N]
[--fast] [--figure PNG]``.

Lecture 11's comparison at full size: ``course.style.transfer.stylize_mesh`` on ``models.teapot(8)`` (4,032
faces) with the ``stripes`` style, 128² views, two random views a step, 300 steps, from ``--seeds`` seeds (3:
0, 1, 2; the seed draws the training views), five ways:

* **soft**: soft rasterization (Liu et al. 2019), texture and vertices;
* **soft, texture only**: ``geometry=False``;
* **NMR**: the Neural 3D Mesh Renderer (``renderer="nmr"``: the z-buffer's image, Kato et al.'s approximate
  gradient at the edges, lecture 08), texture and vertices: the renderer Kato et al. used;
* **z-buffer**: ``renderer="hard"``: the same image without the edge gradient (the vertices still move, through
  the uvs interpolated inside each face);
* **z-buffer, texture only**: the texture alone through the z-buffer, which is also NMR's texture-only run (NMR's
  extra gradient reaches the vertices only).

Each result is judged on 8 held-out views (``held_out_style_loss``: directions no run trained on) by two
renderers, the z-buffer (how a textured mesh is normally looked at; NMR's images are the z-buffer's) and soft
rasterization; lower is more stylish. Reported per run and seed: wall time, the training style term (the last
10 steps, on its own renderer's images: not comparable across renderers), the two judges, the **outline
change** (``outline_change``: 1 - IoU of the z-buffer silhouettes of the result and the start, summed over the
8 views) and the largest vertex offset (the teapot's radius is 1). Then, per way, the mean and the range over
the seeds, and the **paired differences** (two ways run from the same seed see the same training views): a
difference whose mean is smaller than its spread over the seeds is no measurable difference. Last, DeepDream
(``deep_dream_mesh``, 100 steps, seed 0) through soft rasterization and through NMR.
``--figure PNG`` saves the style image and the soft run's teapot (seed 0) from three views (the README's
picture). ``--fast`` runs everything small (to check that the command works; its numbers are not the course's).
"""
from __future__ import annotations

import time

import torch

from .. import models
from ..style import RandomFeatures, stripes
from ..style.transfer import (deep_dream_mesh, held_out_style_loss, outline_change, random_directions, render_texture,
                              stylize_mesh, view_camera)

__all__ = ["WAYS", "PAIRS", "compare_ways", "paired_differences", "bench_style", "format_table", "save_style_picture", "add_arguments", "run"]

REPEAT = 1
DESCRIPTION = ("lecture 11's style transfer (soft, NMR, z-buffer; with and without the vertices) over seeds, "
               "judged on held-out views, and DeepDream")

WAYS = (("soft", dict(renderer="soft")),
        ("soft, texture only", dict(renderer="soft", geometry=False)),
        ("NMR", dict(renderer="nmr")),
        ("z-buffer", dict(renderer="hard")),
        ("z-buffer, texture only", dict(renderer="hard", geometry=False)))

# (a, b, what a - b measures)
PAIRS = (("soft", "soft, texture only", "the vertices, through soft rasterization"),
         ("NMR", "z-buffer, texture only", "the vertices, through NMR"),
         ("z-buffer", "z-buffer, texture only", "the vertices, through the z-buffer's uvs alone"),
         ("NMR", "z-buffer", "NMR's edge gradient"),
         ("soft", "NMR", "soft rasterization against NMR"))

JUDGES = (("held_out", "z-buffer judge"), ("held_out_soft", "soft judge"))


def compare_ways(mesh, style, network, *, steps: int, size: int, views: int = 2, seeds: int = 3,
                 out=None, progress: bool = False) -> list[dict]:
    """Every way of ``WAYS`` from seeds 0 .. seeds-1, each result judged on 8 held-out views (seed 123) of
    ``size``² by the z-buffer and by soft rasterization: one row per (way, seed). out: called with a line per
    run (its time included), or None (lecture 11 calls it so: no times in a notebook); progress: a bar per
    run. Each row also holds the run itself (``result``, a ``StyleRun``)."""
    judges = [view_camera(d, torch.zeros(3, dtype=torch.float64), 3.2, size)
              for d in random_directions(8, torch.Generator().manual_seed(123))]
    rows = []
    for seed in range(seeds):
        for label, extra in WAYS:
            start = time.perf_counter()
            r = stylize_mesh(mesh, style, steps=steps, views=views, size=size, seed=seed, network=network,
                             progress=progress, **extra)
            seconds = time.perf_counter() - start
            row = dict(run=label, seed=seed, steps=steps, seconds=seconds, train=float(r.losses[-10:].mean()),
                       held_out=held_out_style_loss(mesh, r, style, size=size, network=network),
                       held_out_soft=held_out_style_loss(mesh, r, style, size=size, network=network,
                                                         renderer="soft"),
                       outline=outline_change(mesh.faces, mesh.verts, r.verts, judges),
                       moved=float((r.verts - mesh.verts).norm(dim=1).max()), result=r)
            rows.append(row)
            if out is not None:
                out(f"seed {seed}, {label}: {seconds:.1f} s, held-out style loss {row['held_out']:.3f} (z-buffer "
                    f"judge), {row['held_out_soft']:.3f} (soft judge), outline {row['outline']:.3f}")
    return rows


def bench_style(steps: int = 300, size: int = 128, views: int = 2, resolution: int = 8, dream_steps: int = 100,
                seeds: int = 3, figure: str | None = None, out=print) -> list[dict]:
    teapot = models.teapot(resolution, dtype=torch.float64)
    style = stripes(64, dtype=torch.float64)
    net = RandomFeatures(channels=32, seed=0, dtype=torch.float64)
    judges = [view_camera(d, torch.zeros(3, dtype=torch.float64), 3.2, size)
              for d in random_directions(8, torch.Generator().manual_seed(123))]
    rows = compare_ways(teapot, style, net, steps=steps, size=size, views=views, seeds=seeds, out=out)
    first = next(r["result"] for r in rows if r["run"] == "soft")
    for row in rows:
        del row["result"]                                                   # rows are plain numbers (--json)
    for renderer in ("soft", "nmr") if dream_steps else ():
        start = time.perf_counter()
        d = deep_dream_mesh(teapot, steps=dream_steps, views=views, size=size, seed=0, network=net, renderer=renderer)
        rows.append(dict(run=f"DeepDream ({'NMR' if renderer == 'nmr' else renderer})", steps=dream_steps,
                         seconds=time.perf_counter() - start, first=float(d.losses[0]), last=float(d.losses[-1]),
                         outline=outline_change(teapot.faces, teapot.verts, d.verts, judges),
                         moved=float((d.verts - teapot.verts).norm(dim=1).max())))
    out(format_table(rows))
    if figure:
        save_style_picture(teapot, first, style, figure)
        out(f"\nfigure written to {figure}")
    return rows


def _spread(values, fmt=".3f") -> str:
    """'mean (min to max)' of a list."""
    return f"{sum(values) / len(values):{fmt}} ({min(values):{fmt}} to {max(values):{fmt}})"


def paired_differences(rows) -> list[dict]:
    """For each of ``PAIRS`` and each judge: the per-seed differences a - b of the held-out style loss, their
    mean, and ``sign`` "lower" / "higher" where the mean is larger than their spread over the seeds (largest -
    smallest; then every seed agrees in sign), else None: no measurable difference."""
    by = {(r["run"], r["seed"]): r for r in rows if "seed" in r}
    seeds = sorted({s for _, s in by})
    out = []
    for a, b, what in PAIRS:
        if not all((a, s) in by and (b, s) in by for s in seeds):
            continue
        for key, judge in JUDGES:
            diffs = [by[a, s][key] - by[b, s][key] for s in seeds]
            mean, spread = sum(diffs) / len(diffs), max(diffs) - min(diffs)
            sign = (("lower" if mean < 0 else "higher") if len(diffs) > 1 and abs(mean) > spread else None)
            out.append(dict(a=a, b=b, what=what, judge=judge, diffs=diffs, mean=mean, spread=spread, sign=sign))
    return out


def format_table(rows, seconds: bool = True) -> str:
    """The rows as a table: per way the mean (lowest to highest) over the seeds, then the paired differences,
    then DeepDream. seconds: False leaves the times out (a notebook prints no timings)."""
    style_rows = [r for r in rows if "seed" in r]
    seeds = sorted({r["seed"] for r in style_rows})
    lines = [f"{len(seeds)} seed(s): {', '.join(map(str, seeds))}. Per way: mean (lowest to highest) over the seeds",
             f"{'run':<24}{'steps':>6}{'seconds' if seconds else '':>{9 if seconds else 0}}{'train':>26}"
             f"{'held-out, z-buffer judge':>27}{'held-out, soft judge':>27}{'outline':>26}{'moved':>8}"]
    for label in dict.fromkeys(r["run"] for r in style_rows):
        rs = [r for r in style_rows if r["run"] == label]
        col = lambda k: _spread([r[k] for r in rs])                         # noqa: E731
        time_ = f"{sum(r['seconds'] for r in rs) / len(rs):>9.1f}" if seconds else ""
        lines.append(f"{label:<24}{rs[0]['steps']:>6}{time_}"
                     f"{col('train'):>26}{col('held_out'):>27}{col('held_out_soft'):>27}{col('outline'):>26}"
                     f"{max(r['moved'] for r in rs):>8.3f}")
    lines.append("train: the last 10 steps' style term (its own renderer's images); held-out: the style term of "
                 "renders from 8 other views, by the z-buffer (NMR's images are the z-buffer's) or soft "
                 "rasterization; outline: 1 - IoU of the silhouettes against the start, summed over those views; "
                 "moved: the largest vertex offset over the seeds (radius 1)" + ("; seconds: the mean per run" if
                                                                                   seconds else ""))
    pairs = paired_differences(rows)
    if pairs:
        lines.append("\npaired differences of the held-out style loss, a - b, seed by seed (the same training views); "
                     "measurable where the mean is larger than the spread over the seeds:")
        for p in pairs:
            verdict = (f"{p['a']} {p['sign']}" if p["sign"] else "no measurable difference")
            lines.append(f"  {p['a']} - {p['b']} ({p['what']}), {p['judge']}: "
                         f"{', '.join(f'{d:+.3f}' for d in p['diffs'])} (mean {p['mean']:+.3f}, spread "
                         f"{p['spread']:.3f}): {verdict}")
    for r in rows:
        if r["run"].startswith("DeepDream"):
            lines.append(f"{r['run']}: activation {r['first']:.3g} -> {r['last']:.3g} in {r['steps']} steps, "
                         + (f"{r['seconds']:.1f} s; " if seconds else "")
                         + f"outline {r['outline']:.3f}, moved {r['moved']:.3f}")
    return "\n".join(lines)


def save_style_picture(mesh, run, style, path):
    """The style image and the stylised teapot from three views, unlit, sRGB-encoded for the screen as every
    figure of the course (the README's picture)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..shading import linear_to_srgb
    fig, ax = plt.subplots(1, 4, figsize=(12, 3.4))
    ax[0].imshow(linear_to_srgb(style.clamp(0, 1)).numpy()), ax[0].set_title("style")
    for a, d in zip(ax[1:], ([0.6, 0.5, 0.8], [-0.8, 0.3, 0.4], [0.1, 0.9, -0.3])):
        cam = view_camera(torch.tensor(d, dtype=torch.float64), torch.zeros(3, dtype=torch.float64), 3.0, 160)
        image = render_texture(run.verts, mesh.faces, mesh.uvs, run.texture, cam, renderer="hard")
        a.imshow(linear_to_srgb(image.clamp(0, 1)).numpy())
    for a in ax:
        a.axis("off")
    ax[1].set_title("stylised through soft rasterization")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def add_arguments(parser) -> None:
    parser.add_argument("--steps", type=int, default=300, help="Adam steps per style run (300)")
    parser.add_argument("--size", type=int, default=128, help="rendered views, pixels a side (128)")
    parser.add_argument("--views", type=int, default=2, help="random views per step (2)")
    parser.add_argument("--resolution", type=int, default=8, help="models.teapot(resolution) (8: 4,032 faces)")
    parser.add_argument("--seeds", type=int, default=3, help="seeds 0 .. N-1 of every way (3)")
    parser.add_argument("--fast", action="store_true", help="everything small, to check the command works")
    parser.add_argument("--figure", help="save the style image and the stylised teapot here (PNG)")


def run(args) -> list[dict]:
    if args.fast:
        return bench_style(steps=4, size=32, views=1, resolution=3, dream_steps=3, seeds=2, figure=args.figure)
    return bench_style(args.steps, args.size, args.views, args.resolution, seeds=args.seeds, figure=args.figure)
