"""Figures of lecture 04: light geometry, grids of shading quantities. Part of ``course.viz``, which re-exports
them."""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from .core import show_image, to_numpy

__all__ = ["plot_light_geometry", "quantity_grid"]


def plot_light_geometry(normal, toward_light, view=None, ax=None, title: str | None = None):
    """The shading vectors at one surface point, drawn in the plane of the figure (x right, y up).

    normal, toward_light, view: (2,) or (3,) (only x and y are drawn), normalised here. ``toward_light`` is
    ``l``, pointing from the surface *toward* the light, as :func:`course.shading.lambert` takes it; the
    dashed rays show the way the light *travels*, ``-l``, which is what ``DirectionalLight(direction=...)``
    holds. With ``view`` (``v``, toward the eye) the half vector ``h = normalize(l + v)`` and the mirror
    direction ``r = 2 (n·l) n - l`` are drawn too. Returns the axes.
    """
    def unit(x):
        a = to_numpy(x).astype(np.float64)[:2]
        return a / np.linalg.norm(a)

    n, l = unit(normal), unit(toward_light)
    if ax is None:
        _, ax = plt.subplots(figsize=(4.2, 3.4))
    tangent = np.array([n[1], -n[0]])
    corners = np.array([-1.3 * tangent, 1.3 * tangent, 1.3 * tangent - 0.3 * n, -1.3 * tangent - 0.3 * n])
    ax.add_patch(plt.Polygon(corners, facecolor="0.85", edgecolor="0.3", lw=1.5, label="surface"))
    arrows = {"n (normal)": (n, "black", "-"), "l (toward the light)": (l, "tab:orange", "-")}
    if view is not None:
        v = unit(view)
        h = (l + v) / np.linalg.norm(l + v)
        r = 2 * np.dot(n, l) * n - l
        arrows.update({"v (toward the eye)": (v, "tab:blue", "-"), "h = normalize(l + v)": (h, "tab:green", "-"),
                       "r (mirror of l)": (r, "tab:purple", "--")})
    for k, offset in enumerate((-0.25, 0.25)):                                 # two rays of light, travelling -l
        start = 1.25 * l + offset * tangent
        ax.annotate("", xy=start - 0.75 * l, xytext=start,
                    arrowprops=dict(arrowstyle="->", color="tab:orange", ls=":", lw=1.2))
    ax.plot([], [], color="tab:orange", ls=":", label="light travels: DirectionalLight.direction = -l")
    for label, (vec, color, ls) in arrows.items():
        ax.annotate("", xy=vec, xytext=(0, 0), arrowprops=dict(arrowstyle="-|>", color=color, ls=ls, lw=2))
        ax.plot([], [], color=color, ls=ls, lw=2, label=label)                 # legend entry for the arrow
    ax.set_xlim(-1.4, 1.4), ax.set_ylim(-0.4, 1.5)
    ax.set_aspect("equal"), ax.set_xticks([]), ax.set_yticks([])
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    if title:
        ax.set_title(title)
    return ax


def quantity_grid(images, titles=None, label: str = "value", cmap: str = "gray", vmin: float = 0.0,
                  vmax: float = 1.0, size: float = 3.0):
    """Scalar images (H, W) side by side in one colour map, with one shared, labelled colour bar: for a
    quantity (a highlight strength, a cosine), never sRGB-encoded. NaN pixels (nothing there) stay white.
    Returns the figure."""
    n = len(images)
    fig, axes = plt.subplots(1, n, figsize=(size * n + 0.8, size), squeeze=False)
    for k, ax in enumerate(axes.flat):
        show_image(images[k], titles[k] if titles else None, ax=ax, cmap=cmap, vmin=vmin, vmax=vmax)
    fig.colorbar(axes[0, -1].images[-1], ax=list(axes.flat), fraction=0.046 / n * 2, pad=0.02, label=label)
    return fig
