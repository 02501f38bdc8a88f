"""The Gradescope autograder (course/grading/gradescope.py, ``python -m course gradescope NN``).

Every lecture's autograder builds (no grading: a wheel built once is shipped in each), with Gradescope's layout at
the zip's root and executable scripts. setup.sh needs root and the network, so it is read, not run: it installs
from the zip's own files. run_autograder is run for real on lecture 01, in temporary roots (AUTOGRADER_ROOT) with
this environment's python (AUTOGRADER_PYTHON), for each kind of submission: the solution, a wrong one among
several notebooks, the unmodified exercise, a hostile notebook (writes results.json, calls the reference, edits
the autograder's files), one that ends its process, files that are not notebooks, several notebooks none named
like the exercise, nothing, and a broken notebook file. Each results.json is checked against the fields
Gradescope documents.
"""
import json
import os
import stat
import subprocess
import sys
import zipfile
from pathlib import Path

import nbformat
import pytest
from nbformat.v4 import new_code_cell

from course.grading import tasks_for_lecture
from course.grading.grader import course_files, fingerprint
from course.grading.gradescope import build_wheel, cli, pick_notebook

ROOT = Path(__file__).resolve().parent.parent
NAME = "01_representations_and_transforms.ipynb"
EXERCISES = sorted((ROOT / "exercises").glob("[0-9][0-9]_*.ipynb"))

# Gradescope's results.json (gradescope-autograders.readthedocs.io, "Autograder Specifications")
TOP_FIELDS = {"score", "execution_time", "output", "output_format", "test_output_format", "test_name_format",
              "visibility", "stdout_visibility", "extra_data", "tests", "leaderboard"}
TEST_FIELDS = {"score", "max_score", "status", "name", "name_format", "number", "output", "output_format", "tags",
               "visibility", "extra_data"}
VISIBILITY = {"hidden", "after_due_date", "after_published", "visible"}


def validate(data: dict, lecture: int = 1) -> None:
    """``data`` is a results.json Gradescope accepts, with one test per task of ``lecture`` and the total."""
    assert set(data) <= TOP_FIELDS, set(data) - TOP_FIELDS
    assert isinstance(data["execution_time"], int) and data["execution_time"] >= 0
    assert isinstance(data["output"], str) and data["output"]
    assert data["visibility"] in VISIBILITY and data["stdout_visibility"] in VISIBILITY
    tasks = tasks_for_lecture(lecture)
    assert [t["number"] for t in data["tests"]] == [t.id for t in tasks]
    for test, task in zip(data["tests"], tasks):
        assert set(test) <= TEST_FIELDS, set(test) - TEST_FIELDS
        assert test["name"] == f"Task {task.id} {task.name}" and test["max_score"] == task.points
        assert isinstance(test["score"], (int, float)) and 0 <= test["score"] <= test["max_score"]
        assert test["status"] == ("passed" if test["score"] == test["max_score"] else "failed")
        assert isinstance(test["output"], str) and test["output"] and test["visibility"] in VISIBILITY
    assert data["score"] == sum(t["score"] for t in data["tests"])


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    return build_wheel(tmp_path_factory.mktemp("wheel"))


# ----------------------------------------------------------------------------------------------- build

@pytest.mark.parametrize("exercise", EXERCISES, ids=[p.name[:2] for p in EXERCISES])
def test_every_lectures_autograder_builds(exercise, wheel, tmp_path, capsys):
    out = tmp_path / f"autograder_{exercise.stem}.zip"
    options = ["--exercises", str(ROOT / "exercises"), "--wheel", str(wheel)]
    assert cli([exercise.name[:2], "--out", str(out)] + options) == 0
    assert str(out) in capsys.readouterr().out
    with zipfile.ZipFile(out) as archive:
        names = archive.namelist()
        assert names == ["setup.sh", "run_autograder", "requirements.txt", wheel.name, "autograder.json",
                         f"exercise/{exercise.name}"]                    # Gradescope's two scripts at the root
        modes = {info.filename: stat.S_IMODE(info.external_attr >> 16) for info in archive.infolist()}
        assert modes["setup.sh"] == modes["run_autograder"] == 0o755 and modes["autograder.json"] == 0o644
        config = json.loads(archive.read("autograder.json"))
        assert archive.read(f"exercise/{exercise.name}") == exercise.read_bytes()
        assert archive.read(wheel.name) == wheel.read_bytes()
    lecture = int(exercise.name[:2])
    assert config == {"lecture": lecture, "exercise": exercise.name, "timeout": 60.0, "visibility": "visible",
                      "tasks": [t.id for t in tasks_for_lecture(lecture)], "torch": config["torch"]}


def test_the_command_builds_the_wheel_from_this_checkout(tmp_path):
    out = tmp_path / "ag03"                                       # a folder: the files that would be zipped
    had_build = (ROOT / "build").exists()
    run = subprocess.run([sys.executable, "-m", "course", "gradescope", "3", "--out", str(out), "--visibility",
                          "after_published", "--timeout", "30"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    wheels = list(out.glob("course-*-py3-none-any.whl"))
    assert len(wheels) == 1 and os.access(out / "run_autograder", os.X_OK) and os.access(out / "setup.sh", os.X_OK)
    with zipfile.ZipFile(wheels[0]) as built:
        shipped = built.read("course/grading/gradescope.py")
    assert shipped == (ROOT / "course" / "grading" / "gradescope.py").read_bytes()
    assert json.loads((out / "autograder.json").read_text())["visibility"] == "after_published"
    assert (ROOT / "build").exists() == had_build                 # built from a copy: no build/ in the checkout


def test_setup_installs_python_torch_and_the_course_from_the_zips_files(wheel, tmp_path):
    out = tmp_path / "ag01"
    assert cli(["1", "--out", str(out), "--exercises", str(ROOT / "exercises"), "--wheel", str(wheel)]) == 0
    setup, requirements = (out / "setup.sh").read_text(), (out / "requirements.txt").read_text()
    import torch
    assert requirements.splitlines()[1:] == ["--index-url https://download.pytorch.org/whl/cpu",
                                             f"torch=={torch.__version__.split('+')[0]}"]     # the CPU build, pinned
    pip = [line for line in setup.splitlines() if "pip\" install" in line]
    assert pip == ['"$ROOT/venv/bin/pip" install --no-cache-dir -r "$SOURCE/requirements.txt"',
                   f'"$ROOT/venv/bin/pip" install --no-cache-dir "$SOURCE/{wheel.name}"']   # torch first, then ours
    assert (out / wheel.name).is_file()
    assert not any(word in setup for word in ("http", "curl", "wget", "git "))      # nothing else downloaded
    assert "python3 -m venv \"$ROOT/venv\"" in setup and 'ROOT="${AUTOGRADER_ROOT:-/autograder}"' in setup
    for script in ("setup.sh", "run_autograder"):
        assert subprocess.run(["bash", "-n", str(out / script)]).returncode == 0    # valid bash
    run = (out / "run_autograder").read_text()
    assert 'PYTHON="${AUTOGRADER_PYTHON:-$AUTOGRADER_ROOT/venv/bin/python}"' in run


def test_bad_requests_are_refused_with_a_reason(wheel, tmp_path, capsys):
    options = ["--exercises", str(ROOT / "exercises"), "--wheel", str(wheel)]
    assert cli(["99", "--out", str(tmp_path / "x.zip")] + options) == 2
    assert "no exercise matches '99'; the exercises are: 01_representations" in capsys.readouterr().err
    assert cli(["1", "--out", str(tmp_path / "x.zip"), "--exercises", str(ROOT / "exercises"),
                "--wheel", str(tmp_path / "none.whl")]) == 2
    assert "no wheel at" in capsys.readouterr().err and not (tmp_path / "x.zip").exists()


def test_which_notebook_is_graded(tmp_path):
    folder = tmp_path / "submission"
    assert pick_notebook(folder, NAME)[0] is None                              # nothing at all
    (folder / "__MACOSX").mkdir(parents=True)
    (folder / "__MACOSX" / f"._{NAME}").write_text("x")                          # zip leftovers are not files
    (folder / ".ipynb_checkpoints").mkdir()
    (folder / ".ipynb_checkpoints" / "x-checkpoint.ipynb").write_text("{}")
    assert pick_notebook(folder, NAME) == (None, f"Nothing was submitted. Upload {NAME}, the exercise notebook "
                                                 "with your answers.")
    (folder / "deep").mkdir()
    (folder / "deep" / "mine.ipynb").write_text("{}")
    assert pick_notebook(folder, NAME) == (folder / "deep" / "mine.ipynb", "")        # one notebook, any name
    (folder / NAME).write_text("{}")
    path, message = pick_notebook(folder, NAME)
    assert path == folder / NAME and message.endswith(f"{NAME} was graded, the others not.")


def test_the_course_files_are_fingerprinted(tmp_path):
    names = {p.name for p in course_files()}
    assert {"grader.py", "registry.py", "lecture01.py", "camera.py", "mesh.py", "__init__.py"} <= names
    copy = [tmp_path / "lecture01.py", tmp_path / "gone.py"]
    copy[0].write_text("x = 1\n")
    before = fingerprint(copy)
    assert before[str(copy[1])] == "missing"
    copy[0].write_text("x = 2\n")                                   # what a hostile notebook would do, here on a copy
    after = fingerprint(copy)
    assert after[str(copy[0])] != before[str(copy[0])] and after[str(copy[1])] == "missing"


# ------------------------------------------------------------------------------------- run_autograder

@pytest.fixture(scope="module")
def autograder(wheel, tmp_path_factory):
    """Lecture 01's autograder zip, and a function that runs it on a submission: files -> results.json."""
    zip_path = tmp_path_factory.mktemp("zip") / "autograder.zip"
    assert cli(["1", "--out", str(zip_path), "--exercises", str(ROOT / "exercises"), "--wheel", str(wheel),
                "--timeout", "120"]) == 0
    roots = tmp_path_factory.mktemp("roots")

    def run(kind: str, files: dict[str, bytes]) -> tuple[dict, Path]:
        root = roots / kind
        with zipfile.ZipFile(zip_path) as archive:
            archive.extractall(root / "source")
        for name, data in files.items():
            (root / "submission" / name).parent.mkdir(parents=True, exist_ok=True)
            (root / "submission" / name).write_bytes(data)
        (root / "submission").mkdir(parents=True, exist_ok=True)
        env = dict(os.environ, AUTOGRADER_ROOT=str(root), AUTOGRADER_PYTHON=sys.executable)
        done = subprocess.run(["bash", str(root / "source" / "run_autograder")], env=env, capture_output=True,
                              text=True, timeout=600)
        assert done.returncode == 0, done.stderr
        data = json.loads((root / "results" / "results.json").read_text(encoding="utf-8"))
        validate(data)
        return data, root

    return run


def notebook_bytes(path: Path, extra_cells=()) -> bytes:
    nb = nbformat.read(str(path), as_version=4)
    nb.cells += [new_code_cell(source) for source in extra_cells]
    return nbformat.writes(nb).encode("utf-8")


SOLUTION, EXERCISE = ROOT / "solutions" / NAME, ROOT / "exercises" / NAME
BROKEN = "def vertex_normals(verts, faces):\n    raise RuntimeError('broken on purpose')"
HOSTILE = [
    "import json, os\nroot = os.environ.get('AUTOGRADER_ROOT', '/autograder')\n"
    "os.makedirs(root + '/results', exist_ok=True)\n"
    "json.dump({'score': 999, 'tests': []}, open(root + '/results/results.json', 'w'))",        # fake results
    "config = open(root + '/source/autograder.json').read()\n"                                     # read the config,
    "open(root + '/source/autograder.json', 'w').write(config.replace('\"lecture\": 1', '\"lecture\": 2'))",  # edit it
    "print('Task 1.1 rodrigues: 2/2')\nprint('Task 1.2 look_at: 3/3')",                             # fake lines
    "def look_at(eye, target, up):\n    from course.camera import look_at as reference\n"
    "    return reference(eye, target, up)",                                                         # the reference
]


@pytest.mark.timeout(600)
def test_the_solution_scores_full_marks(autograder):
    data, _ = autograder("correct", {NAME: SOLUTION.read_bytes()})
    assert data["score"] == 10 and data["output"] == f"{NAME}: 10/10 points."
    assert all(t["output"] == "All checks passed." and t["visibility"] == "visible" for t in data["tests"])


@pytest.mark.timeout(600)
def test_a_wrong_notebook_among_several_loses_the_broken_task(autograder):
    data, _ = autograder("wrong", {NAME: notebook_bytes(SOLUTION, [BROKEN]), "scratch.ipynb": EXERCISE.read_bytes()})
    scores = {t["number"]: t["score"] for t in data["tests"]}
    assert scores == {"1.1": 2, "1.2": 3, "1.3": 2, "1.4": 0} and data["score"] == 7
    assert "broken on purpose" in data["tests"][3]["output"]
    assert "You uploaded 2 notebooks" in data["output"] and f"{NAME} was graded, the others not." in data["output"]


def test_the_unmodified_exercise_scores_zero_and_says_why(autograder):
    data, _ = autograder("empty", {NAME: EXERCISE.read_bytes()})
    assert data["score"] == 0 and "the exercise as released, with no answers in it" in data["output"]
    assert all(t["output"].startswith("not attempted: ") for t in data["tests"])


@pytest.mark.timeout(600)
def test_a_hostile_notebook_gains_nothing(autograder):
    data, root = autograder("hostile", {"my answers.ipynb": notebook_bytes(SOLUTION, HOSTILE)})
    scores = {t["number"]: t["score"] for t in data["tests"]}
    assert scores == {"1.1": 2, "1.2": 0, "1.3": 2, "1.4": 3} and data["score"] == 7    # not 999, not lecture 02
    assert data["tests"][1]["output"].startswith("look_at calls course.camera.look_at, the package function")
    assert f"my answers.ipynb was graded as {NAME}." in data["output"]


@pytest.mark.timeout(600)
def test_a_notebook_that_ends_its_process_is_graded_without_that_cell(autograder):
    data, _ = autograder("exits", {NAME: notebook_bytes(SOLUTION, ["import os\nos._exit(0)"])})
    assert data["score"] == 10                        # the cell that ended the worker is skipped on its restart
    broken = notebook_bytes(SOLUTION, ["import os\nos._exit(0)"])
    nb = nbformat.reads(broken.decode(), as_version=4)
    nb.cells.insert(2, new_code_cell("import os\nos.kill(os.getpid(), 9)"))   # before rodrigues' check cell
    data, _ = autograder("killed", {NAME: nbformat.writes(nb).encode()})
    assert data["score"] == 10


@pytest.mark.parametrize("kind, files, words", [
    ("not-a-notebook", {"answers.py": b"def look_at(): pass\n", "notes.txt": b"hi"},
     ["Your submission has no notebook (you uploaded: answers.py, notes.txt)", f"Upload {NAME}"]),
    ("two-unnamed", {"a.ipynb": b"{}", "b.ipynb": b"{}"},
     ["You uploaded 2 notebooks (a.ipynb, b.ipynb)", f"cannot tell which one to grade: upload only {NAME}"]),
    ("nothing", {}, ["Nothing was submitted."]),
    ("not-json", {NAME: b"this is not a notebook"}, [f"{NAME} could not be read as a notebook"]),
])
def test_submissions_that_cannot_be_graded_score_zero_with_a_clear_message(autograder, kind, files, words):
    data, _ = autograder(kind, files)
    assert data["score"] == 0
    for word in words:
        assert word in data["output"]
        assert all(word in t["output"] for t in data["tests"])
