"""Lecture 12's graded tasks (course/grading/lecture12.py): the references agree with the package
(course.shadows.gradients.project_onto_plane, the split's shadows, variance_visibility, autograd for the
velocity), they score full marks, a solution written as a student would scores full marks without calling
them, typical mistakes lose points with the diagnosis a student can act on, and calling the package scores 0;
12.5's distribution is where the package's variance test is exact, and everywhere else it is an upper bound."""
import torch

from course.shadows import gradients as shadow_gradients, prefiltered as prefiltered_shadows
from course.grading import lecture12, run_check, tasks_for_lecture
from grading_contract import contract

REFERENCES = {"12.1": lambda x, p, n, l: lecture12._project(x, p, n, l),
              "12.2": lambda x, p, n, l, dl: lecture12._velocity(x, p, n, l, dl),
              "12.3": lambda mu, m2, d, mv: lecture12._lit(mu, m2, d, mv),
              "12.4": lambda l, g, lr: lecture12._step(l, g, lr),
              "12.5": lambda mu, var, d: lecture12._tight(mu, var, d)}


# ------------------------------------------------------------------------------ solutions, as students write

def project_onto_plane(points, plane_point, plane_normal, light):
    n = plane_normal / torch.linalg.norm(plane_normal)
    h = torch.sum((points - plane_point) * n, dim=1, keepdim=True)
    return points - h / torch.dot(n, light) * light


def shadow_velocity(points, plane_point, plane_normal, light, dlight):
    n = plane_normal / torch.linalg.norm(plane_normal)
    h = ((points - plane_point) * n).sum(-1).unsqueeze(-1)
    c, dc = torch.dot(n, light), torch.dot(n, dlight)
    return -h / c * dlight + h * dc / c ** 2 * light


def variance_lit(mu, m2, depth, min_variance=1e-6):
    var = torch.clamp(m2 - mu ** 2, min=min_variance)
    p = var / (var + (depth - mu) ** 2)
    return torch.where(depth <= mu, torch.ones_like(p), p)


def light_step(light, grad, lr):
    g = grad - torch.dot(grad, light) * light
    new = light - lr * g
    return new / torch.linalg.norm(new)


def tight_distribution(mu, var, depth):
    t = depth - mu
    p = var / (var + t ** 2)                                              # lit: the receiver sees itself
    return torch.stack([depth, mu - var / t], -1), torch.stack([p, 1 - p], -1)


SOLUTIONS = {"12.1": project_onto_plane, "12.2": shadow_velocity, "12.3": variance_lit, "12.4": light_step,
             "12.5": tight_distribution}


# ------------------------------------------------------------------------------------- typical mistakes

def in_place_step(light, grad, lr):
    light -= lr * (grad - torch.dot(grad, light) * light)
    light /= light.norm()
    return light


MISTAKES = [
    ("12.1", lambda x, p, n, l: lecture12._project(x, p, n, l, "sign"), 0, ["toward the light"]),
    ("12.1", lambda x, p, n, l: lecture12._project(x, p, n, l, "orthogonal"), 0, ["straight down"]),
    ("12.1", lambda x, p, n, l: lecture12._project(x, p, n, l, "no_point"), 1, ["plane_point"]),
    ("12.1", lambda x, p, n, l: lecture12._project(x, p, n, l).float(), 0, ["dtype"]),
    ("12.2", lambda x, p, n, l, dl: lecture12._velocity(x, p, n, l, dl, "direction_only"), 1, ["(n̂ · dl)"]),
    ("12.2", lambda x, p, n, l, dl: lecture12._velocity(x, p, n, l, dl, "length_only"), 0, ["turns"]),
    ("12.2", lambda x, p, n, l, dl: lecture12._velocity(x, p, n, l, dl, "sign"), 0, ["wrong sign"]),
    ("12.3", lambda mu, m2, d, mv: lecture12._lit(mu, m2, d, mv, "both_sides"), 0, ["fully lit"]),
    ("12.3", lambda mu, m2, d, mv: lecture12._lit(mu, m2, d, mv, "std"), 0, ["variance"]),
    ("12.3", lambda mu, m2, d, mv: lecture12._lit(mu, m2, d, mv, "no_mean"), 0, ["m₂ - μ²"]),
    ("12.3", lambda mu, m2, d, mv: lecture12._lit(mu, m2, d, mv, "no_clamp"), 1, ["clamp"]),
    ("12.4", lambda l, g, lr: lecture12._step(l, g, lr, "ascent"), 1, ["up the loss"]),
    ("12.4", lambda l, g, lr: lecture12._step(l, g, lr, "no_normalize"), 1, ["unit vector"]),
    ("12.4", lambda l, g, lr: lecture12._step(l, g, lr, "no_projection"), 1, ["along the light"]),
    ("12.4", in_place_step, 0, ["in place"]),
    ("12.5", lambda mu, var, d: lecture12._tight(mu, var, d, "symmetric"), 0, ["μ ± σ", "receiver's own depth d"]),
    ("12.5", lambda mu, var, d: lecture12._tight(mu, var, d, "swapped"), 0, ["swapped"]),
    ("12.5", lambda mu, var, d: lecture12._tight(mu, var, d, "sigma"), 0, ["keep the mean"]),
    ("12.5", lambda mu, var, d: lecture12._tight(mu, var, d, "std"), 0, ["with the variance"]),
    ("12.5", lambda mu, var, d: tuple(t.double() for t in lecture12._tight(mu, var, d)), 3, ["float32"]),
    ("12.5", lambda mu, var, d: lecture12._tight(mu, var, d)[0], 0, ["tuple"]),
    ("12.5", lambda mu, var, d: (lambda z, w: (z, w * 1.1))(*lecture12._tight(mu, var, d)), 0, ["distribution"]),
    ("12.5", lambda mu, var, d: (lambda z, w: (z + torch.stack([torch.zeros_like(d), 0.1 + 0 * d], -1), w))(
        *lecture12._tight(mu, var, d)), 0, ["mean"]),
]

(test_the_reference_scores_full_marks, test_a_students_solution_scores_full_marks,
 test_a_typical_mistake_loses_points_with_a_useful_message) = contract(REFERENCES, SOLUTIONS, MISTAKES)


def test_lecture_12_has_five_tasks_the_analysis_worth_the_most():
    tasks = tasks_for_lecture(12)
    assert [t.id for t in tasks] == ["12.1", "12.2", "12.3", "12.4", "12.5"]
    assert tasks[-1].points > max(t.points for t in tasks[:-1])


def test_the_tight_distribution_is_where_the_variance_test_is_exact():
    """A texel holding 12.5's two depths (one planar occluder, and the receiver seen through its gaps): the
    package's variance test returns the true lit fraction, to rounding."""
    mu, var, d = lecture12._texels(7, 16)
    z, w = lecture12.tight_distribution_reference(mu, var, d)
    m1, m2 = (w * z).sum(-1), (w * z * z).sum(-1)
    moments = torch.stack([m1, m2], -1).view(4, 4, 2)
    i, j = torch.meshgrid(torch.arange(4.0, dtype=torch.float64), torch.arange(4.0, dtype=torch.float64),
                          indexing="ij")
    centres = torch.stack([j.reshape(-1), i.reshape(-1)], 1) + 0.5
    estimate = prefiltered_shadows.variance_visibility(moments, centres, d, min_variance=1e-12)
    exact = (w * (z >= d[:, None])).sum(-1)                                 # z = d exactly: the receiver itself
    assert torch.allclose(estimate, exact, rtol=0, atol=1e-10)


def test_the_variance_test_is_an_upper_bound_on_the_lit_fraction():
    """Random discrete depth distributions (1 to 5 depths): the map's estimate is never below the true lit
    fraction P(z >= d) (Cantelli), and with two occluders and nothing lit it leaks light."""
    g = torch.Generator().manual_seed(12)
    for k in range(1, 6):
        z = 1 + torch.rand(200, k, generator=g, dtype=torch.float64)
        w = torch.rand(200, k, generator=g, dtype=torch.float64)
        w = w / w.sum(-1, keepdim=True)
        d = 1 + 1.2 * torch.rand(200, generator=g, dtype=torch.float64)
        mu, m2 = (w * z).sum(-1), (w * z * z).sum(-1)
        estimate = lecture12.variance_lit_reference(mu, m2, d, 1e-12)
        exact = (w * (z >= d[:, None])).sum(-1)
        assert bool((estimate >= exact - 1e-12).all()), k
    two = lecture12.variance_lit_reference(torch.tensor([1.5], dtype=torch.float64),
                                           torch.tensor([0.5 * 1.0 + 0.5 * 4.0], dtype=torch.float64),
                                           torch.tensor([2.5], dtype=torch.float64))
    assert abs(float(two) - 0.2) < 1e-12                                  # occluders at 1 and 2: truly 0 lit


def test_the_references_are_the_package():
    for _, x, p, n, l in lecture12._planes():
        assert torch.allclose(lecture12.project_onto_plane_reference(x, p, n, l),
                              shadow_gradients.project_onto_plane(x, p, n, l), rtol=0, atol=1e-14)
    for _, x, p, n, l, dl in lecture12._velocity_cases():                  # the velocity is the derivative
        _, jvp = torch.func.jvp(lambda light: shadow_gradients.project_onto_plane(x, p, n, light), (l,), (dl,))
        assert torch.allclose(lecture12.shadow_velocity_reference(x, p, n, l, dl), jvp, rtol=0, atol=1e-13)
    mu, m2, d = lecture12._moments(5, 25)                                   # the map's lookup at texel centres
    moments = torch.stack([mu, m2], 1).view(5, 5, 2)                        # row i, column j
    i, j = torch.meshgrid(torch.arange(5.0, dtype=torch.float64), torch.arange(5.0, dtype=torch.float64),
                          indexing="ij")
    centres = torch.stack([j.reshape(-1), i.reshape(-1)], 1) + 0.5          # (x, y) of each texel's centre
    got = prefiltered_shadows.variance_visibility(moments, centres, d)
    assert torch.allclose(got, lecture12.variance_lit_reference(mu, m2, d), rtol=0, atol=1e-12)


def test_the_projection_is_where_the_split_puts_the_shadow():
    """The floater's shadow on the floor: the split's shadowed area equals the area of the occluder's
    projection (the floor is larger than the shadow, nothing else shades it)."""
    mesh, _, _, light = shadow_gradients.shadow_scene("floater")
    split = shadow_gradients.split_by_shadows(mesh, light)
    tri = split.verts[split.faces]
    area = 0.5 * torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], dim=1).norm(dim=1)
    floor = split.source == 0
    shadowed = float(area[floor & ~split.lit].sum())
    s = shadow_gradients.project_onto_plane(mesh.verts[mesh.faces[1]], torch.zeros(3, dtype=torch.float64),
                                            torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64), light)
    expected = 0.5 * float(torch.linalg.cross(s[1] - s[0], s[2] - s[0], dim=0).norm())
    assert abs(shadowed - expected) < 1e-12


def test_project_onto_plane_refuses_bad_input():
    import pytest
    up, zero = torch.tensor([0.0, 1.0, 0.0]), torch.zeros(3)
    with pytest.raises(ValueError, match="parallel"):
        shadow_gradients.project_onto_plane(torch.ones(2, 3), zero, up, torch.tensor([1.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        shadow_gradients.project_onto_plane(torch.ones(3), zero, up, -up)
    with pytest.raises(ValueError, match="finite"):
        shadow_gradients.project_onto_plane(torch.full((1, 3), float("nan")), zero, up, -up)
    with pytest.raises(ValueError, match="non-zero"):
        shadow_gradients.project_onto_plane(torch.ones(1, 3), zero, zero, -up)


def test_calling_the_package_scores_zero():
    for task_id, impl in (("12.1", lambda x, p, n, l: shadow_gradients.project_onto_plane(x, p, n, l)),
                          ("12.3", lambda mu, m2, d, mv: prefiltered_shadows.variance_visibility(mu, m2, d))):
        result = run_check(task_id, impl)
        assert result.points == 0 and "course" in result.message, (task_id, result.message)
