"""Lecture 06's graded tasks (course/grading/lecture06.py): the references score full marks, a solution written
as a student would scores full marks without calling them, typical mistakes lose points with the diagnosis a
student can act on, a function that calls the package's reference scores 0, and the explicit formulas the
checks use agree with course.shadows' building blocks of shadow_factor: 6.2's bias is shadow_factor's, 6.3's
filter is its PCF, and 6.4's acne bias is the least bias that leaves shadow_factor's ground lit."""
import pytest
import torch

from course.camera import project_points
from course.grading import TASKS, run_check, tasks_for_lecture
from course import shadows
from course.grading.lecture06 import _acne_bias, _depth_bias, _light_space, _pcf, _pcf_mistake
from course.models import plane
from course.shading import DirectionalLight
from course.shadows import shadow_factor, shadow_map


# ------------------------------------------------------------------------------ solutions, as students write

def light_space(points, K, R, t, orthographic):
    cam = points @ R.T + t
    z = cam[:, 2:]
    xy1 = torch.cat([cam[:, :2], torch.ones_like(z)], 1) if orthographic else cam / z
    return torch.cat([(xy1 @ K.T)[:, :2], z], 1)


def depth_bias(z, normals, to_light, fx, orthographic, bias, slope_bias, max_slope):
    cos = (normals * to_light).sum(-1).abs() / (normals.norm(dim=-1) * to_light.norm(dim=-1))
    tan = ((1 - cos ** 2).clamp_min(0).sqrt() / cos).clamp(max=max_slope)   # cos = 0: inf, clamped
    texel = torch.full_like(z, 1 / fx) if orthographic else z / fx
    return bias + slope_bias * texel * tan


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


def acne_bias(depth_map, coords, depths, k):
    H, W = depth_map.shape
    row, col = coords[:, 1].floor().long(), coords[:, 0].floor().long()
    r = (k - 1) // 2
    worst = torch.zeros((), dtype=depth_map.dtype)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            rr, cc = row + dy, col + dx
            inside = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
            need = depths[inside] - depth_map[rr[inside], cc[inside]]
            if need.numel():
                worst = torch.maximum(worst, need.max())
    return worst


SOLUTIONS = {"6.1": light_space, "6.2": depth_bias, "6.3": pcf, "6.4": acne_bias}
REFERENCES = {"6.1": _light_space, "6.2": _depth_bias, "6.3": _pcf, "6.4": _acne_bias}


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


def bias_with(**how):
    """The two-part bias with one step changed (the typical mistakes)."""
    def depth_bias(z, normals, to_light, fx, orthographic, bias, slope_bias, max_slope):
        dot = (normals * to_light).sum(-1)
        cos = dot if how.get("signed") else dot.abs()
        if not how.get("raw"):
            cos = cos / (normals.norm(dim=-1) * to_light.norm(dim=-1))
        sin = (1 - cos ** 2).clamp_min(0).sqrt()
        tan = sin / cos if not how.get("sin") else sin
        if not how.get("unclamped"):
            tan = tan.clamp(max=max_slope)
        texel = torch.full_like(z, 1 / fx) if orthographic != how.get("texel_swapped", False) else z / fx
        total = bias + slope_bias * texel * tan
        return z - total if how.get("biased_depth") else total
    return depth_bias


def bias_via_tan_theta(z, normals, to_light, fx, orthographic, bias, slope_bias, max_slope):
    tan = shadows._tan_theta(normals, to_light, max_slope)
    return bias + slope_bias * (torch.full_like(z, 1 / fx) if orthographic else z / fx) * tan


def acne_with(**how):
    return lambda depth_map, coords, depths, k: _acne_bias(depth_map, coords, depths, k, **how)


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
    ("6.2", bias_with(unclamped=True), "clamp tan θ to max_slope"),
    ("6.2", bias_with(texel_swapped=True), "texel"),
    ("6.2", bias_with(signed=True), "either way"),
    ("6.2", bias_with(raw=True), "normalise"),
    ("6.2", bias_with(sin=True), "not sin"),
    ("6.2", bias_with(biased_depth=True), "not the biased depth"),
    ("6.3", pcf_outside_dark, "outside the map counts as lit"),
    ("6.3", pcf_filters_depths, "filters the comparisons, not the depths"),
    ("6.3", pcf_swapped, "rows and columns are swapped"),
    ("6.3", pcf_shadowed, "shadowed fraction"),
    ("6.4", acne_with(own_texel=True), "every texel of its k × k window"),
    ("6.4", acne_with(window="corner"), "the window is centred"),
    ("6.4", acne_with(swap=True), "rows and columns are swapped"),
    ("6.4", acne_with(reduce="mean"), "not the mean"),
    ("6.4", acne_with(clamp=False), "never negative"),
    ("6.4", lambda depth_map, coords, depths, k: _acne_bias(depth_map, coords, depths, k)[None], "return one number"),
]


def test_lecture_06_has_three_tasks_of_three_points_and_an_analysis_of_four():
    tasks = tasks_for_lecture(6)
    assert [t.id for t in tasks] == ["6.1", "6.2", "6.3", "6.4"]
    assert [t.name for t in tasks] == ["light_space", "depth_bias", "pcf", "acne_bias"]
    assert [t.points for t in tasks] == [3, 3, 3, 4]


@pytest.mark.parametrize("task_id", ["6.1", "6.2", "6.3", "6.4"])
def test_the_reference_scores_full_marks(task_id):
    result = run_check(task_id, REFERENCES[task_id], allow_reference=True)
    assert result.points == TASKS[task_id].points, result.message


@pytest.mark.parametrize("task_id", ["6.1", "6.2", "6.3", "6.4"])
def test_a_students_solution_scores_full_marks(task_id):
    result = run_check(task_id, SOLUTIONS[task_id])
    assert result.points == TASKS[task_id].points and result.message == "", result.message


@pytest.mark.parametrize("task_id, impl, words", MISTAKES, ids=lambda v: getattr(v, "__name__", None))
def test_a_typical_mistake_loses_points_with_a_useful_message(task_id, impl, words):
    result = run_check(task_id, impl, allow_reference=True)
    assert result.points < TASKS[task_id].points
    assert words in result.message, result.message
    assert "\n" not in result.message


def light_space_via_reference(points, K, R, t, orthographic):
    return shadows.light_space(points, K, R, t, orthographic)


def bias_via_biased_depth(z, normals, to_light, fx, orthographic, bias, slope_bias, max_slope):
    tan = torch.zeros_like(z)
    return z - shadows.biased_depth(z, 1 / fx, tan, bias, slope_bias)


def pcf_via_reference(depth_map, coords, depths, k):
    return shadows.pcf(depth_map, coords, depths, k)


def acne_via_reference(depth_map, coords, depths, k):
    return _acne_bias(depth_map, coords, depths, k)


@pytest.mark.parametrize("task_id, impl", [("6.1", light_space_via_project), ("6.1", light_space_via_reference),
                                           ("6.2", bias_via_tan_theta), ("6.2", bias_via_biased_depth),
                                           ("6.3", pcf_via_reference), ("6.4", acne_via_reference)],
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
    least = float(_acne_bias(sm.depth[0], xyz[:, :2], xyz[:, 2], k))          # 6.4: the least bias for no acne
    assert least > 0
    assert (shadow_factor(pts, None, sm, bias=least, pcf=k) == 1).all()
    assert (shadow_factor(pts, None, sm, bias=least * (1 - 1e-6), pcf=k) < 1).any()


def test_the_bias_is_shadow_factors():
    """6.2's reference is the slope term shadow_factor subtracts: its biased comparison is shadow_factor's."""
    ground = plane(4.0, dtype=torch.float64)
    light = DirectionalLight((0.6, -1.0, 0.3))
    sm = shadow_map(ground, light, 32)
    g = torch.Generator().manual_seed(2)
    pts = torch.cat([torch.rand(2000, 1, generator=g, dtype=torch.float64) * 3.6 - 1.8,
                     torch.zeros(2000, 1, dtype=torch.float64),
                     torch.rand(2000, 1, generator=g, dtype=torch.float64) * 3.6 - 1.8], 1)
    normals = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64).expand_as(pts)
    to_light = -torch.tensor(light.direction, dtype=torch.float64).expand_as(pts)
    cam = sm.camera
    xyz = _light_space(pts, cam.K, cam.R, cam.t, cam.orthographic)
    total = _depth_bias(xyz[:, 2], normals, to_light, float(cam.K[0, 0]), True, 0.01, 1.5, 10.0)
    mine = _pcf(sm.depth[0], xyz[:, :2], xyz[:, 2] - total, 1)
    assert torch.equal(mine, shadow_factor(pts, normals, sm, bias=0.01, slope_bias=1.5))


def test_the_checks_are_registered_with_references():
    assert TASKS["6.1"].reference == ("course.shadows", "light_space")
    assert TASKS["6.2"].reference == ("course.shadows", "biased_depth")
    assert TASKS["6.3"].reference == ("course.shadows", "pcf")
    assert TASKS["6.4"].reference == ("course.grading.lecture06", "_acne_bias")
