"""What every lecture's graded tasks promise, as tests a lecture's test file takes in.

``tests/test_grading_NN.py`` defines ``REFERENCES`` and ``SOLUTIONS`` ({task id: function}) and ``MISTAKES``
(task id, function, points it should get, words its message must contain), then::

    (test_the_reference_scores_full_marks, test_a_students_solution_scores_full_marks,
     test_a_typical_mistake_loses_points_with_a_useful_message) = contract(REFERENCES, SOLUTIONS, MISTAKES)

so pytest collects the three under the lecture's file.
"""
import pytest

from course.grading import TASKS, run_check


def contract(references, solutions, mistakes):
    @pytest.mark.parametrize("task_id", sorted(references))
    def test_the_reference_scores_full_marks(task_id):
        result = run_check(task_id, references[task_id], allow_reference=True)
        assert (result.points, result.message) == (TASKS[task_id].points, "")

    @pytest.mark.parametrize("task_id", sorted(solutions))
    def test_a_students_solution_scores_full_marks(task_id):
        result = run_check(task_id, solutions[task_id])
        assert (result.points, result.message) == (TASKS[task_id].points, "")

    @pytest.mark.parametrize("task_id, impl, points, words", mistakes,
                             ids=[f"{m[0]}-{m[3][0][:30]}" for m in mistakes])
    def test_a_typical_mistake_loses_points_with_a_useful_message(task_id, impl, points, words):
        result = run_check(task_id, impl, allow_reference=True)            # mistakes are written from references
        assert result.points == points, result.message
        for word in words:
            assert word in result.message, result.message
        assert "\n" not in result.message                                   # one line in the score table

    return (test_the_reference_scores_full_marks, test_a_students_solution_scores_full_marks,
            test_a_typical_mistake_loses_points_with_a_useful_message)
