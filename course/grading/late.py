"""Due dates and the late penalty: ``grade … --due 2025-03-14T23:59 [--late-days 7]``.

A submission is late by the time between its student's due date (``--due`` plus the roster's
``extension_days``) and when it was handed in: the roster's ``submitted`` column where it has one, otherwise the
notebook file's modification time (copying files with ``cp -p``, ``rsync -t`` or an LMS's zip keeps it; a plain
``cp`` does not, so say ``submitted`` in the roster when in doubt). The penalty is linear: a submission ``d`` days
late keeps ``1 - d / N`` of its points (``N = --late-days``), nothing from N days on; ``--late-days 0`` gives a late
submission nothing. The raw score is always kept and shown beside the one after the penalty, never replaced
silently.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path

from .roster import Student, parse_time

__all__ = ["LatePolicy", "Lateness", "lateness", "parse_due"]

_DAY = 86400.0                                                    # seconds


@dataclass(frozen=True)
class LatePolicy:
    """The due date of everyone without an extension, and ``days``, over which the points decay to 0."""
    due: datetime
    days: float = 7.0

    def factor(self, days_late: float) -> float:
        """The share of points a submission ``days_late`` days late keeps: 1 on time, falling linearly to 0."""
        if days_late <= 0:
            return 1.0
        if self.days <= 0:
            return 0.0
        return max(0.0, 1.0 - days_late / self.days)

    def rule(self) -> str:
        """The penalty in words: "a submission d days late keeps 1 - d/7 of its points, none from 7 days on"."""
        if self.days <= 0:
            return "a late submission scores 0"
        return f"a submission d days late keeps 1 - d/{self.days:g} of its points, none from {self.days:g} days on"

    def describe(self) -> str:
        return f"due {self.due.isoformat(timespec='minutes')}; {self.rule()}"


@dataclass(frozen=True)
class Lateness:
    """When one submission came in against its student's due date. ``source``: "roster" or "file time";
    ``days_late`` > 0 when late (negative: early); ``factor``: the share of points kept."""
    submitted: datetime
    source: str
    due: datetime
    days_late: float
    factor: float

    @property
    def late(self) -> bool:
        return self.days_late > 0


def parse_due(text: str) -> datetime:
    """``--due``'s value as an aware datetime; ``ValueError`` saying how to write it."""
    return parse_time(text, "--due")


def lateness(policy: LatePolicy, path, student: Student | None) -> Lateness:
    """How late the notebook at ``path`` is, for ``student`` (None: not on the roster, no extension)."""
    if student is not None and student.submitted is not None:
        submitted, source = student.submitted, "roster"
    else:
        stamp = os.stat(Path(path)).st_mtime
        submitted, source = datetime.fromtimestamp(stamp, tz=timezone.utc).astimezone(), "file time"
    due = policy.due + timedelta(days=student.extension_days if student is not None else 0.0)
    days_late = (submitted - due).total_seconds() / _DAY
    return Lateness(submitted, source, due, days_late, policy.factor(days_late))
