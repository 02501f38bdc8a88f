"""Lecture 06's graded tasks (course/grading/lecture06.py): the references score full marks, a solution written
as a student would scores full marks without calling them, typical mistakes lose points with the diagnosis a
student can act on, a function that calls the package's reference scores 0, and the explicit formulas the
checks of 6.2 and 6.3 use to name mistakes agree with the references, course.shadows' building blocks of
shadow_factor."""
import pytest
import torch

from course.camera import project_points
from course.grading import TASKS, run_check, tasks_for_lecture
from course import shadows
from course.grading.lecture06 import _biased_lit, _light_space, _pcf, _pcf_mistake
from course.models import plane
from course.shading import DirectionalLight
from course.shadows import shadow_factor, shadow_map


# ------------------------------------------------------------------------------ solutions, as students write

def light_space(points, K, R, t, orthographic):
    cam = points @ R.T + t
    z = cam[:, 2:]
    xy1 = torch.cat([cam[:, :2], torch.ones_like(z)], 1) if orthographic else cam / z
    return torch.cat([(xy1 @ K.T)[:, :2], z], 1)


def biased_lit(z, stored, texel, tan_theta, bias, slope_bias):
    return z - (bias + slope_bias * texel * tan_theta) <= stored


def pcf(depth_map, coords, depths, k):
    H, W = depth_map.shape
    row, col = coords[:, 1].floor().long(), coords[:, 0].floor().long()
    r = (k - 1) // 2
    lit = torch.zeros_like(depths)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            rr, cc = row + dy, col + dx
            inside = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
            stored = depth_map[rr.clamp(0, H - 1), cc.clamp(0, W - 1)]
            lit += (~inside | (depths <= stored)).to(depths.dtype)
    return lit / (k * k)


SOLUTIONS = {"6.1": light_space, "6.2": biased_lit, "6.3": pcf}
REFERENCES = {"6.1": _light_space, "6.2": _biased_lit, "6.3": _pcf}


# ------------------------------------------------------------------------------------------ typical mistakes

def light_space_divides_always(points, K, R, t, orthographic):
    cam = points @ R.T + t
    return torch.cat([((cam / cam[:, 2:]) @ K.T)[:, :2], cam[:, 2:]], 1)


def light_space_distance(points, K, R, t, orthographic):
    out = light_space(points, K, R, t, orthographic)
    return torch.cat([out[:, :2], (points @ R.T + t).norm(dim=-1, keepdim=True)], 1)


def light_space_no_t(points, K, R, t, orthographic):
    return light_space(points, K, R, torch.zeros_like(t), orthographic)


def light_space_via_project(points, K, R, t, orthographic):
    xy, z = project_points(points, K, R, t, orthographic=orthographic)
    return torch.cat([xy, z[:, None]], 1)


def lit_no_bias(z, stored, texel, tan_theta, bias, slope_bias):
    return z <= stored


def lit_added(z, stored, texel, tan_theta, bias, slope_bias):
    return z + bias + slope_bias * texel * tan_theta <= stored


def lit_strict(z, stored, texel, tan_theta, bias, slope_bias):
    return z - (bias + slope_bias * texel * tan_theta) < stored


def lit_no_texel(z, stored, texel, tan_theta, bias, slope_bias):
    return z - (bias + slope_bias * tan_theta) <= stored


def lit_via_shadow_factor(z, stored, texel, tan_theta, bias, slope_bias):
    shadow_factor
    return biased_lit(z, stored, texel, tan_theta, bias, slope_bias)


def pcf_outside_dark(depth_map, coords, depths, k):
    return _pcf_mistake(depth_map, coords, depths, k, outside="shadow").to(depth_map.dtype)


def pcf_filters_depths(depth_map, coords, depths, k):
    return _pcf_mistake(depth_map, coords, depths, k, filter_depths=True).to(depth_map.dtype)


def pcf_swapped(depth_map, coords, depths, k):
    return pcf(depth_map, coords.flip(-1), depths, k) if depth_map.shape[0] == depth_map.shape[1] else \
        _pcf_mistake(depth_map, coords, depths, k, swap=True).to(depth_map.dtype)


def pcf_shadowed(depth_map, coords, depths, k):
    return 1 - pcf(depth_map, coords, depths, k)


MISTAKES = [
    ("6.1", light_space_divides_always, "does not divide by depth"),
    ("6.1", light_space_distance, "not the distance"),
    ("6.1", light_space_no_t, "translation t is missing"),
    ("6.2", lit_no_bias, "bias is missing"),
    ("6.2", lit_added, "bias is added"),
    ("6.2", lit_strict, "use <=, not <"),
    ("6.2", lit_no_texel, "texel's world width"),
    ("6.3", pcf_outside_dark, "outside the map counts as lit"),
    ("6.3", pcf_filters_depths, "filters the comparisons, not the depths"),
    ("6.3", pcf_swapped, "rows and columns are swapped"),
    ("6.3", pcf_shadowed, "shadowed fraction"),
]


def test_lecture_06_has_three_tasks_of_three_points_each():
    tasks = tasks_for_lecture(6)
    assert [t.id for t in tasks] == ["6.1", "6.2", "6.3"]
    assert [t.name for t in tasks] == ["light_space", "biased_lit", "pcf"]
    assert all(t.points == 3 for t in tasks)


@pytest.mark.parametrize("task_id", ["6.1", "6.2", "6.3"])
def test_the_reference_scores_full_marks(task_id):
    result = run_check(task_id, REFERENCES[task_id])
    assert result.points == 3, result.message


@pytest.mark.parametrize("task_id", ["6.1", "6.2", "6.3"])
def test_a_students_solution_scores_full_marks(task_id):
    result = run_check(task_id, SOLUTIONS[task_id])
    assert result.points == 3 and result.message == "", result.message


@pytest.mark.parametrize("task_id, impl, words", MISTAKES, ids=lambda v: getattr(v, "__name__", None))
def test_a_typical_mistake_loses_points_with_a_useful_message(task_id, impl, words):
    result = run_check(task_id, impl)
    assert result.points < 3
    assert words in result.message, result.message


def light_space_via_reference(points, K, R, t, orthographic):
    return shadows.light_space(points, K, R, t, orthographic)


def lit_via_reference(z, stored, texel, tan_theta, bias, slope_bias):
    return shadows.biased_lit(z, stored, texel, tan_theta, bias, slope_bias)


def lit_via_biased_depth(z, stored, texel, tan_theta, bias, slope_bias):
    return shadows.biased_depth(z, texel, tan_theta, bias, slope_bias) <= stored


def pcf_via_reference(depth_map, coords, depths, k):
    return shadows.pcf(depth_map, coords, depths, k)


@pytest.mark.parametrize("task_id, impl", [("6.1", light_space_via_project), ("6.1", light_space_via_reference),
                                           ("6.2", lit_via_shadow_factor), ("6.2", lit_via_reference),
                                           ("6.2", lit_via_biased_depth), ("6.3", pcf_via_reference)],
                         ids=lambda v: getattr(v, "__name__", v))
def test_calling_the_reference_scores_zero(task_id, impl):
    result = run_check(task_id, impl)
    assert result.points == 0 and "calls" in result.message, result.message


def test_not_attempted_scores_zero():
    def pcf(depth_map, coords, depths, k):
        raise NotImplementedError()
    result = run_check("6.3", pcf)
    assert result.points == 0 and "not attempted" in result.message


@pytest.mark.parametrize("k", [1, 3, 5])
def test_shadow_factor_is_the_references_in_a_row(k):
    # a tilted ground under a tilted light at 32 texels: acne and an outline, so both outcomes occur
    ground = plane(4.0, dtype=torch.float64)
    sm = shadow_map(ground, DirectionalLight((0.6, -1.0, 0.3)), 32)
    g = torch.Generator().manual_seed(1)
    pts = torch.cat([torch.rand(3000, 1, generator=g, dtype=torch.float64) * 3.6 - 1.8,
                     torch.zeros(3000, 1, dtype=torch.float64),
                     torch.rand(3000, 1, generator=g, dtype=torch.float64) * 3.6 - 1.8], 1)
    cam = sm.camera
    xyz = _light_space(pts, cam.K, cam.R, cam.t, cam.orthographic)
    bias = 0.3 / float(cam.K[0, 0])
    expected = shadow_factor(pts, None, sm, bias=bias, pcf=k)
    got = _pcf(sm.depth[0], xyz[:, :2], xyz[:, 2] - bias, k)
    assert torch.equal(got, expected)
    assert torch.equal(_pcf_mistake(sm.depth[0], xyz[:, :2], xyz[:, 2] - bias, k), expected)   # the formula
    assert expected.unique().numel() >= 2                                     # lit and (partly) shadowed
    if k == 1:
        row, col = xyz[:, 1].floor().long(), xyz[:, 0].floor().long()
        one = _biased_lit(xyz[:, 2], sm.depth[0, row, col], torch.zeros(3000, dtype=torch.float64),
                          torch.zeros(3000, dtype=torch.float64), bias, 0.0)
        assert torch.equal(one.double(), expected)


def test_the_checks_are_registered_with_references():
    assert TASKS["6.1"].reference == ("course.shadows", "light_space")
    assert TASKS["6.2"].reference == ("course.shadows", "biased_lit")
    assert TASKS["6.3"].reference == ("course.shadows", "pcf")
