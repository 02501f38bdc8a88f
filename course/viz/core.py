"""The figures every lecture uses: images, grids, depth, 3D points and meshes, pixel grids, and the explorer
(sliders with a static fallback). Part of ``course.viz``, which re-exports them."""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import torch

from ..tensors import _check_count

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


def _control(widgets, name, spec, continuous):
    """The widget of one explorer parameter (see ``explorer``), with the bounded width every control shares."""
    common = dict(description=name, style={"description_width": "90px"},
                  layout=widgets.Layout(width="100%", min_width="360px", max_width="560px"))
    if isinstance(spec, bool):
        return widgets.Checkbox(value=spec, indent=False, **common)
    if isinstance(spec, list):
        return widgets.Dropdown(options=spec, value=spec[0], **common)
    lo, hi, step, default = spec
    integer = all(isinstance(v, int) and not isinstance(v, bool) for v in spec)
    kind = widgets.IntSlider if integer else widgets.FloatSlider
    return kind(value=default, min=lo, max=hi, step=step, continuous_update=continuous, **common)


def _check_control(name, spec):
    if isinstance(spec, bool):
        return spec
    if isinstance(spec, list):
        if not spec:
            raise ValueError(f"control {name!r}: a list of options must not be empty")
        return spec[0]
    if not isinstance(spec, tuple) or len(spec) != 4:
        raise ValueError(f"slider {name!r}: expected (min, max, step, default), got {spec!r}")
    lo, hi, _, default = spec
    if not lo <= default <= hi:
        raise ValueError(f"slider {name!r}: default {default} lies outside [{lo}, {hi}]")
    return default


def _png(fig) -> str:
    import base64
    import io
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", bbox_inches="tight")
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def explorer(draw, *, figure_scale: float = 1.5, still: bool = False, **sliders) -> None:
    """An ipywidgets explorer: ``draw(**values)`` redraws a figure whenever a control moves.

    ``sliders`` maps a parameter name to its control: ``(min, max, step, default)`` a slider (an integer
    slider when all four are ints), ``True`` / ``False`` a checkbox, a list of options a drop-down whose
    first option is the default. Costly redraws should set ``draw.continuous_update = False``: the picture is
    then redrawn when a slider is released, and the controls are greyed out (disabled) while it is drawn, so
    the explorer shows that it is working and no backlog of redraws can pile up. (While a slider is dragged,
    the front end sends a new value only once the kernel is idle again, skipping the values in between, so a
    live redraw that is slower than the drag lags but never queues.)

    The controls are stacked, one per row, each as wide as the notebook allows between 360 and 560 px (a 90-px
    name, the track, the readout), so a track stays 200-370 px long in any window (JupyterLab at 1024 px with
    the file browser open gives 560); the picture sits below them. The figures ``draw`` makes are drawn at
    ``figure_scale`` times matplotlib's resolution, so a 4-inch figure is about 600 px wide. A notebook opened
    without widget state (saved outputs, an untrusted notebook) shows a one-line note instead of the widget's
    repr; with ``still=True`` the first picture (the defaults) travels with it as a PNG, which a viewer
    without widgets (nbval, nbconvert, a web page) shows instead. Without ipywidgets it draws once with the
    defaults, so the notebook still reads well. Displays the widget itself and returns None (so a cell ending
    in ``explorer(...)`` does not show it twice).
    """
    defaults = {name: _check_control(name, spec) for name, spec in sliders.items()}
    try:
        import ipywidgets as widgets
        from IPython.display import display
    except ImportError:                                                     # no widgets: a static figure
        draw(**defaults)
        return
    continuous = getattr(draw, "continuous_update", True)
    controls = {name: _control(widgets, name, spec, continuous) for name, spec in sliders.items()}

    def redraw(**values):
        busy = [c for c in controls.values() if not continuous and not c.disabled]
        for c in busy:                                                      # greyed out: drawing
            c.disabled = True
        try:
            with plt.rc_context({"figure.dpi": plt.rcParams["figure.dpi"] * figure_scale}):
                draw(**values)
                plt.show()
        finally:
            for c in busy:
                c.disabled = False

    png = None
    if still:
        # The defaults' picture is drawn here, kept as a PNG and closed: it goes into the widget's own state
        # and into the cell's bundle, never as a display of its own, so a kernel without a widget front end
        # (nbval, nbconvert) sees the same outputs on every run. Later redraws go to the widget only.
        before = set(plt.get_fignums())
        with plt.rc_context({"figure.dpi": plt.rcParams["figure.dpi"] * figure_scale}):
            draw(**defaults)
            new = [n for n in plt.get_fignums() if n not in before]
            if new:
                png = _png(plt.figure(new[-1]))
            for n in new:
                plt.close(n)
        picture = widgets.Output()

        def on_change(_=None):
            with picture:
                picture.clear_output(wait=True)
                redraw(**{name: c.value for name, c in controls.items()})
        for c in controls.values():
            c.observe(on_change, names="value")
        if png is not None:
            import base64
            from IPython.display import Image
            picture.append_display_data(Image(data=base64.b64decode(png), format="png"))
    else:
        picture = widgets.interactive_output(redraw, controls)
    box = widgets.VBox([widgets.VBox(list(controls.values())), picture])
    bundle = box._repr_mimebundle_()
    bundle["text/plain"] = (f"[interactive explorer: sliders {', '.join(sliders)}; run the cell in JupyterLab "
                            f"to use them]")
    if png is not None:
        bundle["image/png"] = png
    display(bundle, raw=True)
