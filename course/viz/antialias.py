"""Figures of lecture 05: signals and their samples, sample patterns in a pixel, clipped pieces. Part of
``course.viz``, which re-exports them."""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import torch

from .core import to_numpy

__all__ = ["plot_signal_samples", "plot_pixel_samples", "plot_pixel_pieces"]


def plot_signal_samples(x, signal, samples: dict, curves: dict | None = None, ax=None, xlabel: str | None = None,
                        title: str | None = None):
    """A 1D signal and its samples, for the sampling theorem: ``x`` (N,) and ``signal`` (N,) drawn as a thin
    solid line, ``curves`` more lines at ``x`` (label -> (N,) values, dashed), ``samples`` markers
    (label -> ``(xs (M,), ys (M,))``). The pixel borders (integers) are drawn as light vertical lines and the
    signal's label is "signal". Returns the axes."""
    xs = to_numpy(x)
    if ax is None:
        _, ax = plt.subplots(figsize=(7.5, 2.8))
    for border in range(int(np.floor(xs.min())), int(np.ceil(xs.max())) + 1):
        ax.axvline(border, color="0.9", lw=0.8, zorder=0)
    ax.plot(xs, to_numpy(signal), color="0.55", lw=0.8, label="signal")
    for k, (label, y) in enumerate((curves or {}).items()):
        ax.plot(xs, to_numpy(y), ls=("--", ":", "-.")[k % 3], color=f"C{k + 2}", lw=1.4, label=label)
    for k, (label, (sx, sy)) in enumerate(samples.items()):
        ax.plot(to_numpy(sx), to_numpy(sy), ("o", "s", "D", "^")[k % 4], color=f"C{k}", ms=5, label=label)
    ax.set_xlim(float(xs.min()), float(xs.max()))
    ax.grid(False)
    if xlabel:
        ax.set_xlabel(xlabel)
    if title:
        ax.set_title(title)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return ax


def plot_pixel_samples(offsets: dict, k: int | None = None, size: float = 2.4):
    """Sample positions inside one pixel, one panel per entry: ``offsets`` maps a title to (S, 2) offsets from
    the pixel's top-left corner, in [0, 1]² (x right, y down, as in the image). ``k`` also draws the k × k
    cells of the grid (the strata of stratified jitter). Returns the figure."""
    n = len(offsets)
    fig, axes = plt.subplots(1, n, figsize=(size * n, size), squeeze=False)
    for ax, (title, o) in zip(axes[0], offsets.items()):
        o = to_numpy(o).reshape(-1, 2)
        if k:
            for c in np.linspace(0, 1, k + 1)[1:-1]:
                ax.axvline(c, color="0.8", lw=0.6), ax.axhline(c, color="0.8", lw=0.6)
        ax.add_patch(plt.Rectangle((0, 0), 1, 1, fill=False, lw=1.2, color="0.2"))
        ax.plot(o[:, 0], o[:, 1], "o", color="tab:blue", ms=4)
        ax.plot([0.5], [0.5], "+", color="tab:red", ms=9, label="pixel centre")
        ax.set_xlim(-0.05, 1.05), ax.set_ylim(1.05, -0.05)                     # y down, as in the image
        ax.set_aspect("equal"), ax.set_xticks([0, 0.5, 1]), ax.set_yticks([0, 0.5, 1])
        ax.set_title(title, fontsize=9)
    axes[0, 0].legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    return fig


def plot_pixel_pieces(pieces, colors=None, lines=None, ax=None, title: str | None = None, areas: bool = True):
    """Polygons inside one pixel's square [0, 1]² (x right, y down): ``pieces`` a list of (M, 2) vertices
    relative to the pixel's top-left corner, filled with ``colors`` (linear RGB, sRGB-encoded for display like
    every colour image) and, with ``areas``, labelled with their area (shoelace, absolute value); ``lines`` a
    list of lines (a, b, c), drawn dashed where a x + b y + c = 0 (clipping lines). Returns the axes."""
    from matplotlib.patches import Polygon
    from course.shading import linear_to_srgb
    if ax is None:
        _, ax = plt.subplots(figsize=(3.2, 3.2))
    ax.add_patch(plt.Rectangle((0, 0), 1, 1, fill=False, lw=1.2, color="0.2"))
    for k, piece in enumerate(pieces):
        p = to_numpy(piece).astype(np.float64).reshape(-1, 2)
        if len(p) < 3:
            continue
        rgb = (0.6, 0.7, 0.9) if colors is None else np.clip(to_numpy(linear_to_srgb(
            torch.as_tensor(np.asarray(to_numpy(colors[k]), dtype=np.float64)).clamp(0, 1))), 0, 1)
        ax.add_patch(Polygon(p, closed=True, facecolor=rgb, edgecolor="0.15", lw=0.8))
        if areas:
            area = 0.5 * abs(float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])))
            cx, cy = p.mean(0)
            ax.text(cx, cy, f"{area:.3f}", ha="center", va="center", fontsize=7,
                    bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.8))
    t = np.linspace(-0.2, 1.2, 2)
    for k, (a, b, c) in enumerate(to_numpy(line).astype(np.float64) for line in (lines or [])):
        if abs(b) >= abs(a):
            ax.plot(t, -(a * t + c) / b, "--", color=f"C{3 + k}", lw=1.2)
        else:
            ax.plot(-(b * t + c) / a, t, "--", color=f"C{3 + k}", lw=1.2)
    ax.set_xlim(-0.1, 1.1), ax.set_ylim(1.1, -0.1)                               # y down, as in the image
    ax.set_aspect("equal"), ax.set_xticks([0, 1]), ax.set_yticks([0, 1])
    if title:
        ax.set_title(title, fontsize=9)
    return ax
