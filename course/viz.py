"""Figures for the lectures: images, grids, meshes, points, and interactive explorers with a static fallback.

Every function draws with matplotlib (``origin='upper'``: row 0 at the top, as the course's images are stored)
and returns the figure, so a notebook can both show it and pin it with a printed number.
"""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import torch

__all__ = ["to_numpy", "show_image", "image_grid", "signed_image", "plot_points_3d", "plot_mesh_3d",
           "plot_triangles_2d", "pixel_grid", "explorer", "image_stats"]


def to_numpy(x) -> np.ndarray:
    """A tensor (any device, any grad state) or array → numpy array."""
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().numpy()
    return np.asarray(x)


def image_stats(image) -> str:
    """One deterministic line that pins an image in a notebook: shape, mean colour, coverage of non-background.

    image: (H, W) or (H, W, C). Printed floats are rounded to 4 decimals.
    """
    a = to_numpy(image).astype(np.float64)
    mean = np.round(a.reshape(-1, a.shape[-1]).mean(0) if a.ndim == 3 else a.mean(), 4)
    return f"shape {tuple(a.shape)}, mean {np.array2string(np.asarray(mean), precision=4)}"


def show_image(image, title: str | None = None, ax=None, **imshow_kw):
    """Show an (H, W), (H, W, 3) or (H, W, 4) image with row 0 at the top. Returns the axes."""
    a = to_numpy(image)
    if ax is None:
        _, ax = plt.subplots(figsize=(4, 4))
    if a.ndim == 3 and a.shape[-1] in (3, 4):
        a = np.clip(a, 0, 1)
    ax.imshow(a, interpolation="nearest", **imshow_kw)
    ax.set_xticks([]), ax.set_yticks([])
    if title:
        ax.set_title(title)
    return ax


def image_grid(images, titles=None, cols: int | None = None, size: float = 3.0, **imshow_kw):
    """Several images side by side. Returns the figure."""
    n = len(images)
    cols = cols or n
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(size * cols, size * rows), squeeze=False)
    for k, ax in enumerate(axes.flat):
        if k < n:
            show_image(images[k], titles[k] if titles else None, ax=ax, **imshow_kw)
        else:
            ax.axis("off")
    fig.tight_layout()
    return fig


def signed_image(values, title: str | None = None, ax=None):
    """A signed scalar image (a gradient, an edge function): red positive, blue negative, white zero."""
    a = to_numpy(values)
    lim = float(np.abs(a[np.isfinite(a)]).max()) if np.isfinite(a).any() else 1.0
    ax = show_image(a, title, ax=ax, cmap="RdBu_r", vmin=-lim or -1, vmax=lim or 1)
    return ax


def plot_points_3d(points, colors=None, ax=None, size: float = 4.0, title: str | None = None):
    """A 3-D scatter of points (N, 3) in world space (+y up)."""
    p = to_numpy(points)
    if ax is None:
        fig = plt.figure(figsize=(4, 4))
        ax = fig.add_subplot(projection="3d")
    ax.scatter(p[:, 0], p[:, 2], p[:, 1], s=size, c=None if colors is None else to_numpy(colors))
    _label_axes(ax, title)
    return ax


def plot_mesh_3d(mesh, ax=None, color=(0.6, 0.7, 0.9), edgecolor=(0.2, 0.2, 0.3), title: str | None = None):
    """A mesh as shaded polygons in a 3-D matplotlib axes (world +y drawn up)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    v = to_numpy(mesh.verts)[:, [0, 2, 1]]                                  # matplotlib's z is up
    if ax is None:
        fig = plt.figure(figsize=(4, 4))
        ax = fig.add_subplot(projection="3d")
    ax.add_collection3d(Poly3DCollection(v[to_numpy(mesh.faces)], facecolor=color, edgecolor=edgecolor,
                                         linewidths=0.3, alpha=0.9))
    lo, hi = v.min(0), v.max(0)
    centre, half = (lo + hi) / 2, (hi - lo).max() / 2
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
        setter(c - half, c + half)
    _label_axes(ax, title)
    return ax


def _label_axes(ax, title):
    ax.set_xlabel("x"), ax.set_ylabel("z"), ax.set_zlabel("y (up)")
    if title:
        ax.set_title(title)


def pixel_grid(width: int, height: int, ax=None, centres: bool = True):
    """Draw the pixel squares [j, j+1) × [i, i+1) and, optionally, their centres, in image coordinates."""
    if ax is None:
        _, ax = plt.subplots(figsize=(4, 4 * height / width))
    for x in range(width + 1):
        ax.plot([x, x], [0, height], color="0.8", lw=0.5)
    for y in range(height + 1):
        ax.plot([0, width], [y, y], color="0.8", lw=0.5)
    if centres:
        jj, ii = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
        ax.plot(jj.ravel(), ii.ravel(), ".", color="0.5", ms=3)
    ax.set_xlim(0, width), ax.set_ylim(height, 0)                           # row 0 at the top
    ax.set_aspect("equal")
    return ax


def plot_triangles_2d(tris, ax=None, colors=None, labels: bool = False):
    """Screen-space triangles (T, 3, 2) as outlines over a pixel grid's axes."""
    t = to_numpy(tris).reshape(-1, 3, 2)
    if ax is None:
        _, ax = plt.subplots(figsize=(4, 4))
    for k, tri in enumerate(t):
        closed = np.vstack([tri, tri[:1]])
        ax.plot(closed[:, 0], closed[:, 1], "-", color=None if colors is None else colors[k], lw=1.5)
        if labels:
            for n, (x, y) in enumerate(tri):
                ax.annotate(f"v{n}", (x, y), textcoords="offset points", xytext=(3, 3), fontsize=8)
    return ax


def explorer(draw, **sliders):
    """An ipywidgets explorer: ``draw(**values)`` redraws a figure whenever a slider moves.

    ``sliders`` maps a parameter name to ``(min, max, step, default)``. Costly redraws should pass
    ``continuous_update=False`` through ``draw.continuous_update = False`` or keep images small. Without a
    running widget front-end (a headless run) it falls back to drawing once with the defaults, so the notebook
    still reads well. Returns the widget (or None).
    """
    try:
        import ipywidgets as widgets
        from IPython.display import display
    except ImportError:                                                     # no widgets: a static figure
        draw(**{k: v[3] for k, v in sliders.items()})
        return None
    continuous = getattr(draw, "continuous_update", True)
    controls = {k: widgets.FloatSlider(value=d, min=lo, max=hi, step=st, description=k,
                                       continuous_update=continuous)
                for k, (lo, hi, st, d) in sliders.items()}
    out = widgets.interactive_output(lambda **kw: (draw(**kw), plt.show()), controls)
    box = widgets.VBox([widgets.HBox(list(controls.values())), out])
    display(box)
    return box
