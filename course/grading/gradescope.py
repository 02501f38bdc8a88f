"""A Gradescope autograder for one exercise: ``python -m course gradescope NN [--out FILE.zip | DIR]``.

Gradescope runs an autograder per submission in a container of its own, reruns every submission after a fix and
posts the scores to the LMS; the course provides the autograder. The zip holds, at its root (Gradescope's format)::

    setup.sh             run once when Gradescope builds the image: Python, a virtual environment in
                         /autograder/venv, torch (CPU build, pinned) from requirements.txt, then the course from
                         the wheel in this zip (its dependencies from the package index), every compiled kernel
                         warmed, and ``course-student``, the user the students' code runs as
    run_autograder       run per submission: grades /autograder/submission, writes /autograder/results/results.json
    requirements.txt     torch==<the version this course was built with>, from PyTorch's CPU index
    course-<v>-py3-none-any.whl    the course, built from this checkout when the zip was built
    autograder.json      the lecture, the exercise's file name, the per-cell time limit, the results' visibility
    exercise/NN_topic.ipynb        the exercise as released, to recognise a submission with no answers

Both scripts read the root from ``AUTOGRADER_ROOT`` (default ``/autograder``), so the autograder runs anywhere, and
``run_autograder`` runs ``AUTOGRADER_PYTHON`` (default ``$AUTOGRADER_ROOT/venv/bin/python``): the tests run it on
a temporary root with their own interpreter. ``AUTOGRADER_USER`` names the students' user (default
``course-student``; empty: none), ``AUTOGRADER_WORKER_PYTHON`` the interpreter of the worker that runs the
notebook (default: the autograder's).

What a submission gets (``grade_submission``): the notebook runs with the course's grader (``grade_notebook``: its
cells in a worker process of their own, every check run in the grader's process, per-cell and per-check time
limits), and results.json holds one test per task (``name`` "Task 3.2 barycentric", ``number``, ``score``,
``max_score``, ``status``, ``output``: the diagnosis a check cell prints, ``visibility``), the total ``score``,
the ``execution_time`` and an ``output`` saying which notebook was graded. Which notebook: the only one submitted
(graded under the exercise's name, whatever it was called), or among several the one named like the exercise;
several others, none, a file that is not a notebook, or the exercise unmodified score 0 with the reason in
``output`` and in every test, never a crash.

What is protected (``grader.py`` says how): on Gradescope the autograder runs as root and the notebook's code as
``course-student``, which can write neither the course, nor the autograder's files, nor ``results/``; the scores
are computed in the autograder's own process from plain data; every process of ``course-student`` is ended,
last, before results.json is written, and none of them ever holds the autograder's output (the worker's stdin,
stdout and stderr are ``/dev/null``). Run locally without root (``AUTOGRADER_USER`` empty), the notebook runs as
the autograder's user, with the protections ``sandbox.py`` lists for that case. Gradescope shows you every
submission's files: the copy flags (``python -m course grade ... --flags``) read them for you.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import stat
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

from .release import sources_sha256
from .registry import Result, tasks_for_lecture
from .sandbox import Isolation, end_user_processes
from .workspace import find_exercise

__all__ = ["build_autograder", "build_wheel", "setup_script", "run_script", "run_autograder", "grade_submission",
           "pick_notebook", "results_json", "isolation_here", "VISIBILITY", "STUDENT_USER", "cli"]

VISIBILITY = ("visible", "after_due_date", "after_published", "hidden")      # Gradescope's four settings
CONFIG = "autograder.json"
STUDENT_USER = "course-student"                                               # setup.sh creates it
TORCH_INDEX = "https://download.pytorch.org/whl/cpu"                         # the CPU builds of torch
_SKIPPED = ("__MACOSX", ".ipynb_checkpoints")                                  # zip and Jupyter leftovers


# ---------------------------------------------------------------------------------------- the scripts

def setup_script(wheel: str) -> str:
    """``setup.sh``: everything from the zip's own files (``wheel``: the course's wheel file name), except the
    packages the course depends on, which come from the package index; and the students' own user."""
    return f"""#!/usr/bin/env bash
# Gradescope runs this once, as root, while it builds the autograder's image (python -m course gradescope).
set -euo pipefail
SOURCE="$(cd "$(dirname "$0")" && pwd)"                 # the zip's files: /autograder/source
ROOT="${{AUTOGRADER_ROOT:-/autograder}}"

apt-get update
apt-get install -y --no-install-recommends python3 python3-venv python3-pip
python3 -m venv "$ROOT/venv"
# torch first, pinned: the CPU build (a bare `torch` requirement would fetch a multi-GB CUDA build)
"$ROOT/venv/bin/pip" install --no-cache-dir -r "$SOURCE/requirements.txt"
# the course from the wheel built with this zip; its other dependencies from the package index
"$ROOT/venv/bin/pip" install --no-cache-dir "$SOURCE/{wheel}"
# compile every Numba kernel once, into the image, so that no submission waits for them
"$ROOT/venv/bin/python" -c "from course import kernels; kernels.warm_up()"
# the user the students' code runs as: it can read the course and write only its own folder
id -u {STUDENT_USER} >/dev/null 2>&1 || useradd --system --no-create-home --shell /usr/sbin/nologin {STUDENT_USER}
"""


def run_script() -> str:
    """``run_autograder``: Gradescope copies it to /autograder/run_autograder and runs it per submission."""
    return """#!/usr/bin/env bash
# Gradescope runs this for every submission: grade $AUTOGRADER_ROOT/submission with the course's grader and write
# $AUTOGRADER_ROOT/results/results.json (course/grading/gradescope.py). AUTOGRADER_PYTHON picks the interpreter.
set -uo pipefail
export AUTOGRADER_ROOT="${AUTOGRADER_ROOT:-/autograder}"
PYTHON="${AUTOGRADER_PYTHON:-$AUTOGRADER_ROOT/venv/bin/python}"
export TQDM_DISABLE=1 PYTHONHASHSEED=0
cd "$(dirname "$0")"                 # python -c imports from the folder it starts in first: one the students can't write
exec "$PYTHON" -c 'import sys; from course.grading.gradescope import run_autograder; sys.exit(run_autograder())'
"""


def _torch_version() -> str:
    """The torch this course runs with here, without its local label (2.13.0 for 2.13.0+cpu)."""
    import torch
    return torch.__version__.split("+")[0]


def requirements_text() -> str:
    return (f"# the CPU build of torch, pinned to the version the course was built and tested with\n"
            f"--index-url {TORCH_INDEX}\ntorch=={_torch_version()}\n")


# ---------------------------------------------------------------------------------------------- build

def build_wheel(out_dir) -> Path:
    """Build the course's wheel from this checkout into ``out_dir`` (pip, no network: ``--no-deps --no-index
    --no-build-isolation``) and return its path. The sources are copied to a temporary folder first, so the
    checkout gets no build/ folder. ``ValueError`` when the course is not a checkout (no pyproject.toml)."""
    root = Path(__file__).resolve().parents[2]
    if not (root / "pyproject.toml").is_file():
        raise ValueError(f"the course at {root} is an installed package, not a checkout: build the autograder from a "
                         "clone of the course (or pass --wheel FILE)")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="course-wheel-") as tmp:
        source = Path(tmp) / "course-src"
        source.mkdir()
        for name in ("pyproject.toml", "README.md"):
            shutil.copy2(root / name, source / name)
        shutil.copytree(root / "course", source / "course", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        built = Path(tmp) / "wheel"
        run = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-index", "--no-build-isolation",
                              "--quiet", "--wheel-dir", str(built), str(source)], capture_output=True, text=True)
        wheels = sorted(built.glob("course-*.whl"))
        if run.returncode != 0 or len(wheels) != 1:
            raise RuntimeError(f"building the course's wheel failed:\n{run.stdout}{run.stderr}")
        target = out_dir / wheels[0].name
        shutil.copy2(wheels[0], target)
    return target


def _files(exercise: Path, wheel: Path, timeout: float, visibility: str) -> dict[str, bytes]:
    """The autograder's files, name in the zip -> content."""
    lecture = int(exercise.name[:2])
    config = {"lecture": lecture, "exercise": exercise.name, "timeout": timeout, "visibility": visibility,
              "tasks": [t.id for t in tasks_for_lecture(lecture)], "torch": _torch_version()}
    return {
        "setup.sh": setup_script(wheel.name).encode(),
        "run_autograder": run_script().encode(),
        "requirements.txt": requirements_text().encode(),
        wheel.name: wheel.read_bytes(),
        CONFIG: (json.dumps(config, indent=2) + "\n").encode(),
        f"exercise/{exercise.name}": exercise.read_bytes(),
    }


def build_autograder(which, out, exercises=Path("exercises"), timeout: float = 60.0, visibility: str = "visible",
                     wheel=None) -> Path:
    """Write the autograder of exercise ``which`` (``3``, ``03`` or ``03_rasterization``) to ``out``: a zip when
    ``out`` ends in ``.zip`` (the scripts executable, everything at the zip's root), else a folder of the same
    files. ``wheel``: a course wheel to ship (default: built now from this checkout). Returns ``out``."""
    if visibility not in VISIBILITY:
        raise ValueError(f"visibility must be one of {', '.join(VISIBILITY)}; got {visibility!r}")
    if not timeout > 0:
        raise ValueError(f"the time limit per cell must be positive; got {timeout:g} s")
    if wheel is not None and not Path(wheel).is_file():
        raise ValueError(f"no wheel at {wheel}")
    exercise = find_exercise(Path(exercises), str(which))
    if not tasks_for_lecture(int(exercise.name[:2])):
        raise ValueError(f"{exercise.name} has no graded tasks: there is nothing to autograde")
    out = Path(out)
    with tempfile.TemporaryDirectory(prefix="course-autograder-") as tmp:
        files = _files(exercise, Path(wheel) if wheel else build_wheel(tmp), timeout, visibility)
        if out.suffix == ".zip":
            out.parent.mkdir(parents=True, exist_ok=True)
            with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
                for name, data in files.items():
                    info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
                    executable = name in ("setup.sh", "run_autograder")
                    info.external_attr = ((0o755 if executable else 0o644) | stat.S_IFREG) << 16
                    info.compress_type = zipfile.ZIP_DEFLATED
                    archive.writestr(info, data)
        else:
            for name, data in files.items():
                path = out / name
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_bytes(data)
                if name in ("setup.sh", "run_autograder"):
                    path.chmod(0o755)
    return out


# ---------------------------------------------------------------------------------------------- grade

def _submitted_files(folder: Path) -> list[Path]:
    """Every file a student submitted, however deep (a zip of a folder), without zip or Jupyter leftovers."""
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.rglob("*") if p.is_file()
                  and not any(part in _SKIPPED or part.startswith(".") for part in p.relative_to(folder).parts))


def pick_notebook(folder: Path, expected: str) -> tuple[Path | None, str]:
    """The notebook to grade in the submission ``folder``, and a message for the student ("" when all is plain).

    One notebook: that one, whatever its name. Several: the one named ``expected``. Otherwise None and why: nothing
    submitted, no notebook among the files, or several notebooks and none (or more than one) named ``expected``."""
    files = _submitted_files(folder)
    names = ", ".join(str(p.relative_to(folder)) for p in files)
    notebooks = [p for p in files if p.suffix == ".ipynb"]
    if not files:
        return None, f"Nothing was submitted. Upload {expected}, the exercise notebook with your answers."
    if not notebooks:
        return None, (f"Your submission has no notebook (you uploaded: {names}). Upload {expected}, the exercise "
                      "notebook with your answers (the .ipynb file, not a .py or a PDF).")
    if len(notebooks) == 1:
        return notebooks[0], ""
    exact = [p for p in notebooks if p.name == expected]
    listed = ", ".join(str(p.relative_to(folder)) for p in notebooks)
    if len(exact) == 1:
        return exact[0], f"You uploaded {len(notebooks)} notebooks ({listed}); {expected} was graded, the others not."
    return None, (f"You uploaded {len(notebooks)} notebooks ({listed}) and the autograder cannot tell which one to "
                  f"grade: upload only {expected}.")


def _zero(lecture: int, why: str) -> list[Result]:
    return [Result(t.id, t.name, 0, t.points, why) for t in tasks_for_lecture(lecture)]


def isolation_here() -> Isolation:
    """Who the students' code runs as here: ``AUTOGRADER_USER`` (default ``STUDENT_USER``, which setup.sh creates)
    when the autograder runs as root and that user exists, as on Gradescope; otherwise the autograder's own user
    (a local run: ``sandbox.py`` says what that cannot protect). ``AUTOGRADER_WORKER_PYTHON`` picks the worker's
    interpreter (default: the autograder's)."""
    user = os.environ.get("AUTOGRADER_USER", STUDENT_USER)
    python = os.environ.get("AUTOGRADER_WORKER_PYTHON") or None
    if user and hasattr(os, "geteuid") and os.geteuid() == 0:
        import pwd
        try:
            pwd.getpwnam(user)
            return Isolation(user=user, python=python)
        except KeyError:
            pass
    return Isolation(python=python)


def grade_submission(folder, config: dict, exercise: Path, isolation: Isolation | None = None) \
        -> tuple[list[Result], str]:
    """Grade the submission in ``folder`` for the autograder ``config``: (one Result per task, the message for
    the whole submission). ``exercise``: the released exercise notebook; ``isolation``: who the student's code
    runs as (``isolation_here``)."""
    import nbformat

    from .grader import grade_notebook

    lecture, expected = int(config["lecture"]), str(config["exercise"])
    path, message = pick_notebook(Path(folder), expected)
    if path is None:
        return _zero(lecture, "not graded: " + message), message
    try:
        nb = nbformat.read(str(path), as_version=4)
    except Exception as exc:                                             # not JSON, not a notebook
        why = (f"{path.name} could not be read as a notebook ({type(exc).__name__}): upload the .ipynb file as "
               "Jupyter saved it")
        return _zero(lecture, "not graded: " + why), " ".join(filter(None, [message, why]))
    if sources_sha256(nb) == sources_sha256(nbformat.read(str(exercise), as_version=4)):
        why = (f"{path.name} is the exercise as released, with no answers in it: write each task's function, run "
               "the notebook, save it and upload it again.")
        return _zero(lecture, "not attempted: " + why), " ".join(filter(None, [message, why]))
    notes = [message] if message else []
    if path.name != expected:
        notes.append(f"{path.name} was graded as {expected}.")
    with tempfile.TemporaryDirectory(prefix="submission-") as tmp:      # graded under the exercise's name
        graded = Path(tmp) / expected
        shutil.copyfile(path, graded)
        results = grade_notebook(graded, timeout=float(config.get("timeout", 60.0)), isolation=isolation)
    return results, " ".join(notes)


def results_json(results: list[Result], message: str, config: dict, seconds: float) -> dict:
    """The results.json Gradescope reads: one test per task, the total, the time taken and the message."""
    visibility = str(config.get("visibility", "visible"))
    tests = [{"name": f"Task {r.task} {r.name}", "number": r.task, "score": r.points, "max_score": r.max_points,
              "status": "passed" if r.points == r.max_points else "failed",
              "output": r.message or "All checks passed.", "visibility": visibility} for r in results]
    score, most = sum(r.points for r in results), sum(r.max_points for r in results)
    summary = f"{config['exercise']}: {score}/{most} points."
    return {"score": score, "execution_time": max(0, round(seconds)),
            "output": " ".join(filter(None, [summary, message])), "visibility": visibility,
            "stdout_visibility": "hidden", "tests": tests}


def _write_results(root: Path, data: dict) -> Path:
    """results/results.json, written whole (a temporary file renamed over it, replacing whatever was there)."""
    folder = root / "results"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "results.json"
    tmp = folder / f".results-{os.getpid()}.json"
    tmp.write_text(json.dumps(data, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
    os.replace(tmp, path)
    return path


def run_autograder(root=None) -> int:
    """Grade ``root/submission`` and write ``root/results/results.json`` (root: ``AUTOGRADER_ROOT`` or
    /autograder). Never ends without a results.json: a failure of the autograder itself scores 0 and says so."""
    from .. import kernels

    root = Path(root or os.environ.get("AUTOGRADER_ROOT", "/autograder"))
    start = time.monotonic()
    config = {"exercise": "the exercise", "visibility": "visible"}
    isolation = isolation_here()
    try:
        config = json.loads((root / "source" / CONFIG).read_text(encoding="utf-8"))    # read before anything runs
        exercise = root / "source" / "exercise" / config["exercise"]
        with kernels.using("torch"):                                      # no compiled-kernel cache is read
            results, message = grade_submission(root / "submission", config, exercise, isolation)
    except Exception as exc:                                              # the autograder's own failure
        lecture = config.get("lecture")
        results = _zero(int(lecture), "not graded: the autograder failed") if lecture is not None else []
        message = (f"The autograder itself failed ({type(exc).__name__}: {exc}); this is not your fault: tell your "
                   "instructor.")
    if isolation.user:                                                    # last, before the results: nothing
        end_user_processes(isolation.user)                                # of the student's is left running
    data = results_json(results, message, config, time.monotonic() - start)
    path = _write_results(root, data)
    for r in results:                                                     # stdout: for the instructor
        print(f"Task {r.task} {r.name}: {r.points}/{r.max_points} {r.message}".rstrip())
    print(f"{data['output']}\nwrote {path}")
    print(f"graded with the course from {Path(__file__).resolve().parents[2]}, the students' code running as "
          f"{isolation.user or 'this user (no user of its own: see course/grading/sandbox.py)'}")
    return 0


# ------------------------------------------------------------------------------------------ command line

def cli(argv: list[str] | None = None) -> int:
    """``python -m course gradescope NN [--out FILE.zip|DIR] [--exercises DIR] [--timeout S] [--visibility V]
    [--wheel FILE]``."""
    parser = argparse.ArgumentParser(
        prog="python -m course gradescope",
        description="Build the Gradescope autograder of one exercise: a zip to upload as the assignment's "
                    "autograder (setup.sh, run_autograder, the course's wheel, the exercise).")
    parser.add_argument("lecture", metavar="NN", help="lecture number or exercise name, e.g. 03 or 03_rasterization")
    parser.add_argument("--out", type=Path, metavar="FILE.zip|DIR",
                        help="a zip (ends in .zip) or a folder of the same files (default: autograder_NN_topic.zip)")
    parser.add_argument("--exercises", type=Path, default=Path("exercises"), help="default: exercises")
    parser.add_argument("--timeout", type=float, default=60.0, metavar="SECONDS",
                        help="time limit for each cell of a submission (default: 60); each check gets at most 10 s")
    parser.add_argument("--visibility", choices=VISIBILITY, default="visible",
                        help="when students see the results (Gradescope's setting; default: visible)")
    parser.add_argument("--wheel", type=Path, metavar="FILE",
                        help="ship this course wheel instead of building one from this checkout")
    args = parser.parse_args(argv)
    try:
        exercise = find_exercise(args.exercises, args.lecture)
        out = args.out or Path(f"autograder_{exercise.stem}.zip")
        build_autograder(args.lecture, out, args.exercises, args.timeout, args.visibility, args.wheel)
    except (ValueError, RuntimeError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"wrote {out}: upload it as the autograder of the Gradescope assignment for {exercise.name} "
          f"({sum(t.points for t in tasks_for_lecture(int(exercise.name[:2])))} points)")
    return 0
