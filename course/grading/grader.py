"""The command-line grader: every notebook run in a worker process of its own, every task scored by the grader.

``python -m course grade NOTEBOOK... [--jobs N] [--json FILE] [--csv FILE] [--gradebook FILE] [--timeout
SECONDS] [--user NAME]`` runs each notebook's cells in a fresh worker process (``sandbox.Worker``), keeps going
past cells that raise or hang, then scores every task in its own process.

Grading a class
---------------
The student comes from the path: the folder above the notebook (``class/<student>/03_rasterization.ipynb``),
or ``<student>`` in nbgrader's ``.../submitted/<student>/<assignment>/03_rasterization.ipynb``
(``student_of``). Two notebooks of one student and lecture are an error naming both; when the notebooks are
not in per-student folders (two attempts at one lecture side by side in one folder), each notebook stands
alone, named by its path, as before (``assign_students``). ``--jobs N`` grades N notebooks at once, each in
its own worker with its own time limits, from threads (``grade_notebooks``); the results come out in the
order given, the same as one at a time. The command prints a table, each lost point's reason, and a summary
per task (the mean points and how many scored 0, 1, ..., max), so the class's hard task shows.

A term's options (``gradebook.add_arguments``): ``--roster`` maps folders or file names to students' names, ids,
emails and sections; ``--due`` and ``--late-days`` apply a linear late penalty, shown beside the raw score;
``--canvas`` and ``--moodle`` write the LMS imports, ``--feedback`` one Markdown file per notebook, ``--flags`` a
copy-flag report for the TA (``flags.py``). Scores themselves never depend on them.

What a score can be trusted for
-------------------------------
**The verdicts are computed where no student code runs.** The notebook's cells run in a worker process
(``worker.py``), an IPython shell like Jupyter's kernel, with ``check()`` cells doing nothing there. The grader's
own process never runs a line of the notebook: it asks the worker for each task's function, and every check
then runs in the grader, which makes the inputs, computes the expected values with the package's references
and compares. Each call of the student's function sends the inputs to the worker as plain data and gets plain
data back (tensors, arrays, numbers, strings, containers: ``remote.py``; nothing is unpickled, nothing that
comes back can run), and a render function or optimizer the check hands over is called back in the grader,
autograd included. So nothing the notebook prints, patches (``json``, builtins, torch, ``course.grading``,
IPython callbacks), writes to stdout, or reads from its own stack can change how the grader scores: the grader
reads no output of the notebook's and shares no memory with it. Tasks come from the notebook's ``NN_`` prefix,
never from the notebook; a task whose check cell was deleted scores 0 ("check cell missing").

**Time and processes are controlled from outside.** A cell past ``--timeout`` is interrupted, and the worker is
ended if the cell does not stop; a check past its limit (``DEFAULT_TIMEOUT``) ends the worker (a bare
``except:`` in the student's code cannot swallow it, since the limit is the grader's), and the next task gets a
fresh worker with the notebook's cells run again, the cells that hung or killed the worker skipped
(``NotebookRun``): one runaway task costs only its own points. After each notebook every process it started is
ended, including double-forked daemons (``sandbox.end_processes``), before any result is written. The worker's
memory is capped (``--memory``), so a 30 GB allocation fails in the notebook instead of waking the system's
out-of-memory killer.

**Who the student's code runs as decides what it can touch.** With ``--user NAME`` (the grader running as root,
as Gradescope's autograder does with its own ``course-student``) the notebook runs as that user: it cannot
write the course, the grader's files or the results, and every process of that user is ended after each
notebook. Without it, the notebook runs as you, and can do what you can: read and change your files. The
grader imports every module it checks with before any notebook runs (``prepare_grader``), runs the checks'
arithmetic on the torch path (no compiled-kernel cache that a notebook could have rewritten is read), and
fingerprints the course's files: a notebook that changed one scores 0 ("changed the course's own files"). That
defeats the attacks tried (``tests/test_grading_attacks.py``), but only a user of its own makes them impossible:
grade notebooks you do not trust as root with ``--user``.

**What it does not judge.** Copying: a graded function that calls the package function it re-implements scores
0 ("calls course.camera.look_at ...": the grader reads the notebook's source itself, ``reading.py``, and the
worker reads the live function, ``registry.calls_reference``), but a call hidden on purpose (``getattr`` with a
built string, ``exec``), pasted package code or a classmate's code is for the copy flags and a person
(``flags.py``, whose report also lists code that reaches into the grader, patches modules or forks). And a
notebook that breaks its own process (patching ``builtins.min``) loses what it breaks: the grader scores what
comes back, never more.
"""
from __future__ import annotations

import argparse
import csv
import functools
import hashlib
import importlib
import json
import pkgutil
import sys
import warnings
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

from . import gradebook
from .helpers import summarize_exception
from .registry import DEFAULT_TIMEOUT, CheckTimeout, PeerGone, Result, Task, _task_key, run_check, tasks_for_lecture
from .reading import reaches_reference
from .release import CHECK_CALL
from .sandbox import Isolation, Worker
from .submissions import DuplicateSubmission, Submission, _lecture_number, student_of

__all__ = ["grade_notebook", "grade_notebooks", "student_of", "assign_students", "Submission",
           "DuplicateSubmission", "cli"]


# ----------------------------------------------------------------------------- grading whole notebooks

MAX_RESTARTS = 6                # times one notebook's worker may be started again (a cell or a task ended it)


def _missing(tasks: list[Task], message: str) -> list[Result]:
    return [Result(t.id, t.name, 0, t.points, message) for t in tasks]


_IMPORTED = False


def prepare_grader() -> None:
    """Import every module of the course the checks may use (everything but the benchmarks), once per process,
    before any student code runs: a notebook that rewrites the course's files afterwards changes nothing the
    grader runs (``sandbox.py`` says what a user of the student's own adds)."""
    global _IMPORTED
    if _IMPORTED:
        return
    import course
    for info in pkgutil.walk_packages(course.__path__, "course."):
        if not info.name.startswith(("course.bench", "course.__main__")):
            importlib.import_module(info.name)
    _IMPORTED = True


class NotebookRun:
    """A notebook's code cells run in a worker (``sandbox.Worker``), and the task functions they define.

    The cells run once, in order, each under the cell time limit. A cell that overruns is interrupted (or the
    worker ended, if it does not stop); a cell that was stopped, or that ended the worker (``os._exit``, the
    memory limit), is skipped when the worker is started again, which happens when a task's check ends it (a time
    limit, a crash): the next task finds the notebook's functions defined afresh. ``notes`` say which cells were
    stopped."""

    def __init__(self, cells: list[str], files: dict, cell_timeout: float, isolation: Isolation):
        self.cells, self.files, self.cell_timeout, self.isolation = cells, files, cell_timeout, isolation
        self.worker: Worker | None = None
        self.skip: set[int] = set()
        self.notes: list[str] = []
        self.starts = 0
        self.failure = ""

    def ready(self) -> Worker | None:
        """A live worker that has run the cells, or None (``failure`` says why)."""
        while self.worker is None or not self.worker.alive:
            self.end()
            if self.starts > MAX_RESTARTS or self.failure:
                self.failure = self.failure or "the notebook ended its process too often to be graded"
                return None
            self.starts += 1
            self.worker = Worker(self.isolation, self.files)
            try:
                self.worker.start()
            except (PeerGone, CheckTimeout, OSError, ValueError) as exc:
                self.failure = f"the process to run the notebook did not start ({summarize_exception(exc)})"
                self.end()
                return None
            for index, source in enumerate(self.cells):
                if index in self.skip:
                    continue
                status, why = self.worker.run_cell(source, self.cell_timeout)
                if status in ("timeout", "ended"):                      # stopped: not run again on a restart
                    self._note(f"code cell {index + 1}: {why}")
                    self.skip.add(index)
                if status == "ended":
                    break
        return self.worker

    def _note(self, note: str) -> None:
        if note not in self.notes:
            self.notes.append(note)

    def grade(self, t: Task, check_timeout: float) -> Result:
        worker = self.ready()
        if worker is None:
            return Result(t.id, t.name, 0, t.points, f"not graded: {self.failure}")
        try:
            impl = worker.function(t.name)
        except (PeerGone, CheckTimeout) as exc:
            self.end()
            return Result(t.id, t.name, 0, t.points, f"could not look {t.name} up ({summarize_exception(exc)})")
        if isinstance(impl, str):
            stopped = [n for n in self.notes if "stopped" in n or "died" in n]
            return Result(t.id, t.name, 0, t.points, impl + (f" ({stopped[0]})" if stopped else ""))
        impl.static_reaches = functools.partial(reaches_reference, self.cells, t.name)   # read here, too
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = run_check(t.id, impl, timeout=check_timeout)
        except Exception as exc:                                          # a grader bug must not hide the rest
            result = Result(t.id, t.name, 0, t.points, f"could not check: {summarize_exception(exc)}")
        if worker.alive:
            try:
                worker.forget()
            except (PeerGone, CheckTimeout):
                self.end()
        else:
            self.end()                                                    # a fresh worker for the next task
        return result

    def end(self) -> None:
        if self.worker is not None:
            self.worker.end()
            self.worker = None


def grade_notebook(path, timeout: float = 60.0, isolation: Isolation | None = None) -> list[Result]:
    """Run ``path``'s cells in a worker and score the tasks its ``NN_`` prefix names (see the module docstring).

    ``timeout`` (seconds) limits every cell; each task check gets ``min(timeout, DEFAULT_TIMEOUT)``. Cells that
    raise are skipped past, cells that run too long are interrupted; a task whose check cell is gone scores 0,
    "check cell missing". ``isolation``: who the student's code runs as, and its limits (``sandbox.Isolation``).
    """
    path = Path(path)
    number = _lecture_number(path)
    tasks = tasks_for_lecture(number) if number is not None else []
    if not tasks:
        return []
    try:
        nb = _read_notebook(path)
        files = {path.name: path.read_bytes()}
    except Exception as exc:
        return _missing(tasks, f"could not read the notebook: {summarize_exception(exc)}")
    prepare_grader()
    present = {match.group(1) for cell in nb.cells if cell.cell_type == "code"
               for match in CHECK_CALL.finditer(cell.source)}                # tasks that have a check cell
    cells = [cell.source for cell in nb.cells if cell.cell_type == "code"]
    run = NotebookRun(cells, files, max(1.0, float(timeout)), isolation or Isolation())
    check_timeout = float(min(timeout, DEFAULT_TIMEOUT))
    before = fingerprint(course_files())
    try:
        results = [run.grade(t, check_timeout) if t.id in present else
                   Result(t.id, t.name, 0, t.points, "check cell missing") for t in tasks]
    finally:
        run.end()                                                         # every process of the student's
    changed = [name for name, digest in fingerprint(course_files()).items() if before.get(name) != digest]
    if changed:
        names = ", ".join(Path(n).name for n in changed[:5])
        return _missing(tasks, f"not graded: the notebook changed the course's own files ({names})")
    return results


def course_files() -> list[Path]:
    """Every Python file of the installed course: what a notebook run as the grader's own user could rewrite."""
    return sorted(Path(__file__).resolve().parents[1].rglob("*.py"))


def fingerprint(files: list[Path]) -> dict[str, str]:
    """The sha256 of each file (or "missing"), to tell afterwards whether a notebook changed one."""
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "missing" for p in files}


def _read_notebook(path: Path):
    import nbformat
    return nbformat.read(str(path), as_version=4)


# ------------------------------------------------------------------------------- a class of notebooks

STUDENT_MODES = ("auto", "folder", "notebook")


def assign_students(paths, mode: str = "auto") -> tuple[list[Submission], bool, str]:
    """Who handed in each notebook: (submissions in the order given, read per student?, a note or "").

    ``mode`` "folder": the student comes from the path (``student_of``), and two notebooks of one student and
    lecture raise ``DuplicateSubmission`` naming both. "notebook": every notebook stands alone, named by its
    path (the table of old). "auto": "folder" unless two notebooks share a student and lecture; then
    "notebook", with a note that says which two (``submissions/01_wrong.ipynb`` and
    ``submissions/01_cheater.ipynb`` are two attempts in one folder, not one student's). A path given twice
    is graded once.
    """
    if mode not in STUDENT_MODES:
        raise ValueError(f"mode must be one of {', '.join(STUDENT_MODES)}, got {mode!r}")
    paths = list(dict.fromkeys(Path(p) for p in paths))
    alone = [Submission(p, str(p), _lecture_number(p)) for p in paths]
    if mode == "notebook":
        return alone, False, ""
    submissions = [Submission(p, student_of(p), _lecture_number(p)) for p in paths]
    first: dict[tuple[str, int], Submission] = {}
    for s in submissions:
        if s.lecture is None:                                           # no tasks: nothing to count twice
            continue
        other = first.setdefault((s.student, s.lecture), s)
        if other is not s:
            clash = (f"{other.path} and {s.path} are both lecture {s.lecture:02d} of student {s.student!r}")
            if mode == "folder":
                raise DuplicateSubmission(f"{clash}: grade one of them (move or rename the other)")
            return alone, False, (f"{clash}, so folders are not read as students: each notebook is graded on "
                                  "its own (--students folder makes this an error)")
    return submissions, True, ""


def one_student(paths, name: str) -> list[Submission]:
    """Every notebook of ``paths`` handed in by ``name`` (a student grading their own ``work/``); two notebooks
    of one lecture raise ``DuplicateSubmission``, an empty name ``ValueError``."""
    name = str(name).strip()
    if not name:
        raise ValueError("--student needs a name, e.g. --student \"Ada Lovelace\"")
    submissions, seen = [], {}
    for p in dict.fromkeys(Path(p) for p in paths):
        s = Submission(p, name, _lecture_number(p))
        if s.lecture is not None and seen.setdefault(s.lecture, p) != p:
            raise DuplicateSubmission(f"{seen[s.lecture]} and {p} are both lecture {s.lecture:02d} of student "
                                      f"{name!r}: grade one of them")
        submissions.append(s)
    return submissions


def grade_notebooks(paths, timeout: float = 60.0, jobs: int = 1, progress: bool = True,
                    isolation: Isolation | None = None) -> list[list[Result]]:
    """``grade_notebook`` for each of ``paths``, ``jobs`` at a time; the results in the order of ``paths``.

    Every notebook runs in its own worker with its own time limits, so the results are the same for any ``jobs``.
    With ``jobs`` > 1 threads drive the workers (the work runs in the workers' processes and in the checks, which
    share nothing between notebooks). Each worker takes its own memory (about 400 MB for lecture 03). With a user
    of the students' own (``isolation.user``) one notebook is graded at a time, since every process of that user
    is ended after each. A progress bar (tqdm) counts finished notebooks on stderr; TQDM_DISABLE=1 or
    ``progress=False`` hides it.
    """
    from tqdm.auto import tqdm

    paths = [Path(p) for p in paths]
    if int(jobs) != jobs or jobs < 1:
        raise ValueError(f"jobs is how many notebooks to grade at once, at least 1; got {jobs!r}")
    if jobs > 1 and isolation is not None and isolation.user:
        raise ValueError("with --user one notebook is graded at a time (every process of that user is ended after "
                         "each notebook): leave --jobs out")
    prepare_grader()
    results: list[list[Result] | None] = [None] * len(paths)
    bar_options = {} if progress else {"disable": True}          # unset, tqdm reads TQDM_DISABLE
    with tqdm(total=len(paths), desc="grading", unit="notebook", file=sys.stderr, **bar_options) as bar:
        if jobs == 1 or len(paths) < 2:
            for k, path in enumerate(paths):
                results[k] = grade_notebook(path, timeout=timeout, isolation=isolation)
                bar.update()
            return results
        pool = ThreadPoolExecutor(max_workers=min(int(jobs), len(paths)), thread_name_prefix="grade")
        try:
            futures = {pool.submit(grade_notebook, path, timeout, isolation): k for k, path in enumerate(paths)}
            for future in as_completed(futures):                          # completion order ...
                results[futures[future]] = future.result()                # ... stored in the given order
                bar.update()
        finally:
            pool.shutdown(wait=True, cancel_futures=True)                 # Ctrl-C: no new workers start
    return results


# ------------------------------------------------------------------------------------- command line

Graded = list[tuple[Submission, list[Result]]]                 # each notebook with its results, as given


def _points(results: list[Result]) -> tuple[int, int]:
    return sum(r.points for r in results), sum(r.max_points for r in results)


def _align(rows: list[list[str]], left: int) -> str:
    """Rows of cells as columns: the first ``left`` columns flush left, the others flush right."""
    widths = [max(len(row[k]) for row in rows) for k in range(len(rows[0]))]
    return "\n".join("  ".join(cell.ljust(w) if k < left else cell.rjust(w) for k, (cell, w) in
                               enumerate(zip(row, widths))).rstrip() for row in rows)


def _table(graded: Graded, task_ids: list[str], by_student: bool) -> str:
    """Rows: notebooks (student and notebook name, or the path); columns: task ids and the total."""
    names = ["student", "notebook"] if by_student else ["notebook"]
    rows = [names + task_ids + ["total"]]
    for s, results in graded:
        by_id = {r.task: f"{r.points}/{r.max_points}" for r in results}
        first = [s.student, s.path.name] if by_student else [str(s.path)]
        rows.append(first + [by_id.get(i, "-") for i in task_ids] + ["{}/{}".format(*_points(results))])
    return _align(rows, left=len(names))


def _summary(graded: Graded, task_ids: list[str], by_student: bool) -> str:
    """Per task: how many were graded on it, the mean points, and how many scored 0, 1, ..., max points."""
    per_task = {i: [r for _, results in graded for r in results if r.task == i] for i in task_ids}
    top = max(results[0].max_points for results in per_task.values())
    rows = [["task", "function", "graded", "mean"] + [str(k) for k in range(top + 1)]]
    for task_id, results in per_task.items():
        points, most = [r.points for r in results], results[0].max_points
        rows.append([task_id, results[0].name, str(len(points)), f"{sum(points) / len(points):.2f}/{most}"]
                    + [str(points.count(k)) if k <= most else "" for k in range(top + 1)])
    who = "students" if by_student else "notebooks"
    return (f"Summary: per task, the mean points and how many {who} scored 0, 1, 2, ... points\n"
            + _align(rows, left=2))


def _write_json(path: Path, graded: Graded, by_student: bool, extra: dict | None = None) -> None:
    """{notebook: [record per task]}; ``extra`` (per notebook path) adds the roster's and the due date's fields
    to each of its records (``gradebook.extra_fields``)."""
    extra = extra or {}
    student = (lambda s: {"student": s.student}) if by_student else (lambda s: {})
    data = {str(s.path): [{**student(s), "task": r.task, "points": r.points, "max_points": r.max_points,
                           "message": r.message, **extra.get(s.path, {})} for r in results] for s, results in graded}
    path.write_text(json.dumps(data, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")


def _write_csv(path: Path, graded: Graded, task_ids: list[str], by_student: bool, extra: dict | None = None) -> None:
    """One row per notebook; ``extra`` (per notebook path, column -> value) adds columns after the total."""
    extra = extra or {}
    columns = list(dict.fromkeys(name for fields in extra.values() for name in fields if name != "total"))
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow((["student"] if by_student else []) + ["notebook"] + task_ids + ["total"] + columns)
        for s, results in graded:
            by_id = {r.task: r.points for r in results}
            writer.writerow(([s.student] if by_student else []) + [str(s.path)]
                            + [by_id.get(i, "") for i in task_ids] + [_points(results)[0]]
                            + [extra.get(s.path, {}).get(name, "") for name in columns])


def _write_gradebook(path: Path, graded: Graded, task_ids: list[str]) -> None:
    """One row per student (sorted), one column per task of every lecture graded (empty: no notebook of that
    lecture), and the total."""
    points: dict[str, dict[str, int]] = {}
    for s, results in graded:
        points.setdefault(s.student, {}).update({r.task: r.points for r in results})
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(["student"] + task_ids + ["total"])
        for student in sorted(points):
            row = points[student]
            writer.writerow([student] + [row.get(i, "") for i in task_ids] + [sum(row.values())])


def cli(argv: list[str] | None = None) -> int:
    """``python -m course grade NOTEBOOK... [--jobs N] [--students MODE | --student NAME] [--json FILE] [--csv FILE]
    [--gradebook FILE] [--timeout SECONDS]`` and the term's options of ``gradebook.add_arguments`` (``--roster``,
    ``--due``, ``--late-days``, ``--canvas``, ``--moodle``, ``--feedback``, ``--flags``)."""
    parser = argparse.ArgumentParser(
        prog="python -m course grade",
        description="Run each notebook's cells in a worker process of their own and score its tasks in this one "
                    "(tasks come from the NN_ prefix). "
                    "The student is the folder above the notebook (class/<student>/03_rasterization.ipynb), "
                    "or <student> in nbgrader's submitted/<student>/<assignment>/.")
    parser.add_argument("notebooks", nargs="+", type=Path, metavar="NOTEBOOK")
    parser.add_argument("--jobs", "-j", type=int, default=1, metavar="N",
                        help="grade N notebooks at once, each in its own worker (default: 1); same results, "
                             "N times the memory")
    parser.add_argument("--students", choices=STUDENT_MODES, default="auto",
                        help="folder: the student comes from the path, two notebooks of one student and lecture "
                             "are an error; notebook: each notebook on its own; auto (default): folder, unless "
                             "two notebooks share a student and lecture")
    parser.add_argument("--student", metavar="NAME",
                        help="every notebook given is this student's (your own work/ notebooks: "
                             "--student \"Ada Lovelace\"); two of one lecture are an error")
    parser.add_argument("--json", type=Path, metavar="FILE",
                        help="write {notebook: [{student, task, points, max_points, message}]}")
    parser.add_argument("--csv", type=Path, metavar="FILE",
                        help="one row per notebook (student, notebook, one column per task, total)")
    parser.add_argument("--gradebook", type=Path, metavar="FILE",
                        help="one row per student across every lecture graded, one column per task, and the "
                             "total (reads the students from the folders, as --students folder)")
    parser.add_argument("--timeout", type=float, default=60.0, metavar="SECONDS",
                        help=f"time limit for each cell (default: 60); each task check gets at most "
                             f"{DEFAULT_TIMEOUT:g} s")
    parser.add_argument("--user", metavar="NAME",
                        help="run the notebooks' code as this unprivileged user (the grader must run as root): it "
                             "cannot touch your files, and every process it starts is ended after each notebook; "
                             "without it the code runs as you (see course/grading/sandbox.py)")
    parser.add_argument("--memory", type=float, default=Isolation.memory_gb, metavar="GB",
                        help=f"address space each notebook may use (default: {Isolation.memory_gb:g})")
    gradebook.add_arguments(parser)
    args = parser.parse_args(argv)
    if args.jobs < 1:
        print(f"error: --jobs is how many notebooks to grade at once, at least 1; got {args.jobs}", file=sys.stderr)
        return 2
    missing = [str(p) for p in args.notebooks if not p.is_file()]
    if missing:
        print(f"error: no such notebook: {', '.join(missing)}", file=sys.stderr)
        return 2
    mode = "folder" if args.gradebook and args.students == "auto" else args.students
    try:
        isolation = Isolation(user=args.user, memory_gb=args.memory)
        if args.user:
            Worker(isolation)                                     # checks the user exists and can be switched to
        if args.jobs > 1 and args.user:
            raise ValueError("with --user one notebook is graded at a time (every process of that user is ended "
                             "after each notebook): leave --jobs out")
        if args.student is not None:
            submissions, by_student, note = one_student(args.notebooks, args.student), True, ""
        else:
            submissions, by_student, note = assign_students(args.notebooks, mode)
        plan = gradebook.prepare(args, submissions)               # roster, due date: checked before anything runs
    except (DuplicateSubmission, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if note:
        print(f"note: {note}", file=sys.stderr)
    for s in submissions:
        if s.lecture is None or not tasks_for_lecture(s.lecture):
            print(f"warning: {s.path}: no graded tasks for this notebook (its name must start with a lecture "
                  "number that has tasks, e.g. 01_)", file=sys.stderr)
    from .. import kernels
    with kernels.using("torch"):             # the checks' own arithmetic: no compiled-kernel cache that the
        results = grade_notebooks([s.path for s in submissions], timeout=args.timeout,  # notebooks' code could
                                  jobs=args.jobs, isolation=isolation)                  # have rewritten is read
    graded = list(zip(submissions, results))
    task_ids = sorted({r.task for _, rs in graded for r in rs}, key=_task_key)
    print(_table(graded, task_ids, by_student))
    for s, rs in graded:
        for r in rs:
            if r.points < r.max_points and r.message:
                print(f"  {s.path} {r.task} {r.name}: {r.message}")
    if task_ids:
        print("\n" + _summary(graded, task_ids, by_student))
    marks = gradebook.marks_of(graded, plan)
    for line in gradebook.report(marks, plan):
        print(line)
    extra = gradebook.extra_fields(marks, plan)
    if args.json:
        _write_json(args.json, graded, by_student, extra)
    if args.csv:
        _write_csv(args.csv, graded, task_ids, by_student, extra)
    if args.gradebook:
        _write_gradebook(args.gradebook, graded, task_ids)
    for line in gradebook.write_exports(args, plan, marks, by_student):
        print(line)
    return 0
