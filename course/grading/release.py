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
the outputs and execution counts of graded cells (cells that had a solution region or hidden tests), of
check cells (``check("N.M", ...)``), whose solution scores would mislead a student, and of the cells that use
a graded function (the "use it" cells after the tasks: ``look_at(...)``, a picture of "your shading"), whose
outputs are the solution's and would show a student the answer before they wrote anything. A cell uses a
graded function when it names one, or names a variable that an earlier such cell defined. Those cells are
tagged ``nbval-skip``. Every other cell keeps its outputs.

The output is deterministic: the same solutions give the same bytes, so ``--check`` can tell when
``exercises/`` has drifted from ``solutions/``. Each exercise records in its metadata
(``course_release.sources_sha256``) a hash of its cells' sources as released, so ``release`` can tell an
exercise someone edited since (a student's answers) from one that is merely stale: it refuses to overwrite
an edited exercise unless given ``--force``. Running cells changes outputs only, which is not an edit.
Students work in copies of their own (``python -m course workspace NN``, in ``work/``), where release never
writes.
"""
from __future__ import annotations

import argparse
import ast
import copy
import hashlib
import json
import re
import sys
from pathlib import Path

__all__ = ["release_notebook", "release_source", "render_exercise", "plan_release", "sources_sha256",
           "edited_since_release", "cli", "CHECK_CALL", "RELEASE_KEY"]

BEGIN_SOLUTION, END_SOLUTION = "### BEGIN SOLUTION", "### END SOLUTION"
BEGIN_HIDDEN, END_HIDDEN = "### BEGIN HIDDEN TESTS", "### END HIDDEN TESTS"
STUB_CODE = ("# YOUR CODE HERE", "raise NotImplementedError()")
STUB_MARKDOWN = ("YOUR ANSWER HERE",)
EXERCISE_TAG = "nbval-skip"                       # nbval skips the cell: exercises are not run as tests

CHECK_CALL = re.compile(r"\bcheck\(\s*[\"'](\d+\.\d+)[\"']")   # a check cell: check("3.2", barycentric)
RELEASE_KEY = "course_release"                    # notebook metadata: {"sources_sha256": hash as released}
CELL_MAGIC_OR_SHELL = re.compile(r"^\s*(%%|!)")      # IPython cell magics and shell lines: not Python
LINE_MAGIC = re.compile(r"^(\s*)%\w+\s*")           # %time z = f(1): the Python after the magic's name


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


def _python_tree(source: str):
    """The cell's syntax tree (shell lines and cell magics blanked, line magics' names dropped), or None where
    it is not Python."""
    lines = ["" if CELL_MAGIC_OR_SHELL.match(line) else LINE_MAGIC.sub(r"\1", line) for line in source.splitlines()]
    try:
        return ast.parse("\n".join(lines))
    except SyntaxError:
        return None


def _names_used(source: str) -> set[str]:
    """Every bare name a cell reads (``look_at`` in ``R, t = look_at(...)``; not ``shading.lambert``)."""
    tree = _python_tree(source)
    if tree is None:                                   # not Python: any word that is not an attribute
        return set(re.findall(r"(?<![.\w])([A-Za-z_]\w*)", source))
    return {node.id for node in ast.walk(tree) if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load)}


def _names_defined(source: str) -> set[str]:
    """The names a cell binds at its top level: functions, classes, assignment and loop targets, imports."""
    tree = _python_tree(source)
    if tree is None:
        return set(re.findall(r"^([A-Za-z_]\w*)\s*=", source, flags=re.MULTILINE))
    names = set()
    for statement in tree.body:
        if isinstance(statement, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(statement.name)                  # a function's body binds nothing at the top level
            continue
        for node in ast.walk(statement):
            if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
                names.add(node.id)
            elif isinstance(node, ast.alias):
                names.add((node.asname or node.name).split(".")[0])
    return names


def _clear(cell) -> None:
    """Drop a code cell's outputs and execution count and tag it as not run by nbval."""
    cell.outputs, cell.execution_count = [], None
    tags = list(cell.metadata.get("tags", []))
    if EXERCISE_TAG not in tags:
        tags.append(EXERCISE_TAG)
    cell.metadata["tags"] = tags


def sources_sha256(nb) -> str:
    """A hash of a notebook's cell types and sources: what a student edits (outputs are not hashed)."""
    cells = [[cell.get("cell_type", ""), cell.get("source", "")] for cell in nb.get("cells", [])]
    cells = [[kind, "".join(text) if isinstance(text, list) else text] for kind, text in cells]
    return hashlib.sha256(json.dumps(cells, ensure_ascii=False).encode("utf-8")).hexdigest()


def release_notebook(nb, where: str = "notebook"):
    """The exercise version of a solution notebook (a new notebook; ``nb`` is not modified).

    Clears the outputs of graded cells, check cells and cells that use a graded function (see the module
    docstring), and records the hash of the released sources in ``metadata["course_release"]``.
    """
    import nbformat                      # imported here: check cells import this module and nbformat is slow
    nb = nbformat.from_dict(copy.deepcopy(dict(nb)))
    graded_names: set[str] = set()                     # graded functions and what was computed with them
    for index, cell in enumerate(nb.cells):
        if cell.cell_type not in ("code", "markdown"):
            continue
        cell.source, graded = release_source(cell.source, cell.cell_type, f"{where}, cell {index}")
        if cell.cell_type != "code":
            continue
        is_check = CHECK_CALL.search(cell.source) is not None
        uses_graded = not graded and not is_check and bool(_names_used(cell.source) & graded_names)
        if graded or uses_graded:
            graded_names |= _names_defined(cell.source)
        if graded or is_check or uses_graded:
            _clear(cell)
    nb.metadata[RELEASE_KEY] = {"sources_sha256": sources_sha256(nb)}
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


def edited_since_release(path: Path) -> bool:
    """Whether an exercise notebook's sources differ from those it was released with.

    True as well for a notebook that carries no release record (written by hand, or by a release from
    before records were kept) or that is not a readable notebook: nobody can tell it holds no one's work.
    """
    try:
        nb = json.loads(Path(path).read_text(encoding="utf-8"))
        recorded = nb["metadata"][RELEASE_KEY]["sources_sha256"]
    except (OSError, ValueError, KeyError, TypeError):
        return True
    return sources_sha256(nb) != recorded


def _drift(expected: dict[Path, str], extra: list[Path]) -> tuple[list[str], list[str]]:
    """Stale or missing exercises (safe to release), and exercises edited since they were released."""
    stale, edited = [], []
    for path, text in expected.items():
        if not path.exists():
            stale.append(f"missing: {path}")
        elif path.read_bytes() != text.encode("utf-8"):
            if edited_since_release(path):
                edited.append(f"edited since it was released: {path}")
            else:
                stale.append(f"drifted: {path}")
    return stale + [f"extra: {path} (no solution notebook of that name)" for path in extra], edited


def _check(args, expected: dict[Path, str], extra: list[Path]) -> int:
    """``release --check``: name what differs; advise only commands that keep everyone's edits."""
    stale, edited = _drift(expected, extra)
    for line in stale + edited:
        print(line)
    if len(stale) > len(extra):
        print(f"{args.exercises} differs from a release of {args.solutions}: `python -m course release` "
              f"updates the exercises that were not edited (it never overwrites an edited one)")
    if edited:
        print("an edited exercise may hold a student's answers: `python -m course workspace NN` copies it, "
              "edits included, into work/ (which release never touches) and says what to do next")
    if extra:
        print("remove or rename the extra exercise notebooks")
    if stale or edited:
        return 1
    print(f"{args.exercises} is up to date with {args.solutions} ({len(expected)} notebooks)")
    return 0


def _write(args, expected: dict[Path, str], extra: list[Path]) -> int:
    """``release``: write each exercise that differs, unless it was edited since it was released."""
    args.exercises.mkdir(parents=True, exist_ok=True)
    refused = []
    for path, text in expected.items():
        if path.exists() and path.read_bytes() == text.encode("utf-8"):
            print(f"up to date: {path}")
        elif path.exists() and not args.force and edited_since_release(path):
            refused.append(path)
        else:
            path.write_bytes(text.encode("utf-8"))
            print(f"wrote {path}")
    for path in extra:
        print(f"warning: {path} has no solution notebook; left as it is", file=sys.stderr)
    for path in refused:
        print(f"refused: {path} was edited since it was released (or carries no release record), so it may "
              f"hold someone's answers; left as it is. Copy it first (`python -m course workspace "
              f"{path.name[:2]}` copies it into work/), then pass --force to overwrite it", file=sys.stderr)
    return 1 if refused else 0


def cli(argv: list[str] | None = None) -> int:
    """``python -m course release [--solutions DIR] [--exercises DIR] [--check] [--force]``."""
    parser = argparse.ArgumentParser(prog="python -m course release",
                                     description="Write exercises/ from solutions/, or check they agree.")
    parser.add_argument("--solutions", type=Path, default=Path("solutions"), help="default: solutions")
    parser.add_argument("--exercises", type=Path, default=Path("exercises"), help="default: exercises")
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 and name each notebook that differs from a fresh release")
    parser.add_argument("--force", action="store_true",
                        help="also overwrite exercises edited since they were released (their edits are lost)")
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
    return _check(args, expected, extra) if args.check else _write(args, expected, extra)
