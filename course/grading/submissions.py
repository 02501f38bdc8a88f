"""Who handed in a notebook, and which lecture it is: the records the grader and the class's exports share.

``Submission`` is one notebook to grade; ``student_of`` reads the student from its path (the folder above it, or
nbgrader's ``submitted/<student>/``); ``_lecture_number`` the NN of its ``NN_`` name. Kept apart from ``grader``
so that the roster, gradebook and copy-flag modules use them without importing the grader (no import cycles).
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Submission", "DuplicateSubmission", "student_of"]


def _lecture_number(path: Path) -> int | None:
    match = re.match(r"(\d+)_", path.name)
    return int(match.group(1)) if match else None


@dataclass(frozen=True)
class Submission:
    """One notebook to grade: ``path`` as given, ``student`` who handed it in (``student_of``, or the path
    itself when every notebook stands alone), ``lecture`` the NN of its ``NN_`` name (None: no tasks, not run)."""
    path: Path
    student: str
    lecture: int | None


class DuplicateSubmission(ValueError):
    """Two notebooks of one student and lecture: which of them counts is the teaching assistant's call."""


def student_of(path) -> str:
    """Who handed in ``path``: ``<student>`` in nbgrader's ``.../submitted/<student>/<assignment>/NN_x.ipynb``,
    otherwise the folder above the notebook (``class/<student>/03_rasterization.ipynb``)."""
    parts = Path(os.path.abspath(path)).parts
    if len(parts) >= 4 and parts[-4] == "submitted":
        return parts[-3]
    return parts[-2] if len(parts) >= 2 else str(path)
