"""A student's own copy of an exercise: ``python -m course workspace NN``.

``exercises/`` is written by ``python -m course release`` and checked by the tests, so it is no place for
answers. This command copies ``exercises/NN_topic.ipynb`` into ``work/NN_topic.ipynb`` (``work/`` is
ignored by git, and nothing in the course writes there) and prints where it is and how to open it. It
never overwrites: a copy that exists is left as it is, however old, so running the command again is safe.

An exercise that was edited in place (answers written in ``exercises/``) is copied as it is, edits
included; once the copy exists the command says how to restore the released exercise.
"""
from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from course.grading.release import edited_since_release

__all__ = ["find_exercise", "make_workspace", "cli"]


def find_exercise(exercises: Path, which: str) -> Path:
    """The exercise notebook named by a lecture number (``3``, ``03``) or a file name (``03_rasterization``).

    Raises ValueError naming the exercises there are when none or several match.
    """
    notebooks = sorted(exercises.glob("[0-9][0-9]_*.ipynb")) if exercises.is_dir() else []
    if not notebooks:
        raise ValueError(f"no exercise notebooks in '{exercises}' (run from the course root or pass "
                         f"--exercises DIR)")
    name = Path(which).name.removesuffix(".ipynb")
    if name.isdigit():
        matches = [nb for nb in notebooks if int(nb.name[:2]) == int(name)]
    else:
        matches = [nb for nb in notebooks if nb.stem == name or nb.stem.startswith(name)]
    if len(matches) != 1:
        known = ", ".join(nb.stem for nb in notebooks)
        what = "no exercise" if not matches else f"{len(matches)} exercises"
        raise ValueError(f"{what} matches {which!r}; the exercises are: {known}")
    return matches[0]


def make_workspace(exercise: Path, work: Path) -> tuple[Path, bool]:
    """Copy ``exercise`` into the folder ``work`` unless a copy is there already.

    Returns the copy's path and whether it was written now (False: an existing copy was left as it is).
    """
    target = work / exercise.name
    if target.exists():
        return target, False
    work.mkdir(parents=True, exist_ok=True)
    with open(target, "xb") as out, open(exercise, "rb") as src:   # "x": fail rather than overwrite
        shutil.copyfileobj(src, out)
    return target, True


def _report(exercise: Path, target: Path, written: bool) -> None:
    edited = edited_since_release(exercise)
    if written:
        print(f"copied {exercise} to {target}" + (" (as it is now, edits made since its release included)"
                                                  if edited else ""))
    else:
        print(f"{target} exists: left as it is (your work is never overwritten)")
        if edited and target.read_bytes() != exercise.read_bytes():
            print(f"note: {exercise} holds edits that are not in {target}; copy it by hand under another name "
                  f"if you want to keep them")
    print(f"open it from JupyterLab's file browser, or start JupyterLab on it: jupyter lab {target}")
    if edited and (written or target.read_bytes() == exercise.read_bytes()):
        print(f"your edits are safe in {target}; `python -m course release --force` restores {exercise} as "
              f"released")


def cli(argv: list[str] | None = None) -> int:
    """``python -m course workspace NN [NN ...] [--exercises DIR] [--work DIR]``; no NN lists the exercises."""
    parser = argparse.ArgumentParser(
        prog="python -m course workspace",
        description="Copy an exercise into work/, your own folder (never overwritten; ignored by git).")
    parser.add_argument("lectures", nargs="*", metavar="NN",
                        help="lecture number or exercise name, e.g. 03 or 03_rasterization; none: list them")
    parser.add_argument("--exercises", type=Path, default=Path("exercises"), help="default: exercises")
    parser.add_argument("--work", type=Path, default=Path("work"), help="default: work")
    args = parser.parse_args(argv)
    if not args.lectures:
        return _list(args.exercises, args.work)
    try:
        found = [find_exercise(args.exercises, which) for which in args.lectures]
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    for exercise in found:
        _report(exercise, *make_workspace(exercise, args.work))
    return 0


def _list(exercises: Path, work: Path) -> int:
    """Each exercise and whether it has a copy in ``work`` yet."""
    notebooks = sorted(exercises.glob("[0-9][0-9]_*.ipynb")) if exercises.is_dir() else []
    if not notebooks:
        print(f"error: no exercise notebooks in '{exercises}' (run from the course root or pass --exercises DIR)",
              file=sys.stderr)
        return 2
    for exercise in notebooks:
        copy = work / exercise.name
        print(f"{exercise.name[:2]}  {exercise}  " + (f"your copy: {copy}" if copy.exists() else "no copy yet"))
    print("copy one into your own folder with: python -m course workspace NN")
    return 0
