"""Figures and animations of fits (lecture 10): loss curves, the frames of a fit, GIFs, target | start | result.

Every loop of ``course.inverse`` (and of the texture and multi-view fits) returns a result whose ``.history`` is a
``course.inverse.FitHistory``: the loss at every step, named per-step ``metrics``, and ``snapshots`` taken at
``snapshot_steps``. What a snapshot holds depends on the fit:

* rendered images, (H, W) silhouettes in [0, 1] or (H, W, C) linear colours (a camera fit);
* textures (Ht, Wt, 3), linear colours (a texture fit): shown as images;
* vertices (V, 3) (a mesh fit): they need a ``render(verts) -> image``, e.g. ``mesh_renderer(faces, camera)``.

``history_frames`` turns the snapshots into (H, W, 3) uint8 frames, the way ``course.viz.show_image`` shows
images: an (H, W) image is grey (its values clipped to [0, 1], never gamma-encoded), a colour image is clipped
to [0, 1] and sRGB-encoded (``course.shading.linear_to_srgb``), uint8 images pass through. ``save_gif`` writes
the frames as an animated GIF (Pillow), ``show_gif`` embeds one in a notebook, ``plot_history`` draws the loss
curve and the metrics, and ``fit_figure`` the one-row figure of a fit: the target, the start and the result.

Every figure is drawn with matplotlib (row 0 at the top) and returned, so a notebook can show it and a script
can save and close it.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import torch

__all__ = ["plot_history", "history_frames", "image_to_frame", "mesh_renderer", "save_gif", "save_fit_gif",
           "fit_figure", "show_gif"]

from ..frames import image_to_frame, save_gif       # re-exported: course.frames writes them

# ------------------------------------------------------------------------------------------ helpers

def _numpy(x) -> np.ndarray:
    """A tensor (any device, any grad state) or array → numpy array (``course.viz.to_numpy``; not imported
    from there, so that ``course.viz`` can re-export this module without an import cycle)."""
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().numpy()
    return np.asarray(x)


def _history(history):
    """The FitHistory of ``history``, or of a fit result (anything with ``.history``)."""
    h = getattr(history, "history", history)
    if not all(hasattr(h, name) for name in ("loss", "snapshot_steps", "snapshots", "metrics")):
        raise ValueError("expected a FitHistory (course.inverse) or a fit result with .history, "
                         f"got {type(history).__name__}")
    return h


def _is_vertices(a: np.ndarray) -> bool:
    """A float (V, 3) array: vertices, not an image (a 2-D snapshot with 3 columns is taken for vertices)."""
    return a.ndim == 2 and a.shape[1] == 3 and a.dtype != np.uint8


# ------------------------------------------------------------------------------------------- curves

METRIC_TITLES = {"iou_loss": "silhouette loss (mean over views)", "held_out_psnr": "held-out PSNR (dB)",
                 "held_out_iou": "held-out IoU", "rotation_deg": "rotation error (degrees)",
                 "center_pct": "centre error (% of the distance)"}   # a metric's panel title: readable words


def plot_history(history, *, metrics=None, ax=None, log: bool = True, title: str | None = None):
    """The loss curve of a fit, and its metrics. Returns the figure.

    history: a ``FitHistory`` or a fit result (its ``.history``); ``history.loss`` must not be empty.
    metrics: names in ``history.metrics`` to draw (None: every non-empty one; ``()``: none). Without ``ax``
        the loss and each metric get a panel of their own, side by side (their units differ); with ``ax`` the
        loss is drawn there and the metrics on a twin y axis on the right.
    log: a log-scale loss axis (linear when a loss is <= 0, where a log scale cannot show it).
    title: the loss panel's title.

    The x axis is the step: the loss of step k is the loss before update k; a metric with one more entry
    than the loss (e.g. a camera fit's ``rotation_deg``) also has the final state, at step ``steps``; a
    metric with one entry per snapshot (a texture fit's ``held_out_psnr``) is drawn at ``snapshot_steps``,
    with markers.
    """
    h = _history(history)
    loss = np.asarray(h.loss, dtype=np.float64)
    if loss.size == 0:
        raise ValueError("the history is empty: no loss was recorded (a fit with steps=0?)")
    available = [k for k, v in h.metrics.items() if len(v)]
    if metrics is None:
        metrics = available
    elif isinstance(metrics, str):
        metrics = [metrics]
    for m in metrics:
        if m not in h.metrics or not len(h.metrics[m]):
            raise ValueError(f"unknown or empty metric {m!r}; this history has {available or 'no metrics'}")
    if ax is None:
        n = 1 + len(metrics)
        fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.2), squeeze=False)
        loss_ax, metric_axes = axes[0, 0], list(axes[0, 1:])
    else:
        fig, loss_ax = ax.figure, ax
        metric_axes = [ax.twinx()] * len(metrics) if metrics else []
    loss_ax.plot(np.arange(loss.size), loss, color="C0", lw=1.5, label="loss")
    loss_ax.set_yscale("log" if log and np.all(loss > 0) else "linear")
    loss_ax.set_xlabel("step")
    loss_ax.set_ylabel("loss (log scale)" if loss_ax.get_yscale() == "log" else "loss")
    loss_ax.grid(True, alpha=0.3)
    if title or (ax is None and metrics):
        loss_ax.set_title(title or "loss")
    for k, (m, max_) in enumerate(zip(metrics, metric_axes)):
        values = np.asarray(h.metrics[m], dtype=np.float64)
        at_snapshots = values.size not in (loss.size, loss.size + 1) and values.size == len(h.snapshot_steps)
        steps = np.asarray(h.snapshot_steps) if at_snapshots else np.arange(values.size)
        max_.plot(steps, values, "o-" if at_snapshots else "-", color=f"C{k + 1}", lw=1.5, ms=3, label=m)
        max_.set_xlabel("step")
        if ax is None:
            max_.set_title(METRIC_TITLES.get(m, m.replace("_", " ")))         # a linear axis
            max_.grid(True, alpha=0.3)
    if ax is not None and metrics:
        metric_axes[0].set_ylabel(", ".join(metrics))
        lines = loss_ax.get_lines() + metric_axes[0].get_lines()
        loss_ax.legend(lines, [line.get_label() for line in lines], fontsize=8)
    if ax is None:
        fig.tight_layout()
    return fig


# ------------------------------------------------------------------------------------------- frames

def history_frames(history, render=None, *, srgb: bool = True) -> list:
    """The snapshots of a fit as a list of (H, W, 3) uint8 frames, one per ``history.snapshot_steps``.

    history: a ``FitHistory`` or a fit result (its ``.history``).
    render: None (the snapshots are images: (H, W) silhouettes are grey, (H, W, C) linear colours and
        (Ht, Wt, 3) textures sRGB-encoded, see ``image_to_frame``), or a callable ``render(snapshot) -> image``
        applied to every snapshot first: vertices (V, 3) need one (``mesh_renderer(faces, camera)``), and it
        can show a texture snapshot on its mesh.
    srgb: encode colour images to sRGB (the default; False shows the raw values).

    Raises a ValueError naming the problem for a history without snapshots, vertex snapshots without
    ``render``, and snapshots (or renders) of different sizes, which cannot make one animation.
    """
    h = _history(history)
    if not len(h.snapshots):
        raise ValueError("the history has no snapshots (was the fit run with snapshot_every=None?)")
    if render is not None and not callable(render):
        raise ValueError(f"render must be a callable render(snapshot) -> image, or None, got {type(render).__name__}")
    frames = []
    for k, snap in enumerate(h.snapshots):
        if render is None:
            a = _numpy(snap)
            if _is_vertices(a):
                raise ValueError(f"snapshot {k} holds vertices {a.shape}, not an image: pass render=, e.g. "
                                 "mesh_renderer(faces, camera)")
            image = a
        else:
            image = render(snap)
        frames.append(image_to_frame(image, srgb=srgb, name=f"snapshot {k}"))
        if frames[-1].shape != frames[0].shape:
            raise ValueError(f"snapshots of mixed shapes: snapshot 0 gives a {frames[0].shape[:2]} frame, "
                             f"snapshot {k} a {frames[-1].shape[:2]} one")
    return frames


def mesh_renderer(faces, camera, *, settings=None, lights=None, background=(1.0, 1.0, 1.0), material=None):
    """A ``render(verts) -> image`` for the snapshots of a mesh fit: ``course.render.render``, shaded.

    faces: (F, 3) the fitted mesh's faces (``result.mesh.faces``). camera: the ``Camera`` to see it from.
    settings: a ``course.render.RenderSettings``, or None for ``RenderSettings(shading="phong")`` (e.g.
    ``RenderSettings(antialias="adaptive")`` for smoother edges). lights: None for
    ``course.framing.default_lights()``. background: RGB (3,). material: a ``course.shading.Material`` or None.

    The returned callable takes vertices (V, 3) (drawn with ``faces``) or a whole ``Mesh`` (drawn with its
    own faces, e.g. the target) and returns the (H, W, 3) linear image, without a gradient.
    """
    from ..camera import Camera
    from ..mesh import Mesh
    from ..render import RenderSettings, Scene, default_lights, render
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a course.camera.Camera, got {type(camera).__name__}")
    faces = torch.as_tensor(faces)
    if faces.dim() != 2 or faces.shape[1] != 3:
        raise ValueError(f"faces must be (F, 3), got shape {tuple(faces.shape)}")
    if settings is None:
        settings = RenderSettings(shading="phong")
    elif not isinstance(settings, RenderSettings):
        raise ValueError(f"settings must be a course.render.RenderSettings or None, got {type(settings).__name__}")
    lights = default_lights() if lights is None else tuple(lights)

    def draw(verts):
        if isinstance(verts, Mesh):
            mesh = verts
        else:
            v = torch.as_tensor(verts).detach()
            if v.dim() != 2 or v.shape[1] != 3:
                raise ValueError(f"verts must be (V, 3), got shape {tuple(v.shape)}")
            mesh = Mesh(v, faces.to(v.device))
        with torch.no_grad():
            return render(Scene(mesh, camera, lights=lights, background=background, materials=material), settings).image

    return draw


# --------------------------------------------------------------------------------------------- GIFs

def save_fit_gif(history, path, render=None, *, fps: float = 8, loop: int = 0, labels: bool = True,
                 scale: int | None = None) -> Path:
    """``history_frames`` then ``save_gif``, each frame labelled with its step (``labels=False``: unlabelled).
    history: a ``FitHistory`` or a fit result; render: as in ``history_frames``. Returns the path."""
    h = _history(history)
    frames = history_frames(h, render)
    text = [f"step {s}" for s in h.snapshot_steps] if labels else None
    if text is not None and len(text) != len(frames):
        raise ValueError(f"the history has {len(frames)} snapshots but {len(text)} snapshot_steps")
    return save_gif(frames, path, fps=fps, loop=loop, labels=text, scale=scale)


def show_gif(path):
    """An ``IPython.display.Image`` of the GIF at ``path``, embedded (the notebook keeps it; it plays in
    JupyterLab and on GitHub). Needs IPython (it comes with Jupyter)."""
    from IPython.display import Image
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"no GIF at {path}")
    return Image(data=path.read_bytes(), format="gif")


# -------------------------------------------------------------------------------------------- figure

def fit_figure(target, start, result, *, titles=("target", "start", "result"), captions=None, render=None,
               size: float = 3.0, suptitle: str | None = None, srgb: bool = True):
    """One row of three images: the target, the start and the result of a fit. Returns the figure.

    target, start, result: images ((H, W) silhouettes, (H, W, C) linear colours, textures, uint8 frames), or,
        with ``render``, vertices (V, 3) or Meshes that ``render`` draws (``mesh_renderer(faces, camera)``
        draws both: vertices with its faces, a Mesh with its own). The three may differ in size.
    titles: three titles (or None). captions: None or three strings under the images (e.g. the metric:
        ``f"IoU {r.iou:.3f}"``). size: inches per panel. suptitle: a title over the row.
    """
    items = (target, start, result)
    for name, seq in (("titles", titles), ("captions", captions)):
        if seq is not None and (isinstance(seq, str) or len(seq) != 3):
            raise ValueError(f"{name} must be None or three strings, got {seq!r}")
    frames = []
    for name, item in zip(("target", "start", "result"), items):
        a = item if hasattr(item, "faces") else _numpy(item)
        if render is not None and (hasattr(item, "faces") or _is_vertices(a)):
            a = render(item)
        elif hasattr(item, "faces") or _is_vertices(a):
            raise ValueError(f"{name} is a mesh or vertices {getattr(a, 'shape', '')}, not an image: pass render=, "
                             "e.g. mesh_renderer(faces, camera)")
        frames.append(image_to_frame(a, srgb=srgb, name=name))
    fig, axes = plt.subplots(1, 3, figsize=(3 * size, size + (0.3 if captions else 0.0)))
    for k, (ax, f) in enumerate(zip(axes, frames)):
        ax.imshow(f, interpolation="nearest", extent=(0, f.shape[1], f.shape[0], 0))
        ax.set_xticks([]), ax.set_yticks([])
        if titles is not None:
            ax.set_title(titles[k])
        if captions is not None:
            ax.set_xlabel(captions[k])
    if suptitle:
        fig.suptitle(suptitle)
    fig.tight_layout()
    return fig
