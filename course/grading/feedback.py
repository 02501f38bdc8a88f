"""Feedback to return to each student: ``grade … --feedback DIR`` writes one Markdown file per notebook.

``DIR/<student>/<notebook>.md`` (the student as the roster's submission key, else the folder the notebook came
from) holds the notebook's total, each task's points in a table, the late penalty if there was one (raw and
after), and for every task that lost points the grader's diagnoses, one bullet each: the same words the check
cell prints, so the student can act on them. Copy flags never appear here: they are for the teaching assistant.
"""
from __future__ import annotations

import re
from pathlib import Path

from .late import LatePolicy
from .registry import _diagnoses

__all__ = ["feedback_text", "write_feedback", "feedback_path"]


def _markdown(text: str) -> str:
    """Text as Markdown shows it literally: ``*``, ``<``, ``|`` and backslashes escaped (backticks kept, since
    the grader's messages quote code in them)."""
    return re.sub(r"([\\*<|])", r"\\\1", text)


def _safe(name: str) -> str:
    """A file or folder name from a student key or a path: letters, digits, ``-``, ``_`` and ``.`` kept."""
    return re.sub(r"[^\w.-]+", "_", name).strip("._") or "student"


def feedback_path(folder, mark) -> Path:
    """Where ``mark``'s feedback goes: ``folder/<student>/<notebook stem>.md``."""
    return Path(folder) / _safe(mark.key) / f"{mark.submission.path.stem}.md"


def feedback_text(mark, policy: LatePolicy | None = None) -> str:
    """The Markdown feedback of one graded notebook (a ``gradebook.Mark``)."""
    who = mark.student.name if mark.student else mark.key
    lines = [f"# {mark.submission.path.stem}: {mark.points}/{mark.max_points}", "",
             f"{_markdown(who)}, notebook `{mark.submission.path.name}`", ""]
    if mark.late is not None and mark.late.late:
        rule = f" ({policy.rule()})" if policy else ""
        lines += [f"**Late:** handed in {mark.late.days_late:.2f} days after your due date, "
                  f"{mark.late.due.isoformat(timespec='minutes')}{rule}. Score after the penalty: "
                  f"{mark.points} x {mark.late.factor:.2f} = **{mark.final:g}** of {mark.max_points}.", ""]
    lines += ["| task | function | points |", "| --- | --- | --- |"]
    lines += [f"| {r.task} | `{r.name}` | {r.points}/{r.max_points} |" for r in mark.results]
    lost = [r for r in mark.results if r.points < r.max_points]
    if lost:
        lines += ["", "## What to fix", ""]
        for r in lost:
            lines += [f"### Task {r.task} `{r.name}`: {r.points}/{r.max_points}", ""]
            lines += [f"- {_markdown(d)}" for d in _diagnoses(r.message or "no reason given", r.name)] + [""]
    else:
        lines += ["", "Every task scored full marks."]
    return "\n".join(lines).rstrip() + "\n"


def write_feedback(folder, marks, policy: LatePolicy | None = None) -> list[Path]:
    """Write ``feedback_text`` of each mark under ``folder``; the paths written, in the order of ``marks``."""
    written = []
    for mark in marks:
        path = feedback_path(folder, mark)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(feedback_text(mark, policy), encoding="utf-8")
        written.append(path)
    return written
