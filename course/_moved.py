"""Old module paths that moved into folders: they still import, with a warning that names the new place.

Notebooks from earlier terms say ``from course.shadow_gradients import ...``; since the modules were grouped
into folders (``course.shadows``, ...), that import finds the module at its new path and warns once::

    FutureWarning: course.shadow_gradients moved to course.shadows.gradients: import it from there

It is the same module object under both names, so a function imported either way is the same function (the
graders compare functions by identity). ``MOVED`` lists every old path and its new one.
"""
from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

__all__ = ["MOVED"]

MOVED = {
    "course.shadow_gradients": "course.shadows.gradients",
    "course.prefiltered_shadows": "course.shadows.prefiltered",
    "course.shadow_fit": "course.shadows.fit",
    "course.shadow_art": "course.shadows.art",
    "course.stylize": "course.style.transfer",
    "course.shapes": "course.learning.shapes",
    "course.shape_data": "course.learning.data",
    "course.learn": "course.learning.reconstruction",
    "course.mvtn": "course.learning.mvtn",
    "course.viz_fit": "course.viz.fit",
    "course.fit": "course.inverse",
    "course.losses": "course.inverse.losses",
    "course.large_steps": "course.inverse.large_steps",
    "course.carve": "course.inverse.carve",
    "course.shape_metrics": "course.inverse.metrics",
    "course.fit_texture": "course.inverse.texture",
    "course.fit_views": "course.inverse.views",
}


class _Alias(importlib.abc.Loader):
    def __init__(self, new: str):
        self.new = new
        self.spec = None

    def create_module(self, spec):
        module = importlib.import_module(self.new)
        self.spec = module.__spec__
        return module

    def exec_module(self, module):                                          # already run under its new name;
        module.__spec__ = self.spec                                         # keep its own spec (import set the alias')


class _MovedFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path=None, target=None):
        new = MOVED.get(fullname)
        if new is None:
            return None
        warnings.warn(f"{fullname} moved to {new}: import it from there", FutureWarning, stacklevel=3)
        return importlib.util.spec_from_loader(fullname, _Alias(new))


def install() -> None:
    if not any(isinstance(f, _MovedFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _MovedFinder())                           # before any path finder
