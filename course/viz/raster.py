"""Figures of lectures 03-04: rasters, edge functions, clipping, z-buffer keys, curves. Part of ``course.viz``,
which re-exports them."""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from .core import pixel_grid, plot_triangles_2d, show_image, signed_image, to_numpy

__all__ = ["plot_raster", "plot_curves"]


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
