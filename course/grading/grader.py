"""The command-line grader: every notebook run in a fresh kernel, every task scored by the grader itself.

``python -m course grade NOTEBOOK... [--jobs N] [--json FILE] [--csv FILE] [--gradebook FILE] [--timeout
SECONDS]`` runs each notebook in a fresh ``python3`` kernel, keeps going past cells that raise or hang, then
scores every task itself.

Grading a class
---------------
The student comes from the path: the folder above the notebook (``class/<student>/03_rasterization.ipynb``),
or ``<student>`` in nbgrader's ``.../submitted/<student>/<assignment>/03_rasterization.ipynb``
(``student_of``). Two notebooks of one student and lecture are an error naming both; when the notebooks are
not in per-student folders (two attempts at one lecture side by side in one folder), each notebook stands
alone, named by its path, as before (``assign_students``). ``--jobs N`` grades N notebooks at once, each in
its own kernel with its own time limits, from threads (``grade_notebooks``); the results come out in the
order given, the same as one at a time. The command prints a table, each lost point's reason, and a summary
per task (the mean points and how many scored 0, 1, ..., max), so the class's hard task shows.

A term's options (``gradebook.add_arguments``): ``--roster`` maps folders or file names to students' names, ids,
emails and sections; ``--due`` and ``--late-days`` apply a linear late penalty, shown beside the raw score;
``--canvas`` and ``--moodle`` write the LMS imports, ``--feedback`` one Markdown file per notebook, ``--flags`` a
copy-flag report for the TA (``flags.py``). Scores themselves never depend on them.

How far the grader can be trusted
---------------------------------
The printed score lines are never read. After a notebook has run, the grader executes one more cell in the
same kernel: it drops every ``course`` module from ``sys.modules``, imports a fresh ``course.grading.grader``
(and, through it, fresh ``course.grading`` with its ``registry``, ``helpers`` and ``lecture01`` ... modules,
and reference implementations) from the same installation as the grader, looks the task functions up by name
in the notebook's namespace, runs each check under its time limit, and prints the results as JSON tagged with
a random nonce created for this run. Tasks come from the notebook's ``NN_`` prefix and the registry, never
from the notebook, and a task whose check cell was deleted scores 0 ("check cell missing"). So printing fake
score lines, deleting or editing check cells, and monkeypatching ``course.grading`` (``check``,
``run_check``, ``TASKS``), its modules (``course.grading.helpers``, ``course.grading.lecture03``,
``course.grading.grader``, ...) or the references in ``course.camera``, ``course.raster``, ``course.shading``
gain nothing. Results returned as tensor subclasses are turned into plain tensors before they are compared.
A graded function that can reach the package function it re-implements scores 0 with a message naming it
(``registry.calls_reference`` reads its code before the check runs); a call hidden on purpose (``getattr``
with a built string, ``exec``) is not caught, but reading the code shows it.

What it does not protect against: the student's functions run in the grader's process, unsandboxed. Code
written to attack the grader (patching torch, numpy or builtins, installing import hooks or IPython
event callbacks, inspecting or patching the grader's frames while a check runs, tampering with stdout)
is outside this protection. Sabotage of the grader's own cell ends in 0 points, not more. The grader is not a sandbox: do not run
notebooks you do not trust with your own privileges, and read code whose score surprises you.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import secrets
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

from . import gradebook
from .helpers import summarize_exception
from .registry import DEFAULT_TIMEOUT, TASKS, Result, Task, _task_key, run_check, tasks_for_lecture
from .release import CHECK_CALL
from .submissions import DuplicateSubmission, Submission, _lecture_number, student_of

__all__ = ["grade_notebook", "grade_notebooks", "student_of", "assign_students", "Submission",
           "DuplicateSubmission", "cli"]


# ----------------------------------------------------------------------------- grading whole notebooks

_PACKAGE_ROOT = str(Path(__file__).resolve().parents[2])        # the directory that holds course/
_GRADER_TAG = "course-grader"

# Runs in the student's kernel after every cell of the notebook. Fresh imports, so patches of course.* made
# by the notebook are gone; the results go out as one line tagged with a nonce the notebook never saw.
_GRADER_CELL = """\
def _course_grader_run(nonce, task_ids, timeout, package_root):
    import importlib, json, os, sys
    for name in [name for name in sys.modules if name == "course" or name.startswith("course.")]:
        del sys.modules[name]
    sys.path.insert(0, package_root)
    grader = importlib.import_module("course.grading.grader")
    root = os.path.dirname(os.path.dirname(os.path.dirname(grader.__file__)))      # .../course/grading/grader.py
    if os.path.realpath(root) != os.path.realpath(package_root):
        raise RuntimeError("course was imported from " + grader.__file__)
    results = grader._grade_namespace(globals(), task_ids, timeout)
    sys.stdout.write("\\n" + nonce + " " + json.dumps(results) + "\\n")
    sys.stdout.flush()
_course_grader_run({nonce!r}, {task_ids!r}, {timeout!r}, {root!r})
"""


def _grade_namespace(namespace: dict, task_ids: list[str], timeout: float) -> list[dict]:
    """Run the checks of ``task_ids`` on the functions of those names in ``namespace`` (the grader cell)."""
    results = []
    for task_id in task_ids:
        t = TASKS[task_id]
        impl = namespace.get(t.name)
        if impl is None:
            result = Result(t.id, t.name, 0, t.points,
                            f"{t.name} is not defined (did its cell run without errors?)")
        else:
            try:
                result = run_check(task_id, impl, timeout=timeout)
            except Exception as exc:                                      # a grader bug must not hide the rest
                result = Result(t.id, t.name, 0, t.points, f"could not check: {summarize_exception(exc)}")
        results.append({"task": result.task, "points": result.points, "max_points": result.max_points,
                        "message": result.message})
    return results


def _missing(tasks: list[Task], message: str) -> list[Result]:
    return [Result(t.id, t.name, 0, t.points, message) for t in tasks]


def grade_notebook(path, timeout: float = 60.0) -> list[Result]:
    """Run ``path`` in a fresh kernel and score the tasks its ``NN_`` prefix names (see the module docstring).

    ``timeout`` (seconds) limits every cell; each task check gets ``min(timeout, DEFAULT_TIMEOUT)``. Cells
    that raise are skipped past, cells that run too long are interrupted; a task whose check cell is gone
    scores 0, "check cell missing".
    """
    path = Path(path)
    number = _lecture_number(path)
    tasks = tasks_for_lecture(number) if number is not None else []
    if not tasks:
        return []
    try:
        nb = _read_notebook(path)
    except Exception as exc:
        return _missing(tasks, f"could not read the notebook: {summarize_exception(exc)}")
    present = {match.group(1) for cell in nb.cells if cell.cell_type == "code"
               for match in CHECK_CALL.finditer(cell.source)}                # tasks that have a check cell
    outputs, note = _execute_with_grader(nb, path, [t.id for t in tasks], timeout)
    scored = {r["task"]: r for r in outputs or []}
    results = []
    for t in tasks:
        if t.id not in present:
            results.append(Result(t.id, t.name, 0, t.points, "check cell missing"))
        elif t.id in scored:
            r = scored[t.id]
            points = max(0, min(int(r["points"]), t.points))
            results.append(Result(t.id, t.name, points, t.points, str(r["message"])))
        else:
            results.append(Result(t.id, t.name, 0, t.points, note or "not graded"))
    return results


def _read_notebook(path: Path):
    import nbformat
    return nbformat.read(str(path), as_version=4)


def _execute_with_grader(nb, path: Path, task_ids: list[str], timeout: float):
    """Execute the notebook plus the grader cell; (the grader's results or None, why they are missing)."""
    import nbformat
    from nbclient import NotebookClient
    from nbclient.exceptions import DeadKernelError

    nonce = secrets.token_hex(16)
    check_timeout = float(min(timeout, DEFAULT_TIMEOUT))
    source = _GRADER_CELL.format(nonce=nonce, task_ids=task_ids, timeout=check_timeout, root=_PACKAGE_ROOT)
    nb.cells.append(nbformat.v4.new_code_cell(source, metadata={"tags": [_GRADER_TAG]}))
    grader_cell = nb.cells[-1]
    cell_timeout = max(1, math.ceil(timeout))
    grader_timeout = math.ceil(check_timeout * len(task_ids)) + cell_timeout + 60   # imports, every check
    client = NotebookClient(
        nb, kernel_name="python3", allow_errors=True, interrupt_on_timeout=True, shutdown_kernel="immediate",
        timeout_func=lambda cell: grader_timeout if cell is grader_cell else cell_timeout,
        error_on_timeout={"ename": "CellTimeout", "evalue": f"stopped after {cell_timeout} s", "traceback": []},
        resources={"metadata": {"path": str(path.parent.resolve())}})
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (_PACKAGE_ROOT, env.get("PYTHONPATH")) if p)
    try:
        client.execute(env=env, stderr=subprocess.DEVNULL)                 # kernel chatter is not a result
    except DeadKernelError:
        return None, "the kernel died while running the notebook (sys.exit? out of memory?)"
    except Exception as exc:                                                # kernel did not start, ...
        return None, f"the notebook could not be run: {summarize_exception(exc)}"
    text = "".join(o.get("text", "") for o in grader_cell.get("outputs", []) if o.get("output_type") == "stream")
    found = text.rfind(nonce + " ")
    if found < 0:
        errors = [f"{o.get('ename')}: {o.get('evalue')}" for o in grader_cell.get("outputs", [])
                  if o.get("output_type") == "error"]
        return None, "grading did not finish" + (f" ({errors[0]})" if errors else "")
    line = text[found + len(nonce) + 1:].split("\n", 1)[0]
    return json.loads(line), ""


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


def grade_notebooks(paths, timeout: float = 60.0, jobs: int = 1, progress: bool = True) -> list[list[Result]]:
    """``grade_notebook`` for each of ``paths``, ``jobs`` at a time; the results in the order of ``paths``.

    Every notebook still runs in its own fresh kernel with its own time limits, so the results are the same
    for any ``jobs``. With ``jobs`` > 1 threads drive the kernels (the work runs in the kernels' processes):
    grading one notebook shares no state with another, as each call has its own notebook object, nonce,
    grader cell, client, kernel and (nbclient's, per thread) event loop. Each kernel takes its own memory
    (about 270 MB for lecture 03). A progress bar (tqdm) counts finished notebooks on stderr; TQDM_DISABLE=1
    or ``progress=False`` hides it.
    """
    from tqdm.auto import tqdm

    paths = [Path(p) for p in paths]
    if int(jobs) != jobs or jobs < 1:
        raise ValueError(f"jobs is how many notebooks to grade at once, at least 1; got {jobs!r}")
    results: list[list[Result] | None] = [None] * len(paths)
    bar_options = {} if progress else {"disable": True}          # unset, tqdm reads TQDM_DISABLE
    with tqdm(total=len(paths), desc="grading", unit="notebook", file=sys.stderr, **bar_options) as bar:
        if jobs == 1 or len(paths) < 2:
            for k, path in enumerate(paths):
                results[k] = grade_notebook(path, timeout=timeout)
                bar.update()
            return results
        pool = ThreadPoolExecutor(max_workers=min(int(jobs), len(paths)), thread_name_prefix="grade")
        try:
            futures = {pool.submit(grade_notebook, path, timeout): k for k, path in enumerate(paths)}
            for future in as_completed(futures):                          # completion order ...
                results[futures[future]] = future.result()                # ... stored in the given order
                bar.update()
        finally:
            pool.shutdown(wait=True, cancel_futures=True)                 # Ctrl-C: no new kernels start
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
        description="Run each notebook in a fresh kernel and score its tasks (tasks come from the NN_ prefix). "
                    "The student is the folder above the notebook (class/<student>/03_rasterization.ipynb), "
                    "or <student> in nbgrader's submitted/<student>/<assignment>/.")
    parser.add_argument("notebooks", nargs="+", type=Path, metavar="NOTEBOOK")
    parser.add_argument("--jobs", "-j", type=int, default=1, metavar="N",
                        help="grade N notebooks at once, each in its own kernel (default: 1); same results, "
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
    results = grade_notebooks([s.path for s in submissions], timeout=args.timeout, jobs=args.jobs)
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
