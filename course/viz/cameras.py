"""Figures of lectures 01-02: shapes, voxels, camera frames, pinholes, frustums, image points. Part of
``course.viz``, which re-exports them."""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from ..tensors import _check_count
from .core import _label_axes, plot_mesh_3d, plot_points_3d, to_numpy

__all__ = ["plot_voxels", "plot_camera_frame", "plot_image_points", "fit_view_3d"]


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
    ``focal`` in front of the pinhole at ``x`` (labelled ``x = X/Z`` and the distance ``1`` when ``focal`` is 1,
    the normalised image plane; ``x = f·X/Z`` and ``f`` otherwise). With ``behind`` the real, inverted image at
    ``-focal`` (where a physical sensor sits) is drawn too. ``names`` label the offset's axis pieces (depth,
    offset, image). Returns the axes.
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
    scale, fname = ("", "1") if f == 1 else ("f·", "f")                     # focal 1: the normalised image plane
    ax.annotate(f"{dim} = {scale}{dx}/{dz}", (f, x), textcoords="offset points", xytext=(6, 4), fontsize=10)
    ax.annotate(fname, (f / 2, 0), textcoords="offset points", xytext=(0, -12), fontsize=10, ha="center")
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
