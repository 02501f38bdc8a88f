"""Release: exercises/ is written from solutions/ — solution regions become stubs, hidden tests go, graded
and check cells lose their outputs, the bytes are the same on every run, and --check finds drift."""
import copy
import json
import shutil
from pathlib import Path

import nbformat
import pytest

from course.grading.release import cli, release_notebook, release_source, render_exercise

FIXTURES = Path(__file__).resolve().parent / "fixtures"
SOLUTIONS, EXERCISES = FIXTURES / "solutions", FIXTURES / "exercises"


# ------------------------------------------------------------------------------------------ one cell

def test_solution_region_becomes_a_stub_at_the_begin_marker_indentation():
    source = ("def f(x):\n    if x:\n        ### BEGIN SOLUTION\n        return 1\n        ### END SOLUTION\n"
              "    return 0")
    out, graded = release_source(source)
    assert graded
    assert out == "def f(x):\n    if x:\n        # YOUR CODE HERE\n        raise NotImplementedError()\n    return 0"


def test_a_region_ending_the_cell_leaves_no_trailing_newline():
    out, _ = release_source("def f():\n    ### BEGIN SOLUTION\n    return 1\n    ### END SOLUTION")
    assert out == "def f():\n    # YOUR CODE HERE\n    raise NotImplementedError()"


def test_hidden_tests_are_removed():
    out, graded = release_source('check("1.1", f)\n### BEGIN HIDDEN TESTS\nassert f(0) == 1\n### END HIDDEN TESTS')
    assert (out, graded) == ('check("1.1", f)', True)


def test_markdown_answer_and_untouched_cells():
    out, graded = release_source("Why?\n\n### BEGIN SOLUTION\nBecause.\n### END SOLUTION", "markdown")
    assert (out, graded) == ("Why?\n\nYOUR ANSWER HERE", True)
    assert release_source("x = 1\nprint(x)\n") == ("x = 1\nprint(x)\n", False)


@pytest.mark.parametrize("source, words", [
    ("### BEGIN SOLUTION\nx = 1\n", ["line 1", "no matching '### END SOLUTION'"]),
    ("x = 1\n### END SOLUTION\n", ["line 2", "no matching opening"]),
    ("### BEGIN SOLUTION\n### BEGIN HIDDEN TESTS\n### END HIDDEN TESTS\n### END SOLUTION", ["line 2", "inside"]),
    ("### BEGIN HIDDEN TESTS\n### END SOLUTION\n", ["line 2", "no matching opening"]),
])
def test_malformed_markers_are_named_with_cell_and_line(source, words):
    with pytest.raises(ValueError) as err:
        release_source(source, where="solutions/01_x.ipynb, cell 3")
    for word in ["solutions/01_x.ipynb, cell 3"] + words:
        assert word in str(err.value)


# --------------------------------------------------------------------------------------- one notebook

def test_release_clears_graded_and_check_cells_and_keeps_the_rest():
    solution = nbformat.read(SOLUTIONS / "01_demo.ipynb", as_version=4)
    before = copy.deepcopy(solution)
    exercise = release_notebook(solution)
    assert solution == before                                               # the input is not modified
    assert len(exercise.cells) == len(solution.cells)
    for sol, ex in zip(solution.cells, exercise.cells):
        assert "BEGIN" not in ex.source and "HIDDEN" not in ex.source
        if ex.cell_type != "code":
            continue
        changed = ex.source != sol.source or 'check("' in sol.source
        if changed:                                                         # graded or check cell
            assert ex.outputs == [] and ex.execution_count is None
            assert "nbval-skip" in ex.metadata["tags"]
        else:
            assert ex.outputs == sol.outputs and ex.execution_count == sol.execution_count
    sources = "".join(c.source for c in exercise.cells)
    assert "axis_angle_to_matrix" not in sources and "assert torch.allclose" not in sources
    assert sources.count("raise NotImplementedError()") == 3 and "YOUR ANSWER HERE" in sources
    kept = [c for c in exercise.cells if c.cell_type == "code" and c.outputs]
    assert [c.outputs[0]["text"] for c in kept] == ["setup ok\n"]           # the one ungraded output
    graded_output = [c for c in solution.cells if "look_at defined" in str(c.get("outputs"))]
    assert graded_output, "fixture: a graded cell with an output, to be cleared"


def test_missing_cell_ids_get_stable_names(tmp_path):
    raw = json.loads((SOLUTIONS / "01_demo.ipynb").read_text())
    for cell in raw["cells"]:
        del cell["id"]
    path = tmp_path / "01_demo.ipynb"
    path.write_text(json.dumps(raw))
    assert render_exercise(path) == render_exercise(path)


# ------------------------------------------------------------------------------------------ the CLI

def release(*args) -> int:
    return cli([str(a) for a in args])


def test_the_committed_exercise_fixture_is_up_to_date():
    assert release("--check", "--solutions", SOLUTIONS, "--exercises", EXERCISES) == 0


def test_release_is_deterministic(tmp_path, capsys):
    out = tmp_path / "exercises"
    assert release("--solutions", SOLUTIONS, "--exercises", out) == 0
    first = (out / "01_demo.ipynb").read_bytes()
    assert first.endswith(b"\n") and first == (EXERCISES / "01_demo.ipynb").read_bytes()
    assert release("--solutions", SOLUTIONS, "--exercises", out) == 0
    assert (out / "01_demo.ipynb").read_bytes() == first
    assert "up to date" in capsys.readouterr().out


def test_check_names_drifted_missing_and_extra_notebooks(tmp_path, capsys):
    solutions, exercises = tmp_path / "solutions", tmp_path / "exercises"
    shutil.copytree(SOLUTIONS, solutions)
    shutil.copy(solutions / "01_demo.ipynb", solutions / "02_more.ipynb")
    assert release("--solutions", solutions, "--exercises", exercises) == 0
    assert release("--check", "--solutions", solutions, "--exercises", exercises) == 0
    drifted = exercises / "01_demo.ipynb"
    drifted.write_text(drifted.read_text().replace("YOUR ANSWER HERE", "my answer"))
    (exercises / "02_more.ipynb").unlink()
    (exercises / "03_extra.ipynb").write_text("{}")
    capsys.readouterr()
    assert release("--check", "--solutions", solutions, "--exercises", exercises) == 1
    out = capsys.readouterr().out
    assert f"drifted: {drifted}" in out
    assert f"missing: {exercises / '02_more.ipynb'}" in out
    assert f"extra: {exercises / '03_extra.ipynb'}" in out


def test_missing_solutions_directory_is_a_clear_error(tmp_path, capsys):
    assert release("--solutions", tmp_path / "nowhere", "--exercises", tmp_path / "ex") == 2
    assert "no solutions directory" in capsys.readouterr().err
    assert not (tmp_path / "ex").exists()


def test_malformed_solution_is_reported_with_its_file(tmp_path, capsys):
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("### BEGIN SOLUTION\nx = 1")])
    (tmp_path / "s").mkdir()
    nbformat.write(nb, tmp_path / "s" / "01_bad.ipynb")
    assert release("--solutions", tmp_path / "s", "--exercises", tmp_path / "ex") == 2
    err = capsys.readouterr().err
    assert "01_bad.ipynb, cell 0" in err and "no matching" in err


def test_python_dash_m_course_release_dispatches_here(capsys):
    from course.__main__ import main
    assert main(["release", "--check", "--solutions", str(SOLUTIONS), "--exercises", str(EXERCISES)]) == 0
    assert "up to date" in capsys.readouterr().out
