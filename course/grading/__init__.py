"""Graded exercises: what a notebook's check cell imports, and the tasks of every lecture, registered.

In a notebook a check cell reads ``from course.grading import check`` and ``check("3.2", barycentric)``, and
prints one deterministic line, ``Task 3.2 barycentric: 2/2``, followed by an indented hint only when points
are lost. It never crashes the notebook: not attempted (``NotImplementedError``), an exception, or a hang
(stopped after a time limit) all score 0 with a one-line reason.

The package, one module per job; each imports only the modules above it in this list, never this one::

    helpers.py     the helpers checks are written with: compare, require / Fail, grade_parts, _diagnose, ...
    registry.py    Task, Result, the TASKS registry and its ``task`` decorator, run_check, check, format_result
    lecture01.py   the checks of lecture 1's tasks (1.1-1.4), registered on import; likewise lecture02-15
    release.py     ``python -m course release``: exercises/ written from solutions/
    submissions.py who handed in a notebook (Submission, student_of) and its lecture
    roster.py      the class list: names, ids, emails, sections, extensions (``grade --roster``)
    late.py        due dates and the linear late penalty (``grade --due --late-days``)
    remote.py      calls across a process boundary in plain data, autograd included: how the grader calls a
                   student's function that runs in another process
    sandbox.py     that process: a worker of its own, limited, as a user of its own where it can be, ended whole
    worker.py      what runs in it: the notebook's cells in an IPython shell, and the grader's requests
    reading.py     the notebook's code read, never run: the reference rule, lines worth a TA's reading
    grader.py      ``python -m course grade``: whole notebooks scored by the grader (and how far to trust it)
    gradebook.py   a grading run's exports: Canvas and Moodle imports, the roster's and lateness columns
    feedback.py    one Markdown file per notebook to return to its student (``grade --feedback``)
    flags.py       copy flags for the TA: code like the package's or a classmate's (``grade --flags``)
    gradescope.py  ``python -m course gradescope NN``: a Gradescope autograder zip, and what it runs per submission

Importing ``course.grading`` imports all of them, so every task is registered; the names below are the ones
notebooks, tests and the command line use.
"""
from .helpers import Fail, compare, generator, grade_parts, require, summarize_exception, to_tensor
from .registry import (DEFAULT_TIMEOUT, TASKS, CheckTimeout, Result, Task, check, format_result, run_check, task,
                       tasks_for_lecture)
from . import lecture01, lecture02, lecture03, lecture04, lecture05, lecture06  # noqa: F401  (importing them
from . import lecture07, lecture08, lecture09, lecture10, lecture11  # noqa: F401   registers every task)
from . import lecture12, lecture13, lecture14, lecture15  # noqa: F401
from .grader import cli, grade_notebook
from .registry import _explain_undefined_task_functions

_explain_undefined_task_functions()          # in a notebook: "run the cell that defines `f` first", not a NameError

__all__ = [
    "Task", "Result", "TASKS", "task", "tasks_for_lecture", "Fail", "CheckTimeout", "require", "grade_parts",
    "to_tensor", "compare", "generator", "summarize_exception", "run_check", "check", "format_result",
    "grade_notebook", "cli", "DEFAULT_TIMEOUT",
]
