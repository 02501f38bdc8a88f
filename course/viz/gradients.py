"""Figures of lecture 09: visibility gradients, error against cost. Part of ``course.viz``, which re-exports them."""
from __future__ import annotations

import math
import re

import matplotlib.pyplot as plt

__all__ = ["plot_error_cost", "full_gradient_ms"]

FLOOR = 1e-16            # errors at rounding level are drawn here (a log axis has no 0)


def full_gradient_ms(row: dict) -> float:
    """A ``course.bench.gradients`` row's time (ms) for the whole gradient: finite differences run on a subset of
    k of V vertices (the row's note says "k of V vertices") cost two images per coordinate, so their time is
    scaled by V / k; every other method's time is the row's own."""
    found = re.match(r"(\d[\d,]*) of (\d[\d,]*) vertices", row.get("note", ""))
    if not found:
        return row["ms"]
    k, total = (int(x.replace(",", "")) for x in found.groups())
    return row["ms"] * total / k


def plot_error_cost(panels: dict, size: tuple[float, float] = (4.6, 3.6), cols: int | None = None,
                    whole_gradient: bool = True):
    """Log-log: time (ms, this machine) against the relative L2 error to the exact gradient. ``panels``: title ->
    ``course.bench.gradients`` rows of one scene and one kind of weights, drawn ``cols`` panels to a row (None:
    all in one row). whole_gradient: the time of the whole gradient (``full_gradient_ms``: finite differences
    scaled from their subset of vertices to all of them); False: each row's own time (``bench gradients``'
    plot). One line per method family, each point labelled with its setting (a family of one setting names it
    in the legend); the exact gradient's own time as a dashed vertical line; errors below ``FLOOR`` drawn at it.
    One legend under the panels. Returns the figure."""
    cols = min(cols or len(panels), len(panels))
    rows_of_panels = -(-len(panels) // cols)
    fig, axes = plt.subplots(rows_of_panels, cols, figsize=(size[0] * cols, size[1] * rows_of_panels), squeeze=False)
    families = list(dict.fromkeys(r["family"] for rows in panels.values() for r in rows if r["method"] != "exact"))
    time = full_gradient_ms if whole_gradient else (lambda r: r["ms"])
    for ax, (title, rows) in zip(axes.flat, panels.items()):
        for r in rows:
            if r["method"] == "exact":
                ax.axvline(r["ms"], color="0.3", ls="--", lw=1, label="exact (reference)")
        for i, family in enumerate(families):
            pts = [r for r in rows if r["family"] == family and not math.isnan(r["rel"])]
            if not pts:
                continue
            xs, ys = [time(r) for r in pts], [max(r["rel"], FLOOR) for r in pts]
            single = len({r["param"] for r in pts}) == 1                    # one setting: say it in the legend
            ax.plot(xs, ys, marker="os^vDp<>"[i % 8], color=f"C{i % 10}", ls=":" if "other image" in family else "-",
                    label=f"{family}, {pts[0]['param']}" if single and pts[0]["param"] else family)
            for k, (x, y, r) in enumerate(zip(xs, ys, pts)):
                if r["param"] and not single:                   # alternately above right and below left
                    ax.annotate(r["param"], (x, y), fontsize=7, xytext=(5, 3) if k % 2 == 0 else (-5, -10),
                                ha="left" if k % 2 == 0 else "right", textcoords="offset points",
                                color=f"C{i % 10}")
        xlabel = "time of the whole gradient (ms)" if whole_gradient else "time, forward + gradient (ms)"
        ax.set(xscale="log", yscale="log", xlabel=xlabel, title=title)
        ax.margins(x=0.1, y=0.12)                                           # room for the labels
        ax.set_ylabel("relative error to exact")
        ax.grid(True, which="major", alpha=0.3)
    for ax in axes.flat[len(panels):]:
        ax.axis("off")
    handles = {}
    for ax in axes.flat[:len(panels)]:
        for h, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, h)
    fig.legend(handles.values(), handles.keys(), loc="lower center", ncol=min(len(handles), 4), fontsize=8)
    fig.tight_layout(rect=(0, 0.13 / rows_of_panels, 1, 1))
    return fig
