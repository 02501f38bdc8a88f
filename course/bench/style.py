"""The style-transfer benchmark (lecture 11): ``python -m course bench style [--steps N] [--size PX] [--fast]
[--figure PNG]``.

Lecture 11's runs at full size: ``course.style.transfer.stylize_mesh`` on ``models.teapot(8)`` (4,032 faces) with the
``stripes`` style, 128² views, two random views a step, 300 steps, seed 0, three ways:

* **soft**: soft rasterization, texture and vertices (the method);
* **soft, texture only**: ``geometry=False``: what the vertices add;
* **hard**: the z-buffer (``renderer="hard"``), texture and vertices: what the soft rasterizer changes (the
  vertices still move: the texture is looked up at uvs interpolated from them);

and ``deep_dream_mesh`` (soft, 100 steps). Reported per run: wall time, the training style term (mean of the
last 10 steps: each run's own renderer, so not comparable across renderers), the **held-out style loss**
(``held_out_style_loss`` from 8 other directions, judged by z-buffer renders and by soft ones: a judge favours
the runs trained through its own renderer; lower is more stylish), the **outline change** (``outline_change``:
1 - IoU of the z-buffer silhouettes of the result and the start, summed over those 8 views) and the largest
vertex offset (the teapot's radius is 1). One run each, seed 0: a single seed, so differences of a few percent
in the held-out loss are within what another seed would move.
``--figure PNG`` saves the style image and the soft run's teapot from three views (the README's picture).
``--fast`` runs everything small (to check that the command works; its numbers are not the course's).
"""
from __future__ import annotations

import time

import torch

from .. import models
from ..style import RandomFeatures, stripes
from ..style.transfer import (deep_dream_mesh, held_out_style_loss, outline_change, random_directions, render_texture,
                       stylize_mesh, view_camera)

__all__ = ["bench_style", "format_table", "save_style_picture", "add_arguments", "run"]

REPEAT = 1
DESCRIPTION = ("lecture 11's style transfer and DeepDream at full size: time, style loss on held-out views, "
               "outline change")


def bench_style(steps: int = 300, size: int = 128, views: int = 2, resolution: int = 8, dream_steps: int = 100,
                figure: str | None = None, out=print) -> list[dict]:
    teapot = models.teapot(resolution, dtype=torch.float64)
    style = stripes(64, dtype=torch.float64)
    net = RandomFeatures(channels=32, seed=0, dtype=torch.float64)
    judges = [view_camera(d, torch.zeros(3, dtype=torch.float64), 3.2, size)
              for d in random_directions(8, torch.Generator().manual_seed(123))]
    rows, runs = [], {}
    for label, extra in (("soft", {}), ("soft, texture only", dict(geometry=False)), ("hard", dict(renderer="hard"))):
        start = time.perf_counter()
        r = stylize_mesh(teapot, style, steps=steps, views=views, size=size, seed=0, network=net, **extra)
        seconds = time.perf_counter() - start
        runs[label] = r
        row = dict(run=label, steps=steps, seconds=seconds, train=float(r.losses[-10:].mean()),
                   held_out=held_out_style_loss(teapot, r, style, size=size, network=net),
                   held_out_soft=held_out_style_loss(teapot, r, style, size=size, network=net, renderer="soft"),
                   outline=outline_change(teapot.faces, teapot.verts, r.verts, judges),
                   moved=float((r.verts - teapot.verts).norm(dim=1).max()))
        rows.append(row)
        out(f"{label}: {seconds:.1f} s, held-out style loss {row['held_out']:.3f} (hard judge), "
            f"{row['held_out_soft']:.3f} (soft judge)")
    start = time.perf_counter()
    d = deep_dream_mesh(teapot, steps=dream_steps, views=views, size=size, seed=0, network=net)
    rows.append(dict(run="DeepDream", steps=dream_steps, seconds=time.perf_counter() - start,
                     first=float(d.losses[0]), last=float(d.losses[-1]),
                     outline=outline_change(teapot.faces, teapot.verts, d.verts, judges),
                     moved=float((d.verts - teapot.verts).norm(dim=1).max())))
    out(format_table(rows))
    if figure:
        save_style_picture(teapot, runs["soft"], style, figure)
        out(f"\nfigure written to {figure}")
    return rows


def format_table(rows) -> str:
    lines = [f"{'run':<22}{'steps':>6}{'seconds':>9}{'train':>9}{'held-out':>10}{'(soft)':>8}{'outline':>9}"
             f"{'moved':>8}"]
    for r in rows:
        if r["run"] == "DeepDream":
            lines.append(f"DeepDream: activation {r['first']:.3g} -> {r['last']:.3g} in {r['steps']} steps, "
                         f"{r['seconds']:.1f} s; outline {r['outline']:.3f}, moved {r['moved']:.3f}")
        else:
            lines.append(f"{r['run']:<22}{r['steps']:>6}{r['seconds']:>9.1f}{r['train']:>9.3g}{r['held_out']:>10.3g}"
                         f"{r['held_out_soft']:>8.3g}{r['outline']:>9.3f}{r['moved']:>8.3f}")
    lines.append("train: the last 10 steps' style term (its own renderer); held-out: the style term of z-buffer "
                 "renders from 8 other views, (soft): of soft renders from them (each judge favours the runs trained "
                 "through its renderer); outline: 1 - IoU of the silhouettes against the start, summed over those "
                 "views; moved: the largest vertex offset (radius 1)")
    return "\n".join(lines)


def save_style_picture(mesh, run, style, path):
    """The style image and the stylised teapot from three views, unlit (the README's picture)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 4, figsize=(12, 3.4))
    ax[0].imshow(style.numpy()), ax[0].set_title("style")
    for a, d in zip(ax[1:], ([0.6, 0.5, 0.8], [-0.8, 0.3, 0.4], [0.1, 0.9, -0.3])):
        cam = view_camera(torch.tensor(d, dtype=torch.float64), torch.zeros(3, dtype=torch.float64), 3.0, 160)
        image = render_texture(run.verts, mesh.faces, mesh.uvs, run.texture, cam, renderer="hard")
        a.imshow(image.clamp(0, 1).numpy())
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
    parser.add_argument("--fast", action="store_true", help="everything small, to check the command works")
    parser.add_argument("--figure", help="save the style image and the stylised teapot here (PNG)")


def run(args) -> list[dict]:
    if args.fast:
        return bench_style(steps=4, size=32, views=1, resolution=3, dream_steps=3, figure=args.figure)
    return bench_style(args.steps, args.size, args.views, args.resolution, figure=args.figure)
