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


def plot_error_cost(panels: dict, size: tuple[float, float] = (4.6, 3.6)):
    """Log-log: time of the whole gradient (ms, this machine; ``full_gradient_ms``) against the relative L2
    error to the exact gradient. ``panels``: title -> ``course.bench.gradients`` rows of one scene and one kind
    of weights. One line per method family, each point labelled with its setting (a family of one setting names it in
    the legend); the exact gradient's own time
    as a dashed vertical line; errors below ``FLOOR`` drawn at it. One legend under the panels. Returns the
    figure."""
    fig, axes = plt.subplots(1, len(panels), figsize=(size[0] * len(panels), size[1]), squeeze=False)
    families = list(dict.fromkeys(r["family"] for rows in panels.values() for r in rows if r["method"] != "exact"))
    for ax, (title, rows) in zip(axes[0], panels.items()):
        for r in rows:
            if r["method"] == "exact":
                ax.axvline(r["ms"], color="0.3", ls="--", lw=1, label="exact (reference)")
        for i, family in enumerate(families):
            pts = [r for r in rows if r["family"] == family and not math.isnan(r["rel"])]
            if not pts:
                continue
            xs, ys = [full_gradient_ms(r) for r in pts], [max(r["rel"], FLOOR) for r in pts]
            single = len({r["param"] for r in pts}) == 1                    # one setting: say it in the legend
            ax.plot(xs, ys, marker="os^vDp<>"[i % 8], color=f"C{i % 10}", ls=":" if "other image" in family else "-",
                    label=f"{family}, {pts[0]['param']}" if single and pts[0]["param"] else family)
            for k, (x, y, r) in enumerate(zip(xs, ys, pts)):
                if r["param"] and not single:                   # alternately above right and below left
                    ax.annotate(r["param"], (x, y), fontsize=7, xytext=(5, 3) if k % 2 == 0 else (-5, -10),
                                ha="left" if k % 2 == 0 else "right", textcoords="offset points",
                                color=f"C{i % 10}")
        ax.set(xscale="log", yscale="log", xlabel="time of the whole gradient (ms)", title=title)
        ax.margins(x=0.1, y=0.12)                                           # room for the labels
        ax.set_ylabel("relative error to exact")
        ax.grid(True, which="major", alpha=0.3)
    handles = {}
    for ax in axes[0]:
        for h, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, h)
    fig.legend(handles.values(), handles.keys(), loc="lower center", ncol=min(len(handles), 4), fontsize=8)
    fig.tight_layout(rect=(0, 0.13, 1, 1))
    return fig
