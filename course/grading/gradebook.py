"""From one grading run to the tools a course runs on: a roster, due dates, Canvas and Moodle imports, feedback
files and copy flags (``python -m course grade … --roster R --due D --canvas C --moodle M --feedback F --flags X``).

Every export is written from the same records, one ``Mark`` per graded notebook: the grader's results, the
roster row of the student who handed it in (``roster.py``), and how late it came in (``late.py``). The JSON and
CSV of ``grade`` gain the roster's columns (name, id, email, section) and the lateness (days late, the share kept,
the total after the penalty) beside the raw total; the Canvas and Moodle files carry the total after the penalty,
one column per lecture graded:

    Canvas  Student, ID, SIS User ID, SIS Login ID, Section, then one column per assignment; the second row,
            "Points Possible", gives each assignment's maximum (Canvas's own export has the same two rows).
            Canvas matches a row to a student by ID, then SIS User ID, then SIS Login ID; a new column name
            creates an assignment.
    Moodle  ID number, Email address, then one column per assignment; on import, map "ID number" (or "Email
            address") to the user field of that name and each assignment column to a grade item.

Students on the roster without a notebook get an empty cell (Canvas and Moodle leave an empty cell's grade as it
is); notebooks of students not on the roster cannot be matched and are left out of both files. Both are printed
as notes, never dropped silently.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

from .late import LatePolicy, Lateness, lateness, parse_due
from .registry import Result, tasks_for_lecture
from .roster import Student, find_student, read_roster
from .submissions import DuplicateSubmission, Submission

__all__ = ["Mark", "Plan", "add_arguments", "prepare", "marks_of", "extra_fields", "report", "write_canvas",
           "write_moodle", "assignment_name", "write_exports"]

CANVAS_COLUMNS = ["Student", "ID", "SIS User ID", "SIS Login ID", "Section"]
MOODLE_COLUMNS = ["ID number", "Email address"]


@dataclass(frozen=True)
class Mark:
    """One graded notebook: the ``submission``, its ``results``, its ``student`` on the roster (None: no roster, or
    not on it) and its ``late`` record (None: no due date)."""
    submission: Submission
    results: tuple[Result, ...]
    student: Student | None = None
    late: Lateness | None = None

    @property
    def points(self) -> int:
        return sum(r.points for r in self.results)

    @property
    def max_points(self) -> int:
        return sum(r.max_points for r in self.results)

    @property
    def final(self) -> float:
        """The points after the late penalty, to two decimals (the raw points without a due date)."""
        return round(self.points * self.late.factor, 2) if self.late else float(self.points)

    @property
    def key(self) -> str:
        """Who this is in the exports: the roster's submission key, else the student the grader read."""
        return self.student.submission if self.student else self.submission.student


@dataclass
class Plan:
    """What ``prepare`` read before any notebook ran: the roster (or None), the late policy (or None), each
    submission's roster row by path, and notes to print."""
    roster: dict[str, Student] | None
    policy: LatePolicy | None
    students: dict[Path, Student | None]
    notes: list[str]


# ----------------------------------------------------------------------------------- the command line

def add_arguments(parser) -> None:
    """The ``grade`` options of this module."""
    group = parser.add_argument_group("a term's class: roster, due dates, gradebooks, feedback, copy flags")
    group.add_argument("--roster", type=Path, metavar="CSV",
                       help="who is who: columns submission (folder or file name), name, id, email, and optionally "
                            "section, canvas_id, login, extension_days, submitted")
    group.add_argument("--due", metavar="DATETIME",
                       help="due date, ISO 8601 (2025-03-14T23:59, local time unless it has an offset); late "
                            "submissions lose points (see --late-days), shown beside the raw score")
    group.add_argument("--late-days", type=float, default=7.0, metavar="N",
                       help="a submission d days late keeps 1 - d/N of its points, none from N days on (default: 7; "
                            "0: a late submission scores 0)")
    group.add_argument("--canvas", type=Path, metavar="FILE", help="a Canvas gradebook import CSV (needs --roster)")
    group.add_argument("--moodle", type=Path, metavar="FILE", help="a Moodle grade import CSV (needs --roster)")
    group.add_argument("--feedback", type=Path, metavar="DIR",
                       help="one Markdown file per notebook, DIR/<student>/<notebook>.md: each task's points and "
                            "what to fix")
    group.add_argument("--flags", type=Path, metavar="FILE",
                       help="copy flags for the TA (Markdown): graded functions that read like the package's code or "
                            "each other, matching lines side by side; scores are not changed")
    group.add_argument("--flag-threshold", type=float, default=None, metavar="X",
                       help="flag pairs at or above this similarity, 0-1 (default: course.grading.flags.THRESHOLD)")


def prepare(args, submissions: list[Submission]) -> Plan:
    """Read the roster and the due date and match every submission to a student, before anything runs.
    ``ValueError`` (a ``RosterError``, a bad ``--due``, ``DuplicateSubmission``) says what to fix."""
    if (args.canvas or args.moodle) and not args.roster:
        raise ValueError(f"--{'canvas' if args.canvas else 'moodle'} needs --roster: the gradebook matches students "
                         "by the ids the roster gives")
    if args.late_days < 0:
        raise ValueError(f"--late-days is the number of days over which late points decay, 0 or more; got "
                         f"{args.late_days:g}")
    if args.flag_threshold is not None and not 0 < args.flag_threshold <= 1:
        raise ValueError(f"--flag-threshold is a similarity between 0 and 1; got {args.flag_threshold:g}")
    policy = LatePolicy(parse_due(args.due), args.late_days) if args.due else None
    roster = read_roster(args.roster) if args.roster else None
    students: dict[Path, Student | None] = {}
    notes: list[str] = []
    if roster is not None:
        seen: dict[tuple[str, int], Path] = {}
        for s in submissions:
            student = students[s.path] = find_student(roster, s.student, s.path)
            if student is None:
                notes.append(f"{s.path}: not on the roster (no submission {s.student!r} or {s.path.name!r}); "
                             "graded as it is, left out of the Canvas and Moodle files")
            elif s.lecture is not None and seen.setdefault((student.submission, s.lecture), s.path) != s.path:
                raise DuplicateSubmission(f"{seen[(student.submission, s.lecture)]} and {s.path} are both lecture "
                                          f"{s.lecture:02d} of {student.name} ({student.submission}) on the roster: "
                                          "grade one of them")
    return Plan(roster, policy, students, notes)


def marks_of(graded, plan: Plan) -> list[Mark]:
    """One ``Mark`` per graded notebook, in the order graded (``graded``: (Submission, [Result]) pairs)."""
    marks = []
    for s, results in graded:
        student = plan.students.get(s.path)
        late = lateness(plan.policy, s.path, student) if plan.policy and results else None
        marks.append(Mark(s, tuple(results), student, late))
    return marks


def _number(value: float) -> str:
    """3 for 3.0, 3.5 for 3.50, 6.29 for 6.29: how a score reads in a CSV cell (two decimals at most)."""
    return f"{round(float(value), 2):g}"


def extra_fields(marks: list[Mark], plan: Plan) -> dict[Path, dict[str, object]]:
    """Per notebook, the fields the roster and the due date add to ``grade``'s JSON records and CSV rows."""
    extra: dict[Path, dict[str, object]] = {}
    for m in marks:
        fields: dict[str, object] = {}
        if plan.roster is not None:
            st = m.student
            fields.update(name=st.name if st else "", id=st.id if st else "", email=st.email if st else "",
                          section=st.section if st else "")
        if plan.policy is not None and m.late is not None:
            fields.update(submitted=m.late.submitted.isoformat(timespec="seconds"), submitted_from=m.late.source,
                          due=m.late.due.isoformat(timespec="seconds"), days_late=round(max(m.late.days_late, 0), 3),
                          late_factor=round(m.late.factor, 4), total=m.points, total_after_penalty=m.final)
        if fields:
            extra[m.submission.path] = fields
    return extra


def report(marks: list[Mark], plan: Plan) -> list[str]:
    """Lines to print after the score table: the late rule and every late notebook, raw beside penalised, and
    the roster's notes (students without a notebook, notebooks of students not on it)."""
    lines = []
    if plan.policy is not None:
        late = [m for m in marks if m.late and m.late.late]
        lines += ["", f"Late submissions: {len(late)} ({plan.policy.describe()})"]
        for m in late:
            lines.append(f"  {m.key} {m.submission.path.name}: {m.late.days_late:.2f} days late (submitted "
                         f"{m.late.submitted.isoformat(timespec='minutes')} by {m.late.source}, due "
                         f"{m.late.due.isoformat(timespec='minutes')}): {m.points}/{m.max_points} x "
                         f"{m.late.factor:.2f} = {_number(m.final)}")
    if plan.roster is not None:
        lectures = sorted({m.submission.lecture for m in marks if m.results})
        handed = {(m.student.submission, m.submission.lecture) for m in marks if m.student}
        for lecture in lectures:
            missing = [st.name for key, st in plan.roster.items() if (key, lecture) not in handed]
            if missing:
                lines.append(f"note: no notebook of lecture {lecture:02d} from {len(missing)} student(s) on the "
                             f"roster (empty in the gradebooks): {', '.join(missing)}")
    lines += [f"note: {note}" for note in plan.notes]
    return lines


# ------------------------------------------------------------------------------------- LMS gradebooks

def assignment_name(lecture: int) -> str:
    """The gradebook column of a lecture: its exercise's name (``03_rasterization``) where the course's exercises/
    is at hand (the working directory or this checkout), else ``lecture 03``."""
    for root in (Path.cwd(), Path(__file__).resolve().parents[2]):
        for path in sorted((root / "exercises").glob(f"{lecture:02d}_*.ipynb")):
            return path.stem
    return f"lecture {lecture:02d}"


def _by_student(marks: list[Mark]) -> tuple[list[int], dict[tuple[str, int], Mark]]:
    """The lectures graded, and each roster student's mark per lecture."""
    lectures = sorted({m.submission.lecture for m in marks if m.results})
    return lectures, {(m.student.submission, m.submission.lecture): m for m in marks if m.student and m.results}


def write_canvas(path, marks: list[Mark], roster: dict[str, Student]) -> None:
    """A Canvas gradebook import: one row per roster student (roster order), one column per lecture graded
    holding the points after any late penalty (empty: no notebook), under a "Points Possible" row."""
    lectures, by_student = _by_student(marks)
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(CANVAS_COLUMNS + [assignment_name(n) for n in lectures])
        writer.writerow(["    Points Possible", "", "", "", ""]
                        + [sum(t.points for t in tasks_for_lecture(n)) for n in lectures])
        for key, st in roster.items():
            cells = [_number(by_student[key, n].final) if (key, n) in by_student else "" for n in lectures]
            writer.writerow([st.name, st.canvas_id, st.id, st.login, st.section] + cells)


def write_moodle(path, marks: list[Mark], roster: dict[str, Student]) -> None:
    """A Moodle grade import: ID number, Email address, then the points after any late penalty per lecture."""
    lectures, by_student = _by_student(marks)
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(MOODLE_COLUMNS + [assignment_name(n) for n in lectures])
        for key, st in roster.items():
            cells = [_number(by_student[key, n].final) if (key, n) in by_student else "" for n in lectures]
            writer.writerow([st.id, st.email] + cells)


def write_exports(args, plan: Plan, marks: list[Mark], by_student: bool) -> list[str]:
    """Write the files asked for (Canvas, Moodle, feedback, flags); the lines to print about them."""
    from . import feedback, flags

    printed = []
    if args.canvas:
        write_canvas(args.canvas, marks, plan.roster)
        printed.append(f"Canvas gradebook import: {args.canvas}")
    if args.moodle:
        write_moodle(args.moodle, marks, plan.roster)
        printed.append(f"Moodle grade import: {args.moodle}")
    if args.feedback:
        written = feedback.write_feedback(args.feedback, [m for m in marks if m.results], plan.policy)
        printed.append(f"feedback: {len(written)} file(s) in {args.feedback}")
    if args.flags:
        who = [(m.key if by_student or m.student else str(m.submission.path), m.submission.path) for m in marks]
        threshold = flags.THRESHOLD if args.flag_threshold is None else args.flag_threshold
        found = flags.find_flags(who, threshold)
        flags.write_report(args.flags, found)
        printed.append(f"copy flags: {len(found.flags)} pair(s) at or above {threshold:.2f} in {args.flags} "
                       "(scores unchanged)")
    return printed
