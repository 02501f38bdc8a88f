"""The course as shipped: every lecture has its exercise and solution, exercises match a fresh release,
solutions earn full marks and untouched exercises none, and lectures keep the agreed shape."""
import re
from pathlib import Path

import nbformat
import pytest

from course.grading import tasks_for_lecture
from course.grading.grader import grade_notebook
from course.grading.release import cli as release_cli

ROOT = Path(__file__).resolve().parents[1]
LECTURES = sorted((ROOT / "lectures").glob("[0-9][0-9]_*.ipynb"))


def test_every_lecture_has_an_exercise_and_a_solution_with_three_tasks():
    assert len(LECTURES) >= 4
    for lecture in LECTURES:
        assert (ROOT / "solutions" / lecture.name).exists(), lecture.name
        assert (ROOT / "exercises" / lecture.name).exists(), lecture.name
        assert len(tasks_for_lecture(int(lecture.name[:2]))) >= 3, lecture.name


def test_exercises_match_a_fresh_release(capsys):
    code = release_cli(["--check", "--solutions", str(ROOT / "solutions"), "--exercises", str(ROOT / "exercises")])
    assert code == 0, capsys.readouterr().out


@pytest.mark.parametrize("lecture", LECTURES, ids=lambda p: p.stem)
def test_lecture_shape(lecture):
    nb = nbformat.read(lecture, as_version=4)
    headings = [line for cell in nb.cells if cell.cell_type == "markdown"
                for line in cell.source.splitlines() if line.startswith("#")]
    assert headings[0].startswith(f"# {lecture.name[:2]}")
    for required in ("## Overview", "## You will learn", "## See also"):
        assert required in headings, f"{lecture.name}: no '{required}' heading"
    steps = [h for h in headings if re.match(r"## \d+\. ", h)]
    assert len(steps) >= 3, f"{lecture.name}: fewer than three numbered steps"
    for cell in nb.cells:                                                   # committed with outputs
        if cell.cell_type == "code" and cell.source.strip():
            assert cell.get("execution_count") is not None, f"{lecture.name}: a code cell was never run"


@pytest.mark.parametrize("folder, full", [("solutions", True), ("exercises", False)])
@pytest.mark.parametrize("lecture", LECTURES, ids=lambda p: p.stem[:2])
def test_grades_of_the_shipped_notebooks(lecture, folder, full):
    results = grade_notebook(ROOT / folder / lecture.name, timeout=120)
    tasks = tasks_for_lecture(int(lecture.name[:2]))
    assert [r.task for r in results] == [t.id for t in tasks]               # every task reported
    for r in results:
        if full:
            assert r.points == r.max_points, f"{lecture.name} {r.task}: {r.message}"
        else:
            assert r.points == 0 and "not attempted" in r.message, f"{lecture.name} {r.task}: {r.message}"
