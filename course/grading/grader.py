"""The command-line grader: every notebook run in a fresh kernel, every task scored by the grader itself.

``python -m course grade NOTEBOOK... [--json FILE] [--csv FILE] [--timeout SECONDS]`` runs each notebook
in a fresh ``python3`` kernel, keeps going past cells that raise or hang, then scores every task itself.

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

What it does not protect against: the student's functions run in the grader's process, unsandboxed. Code
written to attack the grader (patching torch, numpy or builtins, installing import hooks or IPython
event callbacks, inspecting or patching the grader's frames while a check runs, tampering with stdout)
is outside this protection, as is a function that simply calls the package's reference implementation.
Sabotage of the grader's own cell ends in 0 points, not more. The grader is not a sandbox: do not run
notebooks you do not trust with your own privileges, and read code whose score surprises you.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import re
import secrets
import subprocess
import sys
from pathlib import Path

from .helpers import summarize_exception
from .registry import DEFAULT_TIMEOUT, TASKS, Result, Task, _task_key, run_check, tasks_for_lecture
from .release import CHECK_CALL

__all__ = ["grade_notebook", "cli"]


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


def _lecture_number(path: Path) -> int | None:
    match = re.match(r"(\d+)_", path.name)
    return int(match.group(1)) if match else None


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


# ------------------------------------------------------------------------------------- command line

def _points(results: list[Result]) -> tuple[int, int]:
    return sum(r.points for r in results), sum(r.max_points for r in results)


def _table(graded: dict[str, list[Result]], task_ids: list[str]) -> str:
    """Rows: notebooks; columns: task ids and the total."""
    rows = [["notebook"] + task_ids + ["total"]]
    for name, results in graded.items():
        by_id = {r.task: f"{r.points}/{r.max_points}" for r in results}
        rows.append([name] + [by_id.get(i, "-") for i in task_ids] + ["{}/{}".format(*_points(results))])
    widths = [max(len(row[k]) for row in rows) for k in range(len(rows[0]))]
    return "\n".join("  ".join(cell.ljust(w) if k == 0 else cell.rjust(w) for k, (cell, w) in
                               enumerate(zip(row, widths))).rstrip() for row in rows)


def _write_json(path: Path, graded: dict[str, list[Result]]) -> None:
    data = {name: [{"task": r.task, "points": r.points, "max_points": r.max_points, "message": r.message}
                   for r in results] for name, results in graded.items()}
    path.write_text(json.dumps(data, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")


def _write_csv(path: Path, graded: dict[str, list[Result]], task_ids: list[str]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(["notebook"] + task_ids + ["total"])
        for name, results in graded.items():
            by_id = {r.task: r.points for r in results}
            writer.writerow([name] + [by_id.get(i, "") for i in task_ids] + [_points(results)[0]])


def cli(argv: list[str] | None = None) -> int:
    """``python -m course grade NOTEBOOK... [--json FILE] [--csv FILE] [--timeout SECONDS]``."""
    parser = argparse.ArgumentParser(
        prog="python -m course grade",
        description="Run each notebook in a fresh kernel and score its tasks (tasks come from the NN_ prefix).")
    parser.add_argument("notebooks", nargs="+", type=Path, metavar="NOTEBOOK")
    parser.add_argument("--json", type=Path, metavar="FILE", help="write {notebook: [{task, points, ...}]}")
    parser.add_argument("--csv", type=Path, metavar="FILE", help="one row per notebook, one column per task")
    parser.add_argument("--timeout", type=float, default=60.0, metavar="SECONDS",
                        help=f"time limit for each cell (default: 60); each task check gets at most "
                             f"{DEFAULT_TIMEOUT:g} s")
    args = parser.parse_args(argv)
    missing = [str(p) for p in args.notebooks if not p.is_file()]
    if missing:
        print(f"error: no such notebook: {', '.join(missing)}", file=sys.stderr)
        return 2
    graded: dict[str, list[Result]] = {}
    for path in args.notebooks:
        if _lecture_number(path) is None or not tasks_for_lecture(_lecture_number(path)):
            print(f"warning: {path}: no graded tasks for this notebook (its name must start with a lecture "
                  "number that has tasks, e.g. 01_)", file=sys.stderr)
        print(f"grading {path} ...", file=sys.stderr, flush=True)
        graded[str(path)] = grade_notebook(path, timeout=args.timeout)
    task_ids = sorted({r.task for results in graded.values() for r in results}, key=_task_key)
    print(_table(graded, task_ids))
    for name, results in graded.items():
        for r in results:
            if r.points < r.max_points and r.message:
                print(f"  {name} {r.task} {r.name}: {r.message}")
    if args.json:
        _write_json(args.json, graded)
    if args.csv:
        _write_csv(args.csv, graded, task_ids)
    return 0
