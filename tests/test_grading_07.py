"""Lecture 07's graded tasks (course/grading/lecture07.py): the references score full marks, a solution written
as a student would scores full marks without calling them, typical mistakes lose points with the diagnosis a
student can act on, and a function that calls a package function doing the task's work scores 0."""
import math

import pytest
import torch

from course import raytrace
from course.grading import TASKS, run_check, tasks_for_lecture
from grading_contract import contract
from course.grading.lecture07 import EPS, _shadow_reference, _slab_reference


def reference_ray_triangle(origins, directions, tris):
    t, _, hit = raytrace.intersect_triangles(origins, directions, tris)
    hit = hit & (t > 0)
    return torch.where(hit, t, torch.full_like(t, math.inf)), hit


REFERENCES = {
    "7.1": reference_ray_triangle,
    "7.2": _slab_reference,
    "7.3": lambda p, light, tris: _shadow_reference(p, light, tris)[0],
}


# ------------------------------------------------------------------------------ solutions, as students write

def moller(o, d, tris, cull=False, strict=False, forward=True, scale=False):
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    p = torch.linalg.cross(d, e2)
    det = (e1 * p).sum(1)
    safe = torch.where(det == 0, torch.ones_like(det), det)
    T = o - v0
    u = (T * p).sum(1) / safe
    q = torch.linalg.cross(T, e1)
    v = (d * q).sum(1) / safe
    t = (e2 * q).sum(1) / safe
    if strict:
        hit = (det != 0) & (u > 0) & (v > 0) & (u + v < 1)
    else:
        hit = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1)
    if cull:
        hit &= det > 0
    if forward:
        hit &= t > 0
    if scale:
        t = t * d.norm(dim=1)
    return torch.where(hit, t, torch.full_like(t, math.inf)), hit


def ray_triangle(origins, directions, tris):
    return moller(origins, directions, tris)


def ray_aabb(origins, directions, lo, hi):
    a, b = (lo - origins) / directions, (hi - origins) / directions
    near, far = torch.minimum(a, b), torch.maximum(a, b)
    zero = directions == 0
    inside = (origins >= lo) & (origins <= hi)
    near = torch.where(zero, torch.where(inside, -math.inf, math.inf), near)
    far = torch.where(zero, torch.where(inside, math.inf, -math.inf), far)
    t_near, t_far = near.amax(-1), far.amin(-1)
    return (t_near <= t_far) & (t_far >= 0), t_near, t_far


def shadow_ray(points, light_position, tris, eps=1e-6, t_max=True, towards=True, t_min=True):
    N, F = points.shape[0], tris.shape[0]
    L = light_position.expand(N, 3)
    d = (L - points) if towards else (points - L)
    o = points.repeat_interleave(F, 0)
    t, hit = moller(o, d.repeat_interleave(F, 0), tris.repeat(N, 1, 1), forward=False)
    t = t.view(N, F)
    ok = hit.view(N, F) & ((t > eps) if t_min else (t > -1e300))
    if t_max:
        ok &= t < 1 - eps
    return ~ok.any(1)


SOLUTIONS = {"7.1": ray_triangle, "7.2": ray_aabb, "7.3": shadow_ray}


# ------------------------------------------------------------------------------------------ mistakes

def slab_with(swap=True, behind=True, planes=True, closed=True, clamp=False, inside_ok=True):
    def ray_aabb(o, d, lo, hi):
        a, b = (lo - o) / d, (hi - o) / d
        near, far = (torch.minimum(a, b), torch.maximum(a, b)) if swap else (a, b)
        if planes:
            zero = d == 0
            inside = (o >= lo) & (o <= hi)
            near = torch.where(zero, torch.where(inside, -math.inf, math.inf), near)
            far = torch.where(zero, torch.where(inside, math.inf, -math.inf), far)
        t_near, t_far = near.amax(-1), far.amin(-1)
        hit = (t_near <= t_far) if closed else (t_near < t_far)
        if behind:
            hit = hit & ((t_far >= 0) if inside_ok else (t_near >= 0))
        return hit, (t_near.clamp_min(0) if clamp else t_near), t_far
    return ray_aabb


MISTAKES = [
    ("7.1", lambda o, d, t: moller(o, d, t, forward=False), 1, ["behind the ray's origin", "t > 0"]),
    ("7.1", lambda o, d, t: moller(o, d, t, cull=True), 0, ["seen from behind", "both windings"]),
    ("7.1", lambda o, d, t: moller(o, d, t, strict=True), 2, ["through an edge or a vertex", ">= 0"]),
    ("7.1", lambda o, d, t: moller(o, d, t, scale=True), 0, ["units of the direction"]),
    ("7.1", lambda o, d, t: (moller(o, d, t)[0].nan_to_num(posinf=-1.0), moller(o, d, t)[1]), 0,
     ["t must be +inf"]),
    ("7.1", lambda o, d, t: moller(o, d, t)[0], 0, ["should return a tuple (t, hit)"]),
    ("7.2", slab_with(swap=False), 0, ["negative direction component", "min and max"]),
    ("7.2", slab_with(behind=False), 0, ["behind the origin", "t_far >= 0"]),
    ("7.2", slab_with(planes=False), 2, ["0 / 0 = NaN", "d == 0"]),
    ("7.2", slab_with(closed=False), 2, ["touches the box at one point"]),
    ("7.2", slab_with(clamp=True), 2, ["do not clamp it to 0"]),
    ("7.2", slab_with(inside_ok=False), 2, ["origin inside the box"]),
    ("7.3", lambda p, l, t: ~shadow_ray(p, l, t), 0, ["swapped"]),
    ("7.3", lambda p, l, t: shadow_ray(p, l, t, t_max=False), 2, ["beyond the light", "0 < t < 1"]),
    ("7.3", lambda p, l, t: shadow_ray(p, l, t, eps=-1e-9), 2, ["shadow acne", "t <= 1e-06"]),
    ("7.3", lambda p, l, t: shadow_ray(p, l, t, t_min=False), 0, ["behind the point"]),
]


def test_lecture_07_has_three_tasks_of_three_points_each():
    assert [(t.id, t.name, t.points) for t in tasks_for_lecture(7)] == [
        ("7.1", "ray_triangle", 3), ("7.2", "ray_aabb", 3), ("7.3", "shadow_ray", 3)]
    assert {task for task, *_ in MISTAKES} == set(REFERENCES)


(test_the_reference_scores_full_marks, test_a_students_solution_scores_full_marks,
 test_a_typical_mistake_loses_points_with_a_useful_message) = contract(REFERENCES, SOLUTIONS, MISTAKES)


CALLING_THE_PACKAGE = {
    "7.1": lambda o, d, tris: raytrace.intersect_triangles(o, d, tris)[::2],
    "7.3": lambda p, light, tris: raytrace.visible(p, light, raytrace.BVH(raytrace.Hits)),
}


@pytest.mark.parametrize("task_id", sorted(CALLING_THE_PACKAGE))
def test_calling_the_reference_scores_zero(task_id):
    result = run_check(task_id, CALLING_THE_PACKAGE[task_id])
    assert result.points == 0 and "the package function this task re-implements" in result.message


def test_moller_trumbore_is_not_allowed_for_7_1():
    result = run_check("7.1", lambda o, d, tris: raytrace.moller_trumbore(o, d, tris)[::2])
    assert result.points == 0 and "calls course.intersect.moller_trumbore" in result.message


def test_the_shadow_reference_agrees_with_the_package_visible():
    """The brute-force reference of 7.3 gives raytrace.visible's answer on points off the surfaces."""
    from course.grading.lecture07 import _shadow_scene
    from course.mesh import Mesh
    tris = _shadow_scene()
    mesh = Mesh(tris.reshape(-1, 3), torch.arange(tris.shape[0] * 3).view(-1, 3))
    p = torch.rand(200, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64) * 4 - 2
    p[:, 1] = p[:, 1].abs() * 0.4 + 0.05
    light = torch.tensor([0.2, 3.0, 0.1], dtype=torch.float64)
    expected = _shadow_reference(p, light, tris)[0]
    assert torch.equal(raytrace.visible(p, light, raytrace.BVH(mesh), offset=EPS), expected)
    assert 0 < int(expected.sum()) < 200


def shadow_ray_with_bvh(points, light_position, tris):
    mesh = type("M", (), {"verts": tris.reshape(-1, 3), "faces": torch.arange(tris.shape[0] * 3).view(-1, 3)})()
    d = light_position - points
    return ~raytrace.BVH(mesh).intersect(points, d, t_min=1e-6, t_max=1 - 1e-6, any_hit=True).hit


def slab_via_package(origins, directions, lo, hi):
    box = torch.stack([lo, hi], 1)
    return raytrace._slab(origins, 1 / directions, box, torch.zeros(len(lo)), torch.full((len(lo),), math.inf))


@pytest.mark.parametrize("task_id, impl, name", [
    ("7.3", shadow_ray_with_bvh, "course.bvh.BVH"),
    ("7.2", slab_via_package, "course.intersect._slab")])
def test_a_package_function_that_does_the_tasks_work_scores_zero(task_id, impl, name):
    result = run_check(task_id, impl)
    assert result.points == 0
    assert result.message.startswith(f"{TASKS[task_id].name} calls {name}, which does this task's work for you")
