"""Write the exercise notebooks from their solutions: ``python -m course release [--check]``.

``solutions/NN_topic.ipynb`` is the source of truth. Graded code sits between nbgrader's markers, so
nbgrader users can adopt the notebooks as they are::

    def look_at(eye, target, up):
        ### BEGIN SOLUTION
        ...the answer...
        ### END SOLUTION

    check("1.2", look_at)
    ### BEGIN HIDDEN TESTS
    ...tests students do not see...
    ### END HIDDEN TESTS

Releasing turns each solution region into ``# YOUR CODE HERE`` + ``raise NotImplementedError()`` at the
indentation of its BEGIN line (``YOUR ANSWER HERE`` in a markdown cell), drops hidden tests, and clears
the outputs and execution counts of graded cells (cells that had a solution region or hidden tests) and of
check cells (``check("N.M", ...)``), whose solution scores would mislead a student. Those cells are tagged
``nbval-skip``. Every other cell keeps its outputs. The output is deterministic: the same solutions give the
same bytes, so ``--check`` can tell when ``exercises/`` has drifted from ``solutions/``.
"""
from __future__ import annotations

import argparse
import copy
import json
import re
import sys
from pathlib import Path

__all__ = ["release_notebook", "release_source", "render_exercise", "plan_release", "cli", "CHECK_CALL"]

BEGIN_SOLUTION, END_SOLUTION = "### BEGIN SOLUTION", "### END SOLUTION"
BEGIN_HIDDEN, END_HIDDEN = "### BEGIN HIDDEN TESTS", "### END HIDDEN TESTS"
STUB_CODE = ("# YOUR CODE HERE", "raise NotImplementedError()")
STUB_MARKDOWN = ("YOUR ANSWER HERE",)
EXERCISE_TAG = "nbval-skip"                       # nbval skips the cell: exercises are not run as tests

CHECK_CALL = re.compile(r"\bcheck\(\s*[\"'](\d+\.\d+)[\"']")   # a check cell: check("3.2", barycentric)


def release_source(source: str, cell_type: str = "code", where: str = "cell") -> tuple[str, bool]:
    """Replace solution regions and drop hidden tests in one cell's source.

    Returns the exercise source and whether the cell was graded (had either kind of region). ``where``
    names the cell in error messages, e.g. ``"solutions/01_camera.ipynb, cell 4"``.
    """
    stub = STUB_CODE if cell_type == "code" else STUB_MARKDOWN
    out: list[str] = []
    region, region_line, graded = None, 0, False
    lines = source.splitlines(keepends=True)
    for number, line in enumerate(lines, 1):
        marker = line.strip()
        if marker in (BEGIN_SOLUTION, BEGIN_HIDDEN):
            if region is not None:
                raise ValueError(f"{where}: {marker!r} on line {number} opens a region inside the "
                                 f"{region!r} region opened on line {region_line}; close that one first")
            region, region_line, graded = marker, number, True
            if marker == BEGIN_SOLUTION:
                indent = line[: len(line) - len(line.lstrip())]
                out += [f"{indent}{text}\n" for text in stub]
        elif marker in (END_SOLUTION, END_HIDDEN):
            expected = END_SOLUTION if region == BEGIN_SOLUTION else END_HIDDEN
            if region is None or marker != expected:
                raise ValueError(f"{where}: {marker!r} on line {number} has no matching opening marker")
            region = None
            if number == len(lines) and not line.endswith("\n") and out and out[-1].endswith("\n"):
                out[-1] = out[-1][:-1]                # the source ended on the marker: no trailing newline
        elif region is None:
            out.append(line)
    if region is not None:
        closing = END_SOLUTION if region == BEGIN_SOLUTION else END_HIDDEN
        raise ValueError(f"{where}: {region!r} on line {region_line} has no matching {closing!r}")
    return "".join(out), graded


def release_notebook(nb, where: str = "notebook"):
    """The exercise version of a solution notebook (a new notebook; ``nb`` is not modified)."""
    import nbformat                      # imported here: check cells import this module and nbformat is slow
    nb = nbformat.from_dict(copy.deepcopy(dict(nb)))
    for index, cell in enumerate(nb.cells):
        if cell.cell_type not in ("code", "markdown"):
            continue
        cell.source, graded = release_source(cell.source, cell.cell_type, f"{where}, cell {index}")
        is_check = cell.cell_type == "code" and CHECK_CALL.search(cell.source) is not None
        if cell.cell_type == "code" and (graded or is_check):
            cell.outputs, cell.execution_count = [], None
            tags = list(cell.metadata.get("tags", []))
            if EXERCISE_TAG not in tags:
                tags.append(EXERCISE_TAG)
            cell.metadata["tags"] = tags
    return nb


def render_exercise(solution_path: Path) -> str:
    """The exact text ``release`` writes for one solution notebook (stable JSON, trailing newline)."""
    import nbformat
    try:
        raw = json.loads(Path(solution_path).read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        raise ValueError(f"{solution_path} is not a notebook (invalid JSON: {err})") from None
    if (raw.get("nbformat"), raw.get("nbformat_minor", 0)) >= (4, 5):   # ids are required from 4.5 on:
        for index, cell in enumerate(raw.get("cells", [])):            # give missing ones stable names,
            cell.setdefault("id", f"cell-{index}")                      # not nbformat's random ones
    nb = nbformat.reads(json.dumps(raw), as_version=4)
    text = nbformat.writes(release_notebook(nb, where=str(solution_path)))
    return text if text.endswith("\n") else text + "\n"


def plan_release(solutions: Path, exercises: Path) -> tuple[dict[Path, str], list[Path]]:
    """Expected exercise texts keyed by path, and the exercise notebooks that have no solution."""
    expected = {exercises / path.name: render_exercise(path) for path in sorted(solutions.glob("*.ipynb"))}
    existing = sorted(exercises.glob("*.ipynb")) if exercises.is_dir() else []
    return expected, [path for path in existing if path not in expected]


def _drift(expected: dict[Path, str], extra: list[Path]) -> list[str]:
    problems = []
    for path, text in expected.items():
        if not path.exists():
            problems.append(f"missing: {path}")
        elif path.read_bytes() != text.encode("utf-8"):
            problems.append(f"drifted: {path}")
    return problems + [f"extra: {path} (no solution notebook of that name)" for path in extra]


def cli(argv: list[str] | None = None) -> int:
    """``python -m course release [--solutions DIR] [--exercises DIR] [--check]``."""
    parser = argparse.ArgumentParser(prog="python -m course release",
                                     description="Write exercises/ from solutions/, or check they agree.")
    parser.add_argument("--solutions", type=Path, default=Path("solutions"), help="default: solutions")
    parser.add_argument("--exercises", type=Path, default=Path("exercises"), help="default: exercises")
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 and name each notebook that differs from a fresh release")
    args = parser.parse_args(argv)
    if not args.solutions.is_dir():
        print(f"error: no solutions directory at '{args.solutions}' (run from the course root or pass "
              f"--solutions DIR)", file=sys.stderr)
        return 2
    try:
        expected, extra = plan_release(args.solutions, args.exercises)
    except ValueError as err:                          # malformed markers or a file that is not JSON
        print(f"error: {err}", file=sys.stderr)
        return 2
    if args.check:
        problems = _drift(expected, extra)
        for line in problems:
            print(line)
        if len(problems) > len(extra):
            print(f"{args.exercises} differs from a release of {args.solutions}: run `python -m course release`")
        if extra:
            print("remove or rename the extra exercise notebooks")
        if problems:
            return 1
        print(f"{args.exercises} is up to date with {args.solutions} ({len(expected)} notebooks)")
        return 0
    args.exercises.mkdir(parents=True, exist_ok=True)
    for path, text in expected.items():
        if path.exists() and path.read_bytes() == text.encode("utf-8"):
            print(f"up to date: {path}")
        else:
            path.write_bytes(text.encode("utf-8"))
            print(f"wrote {path}")
    for path in extra:
        print(f"warning: {path} has no solution notebook; left as it is", file=sys.stderr)
    return 0
