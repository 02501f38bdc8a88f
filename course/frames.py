"""Images as frames: an image tensor as an 8-bit RGB frame the way the course shows it, and frames as a GIF.

The fits' animations (``course.viz.fit``) and shadow art's (``course.shadows.art``) are written with these.
They live apart from ``course.viz.fit`` (which re-exports both) because they need nothing of the renderer: a module
that only writes pictures can use them without importing ``render``.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

__all__ = ["GIF_MIN_SIDE", "image_to_frame", "save_gif"]

GIF_MIN_SIDE = 128           # save_gif's default scale enlarges small frames (64² fits) to at least this side


def _numpy(x) -> np.ndarray:
    """A tensor (any device, any grad state) or array → numpy array."""
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().numpy()
    return np.asarray(x)


def image_to_frame(image, *, srgb: bool = True, name: str = "image") -> np.ndarray:
    """One image → an (H, W, 3) uint8 frame, shown the way ``course.viz.show_image`` shows it.

    image: (H, W) or (H, W, 1) (a silhouette or another quantity in [0, 1]: grey, clipped, never encoded),
    (H, W, 3) or (H, W, 4) linear colours (clipped to [0, 1]; encoded to sRGB unless ``srgb=False``; alpha is
    dropped), or a uint8 (H, W) / (H, W, 3) / (H, W, 4) image, already encoded, which passes through.
    name: how an error message calls the image.
    """
    a = _numpy(image)
    if a.ndim == 3 and a.shape[-1] == 1:
        a = a[..., 0]
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[-1] in (3, 4))):
        raise ValueError(f"{name} must be an image (H, W), (H, W, 1), (H, W, 3) or (H, W, 4), got shape {a.shape}")
    if a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"{name} is empty (shape {a.shape})")
    if a.ndim == 3:
        a = a[..., :3]
    if a.dtype == np.uint8:
        return np.ascontiguousarray(np.repeat(a[..., None], 3, axis=-1) if a.ndim == 2 else a)
    if a.dtype == np.bool_ or np.issubdtype(a.dtype, np.integer):
        a = a.astype(np.float64)
    if not np.issubdtype(a.dtype, np.floating):
        raise ValueError(f"{name} must hold numbers, got dtype {a.dtype}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} contains NaN or inf")
    a = np.clip(a.astype(np.float64), 0.0, 1.0)
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=-1)                              # grey: the value in every channel
    elif srgb:
        from .shading import linear_to_srgb
        a = linear_to_srgb(torch.from_numpy(a)).numpy()
    return (a * 255 + 0.5).astype(np.uint8)


def save_gif(frames, path, *, fps: float = 8, loop: int = 0, labels=None, scale: int | None = None) -> Path:
    """Write ``frames`` as an animated GIF (Pillow). Returns the path (a ``pathlib.Path``).

    frames: a non-empty list of images of one size: (H, W, 3) uint8 frames (``history_frames``) or any image
        ``image_to_frame`` takes (float images are converted the same way).
    fps: frames per second (each frame lasts ``round(1000 / fps)`` ms). loop: 0 loops forever, n plays n + 1 times.
    labels: None, or one string per frame (e.g. ``[f"step {s}" for s in history.snapshot_steps]``), drawn in
        the top-left corner with Pillow's default font, black on a white box.
    scale: an integer enlargement (nearest neighbour, pixels stay square); None: the smallest that makes the
        shorter side at least ``GIF_MIN_SIDE`` (128) pixels, so a 64² fit and its label stay readable.

    GIF stores at most 256 colours per frame (Pillow picks them per frame), and Pillow merges consecutive
    identical frames into one longer frame, so a converged fit may read back with fewer frames.
    """
    from PIL import Image, ImageDraw
    if isinstance(frames, (str, bytes)) or not hasattr(frames, "__len__") or len(frames) == 0:
        raise ValueError("frames must be a non-empty list of images")
    frames = [image_to_frame(f, name=f"frame {k}") for k, f in enumerate(frames)]
    for k, f in enumerate(frames):
        if f.shape != frames[0].shape:
            raise ValueError(f"frames of mixed shapes: frame 0 is {frames[0].shape[:2]}, frame {k} {f.shape[:2]}")
    if isinstance(fps, bool) or not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive number, got {fps!r}")
    if isinstance(loop, bool) or not (isinstance(loop, int) and loop >= 0):
        raise ValueError(f"loop must be a non-negative integer, got {loop!r}")
    if labels is not None and (isinstance(labels, str) or len(labels) != len(frames)):
        raise ValueError(f"labels must be None or one string per frame ({len(frames)}), got {labels!r}")
    H, W = frames[0].shape[:2]
    if scale is None:
        scale = max(1, math.ceil(GIF_MIN_SIDE / min(H, W)))
    if isinstance(scale, bool) or not (isinstance(scale, int) and scale >= 1):
        raise ValueError(f"scale must be a positive integer or None, got {scale!r}")
    images = []
    for k, f in enumerate(frames):
        im = Image.fromarray(np.repeat(np.repeat(f, scale, axis=0), scale, axis=1), mode="RGB")
        if labels is not None and str(labels[k]):
            draw = ImageDraw.Draw(im)
            box = draw.textbbox((3, 2), str(labels[k]))
            draw.rectangle((box[0] - 2, box[1] - 1, box[2] + 2, box[3] + 1), fill=(255, 255, 255))
            draw.text((3, 2), str(labels[k]), fill=(0, 0, 0))
        images.append(im)
    path = Path(path)
    images[0].save(path, format="GIF", save_all=True, append_images=images[1:], duration=round(1000 / fps),
                   loop=loop)
    return path
