"""What grading one submission costs: ``python -m course bench grading``.

Builds a lecture's Gradescope autograder (``python -m course gradescope NN``) in a temporary root and runs its
``run_autograder`` on the solution notebook, ``--repeat`` times, each in a fresh process as Gradescope runs it: the
whole of one submission (the grader's imports, the worker's start, the notebook's cells, every check). With
``--user NAME`` (as root) the notebook runs as that user, as on Gradescope; without it, as this user. Needs a
checkout (the exercises and solutions).
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["bench_grading", "add_arguments", "run"]

DESCRIPTION = "one Gradescope submission graded end to end: run_autograder on a lecture's solution"
REPEAT = 3


def bench_grading(lecture: int = 1, repeat: int = REPEAT, user: str | None = None, worker_python: str | None = None,
                  out=print) -> list[dict]:
    """Seconds per submission of ``run_autograder`` on the solution of ``lecture`` (one row). ``RuntimeError``
    when the solution does not score full marks (the timing of a failure is no timing)."""
    from ..grading.gradescope import build_autograder
    from ..grading.workspace import find_exercise

    root = Path(__file__).resolve().parents[2]
    exercise = find_exercise(root / "exercises", str(lecture))
    solution = root / "solutions" / exercise.name
    with tempfile.TemporaryDirectory(prefix="bench-grading-") as tmp:
        source = Path(tmp) / "autograder" / "source"
        build_autograder(lecture, source, exercises=root / "exercises")
        (Path(tmp) / "autograder" / "submission").mkdir()
        (Path(tmp) / "autograder" / "submission" / exercise.name).write_bytes(solution.read_bytes())
        env = dict(os.environ, AUTOGRADER_ROOT=str(Path(tmp) / "autograder"), AUTOGRADER_PYTHON=sys.executable,
                   AUTOGRADER_USER=user or "", PYTHONPATH=os.pathsep.join(filter(None, [str(root),
                                                                                       os.environ.get("PYTHONPATH")])),
                   AUTOGRADER_WORKER_PYTHON=worker_python or "")
        times, score = [], None
        for _ in range(repeat):
            start = time.perf_counter()
            done = subprocess.run(["bash", str(source / "run_autograder")], env=env, cwd=tmp, capture_output=True,
                                  text=True, timeout=900)
            times.append(time.perf_counter() - start)
            if done.returncode != 0:
                raise RuntimeError(f"run_autograder failed: {done.stderr[-500:]}")
            data = json.loads((Path(tmp) / "autograder" / "results" / "results.json").read_text())
            score = f"{data['score']}/{sum(t['max_score'] for t in data['tests'])}"
            if data["score"] != sum(t["max_score"] for t in data["tests"]):
                raise RuntimeError(f"the solution scored {score}: {data['tests'][0]['output'][:300]}")
    row = {"lecture": exercise.name, "runs as": user or "this user", "score": score,
           "median_s": statistics.median(times), "min_s": min(times), "max_s": max(times)}
    out(f"{row['lecture']}, the notebook's code as {row['runs as']}: {row['median_s']:.2f} s per submission "
        f"(median of {repeat}; {row['min_s']:.2f}-{row['max_s']:.2f} s), score {score}")
    return [row]


def add_arguments(parser) -> None:
    parser.add_argument("--lecture", type=int, default=1, help="the lecture whose solution is graded (default: 1)")
    parser.add_argument("--user", metavar="NAME",
                        help="run the notebook's code as this user (needs root), as Gradescope's autograder does")
    parser.add_argument("--worker-python", metavar="PATH",
                        help="the interpreter the notebook's worker runs (default: this one; with --user, one that "
                             "user can run)")


def run(args) -> list[dict]:
    return bench_grading(args.lecture, args.repeat or REPEAT, args.user, args.worker_python)
