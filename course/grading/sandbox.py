"""Where a student's code runs while the grader grades it: a worker process of its own, limited, ended completely.

``Worker`` starts ``worker.py`` in a fresh process (``python -c``, a new session, stdin, stdout and stderr on
``/dev/null``, so nothing it leaves behind can hold the grader's output open), in a folder of its own that holds a
copy of the notebook, and talks to it through two pipes (``remote.Endpoint``). It runs the notebook's cells one at a
time, each under a time limit (past it: an interrupt, as Jupyter's; if the cell does not stop within
``GRACE`` seconds, the worker is ended), and looks up the task functions for the grader to call.

``Isolation`` says how far the student's process is held apart from the grader:

* ``user``: the login the student's code runs as. The grader must run as root to switch to it (Gradescope's
  autograder does; ``setup.sh`` creates ``course-student``). That user cannot write the course, the grader's files or
  the results, and ``end`` ends every process of that user, whatever session or parent it has escaped to (it also
  caps the user's processes, ``processes``, against a fork bomb).
* Without a user of its own the student's code runs as the grader's user and **can do what that user can**: change
  the files it can write (the installed course included; the grader fingerprints the course's files and scores a
  notebook that changed them 0, and it imports everything it grades with before any student code runs), read the
  grader's files, start processes. ``end`` ends the worker, its session, the processes it adopted (the worker
  adopts its orphans, Linux) and every process that still carries this run's marker in its environment (a
  double-forked daemon does); a process started with a new, empty environment by a process that then exits is
  out of its reach. Grade untrusted notebooks as root with a user of their own (``course grade --user``).
* ``memory_gb``: the worker's address space (a 30 GB allocation fails in the student's code rather than waking the
  system's out-of-memory killer); ``file_size_mb``: the largest file it may write.

Everything here is Linux and macOS (``/proc`` is read on Linux; on macOS the session and the process group are
ended); Windows is not supported.
"""
from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from .registry import CheckTimeout, PeerGone
from .remote import Endpoint, RemoteFunction, decode

__all__ = ["Isolation", "Worker", "GRACE", "START_TIMEOUT", "end_processes", "end_user_processes"]

GRACE = 3.0                 # seconds a cell has to stop after its interrupt before the worker is ended
START_TIMEOUT = 120.0       # seconds the worker may take to start (imports torch and the course)
_BOOT = "from course.grading.worker import main; main()"
_MARKER = "COURSE_GRADING_RUN"


@dataclass(frozen=True)
class Isolation:
    """How the student's process is held apart (see the module docstring)."""
    user: str | None = None
    memory_gb: float | None = 16.0
    file_size_mb: int | None = 1024
    processes: int | None = 512
    python: str | None = None               # the interpreter the worker runs (default: the grader's own)

    def limits(self) -> dict:
        limits = {"core": 0}
        if self.memory_gb:
            limits["memory"] = int(self.memory_gb * 2 ** 30)
        if self.file_size_mb:
            limits["file_size"] = int(self.file_size_mb * 2 ** 20)
        if self.user and self.processes:
            limits["processes"] = int(self.processes)                   # per user: only with a user of its own
        return limits


def _account(user: str) -> tuple[int, int, str]:
    """(uid, gid, name) of ``user`` (a name or a number); ``ValueError`` when there is no such user or the grader
    cannot switch to it."""
    import pwd
    try:
        entry = pwd.getpwuid(int(user)) if str(user).isdigit() else pwd.getpwnam(str(user))
    except KeyError:
        raise ValueError(f"there is no user {user!r} on this machine (create one: useradd --system --no-create-home "
                         f"{user})") from None
    if entry.pw_uid == 0:
        raise ValueError("the student's code must not run as root: name an unprivileged user")
    if os.geteuid() != 0 and entry.pw_uid != os.geteuid():
        raise ValueError(f"running the student's code as {entry.pw_name} needs the grader to run as root")
    return entry.pw_uid, entry.pw_gid, entry.pw_name


class Worker:
    """One worker process for one notebook (see the module docstring). ``start`` may raise ``PeerGone`` (it died
    while starting) or ``CheckTimeout``."""

    def __init__(self, isolation: Isolation = Isolation(), files: dict | None = None, env: dict | None = None):
        self.isolation, self.files = isolation, dict(files or {})
        self.env = dict(os.environ if env is None else env)
        self.folder: Path | None = None
        self.marker = secrets.token_hex(12)
        self.process: subprocess.Popen | None = None
        self.endpoint: Endpoint | None = None
        self.account = _account(isolation.user) if isolation.user else None

    # -- life
    def start(self) -> None:
        """Start the worker in a new folder holding ``files`` (name -> bytes), and wait until it is ready."""
        self.folder = Path(tempfile.mkdtemp(prefix="course-notebook-"))
        for name, data in self.files.items():
            (self.folder / name).write_bytes(data)
        to_worker, from_grader = os.pipe()
        to_grader, from_worker = os.pipe()
        env = dict(self.env, COURSE_GRADING_WORKER="1", MPLBACKEND="Agg", TQDM_DISABLE="1", PYTHONHASHSEED="0",
                   PYTHONUNBUFFERED="1", **{_MARKER: self.marker})
        options = {}
        if self.account:
            uid, gid, name = self.account
            options = {"user": uid, "group": gid, "extra_groups": []}
            env.update(HOME=str(self.folder), USER=name, LOGNAME=name, MPLCONFIGDIR=str(self.folder / ".matplotlib"))
            os.chown(self.folder, uid, gid)
            for path in self.folder.rglob("*"):
                os.chown(path, uid, gid)
        root = str(Path(__file__).resolve().parents[2])                  # the folder that holds course/
        env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
        argv = [self.isolation.python or sys.executable, "-c", _BOOT, str(to_worker), str(from_worker), json.dumps(self.isolation.limits())]
        try:
            self.process = subprocess.Popen(argv, cwd=self.folder, env=env, stdin=subprocess.DEVNULL,
                                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                            pass_fds=(to_worker, from_worker), start_new_session=True, **options)
        finally:
            os.close(to_worker)
            os.close(from_worker)
        self.endpoint = Endpoint(to_grader, from_grader, trusted=True)
        self.endpoint.deadline = time.monotonic() + START_TIMEOUT
        try:
            message, _ = self.endpoint.receive()
        finally:
            self.endpoint.deadline = None
        if message.get("op") != "ready":
            raise PeerGone("the worker did not start")

    @property
    def alive(self) -> bool:
        return (self.process is not None and self.process.poll() is None and self.endpoint is not None
                and not self.endpoint.gone and not self.endpoint.broken)

    def end(self) -> None:
        """End the worker and every process the student's code started (see the module docstring)."""
        if self.process is None:
            return
        end_processes(self.process.pid, self.marker, self.account[0] if self.account else None)
        try:
            self.process.wait(timeout=5)
        except subprocess.TimeoutExpired:                                 # pragma: no cover (SIGKILL was sent)
            pass
        for fd in (self.endpoint.rfd, self.endpoint.wfd) if self.endpoint else ():
            try:
                os.close(fd)
            except OSError:
                pass
        self.endpoint = None
        if self.folder is not None:
            shutil.rmtree(self.folder, ignore_errors=True)

    def exit_note(self) -> str:
        """Why the worker is gone, in a student's words."""
        if self.process is None:
            return ""
        code = self.process.poll()
        if code is None and self.endpoint is not None and (self.endpoint.gone or self.endpoint.broken):
            # The pipe closes a moment before the process is reaped: a worker whose pipe broke is ending.
            try:
                code = self.process.wait(timeout=2)
            except subprocess.TimeoutExpired:
                code = None
        if code is None:
            return ""
        if code < 0:
            try:
                return f"killed by {signal.Signals(-code).name}"
            except ValueError:
                return f"killed by signal {-code}"
        return f"exit code {code}"

    # -- requests
    def _request(self, message: dict, seconds: float | None):
        self.endpoint.deadline = None if seconds is None else time.monotonic() + seconds
        try:
            reply, buffers = self.endpoint.request(message)
        finally:
            self.endpoint.deadline = None
        value, _ = decode(reply["v"], buffers, self.endpoint, trusted=True)
        return value

    def run_cell(self, source: str, seconds: float) -> tuple[str, str]:
        """Run one cell: ("ok", ""), ("error", summary), ("timeout", ...) when it was interrupted after ``seconds``,
        or ("ended", ...) when the worker had to be ended (it hung through the interrupt, or died)."""
        try:
            value = self._request({"op": "run_cell", "source": source}, seconds)
        except CheckTimeout:
            if self.endpoint.broken_frame:
                self.end()
                return "ended", f"stopped after {seconds:g} s"
            os.kill(self.process.pid, signal.SIGINT)                      # as Jupyter's interrupt
            try:
                self.endpoint.broken = False
                self.endpoint.deadline = time.monotonic() + GRACE
                reply, _ = self.endpoint.request_pending()
            except (CheckTimeout, PeerGone):
                self.end()
                return "ended", f"stopped after {seconds:g} s; it did not stop when interrupted"
            finally:
                if self.endpoint is not None:
                    self.endpoint.deadline = None
            return "timeout", f"stopped after {seconds:g} s"
        except PeerGone:
            note = self.exit_note()
            self.end()
            return "ended", "the process running the notebook died" + (f" ({note})" if note else "")
        return ("ok", "") if value.get("ok") else ("error", str(value.get("error", "")))

    def function(self, name: str) -> RemoteFunction | str:
        """The student's function ``name``, as a ``RemoteFunction``, or why there is none."""
        value = self._request({"op": "lookup", "name": name}, 30.0)
        if isinstance(value, dict) and isinstance(value.get("function"), RemoteFunction):
            return value["function"]
        return str(value.get("missing")) if isinstance(value, dict) else f"{name} could not be found"

    def forget(self) -> None:
        """Drop what both sides keep for a task (objects, autograd graphs)."""
        self.endpoint.forget()
        if self.alive:
            self._request({"op": "forget"}, 30.0)


# ------------------------------------------------------------------------------------- ending processes

def _linux_processes() -> dict[int, dict]:
    """pid -> {ppid, pgrp, session, uid} of every process /proc shows."""
    found = {}
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry.name}/stat").read_text()
            fields = stat[stat.rindex(")") + 2:].split()
            uid = os.stat(f"/proc/{entry.name}").st_uid
        except (OSError, ValueError):
            continue
        found[int(entry.name)] = {"ppid": int(fields[1]), "pgrp": int(fields[2]), "session": int(fields[3]),
                                  "uid": uid, "state": fields[0]}
    return found


def _carries(pid: int, marker: str) -> bool:
    try:
        return f"{_MARKER}={marker}".encode() in Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
    except OSError:
        return False


def _targets(root: int, marker: str, uid: int | None) -> list[int]:
    """The processes to end: every process of ``uid``; or the worker ``root``, its descendants, its session and
    process group, and every process carrying ``marker``."""
    me = os.getpid()
    if not sys.platform.startswith("linux"):
        return [root]
    table = _linux_processes()
    if uid is not None:
        return [pid for pid, p in table.items() if p["uid"] == uid and pid != me and p["state"] != "Z"]
    chosen = {pid for pid, p in table.items() if pid == root or p["session"] == root or p["pgrp"] == root}
    grew = True
    while grew:                                                           # descendants of anything chosen
        before = len(chosen)
        chosen |= {pid for pid, p in table.items() if p["ppid"] in chosen}
        grew = len(chosen) > before
    chosen |= {pid for pid in table if pid not in chosen and _carries(pid, marker)}
    return [pid for pid in chosen if pid != me and table[pid]["state"] != "Z"]


def end_processes(root: int, marker: str, uid: int | None = None, rounds: int = 50) -> None:
    """SIGKILL, until none is left, every process of the student's (see ``_targets``); reaps the worker."""
    if not sys.platform.startswith("linux"):
        if root <= 0:
            return
        for kill in (lambda: os.killpg(root, signal.SIGKILL), lambda: os.kill(root, signal.SIGKILL)):
            try:
                kill()
            except (ProcessLookupError, PermissionError):
                pass
        return
    for _ in range(rounds):
        targets = _targets(root, marker, uid)
        if not targets:
            return
        for pid in targets:
            try:
                os.kill(pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
        for pid in targets:                                               # reap what is ours to reap (the
            if pid == root:                                               # worker is its Popen's to reap)
                continue
            try:
                os.waitpid(pid, os.WNOHANG)
            except ChildProcessError:
                pass
        time.sleep(0.01)


def end_user_processes(user: str) -> None:
    """SIGKILL every process of ``user`` (a user of the students' own; the grader runs as root)."""
    uid = _account(user)[0]
    end_processes(-1, "", uid)
