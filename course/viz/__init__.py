"""Figures for the lectures: images, grids, meshes, points, and interactive explorers with a static fallback.

Every function draws with matplotlib (``origin='upper'``: row 0 at the top, as the course's images are stored)
and returns the figure, so a notebook can both show it and pin it with a printed number.

The figures are split by topic: ``core`` (images, grids, 3D points and meshes, the explorer; every lecture),
``cameras`` (lectures 01-02), ``raster`` (03), ``shading`` (04), ``antialias`` (05), ``raytrace`` (07), ``gradients``
(09); a fit's curves and GIFs are in ``course.viz.fit``. Everything is re-exported here:
``from course import viz; viz.show_image(...)``.
"""
from __future__ import annotations

from . import antialias, cameras, core, explorers, gradients, raster, raytrace, shading
from .core import *  # noqa: F401,F403
from .core import DEPTH_CMAP, __all__ as _core_all
from .cameras import *  # noqa: F401,F403
from .raster import *  # noqa: F401,F403
from .shading import *  # noqa: F401,F403
from .antialias import *  # noqa: F401,F403
from .gradients import *  # noqa: F401,F403
from .raytrace import *  # noqa: F401,F403
from .explorers import *  # noqa: F401,F403
from . import learning  # noqa: E402  (lecture 13's explorer; registers itself in explorers.EXPLORERS)
from .learning import *  # noqa: F401,F403

__all__ = (list(_core_all) + cameras.__all__ + raster.__all__ + shading.__all__ + antialias.__all__ + raytrace.__all__
           + gradients.__all__ + explorers.__all__ + learning.__all__)

from .fit import fit_figure, history_frames, mesh_renderer, plot_history, save_fit_gif, save_gif, show_gif
__all__ += ["plot_history", "history_frames", "mesh_renderer", "save_gif", "save_fit_gif", "fit_figure", "show_gif"]
