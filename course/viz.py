"""Figures for the lectures: images, grids, meshes, points, and interactive explorers with a static fallback.

Every function draws with matplotlib (``origin='upper'``: row 0 at the top, as the course's images are stored)
and returns the figure, so a notebook can both show it and pin it with a printed number.
"""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import torch

__all__ = ["to_numpy", "show_image", "image_grid", "signed_image", "show_depth", "plot_points_3d", "plot_mesh_3d",
           "plot_triangles_2d", "pixel_grid", "explorer", "image_stats"]

DEPTH_CMAP = "viridis_r"     # one depth colour map in every lecture: near is yellow, far is dark blue


def to_numpy(x) -> np.ndarray:
    """A tensor (any device, any grad state) or array → numpy array."""
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().numpy()
    return np.asarray(x)


def image_stats(image) -> str:
    """One deterministic line that pins an image in a notebook: its shape and mean colour.

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
    imshow_kw.setdefault("extent", (0, a.shape[1], a.shape[0], 0))         # pixel (i, j) spans [j, j+1) × [i, i+1)
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


def show_depth(depth, title: str | None = None, ax=None, colorbar: bool = True, **imshow_kw):
    """A depth image (H, W), camera-space z, in the course's one depth colour map with a labelled colour bar.

    Pixels where nothing is hit (+inf, as ``Fragments.depth`` stores them, or NaN) are left white.
    Returns the axes.
    """
    a = to_numpy(depth).astype(np.float64)
    a = np.where(np.isfinite(a), a, np.nan)
    ax = show_image(a, title, ax=ax, cmap=imshow_kw.pop("cmap", DEPTH_CMAP), **imshow_kw)
    if colorbar:
        plt.colorbar(ax.images[-1], ax=ax, fraction=0.046, pad=0.04, label="depth (camera z)")
    return ax


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
    if not ax.yaxis_inverted():
        ax.invert_yaxis()                                                   # world z on matplotlib's y: flip it,
    ax.set_xlabel("x"), ax.set_ylabel("z"), ax.set_zlabel("y (up)")         # or the scene is mirrored
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


def explorer(draw, **sliders) -> None:
    """An ipywidgets explorer: ``draw(**values)`` redraws a figure whenever a slider moves.

    ``sliders`` maps a parameter name to ``(min, max, step, default)``. Costly redraws should pass
    ``continuous_update=False`` through ``draw.continuous_update = False`` or keep images small. Without a
    running widget front-end (a headless run) it falls back to drawing once with the defaults, so the notebook
    still reads well. Displays the widget itself and returns None (so a cell ending in ``explorer(...)``
    does not show it twice).
    """
    try:
        import ipywidgets as widgets
        from IPython.display import display
    except ImportError:                                                     # no widgets: a static figure
        draw(**{k: v[3] for k, v in sliders.items()})
        return
    continuous = getattr(draw, "continuous_update", True)
    controls = {k: widgets.FloatSlider(value=d, min=lo, max=hi, step=st, description=k,
                                       continuous_update=continuous)
                for k, (lo, hi, st, d) in sliders.items()}
    out = widgets.interactive_output(lambda **kw: (draw(**kw), plt.show()), controls)
    box = widgets.VBox([widgets.HBox(list(controls.values())), out])
    display(box)


# ------------------------------------------------------------------ lectures 01-02: shapes, cameras, pixels
__all__ += ["plot_voxels", "plot_camera_frame", "plot_image_points", "fit_view_3d"]


def plot_voxels(occupancy, origin=(0.0, 0.0, 0.0), voxel_size: float = 1.0, ax=None, color=(0.6, 0.7, 0.9),
                title: str | None = None):
    """An occupancy grid as cubes in a 3-D axes (world +y drawn up, like `plot_points_3d`).

    occupancy: (X, Y, Z) bool, indexed by world x, y, z; cell [i, j, k] spans
    ``origin + voxel_size * ([i, i+1) × [j, j+1) × [k, k+1))``. Keep grids small (≤ 32³): matplotlib
    draws every face.
    """
    occ = to_numpy(occupancy).astype(bool)
    if occ.ndim != 3:
        raise ValueError(f"occupancy must have shape (X, Y, Z), got {occ.shape}")
    o, s = to_numpy(origin).astype(np.float64), float(voxel_size)
    corners = np.meshgrid(*(o[k] + s * np.arange(occ.shape[k] + 1) for k in range(3)), indexing="ij")
    gx, gy, gz = (c.transpose(0, 2, 1) for c in corners)                    # matplotlib's axes: x, z, y
    if ax is None:
        fig = plt.figure(figsize=(4, 4))
        ax = fig.add_subplot(projection="3d")
    ax.voxels(gx, gz, gy, occ.transpose(0, 2, 1), facecolors=color, edgecolor=(0.2, 0.2, 0.3), linewidth=0.2)
    full = np.argwhere(occ) if occ.any() else np.zeros((1, 3), dtype=np.int64)
    lo, hi = o + s * full.min(0), o + s * (full.max(0) + 1)                # around the occupied cells
    centre, half = (lo + hi)[[0, 2, 1]] / 2, (hi - lo).max() / 2
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
        setter(c - half, c + half)
    _label_axes(ax, title)
    return ax


def plot_camera_frame(R, t, ax=None, scale: float = 0.5, label: str | None = None, K=None,
                      width: int | None = None, height: int | None = None):
    """A camera's centre and axes in a 3-D world plot: +x red (right), +y green (down), +z blue (forward).

    R: (3, 3), t: (3,) world-to-camera (``x_cam = R @ x_world + t``): the camera centre is ``-Rᵀ t`` and the
    rows of R are its axes in world coordinates. With K (3, 3), width and height, the four image corners'
    rays are drawn too, out to depth ``scale`` (the viewing frustum).
    """
    R, t = to_numpy(R).astype(np.float64), to_numpy(t).astype(np.float64)
    eye = -R.T @ t
    if ax is None:
        fig = plt.figure(figsize=(4, 4))
        ax = fig.add_subplot(projection="3d")
    xyz = lambda p: [np.atleast_1d(p[..., k]) for k in (0, 2, 1)]          # world (x, y, z) → plot (x, z, y)
    for axis, colour, name in zip(R, ("tab:red", "tab:green", "tab:blue"), ("x", "y", "z")):
        end = eye + scale * axis
        ax.plot(*xyz(np.stack([eye, end])), color=colour, lw=2)
        ax.text(*[c[0] for c in xyz(end)], name, color=colour, fontsize=9)
    ax.scatter(*xyz(eye), color="k", s=12)
    if label:
        ax.text(*[c[0] for c in xyz(eye)], f" {label}", fontsize=8)
    if K is not None and width is not None and height is not None:
        corners = np.array([[0, 0, 1], [width, 0, 1], [width, height, 1], [0, height, 1]], dtype=np.float64)
        cam = corners @ np.linalg.inv(to_numpy(K).astype(np.float64)).T * scale   # (4, 3) at depth = scale
        world = (cam - t) @ R                                               # Rᵀ (x_cam - t), one per row
        for p in world:
            ax.plot(*xyz(np.stack([eye, p])), color="0.5", lw=0.8)
        ax.plot(*xyz(np.vstack([world, world[:1]])), color="0.5", lw=0.8)
    _include_in_view(ax, np.stack(xyz(np.vstack([eye, eye + scale * R])), 1))
    _label_axes(ax, None)
    return ax


def fit_view_3d(ax, points_world) -> None:
    """Grow a 3-D axes' view (equal lengths on all axes) to contain world points (N, 3), e.g. two corners."""
    p = to_numpy(points_world).astype(np.float64).reshape(-1, 3)
    _include_in_view(ax, p[:, [0, 2, 1]])                                  # world (x, y, z) → plot (x, z, y)


def _include_in_view(ax, points_plot: np.ndarray) -> None:
    """Grow a 3-D axes' limits (kept cubic, so lengths stay equal) to contain ``points_plot`` (N, 3)."""
    limits = np.array([ax.get_xlim(), ax.get_ylim(), ax.get_zlim()])        # (3, 2)
    lo = np.minimum(limits.min(1), points_plot.min(0))
    hi = np.maximum(limits.max(1), points_plot.max(0))
    centre, half = (lo + hi) / 2, (hi - lo).max() / 2
    for setter, c, (a, b) in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre, limits):
        setter(*((c - half, c + half) if a <= b else (c + half, c - half)))  # keep an inverted axis inverted


def plot_image_points(pixels, width: int, height: int, ax=None, colors=None, size: float = 3.0,
                      title: str | None = None, margin: float = 0.0):
    """Projected points (N, 2) as (x, y) = (column, row) pixel coordinates inside the image frame.

    The frame is the rectangle [0, width] × [0, height], row 0 at the top (as images are shown).
    ``margin`` (a fraction of the image size) widens the view to show points that fall outside.
    """
    p = to_numpy(pixels)
    if ax is None:
        _, ax = plt.subplots(figsize=(4, 4 * height / width))
    ax.plot([0, width, width, 0, 0], [0, 0, height, height, 0], color="0.3", lw=1)
    ax.scatter(p[:, 0], p[:, 1], s=size, c=colors if colors is None or isinstance(colors, str) else to_numpy(colors))
    mx, my = margin * width, margin * height
    ax.set_xlim(-mx, width + mx), ax.set_ylim(height + my, -my)             # row 0 at the top
    ax.set_aspect("equal")
    if title:
        ax.set_title(title)
    return ax


# ------------------------------------------------------------------ lectures 03-04: rasterization, shading
__all__ += ["plot_raster", "plot_curves"]


def plot_raster(values, tris=None, ax=None, title: str | None = None, cmap: str = "Blues", vmin=None, vmax=None,
                annotate: bool = False, centres: bool = True, colorbar: bool = False):
    """Per-pixel values (H, W) drawn in image coordinates, over the pixel grid, with triangles on top.

    Pixel (row i, col j) fills the square [j, j+1) × [i, i+1), so triangles (T, 3, 2) given in the same
    (x, y) image coordinates line up with the pixels they cover; row 0 is at the top. ``annotate`` writes
    each pixel's value (integers: coverage counts, face ids) in its square. Returns the axes.
    """
    a = to_numpy(values)
    if a.ndim != 2:
        raise ValueError(f"values must have shape (H, W), got {a.shape}")
    H, W = a.shape
    if ax is None:
        _, ax = plt.subplots(figsize=(4, 4 * H / W))
    image = ax.imshow(a, cmap=cmap, vmin=vmin, vmax=vmax, extent=(0, W, H, 0), interpolation="nearest")
    pixel_grid(W, H, ax=ax, centres=centres)
    if tris is not None:
        plot_triangles_2d(tris, ax=ax, colors=["tab:orange", "tab:red", "tab:green", "tab:purple"] * 64)
    if annotate:
        for i, j in np.ndindex(H, W):
            v = a[i, j]
            text = f"{int(v)}" if float(v).is_integer() else f"{v:.1f}"
            ax.text(j + 0.5, i + 0.5, text, ha="center", va="center", fontsize=7, color="0.1")
    ax.set_xticks([]), ax.set_yticks([])
    if colorbar:
        plt.colorbar(image, ax=ax, fraction=0.046, pad=0.04)
    if title:
        ax.set_title(title)
    return ax


def plot_curves(x, curves: dict, ax=None, xlabel: str | None = None, ylabel: str | None = None,
                title: str | None = None, polar: bool = False):
    """Several curves y(x) on one axes: ``curves`` maps a label to values (N,) at ``x`` (N,).

    ``polar=True`` draws them as lobes: x is an angle in radians measured from the surface normal, which
    points up, over the half plane above the surface (x in [-π/2, π/2], positive to the right).
    Returns the axes.
    """
    xs = to_numpy(x)
    if ax is None:
        fig = plt.figure(figsize=(5, 3.2) if polar else (5, 3.5))
        ax = fig.add_subplot(projection="polar" if polar else None)
    for k, (label, y) in enumerate(curves.items()):
        ax.plot(xs, to_numpy(y), label=label, ls=("-", "--", ":", "-.")[k % 4])   # overlaps stay visible
    if polar:
        ax.set_theta_zero_location("N"), ax.set_theta_direction(-1)         # normal up, angles clockwise
        ax.set_thetamin(-90), ax.set_thetamax(90)
        ax.set_yticklabels([])                                              # radii: read them from numbers
    else:
        ax.grid(alpha=0.3)
        if xlabel:
            ax.set_xlabel(xlabel)
        if ylabel:
            ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    if polar:
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(0.9, 1.0))
    else:
        ax.legend(fontsize=8, loc="best")
    return ax
