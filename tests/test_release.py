"""Release: exercises/ is written from solutions/ — solution regions become stubs, hidden tests go, graded,
check and "use it" cells lose their outputs, the bytes are the same on every run, --check finds drift, and
an exercise edited since its release is never overwritten without --force."""
import copy
import json
import shutil
from pathlib import Path

import nbformat
import pytest

from course.grading.release import (RELEASE_KEY, cli, edited_since_release, release_notebook, release_source,
                                    render_exercise, sources_sha256)

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
    regions = sum(c.source.count("### BEGIN SOLUTION") for c in solution.cells if c.cell_type == "code")
    assert regions >= 3 and sources.count("raise NotImplementedError()") == regions
    assert "YOUR ANSWER HERE" in sources
    kept = [c for c in exercise.cells if c.cell_type == "code" and c.outputs]
    assert [c.outputs[0]["text"] for c in kept] == ["setup ok\n"]           # the one ungraded output
    graded_output = [c for c in solution.cells if "look_at defined" in str(c.get("outputs"))]
    assert graded_output, "fixture: a graded cell with an output, to be cleared"


def use_it_notebook():
    """Setup, a graded task, its check, then cells that use it (or not), all with outputs."""
    def code(source, text):
        cell = nbformat.v4.new_code_cell(source, execution_count=1)
        cell.outputs = [nbformat.v4.new_output("stream", name="stdout", text=text)]
        return cell
    return nbformat.v4.new_notebook(cells=[
        code("import math\nprint('setup')", "setup\n"),
        code("def double(x):\n    ### BEGIN SOLUTION\n    return 2 * x\n    ### END SOLUTION", ""),
        code('check("1.1", double)', "Task 1.1 double: 2/2\n"),
        code("y = double(21)\nprint(y)", "42\n"),                               # uses the task: cleared
        code("print(y + 1)", "43\n"),                                           # uses its result: cleared
        code("def helper():\n    return double(1)\n\nprint(helper())", "2\n"),  # calls it in a body: cleared
        code("%time z = double(1)\nprint(z)", "2\n"),                          # a magic line: still read
        code("print(math.pi)", "3.14\n"),                                       # unrelated: kept
        code("import types\nns = types.SimpleNamespace(double=abs)\nprint(ns.double(-3))", "3\n"),  # attribute
    ])


def test_release_clears_the_cells_that_use_a_graded_function():
    exercise = release_notebook(use_it_notebook())
    kept = [c.outputs[0]["text"] for c in exercise.cells if c.outputs]
    assert kept == ["setup\n", "3.14\n", "3\n"]
    for cell in exercise.cells[1:7]:
        assert cell.outputs == [] and cell.execution_count is None
        assert "nbval-skip" in cell.metadata["tags"]
    assert "tags" not in exercise.cells[7].metadata


def test_release_records_the_hash_of_the_released_sources():
    exercise = release_notebook(use_it_notebook())
    assert exercise.metadata[RELEASE_KEY] == {"sources_sha256": sources_sha256(exercise)}
    ran = copy.deepcopy(exercise)
    ran.cells[3].outputs = [nbformat.v4.new_output("stream", name="stdout", text="a student's output\n")]
    assert sources_sha256(ran) == sources_sha256(exercise)                 # running a cell is not an edit
    ran.cells[1].source = ran.cells[1].source.replace("raise NotImplementedError()", "return x + x")
    assert sources_sha256(ran) != sources_sha256(exercise)                 # writing an answer is


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


def released_copy(tmp_path):
    """A solutions folder with two notebooks and its fresh release."""
    solutions, exercises = tmp_path / "solutions", tmp_path / "exercises"
    shutil.copytree(SOLUTIONS, solutions)
    shutil.copy(solutions / "01_demo.ipynb", solutions / "02_more.ipynb")
    assert release("--solutions", solutions, "--exercises", exercises) == 0
    return solutions, exercises


def answer(path: Path) -> str:
    """Write a student's answer into a released exercise, as JupyterLab would save it; returns the text."""
    path.write_text(path.read_text().replace("YOUR ANSWER HERE", "my answer"))
    return path.read_text()


def change_solution(path: Path) -> None:
    path.write_text(path.read_text().replace("A tiny notebook", "A small notebook"))


def test_check_names_drifted_edited_missing_and_extra_notebooks(tmp_path, capsys):
    solutions, exercises = released_copy(tmp_path)
    assert release("--check", "--solutions", solutions, "--exercises", exercises) == 0
    edited = exercises / "01_demo.ipynb"
    answer(edited)
    (exercises / "02_more.ipynb").unlink()
    (exercises / "03_extra.ipynb").write_text("{}")
    capsys.readouterr()
    assert release("--check", "--solutions", solutions, "--exercises", exercises) == 1
    out = capsys.readouterr().out
    assert f"edited since it was released: {edited}" in out
    assert f"missing: {exercises / '02_more.ipynb'}" in out
    assert f"extra: {exercises / '03_extra.ipynb'}" in out
    assert "python -m course workspace" in out and "--force" not in out


def test_check_on_an_edited_exercise_never_advises_overwriting_it(tmp_path, capsys):
    solutions, exercises = released_copy(tmp_path)
    answer(exercises / "01_demo.ipynb")
    capsys.readouterr()
    assert release("--check", "--solutions", solutions, "--exercises", exercises) == 1
    out = capsys.readouterr().out
    assert "--force" not in out and "`python -m course release`" not in out
    assert "python -m course workspace NN" in out


def test_check_calls_a_stale_exercise_drifted(tmp_path, capsys):
    solutions, exercises = released_copy(tmp_path)
    change_solution(solutions / "01_demo.ipynb")
    capsys.readouterr()
    assert release("--check", "--solutions", solutions, "--exercises", exercises) == 1
    out = capsys.readouterr().out
    assert f"drifted: {exercises / '01_demo.ipynb'}" in out and "edited since" not in out
    assert "`python -m course release`" in out


def test_release_refuses_an_edited_exercise_and_overwrites_it_with_force(tmp_path, capsys):
    solutions, exercises = released_copy(tmp_path)
    edited = exercises / "01_demo.ipynb"
    mine = answer(edited)
    change_solution(solutions / "01_demo.ipynb")
    change_solution(solutions / "02_more.ipynb")
    capsys.readouterr()
    assert release("--solutions", solutions, "--exercises", exercises) == 1
    out, err = capsys.readouterr()
    assert edited.read_text() == mine                                       # the answer is still there
    assert f"refused: {edited}" in err and "workspace 01" in err and "--force" in err
    assert f"wrote {exercises / '02_more.ipynb'}" in out                   # the unedited one is updated
    assert "A small notebook" in (exercises / "02_more.ipynb").read_text()
    assert release("--force", "--solutions", solutions, "--exercises", exercises) == 0
    assert edited.read_text() == render_exercise(solutions / "01_demo.ipynb")
    assert not edited_since_release(edited)


def test_release_overwrites_an_exercise_whose_cells_were_only_run(tmp_path):
    solutions, exercises = released_copy(tmp_path)
    path = exercises / "01_demo.ipynb"
    nb = nbformat.read(path, as_version=4)
    nb.cells[1].outputs = [nbformat.v4.new_output("stream", name="stdout", text="ran\n")]
    nb.cells[1].execution_count = 1
    nbformat.write(nb, path)
    assert not edited_since_release(path)
    change_solution(solutions / "01_demo.ipynb")
    assert release("--solutions", solutions, "--exercises", exercises) == 0
    assert path.read_text() == render_exercise(solutions / "01_demo.ipynb")


@pytest.mark.parametrize("text", [None, "{}", "not json"])
def test_an_exercise_without_a_release_record_counts_as_edited(tmp_path, capsys, text):
    solutions, exercises = released_copy(tmp_path)
    path = exercises / "01_demo.ipynb"
    if text is None:                                                        # a notebook from an older release
        raw = json.loads(path.read_text())
        del raw["metadata"][RELEASE_KEY]
        text = json.dumps(raw)
    path.write_text(text)
    assert edited_since_release(path)
    assert release("--solutions", solutions, "--exercises", exercises) == 1
    assert path.read_text() == text and "refused" in capsys.readouterr().err


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
