"""What a student reads in a check cell: each diagnosis once per task, wrapped at words, and a check cell run
before its function's cell says which cell to run instead of a bare NameError."""
import nbformat
import pytest
import torch
from nbformat.v4 import new_code_cell, new_notebook

from course.grading import Fail, Result, check, format_result, grade_parts
from course.grading.registry import MESSAGE_WIDTH


def test_a_mistake_is_said_once_whatever_the_cases_numbers():
    def shape(n):
        raise Fail(f"case {n}: shape ({n},) expected, got ()")
    earned, message = grade_parts((1, "a", lambda: shape(4)), (1, "b", lambda: shape(3)),
                                  (1, "c", lambda: (_ for _ in ()).throw(Fail("case c: wrong sign"))))
    assert earned == 0
    assert message == "case 4: shape (4,) expected, got (); case c: wrong sign"


def test_a_long_message_is_wrapped_at_words_one_diagnosis_per_line():
    words = " ".join(f"word{i}" for i in range(60))
    message = f"soft_blend(case one): {words}; soft_blend(case two): short"
    text = format_result(Result("8.3", "soft_blend", 1, 3, message))
    lines = text.splitlines()
    assert lines[0] == "Task 8.3 soft_blend: 1/3"
    assert all(len(line) <= MESSAGE_WIDTH for line in lines)
    assert lines[1].startswith("    soft_blend(case one): word0")
    assert lines[-1] == "    soft_blend(case two): short"
    assert " ".join(line.strip() for line in lines[1:-1]) == f"soft_blend(case one): {words}"
    assert format_result(Result("8.3", "soft_blend", 3, 3, "")) == "Task 8.3 soft_blend: 3/3"


def test_a_check_cell_prints_its_score_once(capsys):
    def rodrigues(axis_angle):
        return torch.eye(3, dtype=torch.as_tensor(axis_angle).dtype)       # no rotation at all
    result = check("1.1", rodrigues)
    out = capsys.readouterr().out
    assert out.count("Task 1.1") == 1 and result.points < result.max_points
    result._ipython_display_()                                              # the cell's value: not shown again
    assert capsys.readouterr().out == ""


@pytest.mark.timeout(120)
def test_a_check_cell_run_before_its_function_says_which_cell_to_run():
    nbclient = pytest.importorskip("nbclient")
    nb = new_notebook(cells=[new_code_cell("from course.grading import check"),
                             new_code_cell('check("1.2", look_at)'),
                             new_code_cell("not_a_task_function + 1"),
                             new_code_cell("print('the notebook goes on')")])
    nbclient.NotebookClient(nb, kernel_name="python3", allow_errors=True, timeout=60).execute()
    error = nb.cells[1].outputs[0]
    assert error["ename"] == "NameError"
    assert error["evalue"].startswith("`look_at` is not defined yet: run the cell that defines `look_at` "
                                      "(task 1.2) first")
    other = nb.cells[2].outputs[0]                                          # any other name: as IPython says it
    assert other["ename"] == "NameError" and other["evalue"] == "name 'not_a_task_function' is not defined"
    assert nb.cells[3].outputs[0]["text"] == "the notebook goes on\n"


def test_a_student_grades_their_own_work_under_their_own_name(tmp_path):
    from pathlib import Path

    from course.grading.grader import DuplicateSubmission, _table, one_student
    a, b = tmp_path / "work" / "01_representations_and_transforms.ipynb", tmp_path / "work" / "03_rasterization.ipynb"
    subs = one_student([a, b, a], "Ada Lovelace")
    assert [(s.path, s.student, s.lecture) for s in subs] == [(a, "Ada Lovelace", 1), (b, "Ada Lovelace", 3)]
    table = _table([(subs[0], [Result("1.1", "rodrigues", 2, 2)])], ["1.1"], True)
    assert table.splitlines()[1].split()[:2] == ["Ada", "Lovelace"]
    with pytest.raises(DuplicateSubmission, match="both lecture 01 of student 'Ada'"):
        one_student([a, Path("solutions/01_representations_and_transforms.ipynb")], "Ada")
    with pytest.raises(ValueError, match="--student needs a name"):
        one_student([a], "  ")
