"""``python -m course lab``: JupyterLab for the course, with the shipped notebooks read-only and a terminal that
finds the course.

Plain ``jupyter lab`` works, but two things go wrong in a lecture hall:

* **Running a lecture dirties the clone.** JupyterLab autosaves an open notebook every 120 s: a lecture that runs
  changes its outputs, widget ids and progress bars, and a lecture longer than 120 s is saved half-run (cells
  without outputs, which nbval then rejects). The lecturer's next ``git pull`` aborts on the modified files.
  Here the notebooks under ``lectures/``, ``exercises/`` and ``solutions/`` are served as *not writable*
  (``CourseContentsManager``): JupyterLab runs them as usual but never autosaves them, marks them read-only, and
  Ctrl+S offers *Save As*, so a copy goes to ``work/`` (git ignores it). Saving onto a shipped notebook is
  refused with a message saying so. Authors who edit the shipped notebooks set ``COURSE_EDIT_SHIPPED=1``.
  Autosave stays on for everything else, a student's ``work/`` above all.
* **The terminal finds another Python.** JupyterLab's terminal is a login shell; a ``~/.bashrc`` that sets up
  pyenv or conda puts its own ``python`` first, and ``python -m course ...`` fails (no torch). Here the terminal
  is bash reading ``course/lab_bashrc``, which sources the user's ``~/.bashrc`` and *then* puts the directory of
  the interpreter that launched the lab first on ``PATH``.

Both come from ``course/jupyter_config/jupyter_server_config.py``, put first on ``JUPYTER_CONFIG_PATH`` for the
JupyterLab process only; nothing is installed into the user's Jupyter settings. Any further arguments go to
``jupyter lab`` (``python -m course lab --no-browser --port 8890``).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CONFIG_DIR = Path(__file__).resolve().parent / "jupyter_config"
BASHRC = Path(__file__).resolve().parent / "lab_bashrc"
SHIPPED = ("lectures", "exercises", "solutions")        # the folders whose notebooks the repository owns
READ_ONLY_MESSAGE = ("{path} is a notebook shipped with the course and is read-only here, so that running it "
                     "leaves the clone clean: File > Save Notebook As... into work/ keeps your copy "
                     "(set COURSE_EDIT_SHIPPED=1 before python -m course lab to edit the shipped notebooks)")

__all__ = ["is_shipped", "lab_environment", "lab_command", "cli", "SHIPPED"]


def is_shipped(path: str) -> bool:
    """True for a notebook the repository ships (``lectures/``, ``exercises/``, ``solutions/``, at any depth below
    them), given its path relative to the lab's root as the contents API writes it (``"lectures/01_x.ipynb"``).
    False when ``COURSE_EDIT_SHIPPED`` is set to anything but "" or "0"."""
    if os.environ.get("COURSE_EDIT_SHIPPED", "") not in ("", "0"):
        return False
    parts = [p for p in str(path).replace("\\", "/").split("/") if p]
    return len(parts) >= 2 and parts[0] in SHIPPED and parts[-1].endswith(".ipynb")


def lab_environment(environ=None) -> dict:
    """The JupyterLab process's environment: the course's Jupyter config first on ``JUPYTER_CONFIG_PATH``, and
    ``COURSE_BIN`` (the directory of this interpreter) for the terminal's start-up file."""
    env = dict(os.environ if environ is None else environ)
    paths = [str(CONFIG_DIR)] + [p for p in env.get("JUPYTER_CONFIG_PATH", "").split(os.pathsep) if p]
    env["JUPYTER_CONFIG_PATH"] = os.pathsep.join(paths)
    env["COURSE_BIN"] = str(Path(sys.executable).parent)
    return env


def lab_command(extra=()) -> list:
    """``python -m jupyter lab`` with this interpreter, started in the course root, plus ``extra`` arguments."""
    return [sys.executable, "-m", "jupyter", "lab", f"--ServerApp.root_dir={ROOT}", *extra]


def cli(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m course lab",
        description="JupyterLab at the course root: the shipped notebooks read-only (run them, save copies into "
                    "work/), a terminal whose python is this one. Other arguments go to jupyter lab.")
    parser.add_argument("--print-command", action="store_true",
                        help="print the command and the environment it sets, and start nothing")
    args, extra = parser.parse_known_args(argv)
    env, command = lab_environment(), lab_command(extra)
    if args.print_command:
        print(" ".join(command))
        print(f"JUPYTER_CONFIG_PATH={env['JUPYTER_CONFIG_PATH']}")
        print(f"COURSE_BIN={env['COURSE_BIN']}")
        return 0
    (ROOT / "work").mkdir(exist_ok=True)                               # where Save As puts copies (git ignores it)
    return subprocess.call(command, env=env, cwd=ROOT)


if __name__ == "__main__":
    sys.exit(cli())
