"""The class list: who handed in each submission, their ids for the gradebooks, and their extensions.

``grade … --roster roster.csv`` reads a CSV with a header row. Required columns:

    submission   the submission's folder (``class/<submission>/03_rasterization.ipynb``, or nbgrader's
                 ``submitted/<submission>/...``) or the notebook's file name (``03_rasterization_ada.ipynb``)
    name         the student's name as the gradebook shows it (Canvas: "Student")
    id           the student's id number (Canvas: "SIS User ID"; Moodle: "ID number")
    email        (Moodle can match students by email instead of id number)

Optional columns: ``section``; ``canvas_id`` (Canvas's own user id, its "ID" column); ``login`` (Canvas's "SIS
Login ID"); ``extension_days`` (days added to the due date for this student, e.g. ``2`` or ``0.5``);
``submitted`` (when the student handed in, ISO 8601 such as ``2025-03-14T23:10``, e.g. from the LMS's export;
without it the notebook file's modification time is used). Column names are matched without regard to case or
surrounding spaces; other columns are ignored.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from .submissions import student_of

__all__ = ["Student", "RosterError", "REQUIRED", "OPTIONAL", "read_roster", "find_student", "parse_time"]

REQUIRED = ("submission", "name", "id", "email")
OPTIONAL = ("section", "canvas_id", "login", "extension_days", "submitted")


class RosterError(ValueError):
    """The roster cannot be used as it is; the message names the file, the row and what to change."""


@dataclass(frozen=True)
class Student:
    """One row of the roster (see the module docstring); ``submitted`` is None when the roster does not say."""
    submission: str
    name: str
    id: str
    email: str
    section: str = ""
    canvas_id: str = ""
    login: str = ""
    extension_days: float = 0.0
    submitted: datetime | None = None


def parse_time(text: str, what: str) -> datetime:
    """An ISO 8601 time as an aware datetime: ``2025-03-14T23:59``, ``2025-03-14 23:59:30+01:00``, ``...Z``. No
    offset means local time; a date alone means the end of that day (23:59:59). ``ValueError`` names ``what``."""
    text = text.strip()
    try:
        moment = datetime.fromisoformat(text[:-1] + "+00:00" if text.endswith(("Z", "z")) else text)
    except ValueError:
        raise ValueError(f"{what} {text!r} is not a date and time: write it as 2025-03-14 or 2025-03-14T23:59 "
                         "(ISO 8601; local time unless it ends with an offset such as +01:00 or Z)") from None
    if len(text) == 10:                                         # a date alone: due by the end of that day
        moment = moment.replace(hour=23, minute=59, second=59)
    return moment.astimezone() if moment.tzinfo is None else moment


def _columns(header: list[str], path: Path) -> dict[str, int]:
    """Column name -> index, for the known columns; ``RosterError`` naming any required one that is missing."""
    index = {name.strip().lower(): k for k, name in reversed(list(enumerate(header)))}
    missing = [name for name in REQUIRED if name not in index]
    if missing:
        found = ", ".join(repr(h) for h in header) or "none"
        raise RosterError(f"{path}: no column {', '.join(repr(m) for m in missing)} (its columns: {found}). A roster "
                          f"needs {', '.join(REQUIRED)} and may have {', '.join(OPTIONAL)}")
    return {name: index[name] for name in REQUIRED + OPTIONAL if name in index}


def _student(cells: dict[str, str], where: str) -> Student:
    """One row's cells (column -> text) as a Student; ``RosterError`` for an empty key or a bad number or time."""
    for name in ("submission", "name"):
        if not cells.get(name):
            raise RosterError(f"{where}: the {name} column is empty")
    try:
        extension = float(cells.get("extension_days") or 0)
    except ValueError:
        raise RosterError(f"{where}: extension_days {cells['extension_days']!r} is not a number of days") from None
    if not extension >= 0:
        raise RosterError(f"{where}: extension_days must be 0 or more, got {cells['extension_days']!r}")
    try:
        submitted = parse_time(cells["submitted"], "submitted") if cells.get("submitted") else None
    except ValueError as err:
        raise RosterError(f"{where}: {err}") from None
    return Student(cells["submission"], cells["name"], cells.get("id", ""), cells.get("email", ""),
                   cells.get("section", ""), cells.get("canvas_id", ""), cells.get("login", ""), extension, submitted)


def read_roster(path) -> dict[str, Student]:
    """The roster at ``path``, keyed by its ``submission`` column. ``RosterError`` (a ``ValueError``) names what is
    wrong: no such file, a missing column, an empty key, a submission listed twice, a bad number or time."""
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:             # -sig: Excel's byte-order mark
            rows = list(csv.reader(f))
    except OSError as err:
        raise RosterError(f"cannot read the roster {path}: {err.strerror or err}") from None
    if not rows:
        raise RosterError(f"{path} is empty: a roster needs a header row ({', '.join(REQUIRED)}, ...) and one row "
                          "per student")
    columns = _columns(rows[0], path)
    roster: dict[str, Student] = {}
    line_of_id: dict[str, int] = {}
    for number, row in enumerate(rows[1:], start=2):
        if not any(cell.strip() for cell in row):
            continue                                                         # blank lines at the end
        cells = {name: row[k].strip() if k < len(row) else "" for name, k in columns.items()}
        student = _student(cells, f"{path}, line {number}")
        if student.submission in roster:
            raise RosterError(f"{path}, line {number}: submission {student.submission!r} is listed twice")
        if student.id and line_of_id.setdefault(student.id, number) != number:
            raise RosterError(f"{path}, line {number}: id {student.id!r} is on line {line_of_id[student.id]} too: one "
                              "row per student")
        roster[student.submission] = student
    return roster


def find_student(roster: dict[str, Student], key: str, path: Path) -> Student | None:
    """The roster row of a submission: by its student key, else the folder it is in (``grader.student_of``), else
    the notebook's file name, else its path as given; None when the roster has none of them."""
    for candidate in (key, student_of(path), Path(path).name, str(path)):
        if candidate in roster:
            return roster[candidate]
    return None
