"""Lecture 13's explorer: the shipped reconstruction network's mesh against its target, from a view you turn.

``draw_reconstruction_view(family, azimuth, elevation)`` takes the first test shape of a family (the torus from
the held-out split), the mesh the shipped network (``load_pretrained_reconstructor``, run in float64) predicts
from its view-0 image (azimuth 0°, 30° up; the network was trained on inputs from any of the 24 views, the
explorer always shows it this one), and draws both hard
silhouettes from a camera at (azimuth, elevation), 3.2 units away with a 40° field of view as in the data
(``learning.data.view_cameras``), at 64 × 64 pixels:

* left: the overlap, grey where both cover a pixel, red where only the network does (too big), blue where only
  the target does (missed);
* right: the silhouette IoU against the azimuth at this elevation (every 30°), the azimuths of the 24 views the
  network was trained on marked along the bottom (they sit 30° up), the input view a line, the current view a dot.

The line it prints (``"line"``, also written under the figure, so it follows the controls): the view, its silhouette
IoU, the network's pixels over the target's (a ratio of areas: 1 can still miss many of the target's pixels), the
share of the target's pixels the network covers, and the network mesh's volume over the target's (voxels at 32³,
``learning.data.voxelize``). Every number is float64. The shapes, the network's meshes, their volumes and each
IoU curve are computed once and kept; a redraw rasterizes two meshes of a few hundred faces at 64²; it redraws
when a control is released, its controls greyed out meanwhile (``python -m course bench explorers --only 13`` times it).
"""
from __future__ import annotations

import math
from functools import cache

import matplotlib.pyplot as plt
import numpy as np
import torch

from . import explorers as _explorers
from .core import show_image

__all__ = ["reconstruction_view_explorer", "draw_reconstruction_view", "VIEW_FAMILIES"]

F64 = torch.float64
VIEW_FAMILIES = ("torus", "box", "cylinder", "cone", "capsule", "vase", "star")   # the first is the default
VIEW_SIZE = 64                  # pixels a side of the explorer's views (the data's are 32)
CURVE_STEP = 30.0               # degrees between the azimuths of the IoU curve
TRAINING_VIEWS = 24             # the views the shipped network was trained with (bench learn: views=24)
ELEVATION = 30.0                # the data's cameras sit this far above the horizon
GOLDEN = 180.0 * (3 - math.sqrt(5))                                        # degrees, ≈ 137.5°


@cache
def _shape(family: str):
    """(target Mesh, predicted Mesh, target volume, predicted volume in voxels at 32³) of the family's first
    test shape (the torus: held out), float64."""
    from ..learning.data import make_dataset, voxelize
    from ..mesh import Mesh
    split = "held_out" if family == "torus" else "test"
    data = make_dataset(1, families=(family,), split=split, views=1, size=32, dtype=F64)
    model = _model()
    with torch.no_grad():
        verts = model(data.images[:, 0])[0]
    target, predicted = data.meshes[0], Mesh(verts, model.faces)
    return target, predicted, int(voxelize(target, 32).sum()), int(voxelize(predicted, 32).sum())


@cache
def _model():
    from ..learning.reconstruction import load_pretrained_reconstructor
    return load_pretrained_reconstructor().double()


def _camera(azimuth: float, elevation: float):
    from ..camera import Camera
    a, e = math.radians(azimuth), math.radians(elevation)
    eye = (3.2 * math.cos(e) * math.sin(a), 3.2 * math.sin(e), 3.2 * math.cos(e) * math.cos(a))
    up = (0.0, 1.0, 0.0) if abs(elevation) < 89.0 else (-math.sin(a), 0.0, -math.cos(a))   # straight down: the
    return Camera.look_at(eye, (0.0, 0.0, 0.0), up, fov_y=40.0, width=VIEW_SIZE, height=VIEW_SIZE,
                          dtype=F64)                                      # far side of the shape at the top


def _masks(family: str, azimuth: float, elevation: float):
    """(target, network) hard silhouettes (H, W) bool from the camera at (azimuth, elevation) degrees."""
    from ..raster import rasterize
    target, predicted, _, _ = _shape(family)
    camera = _camera(azimuth, elevation)
    return rasterize(target, camera).mask, rasterize(predicted, camera).mask


def _iou(a: torch.Tensor, b: torch.Tensor) -> float:
    union = int((a | b).sum())
    return 1.0 if union == 0 else int((a & b).sum()) / union


@cache
def _curve(family: str, elevation: float):
    """(azimuths (K,), IoU (K,)) every ``CURVE_STEP`` degrees from -180 to 180 at this elevation."""
    azimuths = np.arange(-180.0, 180.0 + CURVE_STEP / 2, CURVE_STEP)
    return azimuths, np.array([_iou(*_masks(family, float(a), elevation)) for a in azimuths])


def draw_reconstruction_view(family: str = "torus", azimuth: float = 0.0, elevation: float = 90.0) -> dict:
    """The network's mesh and its target seen from (``azimuth``, ``elevation``) degrees: their silhouettes
    overlaid (grey both, red only the network's, blue only the target's) and the silhouette IoU along the
    azimuth at this elevation, the 24 training views' azimuths marked.

    It opens on the held-out torus seen from straight above, a view no training silhouette came from (a
    deformed sphere cannot open the hole, so any network pixel inside it is red). Turn the view: azimuth 0°,
    30° up is the image the network read; every other view shows what it inferred. Returns the view's IoU, the pixel ratio (network's pixels over the target's), the share of
    the target's pixels the network covers, the volume ratio and the line.
    """
    family = _explorers._check_choice("family", family, VIEW_FAMILIES)
    azimuth = float(_explorers._check_range("azimuth", azimuth, -180.0, 180.0))
    elevation = float(_explorers._check_range("elevation", elevation, -60.0, 90.0))
    target, network = _masks(family, azimuth, elevation)
    iou = _iou(target, network)
    pixels = int(network.sum()) / max(int(target.sum()), 1)
    covered = int((network & target).sum()) / max(int(target.sum()), 1)
    _, _, target_volume, network_volume = _shape(family)
    volume = network_volume / max(target_volume, 1)
    azimuths, curve = _curve(family, elevation)
    overlay = torch.ones(VIEW_SIZE, VIEW_SIZE, 3, dtype=F64)              # white background
    overlay[target & network] = torch.tensor([0.35, 0.35, 0.35], dtype=F64)
    overlay[network & ~target] = torch.tensor([0.84, 0.15, 0.16], dtype=F64)   # only the network: too big
    overlay[target & ~network] = torch.tensor([0.12, 0.47, 0.71], dtype=F64)   # only the target: missed
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 4.0), gridspec_kw=dict(width_ratios=[1.0, 1.4]))
    show_image(overlay, f"{family}: azimuth {azimuth:g}°, elevation {elevation:g}°\nIoU {iou:.3f}", ax=axes[0],
               srgb=False)
    axes[0].legend(handles=[plt.Rectangle((0, 0), 1, 1, color=c) for c in ("0.35", "#d62728", "#1f77b4")],
                   labels=["both", "network only", "target only"], loc="lower center", fontsize=7, ncol=3,
                   bbox_to_anchor=(0.5, -0.14), frameon=False)
    ax = axes[1]
    ax.plot(azimuths, curve, marker=".", color="tab:purple", label=f"silhouette IoU at {elevation:g}° up")
    trained = [((k * GOLDEN + 180.0) % 360.0) - 180.0 for k in range(TRAINING_VIEWS)]
    ax.axvline(trained[0], color="tab:orange", ls=":", lw=1.0, label="input view 0 (30° up)")
    ax.plot(trained, [0.02] * len(trained), "^", color="tab:green", ms=4, ls="none",
            label=f"the {TRAINING_VIEWS} training views' azimuths (30° up)")
    ax.plot([azimuth], [iou], "o", color="tab:red", label="this view")
    ax.set_xlim(-180, 180), ax.set_ylim(0, 1), ax.set_xticks(range(-180, 181, 60))
    ax.set_xlabel("azimuth (degrees)"), ax.set_ylabel("IoU of the silhouettes")
    ax.set_title(f"network mesh volume / target's {volume:.2f}", fontsize=10)
    ax.legend(fontsize=7, loc="lower left")
    line = (f"{family}, azimuth {azimuth:g} deg, elevation {elevation:g} deg: silhouette IoU {iou:.3f}, network "
            f"pixels / target's {pixels:.2f}, target's pixels covered {covered:.2f}; network volume / target's "
            f"{volume:.2f}")
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    fig.text(0.5, 0.01, line, ha="center", va="bottom", fontsize=9)        # the printed line, for these values
    return dict(iou=iou, pixels=pixels, covered=covered, volume=volume, line=line)


def reconstruction_view_explorer() -> None:
    """Lecture 13: the shipped network's mesh against its target from a view you turn, with the IoU per view."""
    _explorers._show(draw_reconstruction_view)


_explorers.EXPLORERS["13 reconstruction views"] = (
    reconstruction_view_explorer, draw_reconstruction_view,
    dict(family=list(VIEW_FAMILIES), azimuth=(-180.0, 180.0, 15.0, 0.0), elevation=(-60.0, 90.0, 15.0, 90.0)),
    False)                      # redrawn on release: a new family or elevation computes its shapes and IoU curve
