"""Tasks, the registry, and running one check: ``Task``, ``TASKS``, ``task``, ``run_check``, ``check``.

A **task** is one function a student writes (``Task(id="3.2", name="barycentric", points=2, check=...)``).
Its check is written once with the implementation passed in, ``check(impl) -> (points, message)``, and
registered with the ``task`` decorator by the lecture modules (``lecture01`` ...).

``run_check`` scores one implementation and never raises for anything the student's code does: not
attempted (``NotImplementedError``), an exception, or a hang (stopped after a time limit) all score 0
with a one-line reason. Before it runs a check it reads the function's code: a graded function that can
reach the package function it re-implements (``Task.reference``) scores 0 and is told so
(``calls_reference``). ``check`` is the notebook's check cell: it prints ``Task 3.2 barycentric: 2/2``,
followed by an indented hint only when points are lost.
"""
from __future__ import annotations

import functools
import os
import signal
import textwrap
import threading
import time
import types
import warnings
from dataclasses import dataclass, field
from typing import Callable

from .helpers import _is_library, _not_attempted, summarize_exception

__all__ = ["DEFAULT_TIMEOUT", "Task", "Result", "TASKS", "task", "tasks_for_lecture", "CheckTimeout", "PeerGone",
           "run_check",
           "format_result", "check", "calls_reference"]

DEFAULT_TIMEOUT = 10.0          # seconds one task check may take in a notebook


# ---------------------------------------------------------------------------------- records and registry

@dataclass(frozen=True)
class Task:
    """One graded function: ``id`` "3.2" (lecture 3, task 2), ``name`` the function's name in the notebook,
    ``points`` the maximum, ``check(impl) -> (points_earned, message)``, ``hint`` shown when not attempted,
    ``reference`` the package function the task re-implements, ``("course.raster", "inside_triangle")`` (a
    method as ``"Mesh.vertex_normals"``), which the student's function must not call."""
    id: str
    name: str
    points: int
    check: Callable
    hint: str = ""
    reference: tuple[str, str] | None = None


@dataclass(frozen=True)
class Result:
    """The outcome of one check. ``message`` says what to fix ("" when nothing is wrong)."""
    task: str
    name: str
    points: int
    max_points: int
    message: str = ""
    printed: bool = field(default=False, repr=False, compare=False)   # set by check(): shown already

    def _ipython_display_(self):                  # a check cell ending in check(...) shows its line once
        if not self.printed:
            print(repr(self))


TASKS: dict[str, Task] = {}


def task(id: str, name: str, points: int, hint: str = "", reference: tuple[str, str] | None = None):
    """Decorator registering ``check(impl)`` as the check of task ``id``, which re-implements ``reference``."""
    def register(fn):
        TASKS[id] = Task(id, name, points, fn, hint, reference)
        return fn
    return register


def _task_key(task_id: str) -> tuple[int, ...]:
    return tuple(int(part) for part in task_id.split("."))


def tasks_for_lecture(number: int) -> list[Task]:
    """The registered tasks of lecture ``number`` (the ``NN`` of ``NN_topic.ipynb``), in id order."""
    return sorted((t for t in TASKS.values() if _task_key(t.id)[0] == int(number)), key=lambda t: _task_key(t.id))


# ------------------------------------------------------------------------- reading the student's code

def _is_package_module(value) -> bool:
    """``course`` or one of its modules (by name: the grader re-imports fresh copies)."""
    name = getattr(value, "__name__", "") if isinstance(value, types.ModuleType) else ""
    return name == "course" or name.startswith("course.")


def _is_package_function(value) -> bool:
    """A function defined in ``course`` (not the student's own)."""
    module = str(getattr(value, "__module__", None) or "")
    return module == "course" or module.startswith("course.")


def _code_names(code: types.CodeType) -> set[str]:
    """Every global, attribute and imported name a code object and its nested functions mention."""
    names = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            names |= _code_names(const)
    return names


def _referenced_values(fn, names: set[str]) -> list:
    """The objects ``fn`` can reach without running: its globals by name, closure cells, default arguments."""
    values = [fn.__globals__[n] for n in names if n in getattr(fn, "__globals__", {})]
    for cell in getattr(fn, "__closure__", None) or ():
        try:
            values.append(cell.cell_contents)
        except ValueError:                                               # an empty cell
            pass
    values += list(getattr(fn, "__defaults__", None) or ()) + list((getattr(fn, "__kwdefaults__", None) or {}).values())
    return values


def forbidden_call(impl, name: str, functions) -> str | None:
    """A message when ``impl`` can reach one of the package ``functions`` ((module, qualname) pairs) that
    would do the task's work besides its reference (helpers a task forbids too), else None."""
    for module, qualname in functions:
        try:
            reaches = calls_reference(impl, module, qualname)
        except Exception:                                                # an odd object: let the check judge
            reaches = False
        if reaches:
            return (f"{name} calls {module}.{qualname}, which does this task's work for you: write it yourself "
                    "(the task says which package functions you may use)")
    return None


def calls_reference(fn, module: str, qualname: str, _seen=None) -> bool:
    """True when ``fn``'s code can reach the package function ``module.qualname``: the function itself as a
    global, default or closure value, or a ``course`` module (or, for a method, its class) imported or
    reached from ``fn`` together with the reference's name among the names its code uses. Functions the
    student wrote are followed (helpers, ``functools.partial``, callable objects); package functions other
    than the reference are not, since calling them is allowed where a task says so. Static: nothing runs."""
    remote = getattr(type(fn), "reaches", None)
    if remote is not None:                                               # a function in the student's process:
        return bool(remote(fn, module, qualname))                        # read there (``remote.RemoteFunction``)
    seen = set() if _seen is None else _seen
    if id(fn) in seen or len(seen) > 200:
        return False
    seen.add(id(fn))
    owner, _, attr = qualname.rpartition(".")
    if getattr(fn, "__module__", None) == module and getattr(fn, "__qualname__", None) == qualname:
        return True                                                      # the reference itself
    if isinstance(fn, functools.partial):
        return calls_reference(fn.func, module, qualname, seen)
    if isinstance(fn, types.MethodType):
        return calls_reference(fn.__func__, module, qualname, seen)
    code = getattr(fn, "__code__", None)
    if not isinstance(code, types.CodeType):
        call = getattr(type(fn), "__call__", None)                       # a callable object the student made
        if isinstance(call, types.FunctionType) and not _is_package_function(call):
            return calls_reference(call, module, qualname, seen)
        return False
    if _is_package_function(fn) or _is_library(code.co_filename):
        return False                                                     # other package and library functions
    names = _code_names(code)
    mentions = attr in names                                             # e.g. raster.inside_triangle(...)
    if mentions and any(n == "course" or n.startswith("course.") for n in names):
        return True                                                      # import course... inside the function
    for value in _referenced_values(fn, names):
        if _is_package_module(value):
            if mentions:
                return True                                              # raster.inside_triangle, course.raster...
        elif isinstance(value, type) and value.__module__ == module and value.__qualname__ == owner:
            if mentions:
                return True                                              # Mesh(...).vertex_normals()
        elif callable(value) and not isinstance(value, type) and calls_reference(value, module, qualname, seen):
            return True
    return False


# --------------------------------------------------------------------------------- running one check

class CheckTimeout(BaseException):
    """A check ran past its time limit (a BaseException, so ``except Exception`` in student code can't eat it)."""


class PeerGone(BaseException):
    """The process running the student's code has gone (its pipe closed): it died, or was ended (``remote.py``).
    A BaseException, like CheckTimeout, so that no ``except Exception`` between the call and the grader takes it
    for an error of the student's function."""


def _call_with_time_limit(fn, seconds):
    """``fn()``, stopped by ``CheckTimeout`` after ``seconds``. SIGALRM in the main thread (a kernel runs cells
    there); elsewhere the call runs in a daemon thread, which is asked to stop if it overruns."""
    if not seconds or seconds <= 0:
        return fn()
    if hasattr(signal, "SIGALRM") and threading.current_thread() is threading.main_thread():
        def on_alarm(signum, frame):
            raise CheckTimeout(seconds)
        previous = signal.signal(signal.SIGALRM, on_alarm)
        start = time.monotonic()
        outer_delay, outer_interval = signal.setitimer(signal.ITIMER_REAL, seconds)   # a timer already set
        try:                                                                          # (pytest-timeout, ...)
            return fn()
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous if previous is not None else signal.SIG_DFL)
            if outer_delay > 0:                                                       # is set again
                remaining = max(outer_delay - (time.monotonic() - start), 1e-3)
                signal.setitimer(signal.ITIMER_REAL, remaining, outer_interval)
    box: dict = {}

    def target():
        try:
            box["value"] = fn()
        except BaseException as exc:                                      # re-raised in the caller's thread
            box["error"] = exc
    worker = threading.Thread(target=target, daemon=True, name="course-check")
    worker.start()
    worker.join(seconds)
    if worker.is_alive():
        _stop_thread(worker)
        raise CheckTimeout(seconds)
    if "error" in box:
        raise box["error"]
    return box["value"]


def _stop_thread(worker: threading.Thread) -> None:
    """Ask a runaway check thread to stop: CPython raises CheckTimeout in it at its next Python bytecode
    (a loop inside one long C call runs on until that call returns)."""
    try:
        import ctypes
        ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(worker.ident), ctypes.py_object(CheckTimeout))
    except (ImportError, AttributeError):                                  # not CPython: leave it running
        pass
    worker.join(0.1)


def run_check(task_id: str, impl, timeout: float | None = DEFAULT_TIMEOUT, *, allow_reference: bool = False) -> Result:
    """Score ``impl`` on task ``task_id``; never raises for anything the student's code does.

    A function that can reach the task's reference implementation scores 0 (see ``calls_reference``);
    ``allow_reference=True`` skips that test, for the package's own tests that score variants of the
    reference (the grader never sets it)."""
    t = TASKS.get(str(task_id))
    if t is None:
        raise ValueError(f"unknown task {task_id!r}; known tasks: {', '.join(sorted(TASKS, key=_task_key))}")
    if impl is None or not callable(impl):
        return Result(t.id, t.name, 0, t.points, f"{t.name} is not a function (got {type(impl).__name__})")
    if t.reference and not allow_reference:
        module, qualname = t.reference
        try:
            reaches = calls_reference(impl, module, qualname)
        except Exception:                                                # an odd object: let the check judge
            reaches = False
        if reaches:
            return Result(t.id, t.name, 0, t.points,
                          f"{t.name} calls {module}.{qualname}, the package function this task re-implements: "
                          "write it yourself (other package functions are fine where the task says so)")
    limit = getattr(impl, "time_limit", None) or _call_with_time_limit   # a function in another process is
    try:                                                                  # stopped from outside it
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")                               # keep check output deterministic
            points, message = limit(lambda: t.check(impl), timeout)
    except NotImplementedError as exc:
        if not _not_attempted(exc):
            return Result(t.id, t.name, 0, t.points, summarize_exception(exc))
        hint = t.hint or f"write {t.name}, replacing `raise NotImplementedError()`"
        return Result(t.id, t.name, 0, t.points, f"not attempted yet: {hint}")
    except CheckTimeout:
        return Result(t.id, t.name, 0, t.points,
                      f"stopped after {timeout:g} s: {t.name} did not finish (an endless loop?)")
    except PeerGone as gone:
        return Result(t.id, t.name, 0, t.points,
                      f"the process running the notebook died while {t.name} ran ({gone}): out of memory, or "
                      "exit() / os._exit() in the code?")
    except KeyboardInterrupt:
        raise
    except BaseException as exc:                                          # incl. SystemExit from exit()
        return Result(t.id, t.name, 0, t.points, summarize_exception(exc))
    points = max(0, min(int(points), t.points))
    return Result(t.id, t.name, points, t.points, message if points < t.points else "")


MESSAGE_WIDTH = 100             # a check cell's hint is wrapped at words to this many characters


def format_result(result: Result) -> str:
    """``Task 3.2 barycentric: 1/2``, then the message when points were lost, indented on the lines below and
    wrapped at words (``MESSAGE_WIDTH``), each diagnosis (they are joined by "; ") starting a line of its own.
    ``Result.message`` itself stays one line: the grader's score table and JSON hold it as it is."""
    line = f"Task {result.task} {result.name}: {result.points}/{result.max_points}"
    if result.message and (result.points < result.max_points or not result.max_points):
        for diagnosis in _diagnoses(result.message, result.name):
            line += "\n" + textwrap.fill(diagnosis, MESSAGE_WIDTH, initial_indent="    ", subsequent_indent="      ",
                                         break_long_words=False, break_on_hyphens=False)
    return line


def _diagnoses(message: str, name: str) -> list[str]:
    """A message split where ``grade_parts`` joined its diagnoses: at "; " followed by a case's label, which
    names the task's function ``name`` with its arguments ("soft_blend(tiny gamma ...): ...")."""
    return _split_before(message, "; " + name + "(")


def _split_before(text: str, marker: str) -> list[str]:
    pieces = text.split(marker)
    return [pieces[0]] + [marker[2:] + p for p in pieces[1:]]


def _explain_undefined_task_functions() -> None:
    """In IPython, a NameError for a task's function (a check cell run before the cell that defines the
    function, or after a kernel restart) is shown as what to do: "run the cell that defines
    `boundary_term` (task 9.2) first". Other exceptions are shown as IPython shows them. Installed when
    ``course.grading`` is imported (an exercise notebook's first cell); does nothing outside IPython."""
    try:
        from IPython import get_ipython
    except ImportError:
        return
    shell = get_ipython()
    if shell is None or getattr(shell, "_course_name_errors", False):
        return

    def handler(self, etype, value, tb, tb_offset=None):
        name = getattr(value, "name", None)
        tasks = sorted((t for t in TASKS.values() if t.name == name), key=lambda t: _task_key(t.id))
        if tasks:
            ids = " / ".join(t.id for t in tasks)
            value = NameError(f"`{name}` is not defined yet: run the cell that defines `{name}` (task {ids}) "
                              "first, then this cell again")
            value.name = name
            tb = None                                                     # the message says it all
        self.showtraceback((etype, value, tb), tb_offset=tb_offset)

    shell.set_custom_exc((NameError,), handler)
    shell._course_name_errors = True


def check(task_id: str, impl, *, timeout: float | None = DEFAULT_TIMEOUT) -> Result:
    """For notebook check cells: print the score line (and a hint if points were lost); return the Result.

    In the process the grader runs a notebook in (``COURSE_GRADING_WORKER`` set, ``worker.py``) it does nothing:
    the grader runs every check itself, in its own process."""
    if os.environ.get("COURSE_GRADING_WORKER"):
        t = TASKS.get(str(task_id))
        return Result(str(task_id), t.name if t else "?", 0, t.points if t else 0, "checked by the grader",
                      printed=True)
    try:
        result = run_check(task_id, impl, timeout=timeout)
    except KeyboardInterrupt:
        raise
    except BaseException as exc:                                          # unknown id, a broken grader, ...
        t = TASKS.get(str(task_id))
        result = Result(str(task_id), t.name if t else getattr(impl, "__name__", "?"), 0,
                        t.points if t else 0, f"could not check: {summarize_exception(exc)}")
    result = Result(result.task, result.name, result.points, result.max_points, result.message, printed=True)
    print(format_result(result))
    return result
