"""Figures for the lectures: images, grids, meshes, points, and interactive explorers with a static fallback.

Every function draws with matplotlib (``origin='upper'``: row 0 at the top, as the course's images are stored)
and returns the figure, so a notebook can both show it and pin it with a printed number.
"""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import torch

from .tensors import _check_count

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


def show_image(image, title: str | None = None, ax=None, srgb: bool = True, **imshow_kw):
    """Show an (H, W), (H, W, 3) or (H, W, 4) image with row 0 at the top. Returns the axes.

    A colour image (3 or 4 channels) holds linear RGB: it is clipped to [0, 1] and, with ``srgb=True``
    (default), encoded to sRGB for the screen (alpha stays as it is); ``srgb=False`` shows the raw values.
    An (H, W) image is a quantity drawn through a colour map and is never encoded.
    """
    a = to_numpy(image)
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[-1] in (1, 3, 4))) or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"image must be a non-empty (H, W), (H, W, 3) or (H, W, 4) image, got shape {a.shape}")
    if a.dtype.kind not in "biuf":
        raise ValueError(f"image must hold numbers, got dtype {a.dtype}")
    if a.ndim == 3 and a.shape[-1] == 1:
        a = a[..., 0]                                                       # (H, W, 1): a quantity, like (H, W)
    if ax is None:
        _, ax = plt.subplots(figsize=(4, 4))
    if a.ndim == 3 and a.shape[-1] in (3, 4):
        a = np.clip(a, 0, 1)
        if srgb:
            from course.shading import linear_to_srgb
            a = a.astype(np.float64)                                        # a copy: the caller's array stays linear
            a[..., :3] = linear_to_srgb(torch.from_numpy(a[..., :3])).numpy()
    imshow_kw.setdefault("extent", (0, a.shape[1], a.shape[0], 0))         # pixel (i, j) spans [j, j+1) × [i, i+1)
    ax.imshow(a, interpolation="nearest", **imshow_kw)
    ax.set_xticks([]), ax.set_yticks([])
    if title:
        ax.set_title(title)
    return ax


def image_grid(images, titles=None, cols: int | None = None, size: float = 3.0, srgb: bool = True, **imshow_kw):
    """Several images side by side; colour images are sRGB-encoded for display unless ``srgb=False``
    (see :func:`show_image`). Returns the figure."""
    if isinstance(images, (str, bytes)) or not hasattr(images, "__len__") or len(images) == 0:
        raise ValueError("images must be a non-empty list of images")
    n = len(images)
    if titles is not None and (isinstance(titles, str) or len(titles) != n):
        raise ValueError(f"titles must be None or one per image ({n}), got {titles!r}")
    cols = n if cols is None else _check_count(cols, "cols")
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(size * cols, size * rows), squeeze=False)
    for k, ax in enumerate(axes.flat):
        if k < n:
            show_image(images[k], titles[k] if titles else None, ax=ax, srgb=srgb, **imshow_kw)
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
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {p.shape}")
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
    width, height = _check_count(width, "width"), _check_count(height, "height")
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


def explorer(draw, *, figure_scale: float = 1.5, **sliders) -> None:
    """An ipywidgets explorer: ``draw(**values)`` redraws a figure whenever a slider moves.

    ``sliders`` maps a parameter name to ``(min, max, step, default)``. Costly redraws should pass
    ``continuous_update=False`` through ``draw.continuous_update = False`` or keep images small.

    The sliders are stacked, one per row, each as wide as the notebook allows between 360 and 560 px (a 90-px
    name, the track, the readout), so a track stays 200-370 px long in any window (JupyterLab at 1024 px with
    the file browser open gives 560); the picture sits below them. The figures ``draw`` makes are drawn at
    ``figure_scale`` times matplotlib's resolution, so a 4-inch figure is about 600 px wide. A notebook opened without widget state (saved outputs, an untrusted notebook)
    shows a one-line note instead of the widget's repr. Without ipywidgets it draws once with the defaults,
    so the notebook still reads well. Displays the widget itself and returns None (so a cell ending in
    ``explorer(...)`` does not show it twice).
    """
    for name, spec in sliders.items():
        if len(spec) != 4:
            raise ValueError(f"slider {name!r}: expected (min, max, step, default), got {spec!r}")
        lo, hi, _, default = spec
        if not lo <= default <= hi:
            raise ValueError(f"slider {name!r}: default {default} lies outside [{lo}, {hi}]")
    defaults = {name: spec[3] for name, spec in sliders.items()}
    try:
        import ipywidgets as widgets
        from IPython.display import display
    except ImportError:                                                     # no widgets: a static figure
        draw(**defaults)
        return
    continuous = getattr(draw, "continuous_update", True)
    controls = {name: widgets.FloatSlider(value=d, min=lo, max=hi, step=st, description=name,
                                          continuous_update=continuous, style={"description_width": "90px"},
                                          layout=widgets.Layout(width="100%", min_width="360px", max_width="560px"))
                for name, (lo, hi, st, d) in sliders.items()}

    def redraw(**values):
        with plt.rc_context({"figure.dpi": plt.rcParams["figure.dpi"] * figure_scale}):
            draw(**values)
            plt.show()

    picture = widgets.interactive_output(redraw, controls)
    box = widgets.VBox([widgets.VBox(list(controls.values())), picture])
    bundle = box._repr_mimebundle_()
    bundle["text/plain"] = (f"[interactive explorer: sliders {', '.join(sliders)}; run the cell in JupyterLab "
                            f"to use them]")
    display(bundle, raw=True)


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
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"pixels must have shape (N, 2), (x, y) image coordinates, got {p.shape}")
    width, height = _check_count(width, "width"), _check_count(height, "height")
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


# ---- lecture 03: added figures
__all__ += ["draw_triangle", "plot_edge_function", "plot_raster_legend", "plot_clip_side", "plot_zbuffer_keys"]


def draw_triangle(ax, tri, color="k", label: str | None = None, vertex_labels: bool = True, edge=None,
                  **line_kw):
    """Outline one screen-space triangle (3, 2) on an image axes, name its corners v0, v1, v2, and
    optionally mark one edge ``(a, b)`` (corner indices) with an arrow from a to b.

    The labels sit just outside the triangle (pushed away from its centroid), so they never hide the pixels
    inside. Returns the outline's line (for a legend).
    """
    t = to_numpy(tri).astype(np.float64).reshape(3, 2)
    closed = np.vstack([t, t[:1]])
    line, = ax.plot(closed[:, 0], closed[:, 1], "-", color=color, lw=line_kw.pop("lw", 1.5), label=label, **line_kw)
    if vertex_labels:
        centre = t.mean(0)
        for n, p in enumerate(t):
            away = (p - centre) / (np.linalg.norm(p - centre) or 1.0)       # unit vector out of the triangle
            ax.annotate(f"v{n}", p, textcoords="offset points", xytext=tuple(10 * away), ha="center",
                        va="center", fontsize=9, color=color, fontweight="bold")
    if edge is not None:
        a, b = t[edge[0]], t[edge[1]]
        ax.annotate("", b, a, arrowprops=dict(arrowstyle="-|>", color=color, lw=2.5, shrinkA=0, shrinkB=0))
    return line


def plot_edge_function(values, tri, width: float, height: float, edge=None, title: str | None = None, ax=None):
    """An edge function (or any signed scalar) sampled over the image [0, width] × [0, height], with the
    triangle (3, 2) on top: red positive, blue negative, white zero, as ``signed_image``.

    values: (h, w) samples on a grid finer than the pixels, covering the whole image. ``edge=(a, b)`` marks the
    edge a→b that the function belongs to with an arrow. Returns the axes.
    """
    a = to_numpy(values)
    lim = float(np.abs(a[np.isfinite(a)]).max()) if np.isfinite(a).any() else 1.0
    ax = show_image(a, title, ax=ax, cmap="RdBu_r", vmin=-lim or -1, vmax=lim or 1, extent=(0, width, height, 0))
    draw_triangle(ax, tri, color="k", edge=edge)
    ax.set_xlim(0, width), ax.set_ylim(height, 0)
    return ax


def plot_raster_legend(values, tris=None, ax=None, tri_labels=None, tri_colors=None, fill_labels=None,
                       vertex_labels: bool = False, legend_loc: str = "upper right", **raster_kw):
    """``plot_raster`` with a legend that tells outlines from fills.

    values: (H, W) per-pixel values; tris: (T, 3, 2) image-coordinate triangles, outlined in ``tri_colors``
    (default orange, red, green, purple, ...) and named ``tri_labels`` (T,) in the legend; ``fill_labels``
    maps a pixel value to its legend entry (a swatch in the colour that value gets). ``vertex_labels`` names
    the corners v0, v1, v2. ``legend_loc`` is a matplotlib location, or "below" / "right" to put the legend
    outside the image. Other keywords (cmap, vmin, vmax, title, annotate, centres) go to ``plot_raster``.
    Returns the axes.
    """
    from matplotlib.patches import Patch
    ax = plot_raster(values, ax=ax, **raster_kw)
    handles = []
    if fill_labels:
        image = ax.images[-1]
        for value, name in fill_labels.items():
            handles.append(Patch(facecolor=image.cmap(image.norm(value)), edgecolor="0.5", label=name))
    if tris is not None:
        t = to_numpy(tris).reshape(-1, 3, 2)
        colors = tri_colors or ["tab:orange", "tab:red", "tab:green", "tab:purple"] * len(t)
        for k, tri in enumerate(t):
            name = tri_labels[k] if tri_labels else None
            line = draw_triangle(ax, tri, color=colors[k], label=name, vertex_labels=vertex_labels)
            if name:
                handles.append(line)
    if handles:
        where = {"below": dict(loc="upper center", bbox_to_anchor=(0.5, -0.02), ncol=2),
                 "right": dict(loc="upper left", bbox_to_anchor=(1.02, 1.0))}.get(legend_loc, dict(loc=legend_loc))
        ax.legend(handles=handles, fontsize=7, framealpha=0.9, **where)
    return ax


def plot_clip_side(tri_cam, clipped, near: float, ax=None, title: str | None = None):
    """Near-plane clipping seen from the side, in camera space: depth z to the right, y down (as the camera's
    y axis points), the eye at the origin.

    tri_cam: (3, 3) the original triangle (dashed outline, corners named v0, v1, v2); clipped: (C, 3, 3) the
    triangles clipping made (filled, one colour each); near: the plane z = near (a vertical line, the part
    behind it shaded). Returns the axes.
    """
    from matplotlib.patches import Polygon
    t = to_numpy(tri_cam).astype(np.float64).reshape(3, 3)
    c = to_numpy(clipped).astype(np.float64).reshape(-1, 3, 3)
    if ax is None:
        _, ax = plt.subplots(figsize=(4.5, 3.5))
    zs = np.concatenate([t[:, 2], c[..., 2].ravel(), [0.0, near]])
    ys = np.concatenate([t[:, 1], c[..., 1].ravel(), [0.0]])
    pad = 0.1 * max(np.ptp(zs), np.ptp(ys), 1e-9)
    z_lo, z_hi, y_lo, y_hi = zs.min() - pad, zs.max() + pad, ys.min() - pad, ys.max() + pad
    ax.axvspan(z_lo, near, color="0.9", zorder=0, label="z < near: clipped away")
    ax.axvline(near, color="0.3", lw=1.2, label=f"near plane z = {near:g}")
    colors = ["tab:blue", "tab:orange", "tab:green", "tab:purple"]
    for k, piece in enumerate(c):
        ax.add_patch(Polygon(piece[:, [2, 1]], closed=True, facecolor=colors[k % 4], alpha=0.45,
                             edgecolor=colors[k % 4], lw=1.5, label=f"clipped triangle {k}"))
        on_plane = np.isclose(piece[:, 2], near)
        ax.plot(piece[on_plane, 2], piece[on_plane, 1], "o", color="k", ms=4)
    closed = np.vstack([t, t[:1]])
    ax.plot(closed[:, 2], closed[:, 1], "--", color="k", lw=1.2, label="original triangle")
    centre = t[:, [2, 1]].mean(0)
    for n, p in enumerate(t[:, [2, 1]]):
        away = (p - centre) / (np.linalg.norm(p - centre) or 1.0)
        ax.annotate(f"v{n}", p, textcoords="offset points", xytext=tuple(10 * away), ha="center", va="center",
                    fontsize=9)
    ax.plot([0], [0], "k^", ms=7, label="eye")
    ax.set_xlim(z_lo, z_hi), ax.set_ylim(y_hi, y_lo)                        # camera y points down
    ax.set_aspect("equal")
    ax.set_xlabel("z (depth)"), ax.set_ylabel("y (down)")
    ax.legend(fontsize=7, loc="best", framealpha=0.9)
    if title:
        ax.set_title(title)
    return ax


def plot_zbuffer_keys(pixel_index, depth, face_id, keys=None, ax=None, title: str | None = None):
    """The z-buffer's scatter-min, fragment by fragment: one column per pixel, each fragment a dot at its
    depth labelled with its face id (and its packed key, if given); the fragment each pixel keeps, the one
    with the smallest key, is ringed. Fragments tied in depth at one pixel are drawn side by side.

    pixel_index, depth, face_id: (M,) one entry per fragment; keys: (M,) int64 packed keys
    ``(float32 depth bits << 32) | face id``, drawn as ``depth bits:face`` in hex. Returns the axes.
    """
    pix = to_numpy(pixel_index).astype(np.int64)
    z = to_numpy(depth).astype(np.float64)
    face = to_numpy(face_id).astype(np.int64)
    order_key = to_numpy(keys).astype(np.int64) if keys is not None else None
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 3.5))
    columns = np.unique(pix)
    colors = plt.get_cmap("tab10")
    for col, p in enumerate(columns):
        idx = np.nonzero(pix == p)[0]
        rank = order_key[idx] if order_key is not None else np.lexsort((face[idx], z[idx]))
        kept = idx[np.argmin(rank)] if order_key is not None else idx[rank[0]]
        x_of = {}
        for m in idx:
            tie = int(np.sum(z[idx[:np.searchsorted(idx, m)]] == z[m]))      # earlier fragments at this depth
            left = tie % 2 == 1                                             # a tie: the second one on the left
            x_of[m] = col - 0.12 * ((tie + 1) // 2) if left else col + 0.12 * (tie // 2)
            ax.plot(x_of[m], z[m], "o", color=colors(face[m] % 10), ms=8, zorder=3)
            text = f"face {face[m]}"
            if order_key is not None:
                text += f"  key {(int(order_key[m]) >> 32) & 0xFFFFFFFF:08X}:{int(order_key[m]) & 0xFFFFFFFF:08X}"
            ax.annotate(text, (x_of[m], z[m]), textcoords="offset points", xytext=(-9 if left else 9, 0),
                        ha="right" if left else "left", va="center", fontsize=7)
        ax.plot(x_of[kept], z[kept], "o", ms=16, mfc="none", mec="k", mew=1.8, zorder=4)
    ax.plot([], [], "o", ms=12, mfc="none", mec="k", mew=1.8, label="kept: the smallest key")
    ax.set_xticks(range(len(columns)), [f"pixel {p}" for p in columns])
    ax.set_xlim(-0.9, len(columns) - 0.5 + 0.9)
    ax.set_ylabel("depth (camera z)")
    ax.invert_yaxis()                                                       # near at the top
    ax.legend(fontsize=7, loc="lower right")
    if title:
        ax.set_title(title)
    return ax


# ---- lectures 01-02: added figures
__all__ += ["plot_vectors_2d", "plot_pinhole", "plot_frustum_3d", "plot_frustum_side"]

_VECTOR_COLOURS = ("tab:blue", "tab:red", "tab:green", "tab:orange", "tab:purple")


def plot_vectors_2d(origin, vectors: dict, ax=None, curve=None, title: str | None = None, colors=None):
    """Labelled arrows from one point of a plane, over an optional curve, with a legend.

    origin: (2,); ``vectors`` maps a legend label to a vector (2,); curve: (N, 2), drawn in grey (the surface
    the vectors belong to). Both axes have the same scale, so right angles look right. Returns the axes.
    """
    o = to_numpy(origin).astype(np.float64)
    if ax is None:
        _, ax = plt.subplots(figsize=(4, 4))
    ends = [o]
    if curve is not None:
        c = to_numpy(curve).astype(np.float64)
        ax.plot(c[:, 0], c[:, 1], color="0.5", lw=1.5, label="surface")
        ends.append(c)
    for k, (label, v) in enumerate(vectors.items()):
        v = to_numpy(v).astype(np.float64)
        colour = colors[k] if colors is not None else _VECTOR_COLOURS[k % len(_VECTOR_COLOURS)]
        ax.annotate("", o + v, o, arrowprops=dict(arrowstyle="-|>", color=colour, lw=2, shrinkA=0, shrinkB=0))
        ax.plot([], [], color=colour, lw=2, label=label)                   # a legend entry for the arrow
        ends.append(o + v)
    ax.plot(*o, "o", color="k", ms=4)
    p = np.vstack([np.atleast_2d(e) for e in ends])
    lo, hi = p.min(0), p.max(0)
    pad = 0.15 * (hi - lo).max()
    ax.set_xlim(lo[0] - pad, hi[0] + pad), ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=2)   # below: arrows stay visible
    if title:
        ax.set_title(title)
    return ax


def plot_pinhole(depth: float, offset: float, focal: float = 1.0, ax=None, behind: bool = True,
                 names=("Z", "X", "x")):
    """The pinhole camera seen from the side: similar triangles give ``x = focal · offset / depth``.

    A point at camera-space ``depth`` (along the optical axis, drawn to the right) and ``offset`` from the axis
    (drawn upward) sends a ray through the pinhole at the origin; it crosses the image plane at distance
    ``focal`` in front of the pinhole at ``x``. With ``behind`` the real, inverted image at ``-focal`` (where a
    physical sensor sits) is drawn too. ``names`` label the offset's axis pieces (depth, offset, image).
    Returns the axes.
    """
    Z, X, f = float(depth), float(offset), float(focal)
    x = f * X / Z
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 2.8))
    left = -1.3 * f if behind else -0.2 * f
    ax.axhline(0.0, color="0.6", lw=0.8, ls="-.", label="optical axis")
    ax.fill([0, Z, Z], [0, 0, X], color="tab:blue", alpha=0.15, lw=0)      # the big triangle: depth, offset
    ax.fill([0, f, f], [0, 0, x], color="tab:orange", alpha=0.45, lw=0)     # the small one: focal, image
    ax.plot([left if behind else 0.0, Z], [left * X / Z if behind else 0.0, X], color="tab:red", lw=1.2,
            label="ray through the pinhole")
    span = 1.6 * max(abs(x), 0.1 * f)
    ax.plot([f, f], [-span, span], color="k", lw=2, label=f"image plane, {f:g} in front")
    if behind:
        ax.plot([-f, -f], [-span, span], color="k", lw=2, ls=":", label="sensor behind (image upside down)")
        ax.plot(-f, -x, "o", color="tab:orange", ms=5, mfc="none")
    ax.plot([Z, Z], [0, X], color="tab:blue", lw=2)
    ax.plot(Z, X, "o", color="tab:blue", ms=6)
    ax.plot(f, x, "o", color="tab:orange", ms=6)
    ax.plot(0, 0, "o", color="k", ms=5)
    ax.annotate("pinhole", (0, 0), textcoords="offset points", xytext=(-10, -14), fontsize=8)
    dz, dx, dim = names
    ax.annotate(dz, (Z / 2, 0), textcoords="offset points", xytext=(0, -12), fontsize=10, ha="center")
    ax.annotate(dx, (Z, X / 2), textcoords="offset points", xytext=(6, 0), fontsize=10, va="center")
    ax.annotate(f"{dim} = f·{dx}/{dz}", (f, x), textcoords="offset points", xytext=(6, 4), fontsize=10)
    ax.annotate("f", (f / 2, 0), textcoords="offset points", xytext=(0, -12), fontsize=10, ha="center")
    ax.set_aspect("equal")
    ax.set_xlabel(f"depth {dz} (optical axis)"), ax.set_ylabel(f"offset {dx}")
    ax.legend(fontsize=7, loc="upper left")
    return ax


def _frustum_corners(K, depth: float, width: int, height: int) -> np.ndarray:
    """Camera-space (4, 3) points where the rays through the image's corners reach ``depth``."""
    corners = np.array([[0, 0, 1], [width, 0, 1], [width, height, 1], [0, height, 1]], dtype=np.float64)
    return corners @ np.linalg.inv(to_numpy(K).astype(np.float64)).T * depth


def plot_frustum_3d(K, R, t, width: int, height: int, near: float, far: float, ax=None,
                    color=(1.0, 0.6, 0.2)):
    """A pinhole camera's viewing frustum in a 3-D world plot (world +y drawn up, like `plot_mesh_3d`).

    K, R: (3, 3), t: (3,) with ``x_cam = R @ x_world + t``. Draws the near and far planes (filled) between the
    rays through the four image corners, and dashed rays from the camera centre to the near plane. Only what
    lies inside this truncated pyramid, at depths in [near, far], is rendered. Returns the axes.
    """
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    R, t = to_numpy(R).astype(np.float64), to_numpy(t).astype(np.float64)
    eye = -R.T @ t
    if ax is None:
        fig = plt.figure(figsize=(4, 4))
        ax = fig.add_subplot(projection="3d")
    planes = [(_frustum_corners(K, d, width, height) - t) @ R for d in (near, far)]   # (4, 3) world each
    for p, alpha in zip(planes, (0.45, 0.15)):
        ax.add_collection3d(Poly3DCollection([p[:, [0, 2, 1]]], facecolor=color, edgecolor="0.3", alpha=alpha))
    for a, b in zip(*planes):
        ax.plot([a[0], b[0]], [a[2], b[2]], [a[1], b[1]], color="0.3", lw=0.8)       # plot axes: x, z, y
        ax.plot([eye[0], a[0]], [eye[2], a[2]], [eye[1], a[1]], color="0.3", lw=0.8, ls="--")
    ax.scatter([eye[0]], [eye[2]], [eye[1]], color="k", s=12)
    _include_in_view(ax, np.vstack([eye, *planes])[:, [0, 2, 1]])
    _label_axes(ax, None)
    return ax


def plot_frustum_side(K, height: int, near: float, far: float, points_cam=None, ax=None,
                      title: str | None = None):
    """The viewing frustum seen from the side (the camera's y–z plane), with camera-space points.

    Depth z runs to the right and camera +y is drawn downward, as in the image. The frustum's top and bottom
    are the rays through rows 0 and ``height`` (K: (3, 3)); the near and far planes close it. points_cam:
    (N, 3) camera-space points, drawn in blue where they lie inside the frustum (vertically and in depth) and
    in grey where they are clipped. Returns the axes.
    """
    Kn = to_numpy(K).astype(np.float64)
    top, bottom = -Kn[1, 2] / Kn[1, 1], (height - Kn[1, 2]) / Kn[1, 1]   # y / z along the two bounding rays
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 3))
    z_end = 1.1 * far
    for slope in (top, bottom):
        ax.plot([0, z_end], [0, slope * z_end], color="0.4", lw=0.8, ls="--")
    ax.fill([near, far, far, near], [top * near, top * far, bottom * far, bottom * near], color=(1.0, 0.6, 0.2),
            alpha=0.25, lw=0, label="viewing frustum")
    for z, name in ((near, "near"), (far, "far")):
        ax.plot([z, z], [top * z, bottom * z], color="tab:orange", lw=2)
        ax.annotate(f"{name} = {z:g}", (z, top * z), textcoords="offset points", xytext=(0, 5), fontsize=8,
                    ha="center")
    if points_cam is not None:
        p = to_numpy(points_cam).astype(np.float64)
        y_over_z = p[:, 1] / np.where(p[:, 2] > 0, p[:, 2], np.inf)
        inside = (p[:, 2] >= near) & (p[:, 2] <= far) & (y_over_z >= top) & (y_over_z <= bottom)
        ax.scatter(p[~inside, 2], p[~inside, 1], s=1, color="0.6", label="clipped")
        ax.scatter(p[inside, 2], p[inside, 1], s=1, color="tab:blue", label="inside")
    ax.plot(0, 0, "o", color="k", ms=4)
    ax.set_xlim(-0.05 * z_end, z_end)
    if not ax.yaxis_inverted():
        ax.invert_yaxis()                                                   # camera +y points down the image
    ax.set_xlabel("z_cam (forward)"), ax.set_ylabel("y_cam (down)")
    ax.legend(fontsize=8, loc="upper left", markerscale=4)
    if title:
        ax.set_title(title)
    return ax


# ---- lecture 04: added figures
__all__ += ["plot_light_geometry", "quantity_grid"]


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


# ---- lecture 05: added figures
__all__ += ["plot_signal_samples", "plot_pixel_samples", "plot_pixel_pieces"]


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

from .viz_fit import fit_figure, history_frames, mesh_renderer, plot_history, save_fit_gif, save_gif, show_gif
__all__ += ["plot_history", "history_frames", "mesh_renderer", "save_gif", "save_fit_gif", "fit_figure", "show_gif"]
