"""Copy flags (course/grading/flags.py), measured on this course's own code: every package reference pasted with
renamed variables is flagged; correct solutions written independently and differently are not, neither against
the reference, nor against the solution notebook, nor against each other; a classmate's code copied with renamed
names and reordered lines is flagged; the report puts the matching lines side by side. Nothing here runs a
notebook: flags only read code.

Measured when the threshold was set (0.65): the 45 pasted references score 0.84-1.00 against their reference;
the eight independent solutions of HONEST score at most 0.42 against anything.
"""
import math

import pytest
import torch

from class_fixtures import HONEST, ROOT, exercise_with, parenthesise, pasted_reference, rename_locals, write
from course.grading import TASKS, run_check
from course.grading import flags

TASKS_WITH_REFERENCE = sorted((i for i, t in TASKS.items() if t.reference), key=lambda i: tuple(map(int, i.split("."))))


def template(task_id: str) -> list[str]:
    """The exercise's version of the task's function as ``flags`` takes it out of a student's code."""
    lecture = int(task_id.split(".")[0])
    path = next((ROOT / "exercises").glob(f"{lecture:02d}_*.ipynb"))
    import nbformat
    found = flags.function_source(nbformat.read(str(path), as_version=4), TASKS[task_id].name)
    return flags.template_lines(found[0])


def student(task_id: str, source: str, who: str = "student") -> flags.Code:
    return flags._code(who, "test", source, template(task_id))


def solution_notebook(task_id: str) -> flags.Code:
    import nbformat
    lecture = int(task_id.split(".")[0])
    path = next((ROOT / "solutions").glob(f"{lecture:02d}_*.ipynb"))
    return flags.notebook_code(nbformat.read(str(path), as_version=4), TASKS[task_id], "solution", str(path),
                               template(task_id))


# --------------------------------------------------------------------------------------- normalising code

ORIGINAL = '''def area(tri):
    """Twice the signed area."""
    a, b, c = tri          # the corners
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
'''
DISGUISED = '''def my_area(triangle):
    # corners first
    p, q, r = triangle
    'a string used as a comment'
    return (q[0] - p[0]) * (r[1] - p[1]) \
        - (q[1] - p[1]) * (r[0] - p[0])
'''


def test_names_comments_docstrings_and_layout_change_no_token():
    assert flags.tokens_of(ORIGINAL)[0] == flags.tokens_of(DISGUISED)[0]
    changed = DISGUISED.replace("(r[0] - p[0])", "(r[0] + p[0])")
    assert flags.tokens_of(changed)[0] != flags.tokens_of(ORIGINAL)[0]             # an operator is code
    assert flags.tokens_of("def f(x):\n    return x.sum(dim=-1)\n")[0] == [          # attribute and keyword
        "def", "_", "(", "_", ")", ":", "NEWLINE", "INDENT",                        # names stay
        "return", "_", ".", "sum", "(", "dim", "=", "-", "1", ")", "NEWLINE", "DEDENT"]
    number = flags.tokens_of("def f(x):\n    return x * 1e-12\n")[0]
    assert number == flags.tokens_of("def g(y):\n    return y*1E-12\n")[0]


def test_the_exercises_own_lines_are_not_counted():
    unattempted = flags.function_source(exercise_with("01_representations_and_transforms.ipynb", {}), "look_at")
    assert student("1.2", unattempted[0]).tokens == ()                             # nothing of the student's own
    answered = student("1.2", HONEST["1.2"][0])
    assert "def" not in answered.tokens and len(answered.tokens) >= flags.MIN_TOKENS


# ------------------------------------------------------------------------------------------- measurements

@pytest.mark.parametrize("task_id", TASKS_WITH_REFERENCE)
def test_the_reference_pasted_with_renamed_variables_is_flagged(task_id):
    reference = flags.reference_code(TASKS[task_id])
    pasted = student(task_id, pasted_reference(task_id), "paster")
    score, tiles = flags.similarity(pasted, reference)
    assert score >= flags.THRESHOLD, f"{task_id}: {score:.2f}"
    assert tiles and all(size >= flags.RUN for _, _, size in tiles)


@pytest.mark.parametrize("task_id", sorted(HONEST))
def test_independent_correct_solutions_are_not_flagged(task_id):
    a, b = (student(task_id, source, who) for source, who in zip(HONEST[task_id], ("ana", "ben")))
    for source in HONEST[task_id]:                                     # both are honest and correct
        namespace = {"torch": torch, "math": math}
        exec(source, namespace)
        result = run_check(task_id, namespace[TASKS[task_id].name])
        assert (result.points, result.message) == (TASKS[task_id].points, "")
    others = [flags.reference_code(TASKS[task_id]), solution_notebook(task_id), b]
    scores = [flags.similarity(a, other)[0] for other in others]
    scores += [flags.similarity(b, other)[0] for other in others[:2]]
    assert max(scores) < flags.THRESHOLD - 0.15, [f"{s:.2f}" for s in scores]        # a margin, not a near miss


def test_a_classmates_code_with_renamed_names_and_reordered_lines_is_flagged():
    original = student("3.2", HONEST["3.2"][0], "ana")
    lines = rename_locals(HONEST["3.2"][0], prefix="x").splitlines()
    assert lines[9].lstrip().startswith("xbeta") and lines[10].lstrip().startswith("xgamma")
    lines[9], lines[10] = lines[10], lines[9]                    # beta and gamma do not depend on each other
    copied = student("3.2", "\n".join(lines) + "\n", "cat")
    score, _ = flags.similarity(original, copied)
    assert score >= flags.THRESHOLD, f"{score:.2f}"


@pytest.mark.parametrize("task_id, k", [(t, k) for t in sorted(HONEST) for k in range(2)])
def test_a_copy_renamed_and_parenthesised_is_flagged(task_id, k):
    """Measured before the canonical form: 0.21-0.68 (a run of 8 tokens broken by every added bracket)."""
    source = HONEST[task_id][k]
    disguised = parenthesise(rename_locals(source, prefix="x"))
    assert disguised.count("(") > source.count("(") + 10
    score, _ = flags.similarity(student(task_id, source, "ana"), student(task_id, disguised, "cat"))
    assert score >= flags.THRESHOLD, f"{score:.2f}"


def test_the_canonical_form_undoes_what_does_not_change_the_program():
    disguised = ('def g(x, y):\n    """doc"""\n    from torch import sin as s\n    v = (x * 2) * 1 + 0\n'
                 "    u = (x) + (y)\n    v += 0 * 3\n    return s((u)) + -(-v)\n")
    canonical, rows = flags.canonical(disguised, {"s": "torch.sin"})
    assert "torch.sin(u)" in canonical and "(x)" not in canonical and "* 1" not in canonical
    assert "doc" not in canonical and "-(-" not in canonical and "v = v + 0" in canonical
    assert canonical.index("v = x * 2") < canonical.index("u = x + y")        # independent: one order
    assert rows[canonical.splitlines().index("    u = x + y")] == 4          # mapped to its own line
    plain = "def f(p, q):\n    a = p + q\n    b = p * 2\n    return torch.sin(a) + b\n"
    swapped = "def f(p, q):\n    b = p * 2\n    a = p + q\n    return torch.sin(a) + b\n"
    assert flags.canonical_tokens(plain)[0] == flags.canonical_tokens(swapped)[0]
    aliased = "def f(p, q):\n    from torch import sin\n    b = p * 2\n    a = p + q\n    return sin(a) + b\n"
    assert flags.canonical_tokens(aliased)[0][-12:] == flags.canonical_tokens(plain)[0][-12:]
    dependent = "def f(p):\n    a = p + 1\n    p = a * 2\n    return p\n"      # a write after a read: kept in order
    assert flags.canonical(dependent)[0].index("a = p + 1") < flags.canonical(dependent)[0].index("p = a * 2")


GRAM = ["def gram_matrix(features):\n    B, C, H, W = features.shape\n    flat = features.reshape(B, C, H * W)\n"
        "    return flat @ flat.transpose(1, 2) / (H * W)\n",
        "def gram_matrix(x):\n    b, c, h, w = x.shape\n    f = x.reshape(b, c, h * w)\n"
        "    return f @ f.transpose(1, 2) / (h * w)\n"]


def test_a_formula_task_is_not_judged_even_when_two_students_write_it_alike(tmp_path):
    name = next((ROOT / "exercises").glob("11_*.ipynb")).name
    notebooks = [(who, write(exercise_with(name, {"gram_matrix": source}), tmp_path / who / name))
                 for who, source in zip(("ana", "ben"), GRAM)]
    found = flags.find_flags(notebooks)
    assert not [f for f in found.flags if f.task == "11.1"]
    assert found.formulas["11.1"] < flags.FORMULA_TOKENS and set(found.too_short["11.1"]) == {"ana", "ben"}
    assert flags.similarity(student("11.1", GRAM[0]), student("11.1", GRAM[1]))[0] >= flags.THRESHOLD   # alike


def test_code_worth_reading_is_listed_and_scores_nothing(tmp_path):
    name = "01_representations_and_transforms.ipynb"
    probing = ["import course.grading.registry as r\nr.calls_reference = lambda *a: False",
               "import builtins\nbuiltins.min = max", "import os\nif os.fork() == 0:\n    os.setsid()",
               "get_ipython().events.register('post_run_cell', print)", "from course.grading import check"]
    path = write(exercise_with(name, {}, probing), tmp_path / "eve" / name)
    found = flags.find_flags([("eve", path)])
    whys = [why for who, _, _, _, why in found.worth_reading]
    assert whys == ["imports the grader's internals", "patches r.calls_reference", "patches builtins.min",
                    "forks a process", "starts a new session (a daemon)", "registers an IPython event callback"]
    report = tmp_path / "flags.md"
    flags.write_report(report, found)
    assert "## Code worth reading" in report.read_text() and "`builtins.min = max`" in report.read_text()


def test_tiles_cover_each_token_once_longest_runs_first():
    a = list("abcdefgh") + list("XYZ") + list("ijklmnop")
    b = list("ijklmnop") + list("QQ") + list("abcdefgh")
    found = flags.tiles(a, b, run=4)
    assert sorted(found) == [(0, 10, 8), (11, 0, 8)]                # reordered blocks both found
    assert flags.tiles(list("abcabc"), list("abc"), run=3) == [(0, 0, 3)]   # b's tokens used once


# ------------------------------------------------------------------------------------- a class, reported

@pytest.fixture(scope="module")
def a_class(tmp_path_factory):
    """ana and ben answer 1.1 and 1.2 honestly and differently; cat pastes the package's look_at and copies ana's
    rodrigues with names changed; dan leaves the exercise as it is; eve answers 1.3 with the one-liner."""
    root = tmp_path_factory.mktemp("flags")
    name = "01_representations_and_transforms.ipynb"
    answers = {
        "ana": {"rodrigues": HONEST["1.1"][0], "look_at": HONEST["1.2"][0]},
        "ben": {"rodrigues": HONEST["1.1"][1], "look_at": HONEST["1.2"][1]},
        "cat": {"rodrigues": rename_locals(HONEST["1.1"][0], prefix="c"),
                "look_at": "from course.tensors import as_tensor, _check_shape\n\n" + pasted_reference("1.2")},
        "dan": {},
        "eve": {"world_to_camera": "def world_to_camera(points, R, t):\n    return points @ R.T + t\n"},
    }
    return [(who, write(exercise_with(name, a), root / who / name)) for who, a in answers.items()]


def test_the_class_flags_exactly_the_pasted_and_the_copied(a_class, tmp_path):
    found = flags.find_flags(a_class)
    pairs = {(f.task, f.left.who, f.right.who) for f in found.flags}
    # the paste may also match the solution notebook, itself written from the package (0.68 since look_at
    # scales its vectors by a power of two); no one else is flagged
    assert {("1.1", "ana", "cat"), ("1.2", "cat", "package course.camera.look_at")} <= pairs, pairs
    assert pairs <= {("1.1", "ana", "cat"), ("1.2", "cat", "package course.camera.look_at"),
                     ("1.2", "cat", "solution notebook")}, pairs
    assert [f.similarity for f in found.flags] == sorted((f.similarity for f in found.flags), reverse=True)
    assert found.too_short["1.3"] == ["eve"]                        # one line: too short to tell
    assert found.references["1.2"] == ["package course.camera.look_at", "solution notebook"]
    report = tmp_path / "flags.md"
    flags.write_report(report, found)
    text = report.read_text(encoding="utf-8")
    assert text.startswith(f"# Copy flags: {len(found.flags)} pair(s) at or above similarity 0.65")
    side_by_side = [line for line in text.splitlines() if " | " in line]
    assert any("cross_matrix" not in line and "skew[0, 1]" in line and "cskew" in line for line in side_by_side)
    assert any("torch.linalg.cross" in line.split(" | ")[0] and "torch.linalg.cross" in line.split(" | ")[1]
               for line in side_by_side)                            # look_at: cat's line beside the package's
    assert "Task 1.3 world_to_camera: the course's own answer has 11 tokens" in text    # a formula, not compared


def test_a_larger_threshold_flags_fewer_and_the_report_says_so(a_class, tmp_path):
    found = flags.find_flags(a_class, threshold=0.999)
    assert all(f.similarity >= 0.999 for f in found.flags)
    assert len(found.flags) < len(flags.find_flags(a_class).flags)
