"""A term's class from one grading run: the roster, due dates and late penalties, the Canvas and Moodle imports,
feedback files and copy flags (course/grading/roster.py, late.py, gradebook.py, feedback.py; ``grade`` options).

Most tests build their records by hand, so no worker starts. One fixture grades a class of four lecture-01
notebooks made from the released exercise (tests/class_fixtures.py): ana and ben answer tasks 1.1 and 1.2
honestly and differently, cat pastes the package's look_at and copies ana's rodrigues with names changed (both
pass: scores unchanged, flags raised), eve hands in the exercise untouched and is not on the roster, and dan is on
the roster without a notebook. ben is late by his file's time, with a day's extension; cat is late by the roster's
submitted column.
"""
import contextlib
import csv
import io
import json
import os
from datetime import datetime, timedelta, timezone
from pathlib import Path

import pytest

from class_fixtures import HONEST, exercise_with, pasted_reference, rename_locals, write
from course.grading import TASKS, Result
from course.grading.feedback import feedback_text, write_feedback
from course.grading.grader import Submission, cli
from course.grading.gradebook import Mark, write_canvas, write_moodle
from course.grading.late import LatePolicy, Lateness, lateness, parse_due
from course.grading.roster import RosterError, Student, read_roster

NAME = "01_representations_and_transforms.ipynb"
DUE = datetime(2025, 3, 14, 23, 59, tzinfo=timezone.utc)
ROSTER = """\ufeffSubmission,Name,ID,Email,Section,canvas_id,login,extension_days,submitted,notes
ana,"Lovelace, Ana",1001,ana@uni.edu,A,501,ana1,,,first row
ben,"Babbage, Ben",1002,ben@uni.edu,B,502,ben2,1,,
cat,"Cat, Cat",1003,cat@uni.edu,A,503,cat3,,2025-03-24T23:59:00+00:00,
dan,"Dan, Dan",1004,dan@uni.edu,B,504,dan4,,,

"""


def roster_file(tmp_path: Path, text: str = ROSTER) -> Path:
    path = tmp_path / "roster.csv"
    path.write_text(text, encoding="utf-8")
    return path


# ------------------------------------------------------------------------------------------------ roster

def test_a_roster_is_read_by_column_name(tmp_path):
    roster = read_roster(roster_file(tmp_path))
    assert list(roster) == ["ana", "ben", "cat", "dan"]                 # the roster's order; blank line skipped
    assert roster["ana"] == Student("ana", "Lovelace, Ana", "1001", "ana@uni.edu", "A", "501", "ana1", 0.0, None)
    assert roster["ben"].extension_days == 1.0
    assert roster["cat"].submitted == datetime(2025, 3, 24, 23, 59, tzinfo=timezone.utc)


@pytest.mark.parametrize("text, words", [
    ("submission,name,id\nana,Ana,1\n", ["no column 'email'", "its columns: 'submission', 'name', 'id'"]),
    ("submission,name,id,email\nana,Ana,1,a@x\nana,Ann,2,b@x\n", ["line 3", "'ana' is listed twice"]),
    ("submission,name,id,email,extension_days\nana,Ana,1,a@x,two\n", ["line 2", "'two' is not a number of days"]),
    ("submission,name,id,email,extension_days\nana,Ana,1,a@x,-1\n", ["extension_days must be 0 or more"]),
    ("submission,name,id,email,submitted\nana,Ana,1,a@x,14/03/2025\n", ["line 2", "'14/03/2025' is not a date"]),
    ("submission,name,id,email\n,Ana,1,a@x\n", ["line 2", "the submission column is empty"]),
    ("submission,name,id,email\nana,Ana,1,a@x\nann,Ana,1,a@x\n", ["line 3", "id '1' is on line 2 too"]),
    ("", ["is empty", "header row"]),
])
def test_a_bad_roster_is_refused_saying_what_to_fix(tmp_path, text, words):
    with pytest.raises(RosterError) as error:
        read_roster(roster_file(tmp_path, text))
    for word in words:
        assert word in str(error.value)
    with pytest.raises(RosterError, match="cannot read the roster"):
        read_roster(tmp_path / "missing.csv")


# ------------------------------------------------------------------------------------------- due dates

def test_due_dates_are_iso_8601_and_a_date_alone_means_the_end_of_that_day():
    assert parse_due("2025-03-14T23:59+00:00") == DUE
    assert parse_due("2025-03-14T23:59Z") == DUE
    assert parse_due("2025-03-14").replace(tzinfo=None) == datetime(2025, 3, 14, 23, 59, 59)
    for bad in ("14.03.2025", "2025-13-01", "tomorrow"):
        with pytest.raises(ValueError, match="--due .* is not a date and time.*ISO 8601"):
            parse_due(bad)


def test_the_penalty_decays_linearly_to_nothing():
    policy = LatePolicy(DUE, days=4)
    assert [policy.factor(d) for d in (-1, 0, 1, 2, 4, 9)] == [1.0, 1.0, 0.75, 0.5, 0.0, 0.0]
    assert LatePolicy(DUE, days=0).factor(0.01) == 0.0 and LatePolicy(DUE, days=0).factor(0) == 1.0


def test_lateness_comes_from_the_roster_else_the_files_time_and_counts_extensions(tmp_path):
    path = tmp_path / NAME
    path.write_text("{}", encoding="utf-8")
    stamp = (DUE + timedelta(days=2)).timestamp()
    os.utime(path, (stamp, stamp))
    policy = LatePolicy(DUE, days=4)
    by_file = lateness(policy, path, None)
    assert (by_file.source, round(by_file.days_late, 6), by_file.factor) == ("file time", 2.0, 0.5)
    extended = lateness(policy, path, Student("x", "X", "1", "x@y", extension_days=1.5))
    assert (round(extended.days_late, 6), extended.factor) == (0.5, 0.875)
    told = lateness(policy, path, Student("x", "X", "1", "x@y", submitted=DUE - timedelta(hours=1)))
    assert (told.source, told.late, told.factor) == ("roster", False, 1.0)


# ----------------------------------------------------------------------------- exports from hand-made marks

def hand_made_marks(tmp_path):
    """ana full marks on time, ben 5/10 half a day late (factor 0.75 with days=2), zed not on the roster."""
    roster = read_roster(roster_file(tmp_path))
    policy = LatePolicy(DUE, days=2)
    results = [Result("1.1", "rodrigues", 2, 2), Result("1.2", "look_at", 3, 3), Result("1.3", "world_to_camera", 0, 2,
               "world_to_camera([[1, 2, 3]]) gives *nothing* <here> | there; world_to_camera(empty): wrong shape"),
               Result("1.4", "vertex_normals", 0, 3, "not attempted yet: write vertex_normals")]
    full = [Result(t.id, t.name, t.points, t.points) for t in (TASKS["1.1"], TASKS["1.2"], TASKS["1.3"], TASKS["1.4"])]
    ben_late = Lateness(DUE + timedelta(days=1.5), "roster", DUE + timedelta(days=1), 0.5, 0.75)
    marks = [Mark(Submission(Path("class/ana") / NAME, "ana", 1), tuple(full), roster["ana"], None),
             Mark(Submission(Path("class/ben") / NAME, "ben", 1), tuple(results), roster["ben"], ben_late),
             Mark(Submission(Path("class/zed") / NAME, "zed", 1), tuple(full), None, None)]
    return roster, policy, marks


def test_canvas_and_moodle_files_have_their_columns_one_row_per_roster_student(tmp_path):
    roster, _, marks = hand_made_marks(tmp_path)
    write_canvas(tmp_path / "canvas.csv", marks, roster)
    write_moodle(tmp_path / "moodle.csv", marks, roster)
    canvas = list(csv.reader((tmp_path / "canvas.csv").read_text(encoding="utf-8").splitlines()))
    moodle = list(csv.reader((tmp_path / "moodle.csv").read_text(encoding="utf-8").splitlines()))
    column = "01_representations_and_transforms"
    assert canvas == [["Student", "ID", "SIS User ID", "SIS Login ID", "Section", column],
                      ["    Points Possible", "", "", "", "", "10"],
                      ["Lovelace, Ana", "501", "1001", "ana1", "A", "10"],
                      ["Babbage, Ben", "502", "1002", "ben2", "B", "3.75"],          # 5 x 0.75, after the penalty
                      ["Cat, Cat", "503", "1003", "cat3", "A", ""],                  # no notebook: left as it is
                      ["Dan, Dan", "504", "1004", "dan4", "B", ""]]                  # zed: not on the roster
    assert moodle == [["ID number", "Email address", column], ["1001", "ana@uni.edu", "10"],
                      ["1002", "ben@uni.edu", "3.75"], ["1003", "cat@uni.edu", ""], ["1004", "dan@uni.edu", ""]]


def test_feedback_gives_each_tasks_points_and_each_diagnosis(tmp_path):
    _, policy, marks = hand_made_marks(tmp_path)
    text = feedback_text(marks[1], policy)
    lines = text.splitlines()
    assert lines[0] == "# 01_representations_and_transforms: 5/10" and "Babbage, Ben" in lines[2]
    assert "**Late:** handed in 0.50 days after your due date" in text and "5 x 0.75 = **3.75** of 10" in text
    assert "| 1.3 | `world_to_camera` | 0/2 |" in lines and "| 1.1 | `rodrigues` | 2/2 |" in lines
    assert "- world_to_camera([[1, 2, 3]]) gives \\*nothing\\* \\<here> \\| there" in lines     # one bullet per
    assert "- world_to_camera(empty): wrong shape" in lines                                 # diagnosis, escaped
    assert "### Task 1.4 `vertex_normals`: 0/3" in lines and "### Task 1.1" not in text
    assert "Every task scored full marks." in feedback_text(marks[0])
    written = write_feedback(tmp_path / "feedback", marks, policy)
    assert [p.relative_to(tmp_path / "feedback").as_posix() for p in written] == [
        "ana/01_representations_and_transforms.md", "ben/01_representations_and_transforms.md",
        "zed/01_representations_and_transforms.md"]
    assert written[1].read_text(encoding="utf-8") == text


# ------------------------------------------------------------------------------ the command line refuses

@pytest.mark.parametrize("options, words", [
    (["--canvas", "c.csv"], ["--canvas needs --roster"]),
    (["--due", "next friday"], ["--due 'next friday' is not a date and time"]),
    (["--late-days", "-1"], ["--late-days", "0 or more"]),
    (["--flags", "f.md", "--flag-threshold", "2"], ["--flag-threshold", "between 0 and 1"]),
])
def test_bad_options_are_refused_before_any_notebook_runs(tmp_path, capsys, options, words):
    notebook = write(exercise_with(NAME, {}), tmp_path / "class" / "ana" / NAME)
    assert cli([str(notebook)] + options) == 2
    err = capsys.readouterr().err
    for word in words:
        assert word in err


def test_a_roster_problem_or_two_notebooks_of_one_student_stop_the_run(tmp_path, capsys):
    first = write(exercise_with(NAME, {}), tmp_path / "class" / "ana" / NAME)
    bad = roster_file(tmp_path, "submission,name,id\nana,Ana,1\n")
    assert cli([str(first), "--roster", str(bad)]) == 2
    assert "no column 'email'" in capsys.readouterr().err
    second = write(exercise_with(NAME, {}), tmp_path / "class" / "ana" / NAME.replace(".ipynb", "-Copy1.ipynb"))
    roster = roster_file(tmp_path, "submission,name,id,email\nana,Ana,1,a@x\n")
    assert cli([str(first), str(second), "--roster", str(roster), "--students", "notebook"]) == 2
    err = capsys.readouterr().err                                   # each on its own, but one student on the roster
    assert "are both lecture 01 of Ana (ana) on the roster" in err and str(first) in err and str(second) in err


# ---------------------------------------------------------------------------------------- a class, graded

def set_time(path: Path, when: datetime) -> None:
    os.utime(path, (when.timestamp(), when.timestamp()))


@pytest.fixture(scope="module")
def graded_class(tmp_path_factory):
    """The class of the module docstring graded once with every option: (stdout, JSON, CSV rows, folder)."""
    root = tmp_path_factory.mktemp("term")
    answers = {
        "ana": {"rodrigues": HONEST["1.1"][0], "look_at": HONEST["1.2"][0]},
        "ben": {"rodrigues": HONEST["1.1"][1], "look_at": HONEST["1.2"][1]},
        "cat": {"rodrigues": rename_locals(HONEST["1.1"][0], prefix="c"),
                "look_at": "from course.tensors import as_tensor, _check_shape\n\n" + pasted_reference("1.2")},
        "eve": {},
    }
    paths = {who: write(exercise_with(NAME, a), root / "class" / who / NAME) for who, a in answers.items()}
    set_time(paths["ana"], DUE - timedelta(days=1))
    set_time(paths["ben"], DUE + timedelta(days=2.5))           # 1.5 days after his extended due date
    set_time(paths["cat"], DUE - timedelta(days=3))             # the roster says 10 days late: it wins
    set_time(paths["eve"], DUE)
    out = root / "out"
    out.mkdir()
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = cli([str(p) for p in paths.values()] + [
            "--roster", str(roster_file(root)), "--due", "2025-03-14T23:59+00:00", "--late-days", "5",
            "--json", str(out / "grades.json"), "--csv", str(out / "grades.csv"), "--canvas", str(out / "canvas.csv"),
            "--moodle", str(out / "moodle.csv"), "--feedback", str(out / "feedback"), "--flags", str(out / "flags.md"),
            "--timeout", "120"])
    assert code == 0
    rows = list(csv.reader((out / "grades.csv").read_text(encoding="utf-8").splitlines()))
    return printed.getvalue(), json.loads((out / "grades.json").read_text(encoding="utf-8")), rows, out


@pytest.mark.timeout(600)
def test_scores_are_unchanged_by_the_flags_and_the_penalty_is_shown_beside_them(graded_class):
    stdout, data, rows, _ = graded_class
    totals = {records[0]["student"]: sum(r["points"] for r in records) for records in data.values()}
    assert totals == {"ana": 5, "ben": 5, "cat": 5, "eve": 0}               # pasting passes; flags change nothing
    ben = next(records for records in data.values() if records[0]["student"] == "ben")
    assert {k: ben[0][k] for k in ("name", "id", "email", "section", "submitted_from", "days_late", "late_factor",
                                   "total", "total_after_penalty")} == {
        "name": "Babbage, Ben", "id": "1002", "email": "ben@uni.edu", "section": "B", "submitted_from": "file time",
        "days_late": 1.5, "late_factor": 0.7, "total": 5, "total_after_penalty": 3.5}
    assert rows[0][:7] == ["student", "notebook", "1.1", "1.2", "1.3", "1.4", "total"]
    assert rows[0][7:] == ["name", "id", "email", "section", "submitted", "submitted_from", "due", "days_late",
                           "late_factor", "total_after_penalty"]
    by_student = {row[0]: dict(zip(rows[0], row)) for row in rows[1:]}
    assert (by_student["cat"]["total"], by_student["cat"]["submitted_from"], by_student["cat"]["late_factor"],
            by_student["cat"]["total_after_penalty"]) == ("5", "roster", "0.0", "0.0")
    assert by_student["eve"]["name"] == "" and by_student["ana"]["days_late"] == "0"
    assert "Late submissions: 2 (due 2025-03-14T23:59+00:00; a submission d days late keeps 1 - d/5" in stdout
    assert "ben 01_representations_and_transforms.ipynb: 1.50 days late" in stdout and "5/10 x 0.70 = 3.5" in stdout
    assert "from 1 student(s) on the roster (empty in the gradebooks): Dan, Dan" in stdout
    assert "not on the roster" in stdout and "class/eve" in stdout


def test_the_lms_files_carry_the_score_after_the_penalty(graded_class):
    *_, out = graded_class
    canvas = list(csv.reader((out / "canvas.csv").read_text(encoding="utf-8").splitlines()))
    moodle = list(csv.reader((out / "moodle.csv").read_text(encoding="utf-8").splitlines()))
    assert [row[0] for row in canvas] == ["Student", "    Points Possible", "Lovelace, Ana", "Babbage, Ben", "Cat, Cat",
                                          "Dan, Dan"]                          # eve: not on the roster, left out
    assert [row[-1] for row in canvas[1:]] == ["10", "5", "3.5", "0", ""]
    assert moodle[1:] == [["1001", "ana@uni.edu", "5"], ["1002", "ben@uni.edu", "3.5"], ["1003", "cat@uni.edu", "0"],
                          ["1004", "dan@uni.edu", ""]]


def test_every_notebook_gets_its_feedback_file(graded_class):
    *_, out = graded_class
    files = sorted(p.relative_to(out / "feedback").as_posix() for p in (out / "feedback").rglob("*.md"))
    assert files == [f"{who}/01_representations_and_transforms.md" for who in ("ana", "ben", "cat", "eve")]
    ana = (out / "feedback" / "ana" / "01_representations_and_transforms.md").read_text(encoding="utf-8")
    assert ana.startswith("# 01_representations_and_transforms: 5/10\n\nLovelace, Ana")
    assert "### Task 1.3 `world_to_camera`: 0/2" in ana and "not attempted yet" in ana and "Late" not in ana
    ben = (out / "feedback" / "ben" / "01_representations_and_transforms.md").read_text(encoding="utf-8")
    assert "5 x 0.70 = **3.5** of 10" in ben
    assert "paste" not in ben and "flag" not in ben.lower()                # flags are for the TA only


def test_the_flags_report_names_the_paste_and_the_copy(graded_class):
    stdout, *_, out = graded_class
    text = (out / "flags.md").read_text(encoding="utf-8")
    headers = [line for line in text.splitlines() if line.startswith("## Task")]
    assert len(headers) in (2, 3) and all("rodrigues" in h or "look_at" in h for h in headers)   # (3: the paste
    # matches the solution notebook too, which is written from the package)
    assert "- left: ana (" in text and "- right: cat (" in text
    assert "- left: cat (" in text and "- right: package course.camera.look_at" in text
    assert "ben" not in text.split("## Not compared")[0]                 # honest work is not flagged
    assert f"copy flags: {len(headers)} pair(s) at or above 0.65" in stdout
