"""Figures of lecture 07: soft shadows on a receiver, with the casters painted so they stand out. Part of
``course.viz``, which re-exports them."""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize, to_rgb
from matplotlib.patches import Patch

from .core import show_image, to_numpy

__all__ = ["lit_fraction_grid"]

CASTER_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:red")
BACKGROUND = "#b9c9d9"                     # neither black (umbra) nor white (lit) nor a caster's colour


def lit_fraction_grid(fractions, labels, titles=None, casters=(), size: float = 3.0):
    """Lit fractions on a receiver, in grey (0 black: umbra, 1 white: lit), beside each other, with the
    objects that cast the shadows painted in solid colours and the background in pale blue, so a white caster
    never melts into a lit, white ground.

    fractions: list of (H, W) images in [0, 1] (read where ``labels`` is 0). labels: (H, W) int: 0 on the
    receiver, k >= 1 on caster k (painted ``CASTER_COLOURS[k - 1]``), -1 where nothing is seen. casters: the
    casters' names, for the legend. Returns the figure."""
    lab = to_numpy(labels).astype(np.int64)
    n = len(fractions)
    fig, axes = plt.subplots(1, n, figsize=(size * n + 1.6, size), squeeze=False)
    for k, ax in enumerate(axes.flat):
        f = np.clip(to_numpy(fractions[k]).astype(np.float64), 0, 1)
        rgb = np.repeat(np.where(lab == 0, f, 0.0)[..., None], 3, axis=2)   # (H, W, 3) grey on the receiver
        rgb[lab < 0] = to_rgb(BACKGROUND)
        for c in range(1, int(lab.max(initial=0)) + 1):
            rgb[lab == c] = to_rgb(CASTER_COLOURS[(c - 1) % len(CASTER_COLOURS)])
        show_image(rgb, titles[k] if titles else None, ax=ax, srgb=False)
    fig.colorbar(ScalarMappable(Normalize(0, 1), "gray"), ax=list(axes.flat), fraction=0.046 / n * 2, pad=0.02,
                 label="lit fraction (receiver)")
    handles = [Patch(color=CASTER_COLOURS[k % len(CASTER_COLOURS)], label=name) for k, name in enumerate(casters)]
    handles.append(Patch(color=BACKGROUND, label="background"))
    axes[0, 0].legend(handles=handles, fontsize=7, loc="upper left", framealpha=0.9)
    return fig
