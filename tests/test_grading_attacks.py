"""Attacks on the grader, tried as a determined student would, against lecture 01's real Gradescope autograder.

The autograder is built by ``python -m course gradescope 01`` and laid out as Gradescope lays it out: the zip in a
temporary ``AUTOGRADER_ROOT``/source, the submission in /submission, and the course installed from its own wheel
into a folder of this test's (so attacks that rewrite the installed course rewrite that copy, never the checkout).
Each attack is a cell appended to the unanswered exercise (honestly worth 0) or to the solution (worth 10 when the
attack only adds output); each must score what the notebook honestly earns, never more.

Run as the autograder's own user ("same user", how a TA's laptop grades) and, where this machine allows it (root,
the user ``nobody``, and an interpreter that user can run), as Gradescope runs it: the students' code as a user of
its own.
"""
import json
import os
import shutil
import subprocess
import sys
import threading
import time
import zipfile
from pathlib import Path

import nbformat
import pytest
from nbformat.v4 import new_code_cell

from course.grading.gradescope import build_wheel, cli

ROOT = Path(__file__).resolve().parent.parent
NAME = "01_representations_and_transforms.ipynb"
SOLUTION, EXERCISE = ROOT / "solutions" / NAME, ROOT / "exercises" / NAME
FULL = {"1.1": 2, "1.2": 3, "1.3": 2, "1.4": 3}
ZERO = {task: 0 for task in FULL}

pytestmark = pytest.mark.timeout(900)


def _separate_user_python() -> str | None:
    """An interpreter ``nobody`` can run that imports this environment's packages, when the tests run as root."""
    if not hasattr(os, "geteuid") or os.geteuid() != 0 or not sys.platform.startswith("linux"):
        return None
    import pwd
    try:
        pwd.getpwnam("nobody")
    except KeyError:
        return None
    site = [p for p in sys.path if p.endswith("site-packages")]
    version = f"python{sys.version_info.major}.{sys.version_info.minor}"
    for python in (sys.executable, f"/usr/bin/{version}", f"/usr/local/bin/{version}"):
        if not Path(python).exists():
            continue
        try:                                                              # as the worker will be started
            run = subprocess.run([python, "-c", "import torch, IPython, numpy"], cwd="/tmp", capture_output=True,
                                 env={"PYTHONPATH": os.pathsep.join(site), "HOME": "/tmp"}, user="nobody",
                                 group=pwd.getpwnam("nobody").pw_gid, extra_groups=[])
        except OSError:
            continue
        if run.returncode == 0:
            return python
    return None


SEPARATE = _separate_user_python()
needs_user = pytest.mark.skipif(SEPARATE is None, reason="needs root, the user nobody and an interpreter it can run")


@pytest.fixture(scope="module", autouse=True)
def checkout_untouched():
    """The attacks rewrite the course they are graded with: the copy in the test's folder, never this checkout."""
    from course.grading.grader import course_files, fingerprint
    before = fingerprint(course_files())
    yield
    assert fingerprint(course_files()) == before


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    return build_wheel(tmp_path_factory.mktemp("wheel"))


@pytest.fixture(scope="module")
def zip_path(wheel, tmp_path_factory):
    out = tmp_path_factory.mktemp("zip") / "autograder.zip"
    assert cli(["1", "--out", str(out), "--exercises", str(ROOT / "exercises"), "--wheel", str(wheel),
                "--timeout", "5"]) == 0
    return out


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory):
    """The course installed from the wheel, without its dependencies (those are this environment's)."""
    site = tmp_path_factory.mktemp("site")
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-index", "--target",
                    str(site), str(wheel)], check=True)
    return site


class Run:
    """One run_autograder: its results.json, stdout, when it exited and when its output was closed."""

    def __init__(self, root: Path, data: dict, stdout: str, exited: float, closed: float, site: Path):
        self.root, self.data, self.stdout, self.exited, self.closed, self.site = root, data, stdout, exited, closed, site

    @property
    def scores(self) -> dict:
        return {t["number"]: t["score"] for t in self.data["tests"]}

    def leftovers(self) -> list[int]:
        """Processes still alive whose environment names this run's root."""
        mark = f"AUTOGRADER_ROOT={self.root}".encode()
        found = []
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit() and int(entry.name) != os.getpid():
                try:
                    if mark in (entry / "environ").read_bytes().split(b"\0"):
                        found.append(int(entry.name))
                except OSError:
                    pass
        return found


@pytest.fixture
def autograder(zip_path, installed, tmp_path):
    """Run lecture 01's autograder on a notebook: ``run(notebook_bytes, separate=False) -> Run``."""
    count = iter(range(100))

    def run(notebook: bytes, separate: bool = False) -> Run:
        here = tmp_path / f"run{next(count)}"
        root = here / "autograder"
        with zipfile.ZipFile(zip_path) as archive:
            archive.extractall(root / "source")
        (root / "submission").mkdir(parents=True)
        (root / "submission" / NAME).write_bytes(notebook)
        site = here / "site"
        shutil.copytree(installed, site)                                  # each attack rewrites its own copy
        paths = [str(site)] + [p for p in sys.path if p.endswith("site-packages")]
        env = dict(os.environ, AUTOGRADER_ROOT=str(root), AUTOGRADER_PYTHON=sys.executable,
                   PYTHONPATH=os.pathsep.join(paths), AUTOGRADER_USER="nobody" if separate else "")
        if separate:
            env["AUTOGRADER_WORKER_PYTHON"] = SEPARATE
            for path in [site, here, *here.parents]:                    # nobody reads the installed course
                if path == Path("/"):
                    break
                path.chmod(path.stat().st_mode | 0o005)
        process = subprocess.Popen(["bash", str(root / "source" / "run_autograder")], env=env, cwd=here,
                                   stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        exited = {}
        waiter = threading.Thread(target=lambda: (process.wait(), exited.setdefault("t", time.monotonic())))
        waiter.start()
        stdout = process.stdout.read().decode()                           # returns when the output is closed
        closed = time.monotonic()
        waiter.join()
        assert process.returncode == 0, stdout
        data = json.loads((root / "results" / "results.json").read_text())
        assert f"course from {site}" in stdout                            # graded with the copy, not the checkout
        return Run(root, data, stdout, exited["t"], closed, site)
    return run


def with_cells(path: Path, *sources: str) -> bytes:
    nb = nbformat.read(str(path), as_version=4)
    nb.cells += [new_code_cell(source) for source in sources]
    return nbformat.writes(nb).encode()


def with_answers(path: Path, answers: dict[str, str]) -> bytes:
    """The notebook with the cell defining each function of ``answers`` replaced by that source."""
    nb = nbformat.read(str(path), as_version=4)
    for cell in nb.cells:
        for name, source in answers.items():
            if cell.cell_type == "code" and cell.source.lstrip().startswith(f"def {name}("):
                cell.source = source
    return nbformat.writes(nb).encode()


# ------------------------------------------------------------------------------------------- the attacks

FAKE_LINES = "\n".join(f"Task {t} x: {p}/{p}" for t, p in FULL.items())
FAKE_JSON = json.dumps([{"task": t, "points": p, "max_points": p, "message": ""} for t, p in FULL.items()])

POST_RUN_CELL = f"""\
import sys
def forge(result):                               # after every cell, and after whatever the grader adds
    sys.stdout.write({FAKE_LINES!r} + "\\n" + "0" * 32 + " " + {FAKE_JSON!r} + "\\n")
get_ipython().events.register("post_run_cell", forge)
"""

JSON_DUMPS = f"""\
import json
json.dumps = lambda *args, **kwargs: {FAKE_JSON!r}
"""

# the installed grader's check runner rewritten to give full marks, restored a few seconds later so that a
# fingerprint taken at the end matches
REWRITE_REGISTRY = """\
import pathlib, threading, time
import course.grading.registry as registry
path = pathlib.Path(registry.__file__)
original = path.read_text()
path.write_text(original.replace("points = max(0, min(int(points), t.points))", "points = t.points"))
restore = lambda *args: path.write_text(original)
if DELAY:                                        # later, from a thread
    threading.Thread(target=lambda: (time.sleep(DELAY), restore()), daemon=True).start()
else:                                            # after this cell, as the grader's imports would run
    get_ipython().events.register("post_run_cell", restore)
"""

REWRITE_INIT = """\
import pathlib, course
init = pathlib.Path(course.__file__)
init.write_text(init.read_text() + '''
import course.grading.registry as _registry
_check = _registry.run_check
def _full(task_id, impl, *args, **kwargs):
    result = _check(task_id, impl, *args, **kwargs)
    return _registry.Result(result.task, result.name, result.max_points, result.max_points, "")
_registry.run_check = _full
''')
"""

# shape-correct wrong answers, and the builtins and tensor methods a check compares with made to agree
WRONG = {"rodrigues": "def rodrigues(axis_angle):\n    return torch.eye(3, dtype=axis_angle.dtype)",
         "look_at": "def look_at(eye, target, up):\n    return torch.eye(3, dtype=eye.dtype), -eye",
         "world_to_camera": "def world_to_camera(points, R, t):\n    return points.clone()",
         "vertex_normals": "def vertex_normals(verts, faces):\n    return torch.zeros_like(verts)"}
PATCH_BUILTINS = """\
import builtins, torch
builtins.min = lambda *args, **kwargs: max(*args, **kwargs)
builtins.abs = lambda x: 0 * x
torch.Tensor.any = lambda self, *args, **kwargs: torch.tensor(False)
torch.Tensor.all = lambda self, *args, **kwargs: torch.tensor(True)
torch.allclose = lambda *args, **kwargs: True
"""

LEFT_BEHIND = """\
import json, os, time
root = os.environ.get("AUTOGRADER_ROOT", "/autograder")
grader = os.getppid()
if os.fork() == 0:
    os.setsid()
    if os.fork() == 0:                           # a daemon: a new session, its parent gone
        held = []
        for fd in (1, 2):
            try:
                held.append(open(f"/proc/{grader}/fd/{fd}", "w"))   # hold the autograder's output open
            except OSError:
                pass
        for _ in range(40):
            time.sleep(0.5)
            try:
                os.makedirs(root + "/results", exist_ok=True)
                with open(root + "/results/results.json", "w") as f:
                    json.dump({"score": 999, "tests": []}, f)
            except OSError:
                pass
        os._exit(0)
    os._exit(0)
os.wait()
"""

RETRY_LOOP = """\
import time
def world_to_camera(points, R, t):
    while True:                                  # an ordinary retry loop around a bare except
        try:
            time.sleep(0.05)
            return points @ undefined_name
        except:
            pass
"""

FRAMES = """\
import sys, torch
def rodrigues(axis_angle):                       # look for the grader's expected value up the stack
    frame = sys._getframe(1)
    while frame is not None:
        for value in frame.f_locals.values():
            if isinstance(value, torch.Tensor) and value.shape == (3, 3) and value is not axis_angle:
                return value.clone()
        frame = frame.f_back
    return torch.zeros(3, 3, dtype=axis_angle.dtype)
"""

LIAR = """\
import torch
class Anything:                                  # equal to everything, shaped like the answer
    shape, dtype = (3, 3), torch.float32
    def __eq__(self, other): return True
    def __array__(self, *args, **kwargs): raise RuntimeError
def look_at(eye, target, up):
    return Anything(), Anything()
class Liar(torch.Tensor):                        # a tensor whose comparisons always agree
    def __eq__(self, other): return torch.ones_like(other, dtype=torch.bool)
    def __sub__(self, other): return torch.zeros_like(other)
    def __rsub__(self, other): return torch.zeros_like(other)
def world_to_camera(points, R, t):
    return torch.zeros_like(points).as_subclass(Liar)
"""

HUGE = """\
import torch
def world_to_camera(points, R, t):               # a result too large to send: 2 GB
    return torch.zeros(2**28, dtype=torch.float64)
"""

DISABLE_REFERENCE_RULE = """\
import course.grading.registry as registry
registry.calls_reference = lambda *args, **kwargs: False
from course.mesh import Mesh as Surface
def vertex_normals(verts, faces):                # the reference, with the worker's reading of the rule off
    return Surface(verts, faces).vertex_normals()
"""


def honest(answers: dict[str, str]) -> dict[str, int]:
    """What ``answers`` (function name -> source) earn, each checked here, in this process."""
    import torch

    from course.grading import TASKS, run_check
    namespace = {"torch": torch}
    for source in answers.values():
        exec(source, namespace)
    return {t: run_check(t, namespace[TASKS[t].name]).points for t in FULL}


def test_output_made_in_the_notebook_changes_nothing(autograder):
    attacks = (POST_RUN_CELL, JSON_DUMPS)                                # printed lines, a patched json
    assert autograder(with_cells(EXERCISE, *attacks)).scores == ZERO
    wrong = honest(WRONG)
    assert sum(wrong.values()) < 5
    assert autograder(with_cells(EXERCISE, *WRONG.values(), *attacks)).scores == wrong  # shape-correct, wrong
    assert autograder(with_cells(SOLUTION, *attacks)).scores == FULL


def test_patched_builtins_and_tensor_methods_break_only_the_notebooks_own_process(autograder):
    run = autograder(with_cells(EXERCISE, *WRONG.values(), PATCH_BUILTINS))
    wrong = honest(WRONG)
    assert all(run.scores[t] <= wrong[t] for t in FULL)          # the process that ran the patch is the student's:
    run = autograder(with_cells(SOLUTION, PATCH_BUILTINS))       # what breaks there costs the student, never more
    assert all(run.scores[t] <= FULL[t] for t in FULL)


def test_rewriting_the_installed_grader_and_restoring_it_gains_nothing(autograder):
    quickly, late = REWRITE_REGISTRY.replace("DELAY", "0"), REWRITE_REGISTRY.replace("DELAY", "30")
    run = autograder(with_cells(SOLUTION, *WRONG.values(), quickly))     # the grader had imported it already
    assert run.scores == honest(WRONG)
    run = autograder(with_cells(SOLUTION, *WRONG.values(), late))        # still rewritten when grading ends
    assert run.scores == ZERO and "changed the course's own files (registry.py)" in run.data["tests"][0]["output"]


def test_rewriting_the_course_package_scores_nothing(autograder):
    run = autograder(with_cells(SOLUTION, REWRITE_INIT))                 # a changed course: not graded at all
    assert run.scores == ZERO and "changed the course's own files" in run.data["tests"][0]["output"]


def test_a_left_behind_process_can_neither_rewrite_the_results_nor_hold_the_output(autograder):
    run = autograder(with_cells(EXERCISE, LEFT_BEHIND))
    assert run.closed - run.exited < 1.0                                 # the output closed when it exited
    time.sleep(1.5)                                                      # the daemon would have written by now
    assert json.loads((run.root / "results" / "results.json").read_text()) == run.data
    assert run.scores == ZERO and run.leftovers() == []


def test_a_bare_except_costs_only_its_own_task(autograder):
    start = time.monotonic()
    run = autograder(with_answers(SOLUTION, {"world_to_camera": RETRY_LOOP}))
    assert run.scores == dict(FULL, **{"1.3": 0})
    assert run.data["tests"][2]["output"].startswith("stopped after 5 s")
    assert time.monotonic() - start < 60


def test_hangs_allocations_forks_and_a_killed_process(autograder):
    cells = ["while True:\n    pass",                                     # interrupted after 5 s, not run again
             "import torch\nhuge = torch.ones(30 * 2**30 // 4)",          # 30 GB: refused by the memory limit
             "import os, time\nfor _ in range(50):\n    if os.fork() == 0:\n        time.sleep(300)\n"
             "        os._exit(0)",
             "import os\nos.kill(os.getpid(), 9)"]                         # skipped when the worker restarts
    run = autograder(with_cells(SOLUTION, *cells))
    assert run.scores == FULL
    assert run.leftovers() == []


def test_results_that_lie_or_reach_for_the_grader_score_nothing(autograder):
    answers = {"rodrigues": FRAMES, "look_at": LIAR, "world_to_camera": HUGE, "vertex_normals": DISABLE_REFERENCE_RULE}
    run = autograder(with_answers(SOLUTION, answers))
    assert run.scores == ZERO
    assert "calls course.mesh.Mesh.vertex_normals" in run.data["tests"][3]["output"]


# ---------------------------------------------------------------------------- as Gradescope runs it: a user

@needs_user
def test_as_a_user_of_its_own_the_course_and_the_results_cannot_be_written(autograder):
    writes = """\
import os, pathlib, course
root = os.environ["AUTOGRADER_ROOT"]
denied = []
for path in [pathlib.Path(course.__file__), pathlib.Path(root) / "results" / "results.json",
             pathlib.Path(root) / "source" / "autograder.json"]:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("forged")
    except OSError:
        denied.append(path.name)
assert len(denied) == 3, denied
"""
    run = autograder(with_cells(SOLUTION, writes, LEFT_BEHIND), separate=True)
    assert run.scores == FULL
    assert (run.site / "course" / "__init__.py").read_text() != "forged"
    assert json.loads((run.root / "source" / "autograder.json").read_text())["lecture"] == 1
    assert run.closed - run.exited < 1.0
    time.sleep(1.5)
    assert json.loads((run.root / "results" / "results.json").read_text()) == run.data
    assert run.leftovers() == []
