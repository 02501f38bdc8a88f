"""Lecture 11's graded tasks (course/grading/lecture11.py): the references agree with the package
(course.style.gram_matrix and style_loss, course.style.transfer.random_directions and deep_dream_mesh's step), they
score full marks, a solution written as a student would scores full marks without calling them, typical
mistakes lose points with the diagnosis a student can act on, and calling the package scores 0. Task 11.5 is a
design (how to judge two runs): the mistakes graded are the designs that do not work (two runs seen from
different views, the standard error of independent means, the spread instead of the standard error)."""
import math

import torch

from course.style import features as style, transfer as stylize
from course.grading import lecture11, run_check, tasks_for_lecture
from grading_contract import contract

REFERENCES = {"11.1": lambda f: lecture11._gram(f),
              "11.2": lambda g, t: lecture11._style(g, t),
              "11.3": lambda n, gen: lecture11._directions(n, gen),
              "11.4": lambda x, objective, step: lecture11._dream(x, objective, step),
              "11.5": lambda ra, rb, loss, n, gen: lecture11._compare(ra, rb, loss, n, gen)}


# ------------------------------------------------------------------------------ solutions, as students write

def gram_matrix(features):
    if features.dim() == 4:
        features = features.squeeze(0)
    C, H, W = features.shape
    F = features.reshape(C, H * W)
    return F @ F.transpose(0, 1) / (H * W)


def style_loss(grams, target_grams):
    total = 0
    for G, T in zip(grams, target_grams):
        total = total + torch.sum((G - T) ** 2) / torch.sum(T ** 2)
    return total


def random_directions(n, gen):
    z = torch.rand(n, generator=gen, dtype=torch.float64) * 2 - 1
    phi = torch.rand(n, generator=gen, dtype=torch.float64) * 2 * math.pi
    s = torch.sqrt(1 - z ** 2)
    return torch.stack([s * torch.cos(phi), s * torch.sin(phi), z], dim=1)


def deep_dream_step(x, objective, step_size):
    x = x.detach().clone().requires_grad_(True)
    objective(x).backward()
    g = x.grad
    with torch.no_grad():
        if g.abs().sum() == 0:
            return x.clone()
        return x + step_size * g / g.abs().mean()


def compare_runs(render_a, render_b, loss, n, gen):
    dirs = random_directions(n, gen)
    a = torch.tensor([float(loss(render_a(d))) for d in dirs], dtype=torch.float64)
    b = torch.tensor([float(loss(render_b(d))) for d in dirs], dtype=torch.float64)
    diff = a - b
    se = diff.std(unbiased=False) / n ** 0.5
    m = diff.mean()
    return float(m), float(se), ("a" if m < -2 * se else "b" if m > 2 * se else "none")


SOLUTIONS = {"11.1": gram_matrix, "11.2": style_loss, "11.3": random_directions, "11.4": deep_dream_step,
             "11.5": compare_runs}


# ------------------------------------------------------------------------------------- typical mistakes

def angles(n, gen):
    u = torch.rand(n, 2, generator=gen, dtype=torch.float64)
    theta, phi = math.pi * u[:, 0], 2 * math.pi * u[:, 1]
    return torch.stack([torch.sin(theta) * torch.cos(phi), torch.sin(theta) * torch.sin(phi), torch.cos(theta)], 1)


def unseeded(n, gen):
    return random_directions(n, torch.Generator().manual_seed(torch.seed() % 1000))


def half_azimuth(n, gen):
    d = random_directions(n, gen)
    return torch.stack([d[:, 0].abs(), d[:, 1], d[:, 2]], 1)


def not_normalised(n, gen):
    return torch.randn(n, 3, generator=gen, dtype=torch.float64)


MISTAKES = [
    ("11.1", lambda f: lecture11._gram(f, "none"), 0, ["not averaged", "H W"]),
    ("11.1", lambda f: lecture11._gram(f, "chw"), 0, ["C H W"]),
    ("11.1", lambda f: (lambda F: F.T @ F / F.shape[1])(f.reshape(f.shape[0], -1)), 0, ["F Fᵀ"]),
    ("11.1", lambda f: gram_matrix(f) if f.dim() == 3 else f @ f, 1, ["batch"]),
    ("11.2", lambda g, t: lecture11._style(g, t, relative=False), 0, ["relative"]),
    ("11.2", lambda g, t: lecture11._style(g, t, squared=False), 0, ["squared norms"]),
    ("11.2", lambda g, t: lecture11._style(g, t, reduce="mean"), 0, ["mean over the layers"]),
    ("11.2", lambda g, t: torch.tensor(float(lecture11._style(g, t)), dtype=g[0].dtype), 1, ["no gradient"]),
    ("11.3", angles, 1, ["poles are crowded", "cos θ"]),
    ("11.3", unseeded, 2, ["generator"]),
    ("11.3", half_azimuth, 1, ["mean of x"]),
    ("11.3", not_normalised, 0, ["unit vectors"]),
    ("11.4", lambda x, o, s: lecture11._dream(x, o, s, sign=-1.0), 1, ["ascent"]),
    ("11.4", lambda x, o, s: lecture11._dream(x, o, s, norm="none"), 1, ["not normalised"]),
    ("11.4", lambda x, o, s: lecture11._dream(x, o, s, norm="l2"), 1, ["mean |g|"]),
    ("11.4", lambda x, o, s: lecture11._dream(x, o, s).requires_grad_(True), 0, ["detached"]),
    ("11.4", lambda x, o, s: lecture11._dream(x, o, s, guard=False), 2, ["g = 0", "unchanged"]),
    ("11.5", lambda *a: lecture11._compare(*a, paired=False), 3, ["different views", "same views"]),
    ("11.5", lambda *a: lecture11._compare(*a, se="unpaired"), 3, ["independent means", "paired differences"]),
    ("11.5", lambda *a: lecture11._compare(*a, se="spread"), 4, ["not the standard error", "√n"]),
    ("11.5", lambda *a: lecture11._compare(*a, sign=-1.0), 4, ["LOWER loss"]),
    ("11.5", lambda *a: lecture11._compare(*a, kind="angles"), 4, ["poles are crowded"]),
    ("11.5", lambda *a: lecture11._compare(*a, threshold=1.0), 4, ["more than 2 standard errors"]),
    ("11.5", lambda ra, rb, loss, n, gen: (0.0, 0.0, "none"), 0, ["called 0 times"]),
]

(test_the_reference_scores_full_marks, test_a_students_solution_scores_full_marks,
 test_a_typical_mistake_loses_points_with_a_useful_message) = contract(REFERENCES, SOLUTIONS, MISTAKES)


def test_lecture_11_has_five_tasks_and_the_design_is_worth_the_most():
    tasks = tasks_for_lecture(11)
    assert [t.id for t in tasks] == ["11.1", "11.2", "11.3", "11.4", "11.5"]
    assert tasks[-1].points > max(t.points for t in tasks[:-1])


def test_the_judges_reference_pairs_the_views_and_cancels_what_they_share():
    """A run against a copy of itself: exactly 0 with the same views; a run a fixed 0.1 lower everywhere is
    measurably better from 3 views (every paired difference is -0.1: standard error 0)."""
    run = lambda d: torch.full((2, 2, 3), 5 + float(d[2]), dtype=torch.float64)           # noqa: E731
    lower = lambda d: run(d) - 0.1                                                         # noqa: E731
    loss = lambda image: image.mean()                                                      # noqa: E731
    assert lecture11.compare_runs_reference(run, run, loss, 20, torch.Generator().manual_seed(0))[2] == "none"
    diff, se, verdict = lecture11.compare_runs_reference(lower, run, loss, 3, torch.Generator().manual_seed(0))
    assert abs(float(diff) + 0.1) < 1e-12 and float(se) < 1e-12 and verdict == "a"


def test_the_references_are_the_package():
    g = torch.Generator().manual_seed(0)
    f = torch.relu(torch.randn(5, 7, 6, generator=g, dtype=torch.float64))
    assert torch.allclose(lecture11.gram_matrix_reference(f), style.gram_matrix(f), rtol=1e-14, atol=0)
    grams = [style.gram_matrix(torch.relu(torch.randn(c, 4, 4, generator=g, dtype=torch.float64))) for c in (3, 4)]
    targets = [style.gram_matrix(torch.relu(torch.randn(c, 4, 4, generator=g, dtype=torch.float64))) for c in (3, 4)]
    assert torch.allclose(lecture11.style_loss_reference(grams, targets), style.style_loss(grams, targets),
                          rtol=1e-14, atol=0)
    a = lecture11.random_directions_reference(100, torch.Generator().manual_seed(3))
    b = stylize.random_directions(100, torch.Generator().manual_seed(3))
    assert torch.allclose(a, b, rtol=0, atol=1e-15)


def test_calling_the_package_scores_zero():
    for task_id, impl in (("11.1", lambda f: style.gram_matrix(f)),
                          ("11.2", lambda g, t: style.style_loss(g, t)),
                          ("11.3", lambda n, gen: stylize.random_directions(n, gen))):
        result = run_check(task_id, impl)
        assert result.points == 0 and "course" in result.message, (task_id, result.message)
