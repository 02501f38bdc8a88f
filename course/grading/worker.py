"""The process that runs a student's notebook for the grader, and nothing else.

``sandbox.start_worker`` starts it as ``python -c "from course.grading.worker import main; main()" RFD WFD LIMITS``:
two pipe ends to the grader and the limits to put on itself (JSON: memory, processes, file size). It sets those
limits, marks itself as the process that adopts its orphans (Linux), starts an IPython shell (the shell Jupyter's
kernel runs, so magics and ``display`` work as in JupyterLab), and then answers the grader's requests
(``remote.Endpoint``) until the grader closes the pipe or ends it:

    run_cell   run one cell of the notebook in the shell (the grader times it, and interrupts or ends the worker
               when it runs too long); answers whether it raised and a one-line summary
    lookup     the student's function of a task, by name, sent back as a handle the grader can call
    reaches    whether a function's code can reach a package function (``registry.calls_reference``)
    forget     drop the objects and autograd graphs kept for the grader (between tasks)

Calls the grader makes through a handle run the student's function here on the arguments it sent, and send back
what it returned (``remote.py``). Everything here runs in the student's process and is trusted for nothing: the
grader computes the expected values and the scores in its own process, from what comes back.

``check()`` cells do nothing here (``COURSE_GRADING_WORKER`` is set): the grader runs the checks itself.
"""
from __future__ import annotations

import json
import os
import sys

__all__ = ["main"]


def _limit_self(limits: dict) -> None:
    """Soft and hard limits on this process and its children, set before any student code runs (a process cannot
    raise its own hard limits again)."""
    import resource
    for key, name in (("memory", "RLIMIT_AS"), ("processes", "RLIMIT_NPROC"), ("file_size", "RLIMIT_FSIZE"),
                      ("core", "RLIMIT_CORE")):
        value = limits.get(key)
        if value is None or not hasattr(resource, name):
            continue
        try:
            resource.setrlimit(getattr(resource, name), (int(value), int(value)))
        except (ValueError, OSError):                                       # a limit lower than in use: skip
            pass
    if sys.platform.startswith("linux"):
        try:
            import ctypes
            ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0)       # PR_SET_CHILD_SUBREAPER: adopt orphans
        except (OSError, AttributeError):
            pass


def _summary(exc: BaseException | None) -> str:
    if exc is None:
        return ""
    from .helpers import summarize_exception
    return summarize_exception(exc)


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    rfd, wfd, limits = int(argv[0]), int(argv[1]), json.loads(argv[2]) if len(argv) > 2 else {}
    _limit_self(limits)
    os.environ["COURSE_GRADING_WORKER"] = "1"
    # The grader stops a hanging cell with SIGINT (as Jupyter does). A process started in the background by a shell
    # without job control (`python -m course grade ... &` in a script, a cron job) inherits SIGINT ignored, and
    # Python then keeps it ignored: every hanging cell would cost its worker. Take the interrupt back.
    import signal
    signal.signal(signal.SIGINT, signal.default_int_handler)

    from IPython.core.interactiveshell import InteractiveShell

    from .registry import calls_reference
    from .remote import Endpoint, PeerGone

    shell = InteractiveShell.instance()
    shell.user_ns["__name__"] = "__main__"

    def run_cell(message):
        result = shell.run_cell(str(message["source"]), store_history=True)
        error = result.error_before_exec or result.error_in_exec
        return {"ok": error is None, "error": _summary(error)}

    def lookup(message):
        name = str(message["name"])
        if name not in shell.user_ns:
            return {"missing": f"{name} is not defined (did its cell run without errors?)"}
        value = shell.user_ns[name]
        if not callable(value) or isinstance(value, type):
            return {"missing": f"{name} is not a function (got {type(value).__name__})"}
        return {"function": value}

    def reaches(message):
        fn = endpoint.exported(int(message["h"]))
        try:
            return bool(calls_reference(fn, str(message["module"]), str(message["qualname"])))
        except Exception:                                                   # an odd object: let the check judge
            return False

    def forget(message):
        endpoint.forget()
        return None

    endpoint = Endpoint(rfd, wfd, trusted=False, handlers={"run_cell": run_cell, "lookup": lookup,
                                                            "reaches": reaches, "forget": forget})
    endpoint.send({"op": "ready", "pid": os.getpid()})
    while True:
        try:
            message, buffers = endpoint.receive()
        except PeerGone:
            os._exit(0)
        except KeyboardInterrupt:                                           # an interrupt that came too late
            continue
        try:
            endpoint.serve(message, buffers)
        except PeerGone:
            os._exit(0)
        except KeyboardInterrupt:
            endpoint.send({"op": "raise", "exc": {"type": "KeyboardInterrupt", "bases": [], "message": "interrupted",
                                                  "frames": []}})
