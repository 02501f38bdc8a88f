"""Grading a class: students read from the paths (per-student folders and nbgrader's submitted/ tree), the
student column in the table, JSON and CSV, the gradebook with one row per student across lectures, the
summary per task, --jobs N giving the same results as one notebook at a time, and two notebooks of one
student and lecture refused with both paths named.

The class is built in tmp_path from the course's own notebooks: solutions score full marks, released exercises
0 (lecture 01's too: it is there to show up in the gradebook), and "carol" hands in the solution with one task's
function redefined to raise, so she loses that task only.
"""
import contextlib
import csv
import io
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest
from nbformat.v4 import new_code_cell

from course.grading import TASKS, tasks_for_lecture
from course.grading.grader import DuplicateSubmission, assign_students, cli, student_of

ROOT = Path(__file__).resolve().parent.parent
FIXTURES = Path(__file__).resolve().parent / "fixtures"
LECTURE03 = "03_rasterization.ipynb"
LECTURE01 = "01_representations_and_transforms.ipynb"
BROKEN = "3.4"                                          # carol's one broken task
TASKS03 = [t.id for t in tasks_for_lecture(3)]
TASK_IDS = [t.id for t in tasks_for_lecture(1)] + TASKS03       # the columns: every task of lectures 01 and 03


def copy(source: Path, target: Path) -> Path:
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(source, target)
    return target


def break_task(path: Path, task_id: str) -> None:
    """Append a cell that redefines task ``task_id``'s function to raise: the grader, which looks the function
    up after every cell has run, scores that task 0 and every other task as before."""
    nb = nbformat.read(str(path), as_version=4)
    name = TASKS[task_id].name
    nb.cells.append(new_code_cell(f"def {name}(*args, **kwargs):\n    raise RuntimeError('carol broke {name}')"))
    nbformat.write(nb, str(path))


@pytest.fixture(scope="module")
def a_class(tmp_path_factory):
    """Four students, five notebooks: alice (lecture 01 unattempted, 03 solved), bob (03, unattempted), carol (03,
    solved but task 3.4 broken), dave (03 unattempted, in nbgrader's submitted/<student>/<assignment>/)."""
    root = tmp_path_factory.mktemp("course")
    notebooks = [
        copy(ROOT / "exercises" / LECTURE01, root / "class" / "alice" / LECTURE01),
        copy(ROOT / "solutions" / LECTURE03, root / "class" / "alice" / LECTURE03),
        copy(ROOT / "exercises" / LECTURE03, root / "class" / "bob" / LECTURE03),
        copy(ROOT / "solutions" / LECTURE03, root / "class" / "carol" / LECTURE03),
        copy(ROOT / "exercises" / LECTURE03, root / "nbgrader" / "submitted" / "dave" / "ps03" / LECTURE03),
    ]
    break_task(notebooks[3], BROKEN)
    return root, notebooks


def grade(notebooks, out: Path, *options):
    """Run the command line; (what it printed, the JSON, the CSV rows, the gradebook rows)."""
    out.mkdir(parents=True, exist_ok=True)
    json_path, csv_path, book_path = out / "grades.json", out / "grades.csv", out / "gradebook.csv"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = cli([str(p) for p in notebooks] + ["--json", str(json_path), "--csv", str(csv_path),
                                                  "--gradebook", str(book_path), "--timeout", "120"]
                   + list(options))
    assert code == 0
    rows = [list(csv.reader(path.read_text(encoding="utf-8").splitlines())) for path in (csv_path, book_path)]
    return printed.getvalue(), json.loads(json_path.read_text(encoding="utf-8")), rows[0], rows[1]


@pytest.fixture(scope="module")
def graded(a_class):
    """The class graded one notebook at a time and three at a time: {jobs: (printed, JSON, CSV, gradebook)}."""
    root, notebooks = a_class
    return {jobs: grade(notebooks, root / f"jobs{jobs}", "--jobs", str(jobs)) for jobs in (1, 3)}


def expected_points(student: str, task_id: str) -> int | None:
    """What each student of ``a_class`` scores on ``task_id`` (None: no notebook of that lecture)."""
    most = TASKS[task_id].points
    if task_id.startswith("1."):
        return 0 if student == "alice" else None
    return {"alice": most, "bob": 0, "carol": 0 if task_id == BROKEN else most, "dave": 0}[student]


# ------------------------------------------------------------------------------ students from paths

def test_the_student_is_the_folder_above_or_nbgraders_student_folder():
    assert student_of(Path("class/alice/03_rasterization.ipynb")) == "alice"
    assert student_of(Path("course/nbgrader/submitted/dave/ps03/03_rasterization.ipynb")) == "dave"
    assert student_of(Path("submitted/03_rasterization.ipynb")) == "submitted"        # too shallow for nbgrader
    assert student_of(Path("exercises/03_rasterization.ipynb")) == "exercises"


def test_two_notebooks_of_one_student_and_lecture_are_refused_naming_both(tmp_path, capsys):
    first = copy(ROOT / "exercises" / LECTURE03, tmp_path / "class" / "alice" / LECTURE03)
    second = copy(ROOT / "exercises" / LECTURE03, tmp_path / "class" / "alice" / "03_rasterization-Copy1.ipynb")
    with pytest.raises(DuplicateSubmission, match="lecture 03 of student 'alice'") as error:
        assign_students([first, second], mode="folder")
    assert str(first) in str(error.value) and str(second) in str(error.value)
    for options in (["--students", "folder"], ["--gradebook", str(tmp_path / "book.csv")]):
        assert cli([str(first), str(second)] + options) == 2                     # refused before any worker
        err = capsys.readouterr().err
        assert str(first) in err and str(second) in err and "grade one of them" in err
    assert not (tmp_path / "book.csv").exists()


def test_nbgraders_layout_names_one_student_across_assignment_folders():
    a = Path("x/submitted/dave/ps03/03_rasterization.ipynb")
    b = Path("x/submitted/dave/ps03-late/03_rasterization.ipynb")
    with pytest.raises(DuplicateSubmission, match="dave"):
        assign_students([a, b], mode="folder")
    submissions, by_student, note = assign_students([a, Path("x/submitted/erin/ps03/03_rasterization.ipynb")])
    assert [s.student for s in submissions] == ["dave", "erin"] and by_student and note == ""


def test_notebooks_side_by_side_in_one_folder_stand_alone_by_default():
    paths = [FIXTURES / "solutions" / "01_demo.ipynb", FIXTURES / "submissions" / "01_wrong.ipynb",
             FIXTURES / "submissions" / "01_cheater.ipynb"]
    submissions, by_student, note = assign_students(paths)                     # auto
    assert not by_student and [s.student for s in submissions] == [str(p) for p in paths]
    assert "01_wrong.ipynb" in note and "01_cheater.ipynb" in note and "--students folder" in note
    submissions, by_student, _ = assign_students(paths[:2])                     # no clash: per-student folders
    assert by_student and [s.student for s in submissions] == ["solutions", "submissions"]
    submissions, by_student, _ = assign_students(paths[:2], mode="notebook")
    assert not by_student and [s.student for s in submissions] == [str(p) for p in paths[:2]]
    assert len(assign_students(paths[:1] * 2)[0]) == 1                           # a path given twice: once


# --------------------------------------------------------------------------------- a class, graded

@pytest.mark.timeout(600)
def test_jobs_3_gives_exactly_the_results_of_one_at_a_time(a_class, graded):
    one, three = graded[1], graded[3]
    assert one == three                                      # stdout (table, reasons, summary), JSON, CSV, book
    assert list(three[1]) == [str(p) for p in a_class[1]]   # JSON in the order given, not of completion


def test_the_table_json_and_csv_carry_the_student(a_class, graded):
    stdout, data, rows, _ = graded[1]
    _, notebooks = a_class
    students = ["alice", "alice", "bob", "carol", "dave"]
    table = stdout.split("\n\n")[0].splitlines()
    assert table[0].split() == ["student", "notebook"] + TASK_IDS + ["total"]
    assert [line.split()[:2] for line in table[1:6]] == [[s, p.name] for s, p in zip(students, notebooks)]
    assert list(data) == [str(p) for p in notebooks]
    for student, (path, results) in zip(students, data.items()):
        assert all(r["student"] == student for r in results)
        assert {r["task"]: r["points"] for r in results} == {
            r["task"]: expected_points(student, r["task"]) for r in results}
    carol = {r["task"]: r for r in data[str(notebooks[3])]}
    assert "carol broke" in carol[BROKEN]["message"]
    assert rows[0][:2] == ["student", "notebook"] and rows[0][-1] == "total"
    assert [row[:2] for row in rows[1:]] == [[s, str(p)] for s, p in zip(students, notebooks)]


def test_the_gradebook_has_one_row_per_student_across_lectures(graded):
    _, _, _, book = graded[1]
    assert book[0] == ["student"] + TASK_IDS + ["total"]
    assert [row[0] for row in book[1:]] == ["alice", "bob", "carol", "dave"]          # one row each, sorted
    for row in book[1:]:
        student, cells = row[0], dict(zip(TASK_IDS, row[1:-1]))
        expected = {i: expected_points(student, i) for i in TASK_IDS}
        assert cells == {i: "" if p is None else str(p) for i, p in expected.items()}   # no notebook: empty
        assert int(row[-1]) == sum(p for p in expected.values() if p is not None)


def test_the_summary_gives_each_tasks_mean_and_distribution(graded):
    stdout = graded[1][0]
    summary = stdout[stdout.index("Summary:"):].splitlines()
    assert "how many students scored 0, 1, 2, ... points" in summary[0]
    top = max(TASKS[i].points for i in TASK_IDS)
    assert summary[1].split() == ["task", "function", "graded", "mean"] + [str(k) for k in range(top + 1)]
    rows = {line.split()[0]: line.split() for line in summary[2:] if line.strip()}
    for task_id in TASK_IDS:
        points = [p for p in (expected_points(s, task_id) for s in ("alice", "bob", "carol", "dave"))
                  if p is not None]
        most = TASKS[task_id].points
        counts = [str(points.count(k)) for k in range(most + 1)]
        assert rows[task_id] == [task_id, TASKS[task_id].name, str(len(points)),
                                 f"{sum(points) / len(points):.2f}/{most}"] + counts
    fraction = {i: float(rows[i][3].split("/")[0]) / TASKS[i].points for i in TASKS03}
    assert min(fraction, key=fraction.get) == BROKEN        # the task the class found hard stands out


def test_jobs_must_be_positive_and_the_progress_bar_obeys_tqdm_disable(tmp_path, capsys):
    notes = tmp_path / "notes.ipynb"                     # no NN_ prefix: no tasks, never run
    notes.write_text("{}", encoding="utf-8")
    assert cli([str(notes), "--jobs", "0"]) == 2 and "--jobs" in capsys.readouterr().err
    shown = {}
    for hidden in (False, True):
        env = {k: v for k, v in os.environ.items() if not k.startswith("TQDM_")} | {"PYTHONPATH": str(ROOT)}
        if hidden:
            env["TQDM_DISABLE"] = "1"
        run = subprocess.run([sys.executable, "-m", "course", "grade", str(notes), "--jobs", "2"], env=env,
                             capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stderr
        shown[hidden] = "grading: 100%" in run.stderr
    assert shown == {False: True, True: False}
