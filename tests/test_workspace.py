"""`python -m course workspace NN`: a student's own copy of an exercise in work/, never overwritten."""
import shutil
from pathlib import Path

import pytest

from course.grading.release import cli as release_cli
from course.grading.workspace import cli, find_exercise, make_workspace

FIXTURES = Path(__file__).resolve().parent / "fixtures"


@pytest.fixture
def course(tmp_path):
    """A course root with two released exercises (01_demo, 02_more) and no work/ yet."""
    solutions, exercises = tmp_path / "solutions", tmp_path / "exercises"
    shutil.copytree(FIXTURES / "solutions", solutions)
    shutil.copy(solutions / "01_demo.ipynb", solutions / "02_more.ipynb")
    assert release_cli(["--solutions", str(solutions), "--exercises", str(exercises)]) == 0
    return tmp_path


def workspace(root: Path, *args) -> int:
    return cli([*map(str, args), "--exercises", str(root / "exercises"), "--work", str(root / "work")])


def test_copies_the_exercise_into_work_and_says_how_to_open_it(course, capsys):
    assert workspace(course, "01") == 0
    copy = course / "work" / "01_demo.ipynb"
    assert copy.read_bytes() == (course / "exercises" / "01_demo.ipynb").read_bytes()
    out = capsys.readouterr().out
    assert f"copied {course / 'exercises' / '01_demo.ipynb'} to {copy}" in out
    assert f"jupyter lab {copy}" in out
    assert "--force" not in out                                            # nothing to restore


def test_an_existing_copy_is_never_overwritten(course, capsys):
    assert workspace(course, "1") == 0
    copy = course / "work" / "01_demo.ipynb"
    copy.write_text("my answers")
    capsys.readouterr()
    assert workspace(course, "01_demo") == 0
    assert copy.read_text() == "my answers"
    assert "left as it is" in capsys.readouterr().out
    path, written = make_workspace(course / "exercises" / "01_demo.ipynb", course / "work")
    assert (path, written) == (copy, False) and copy.read_text() == "my answers"


def test_an_exercise_edited_in_place_is_copied_with_its_edits(course, capsys):
    exercise = course / "exercises" / "01_demo.ipynb"
    exercise.write_text(exercise.read_text().replace("YOUR ANSWER HERE", "my answer"))
    assert workspace(course, "01") == 0
    assert "my answer" in (course / "work" / "01_demo.ipynb").read_text()
    out = capsys.readouterr().out
    assert "edits made since its release included" in out
    assert "your edits are safe in" in out and "release --force" in out   # only once the copy exists


def test_an_edited_exercise_beside_an_older_copy_is_not_copied_over_it(course, capsys):
    assert workspace(course, "01") == 0
    exercise = course / "exercises" / "01_demo.ipynb"
    exercise.write_text(exercise.read_text().replace("YOUR ANSWER HERE", "my answer"))
    capsys.readouterr()
    assert workspace(course, "01") == 0
    out = capsys.readouterr().out
    assert "my answer" not in (course / "work" / "01_demo.ipynb").read_text()
    assert "holds edits that are not in" in out and "--force" not in out


@pytest.mark.parametrize("which, name", [("2", "02_more"), ("02", "02_more"), ("02_more", "02_more"),
                                         ("exercises/01_demo.ipynb", "01_demo"), ("01_de", "01_demo")])
def test_exercises_are_found_by_number_or_name(course, which, name):
    assert find_exercise(course / "exercises", which).stem == name


@pytest.mark.parametrize("which, words", [("7", "no exercise matches '7'"), ("0", "no exercise"),
                                          ("nowhere", "the exercises are: 01_demo, 02_more")])
def test_an_unknown_exercise_is_a_clear_error(course, capsys, which, words):
    assert workspace(course, which) == 2
    assert words in capsys.readouterr().err
    assert not (course / "work").exists()


def test_no_argument_lists_the_exercises_and_the_copies(course, capsys):
    assert workspace(course, "02") == 0
    capsys.readouterr()
    assert workspace(course) == 0
    out = capsys.readouterr().out
    assert "01_demo.ipynb  no copy yet" in out
    assert f"your copy: {course / 'work' / '02_more.ipynb'}" in out


def test_a_missing_exercises_folder_is_a_clear_error(tmp_path, capsys):
    assert workspace(tmp_path, "01") == 2
    assert "no exercise notebooks in" in capsys.readouterr().err


def test_python_dash_m_course_workspace_dispatches_here(course, capsys):
    from course.__main__ import main
    assert main(["workspace", "02", "--exercises", str(course / "exercises"), "--work", str(course / "w")]) == 0
    assert (course / "w" / "02_more.ipynb").exists()


def test_work_and_the_virtual_environment_are_ignored_by_git():
    lines = (Path(__file__).resolve().parents[1] / ".gitignore").read_text().splitlines()
    assert "/work/" in lines and ".venv/" in lines
