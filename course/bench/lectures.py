"""How long each lecture takes to run: ``python -m course bench lectures [--only 09 10 ...]``.

Each lecture notebook (``lectures/NN_*.ipynb``, or ``--folder solutions``) is run top to bottom in a fresh Jupyter
kernel, as *Run All* does in JupyterLab, with the compiled kernels' cache warmed first (``kernels.warm_up`` in a
process of its own, so the first lecture does not pay for compiling). Reported per lecture: the seconds from the
kernel's start to the last cell's end, and its three slowest cells (code cell number as JupyterLab counts cells
from 1, and seconds). ``BUDGET_S`` is what a lecture may take (the README's lecture table quotes these numbers).
The lectures run one after another, never side by side: the machine's cores are the lecture's.
"""
from __future__ import annotations

import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

__all__ = ["BUDGET_S", "run_notebook", "bench_lectures", "add_arguments", "run"]

DESCRIPTION = "each lecture's Run All in a fresh kernel: seconds, and the three slowest cells"
REPEAT = 1
BUDGET_S = 60.0


def _seconds(cell) -> float:
    timing = cell.get("metadata", {}).get("execution", {})
    start, end = timing.get("iopub.execute_input"), timing.get("shell.execute_reply")
    if not start or not end:
        return 0.0
    parse = lambda text: datetime.fromisoformat(text.replace("Z", "+00:00"))  # noqa: E731
    return (parse(end) - parse(start)).total_seconds()


def run_notebook(path: Path, timeout: float = 900.0) -> dict:
    """Run ``path`` in a fresh kernel in its own folder: {"seconds", "cells": [(cell number, seconds)]}."""
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(str(path), as_version=4)
    client = NotebookClient(nb, kernel_name="python3", timeout=timeout, record_timing=True,
                            resources={"metadata": {"path": str(path.parent)}})
    start = time.perf_counter()
    client.execute(stderr=subprocess.DEVNULL)                             # the kernel's own chatter
    seconds = time.perf_counter() - start
    cells = [(number, _seconds(cell)) for number, cell in enumerate(nb.cells, 1) if cell.cell_type == "code"]
    return {"seconds": seconds, "cells": cells}


def bench_lectures(folder: str = "lectures", only=None, out=print) -> list[dict]:
    """One row per notebook of ``folder``: lecture, seconds, over the budget?, slowest three cells."""
    root = Path(__file__).resolve().parents[2] / folder
    if not root.is_dir():
        raise RuntimeError(f"no {folder}/ folder here: run the lectures' benchmark from a checkout of the course")
    subprocess.run([sys.executable, "-c", "from course import kernels; kernels.warm_up()"], check=True,
                   capture_output=True)
    rows = []
    out(f"{'lecture':<42} {'seconds':>8}  slowest cells (cell: seconds)")
    for path in sorted(root.glob("[0-9][0-9]_*.ipynb")):
        if only and not any(path.name.startswith(f"{int(o):02d}_") if str(o).isdigit() else str(o) in path.name
                            for o in only):
            continue
        timing = run_notebook(path)
        slowest = sorted(timing["cells"], key=lambda c: -c[1])[:3]
        row = {"lecture": path.stem, "seconds": round(timing["seconds"], 1), "over_budget": timing["seconds"] > BUDGET_S,
               "slowest": [(n, round(s, 1)) for n, s in slowest]}
        rows.append(row)
        flag = "  over the budget" if row["over_budget"] else ""
        out(f"{path.stem:<42} {timing['seconds']:>8.1f}  " + ", ".join(f"{n}: {s:.1f}" for n, s in slowest) + flag)
    total = sum(r["seconds"] for r in rows)
    out(f"{'all':<42} {total:>8.1f}  (budget {BUDGET_S:g} s a lecture; {sum(r['over_budget'] for r in rows)} over)")
    return rows


def add_arguments(parser) -> None:
    parser.add_argument("--only", nargs="+", metavar="NN", help="only these lectures (numbers or words of the name)")
    parser.add_argument("--folder", default="lectures", choices=["lectures", "solutions", "exercises"],
                        help="which notebooks (default: lectures)")


def run(args) -> list[dict]:
    return bench_lectures(args.folder, args.only)
