"""Lecture 07's graded tasks (course/grading/lecture07.py): the references score full marks, a solution written
as a student would scores full marks without calling them, typical mistakes lose points with the diagnosis a
student can act on, and a function that calls a package function doing the task's work scores 0."""
import math

import pytest
import torch

from course import raytrace
from course.intersect import _watertight
from course.grading import TASKS, run_check, tasks_for_lecture
from grading_contract import contract
from course.grading.lecture07 import EPS, _area_reference, _shadow_reference, _slab_reference, _slope_reference


def reference_ray_triangle(origins, directions, tris):
    t, _, hit = raytrace.moller_trumbore(origins, directions, tris)
    hit = hit & (t > 0)
    return torch.where(hit, t, torch.full_like(t, math.inf)), hit


def reference_closest_hit(origins, directions, tree):
    """Brute force over the tree's triangles with the watertight test: the nearest t > 0 and its face id."""
    N, F = origins.shape[0], tree.tris.shape[0]
    T = tree.tris.repeat(N, 1, 1)                                       # (the task forbids intersect_triangles)
    t, _, hit = _watertight(origins.repeat_interleave(F, 0), directions.repeat_interleave(F, 0), *T.unbind(1))
    t = torch.where(hit & (t > 0), t, torch.full_like(t, math.inf)).view(N, F)
    best, slot = t.min(1)
    return best, torch.where(torch.isfinite(best), tree.order[slot], torch.full_like(slot, -1))


REFERENCES = {
    "7.1": reference_ray_triangle,
    "7.2": _slab_reference,
    "7.3": lambda p, light, tris: _shadow_reference(p, light, tris)[0],
    "7.4": reference_closest_hit,
    "7.5": _area_reference,
    "7.6": _slope_reference,
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


def closest_hit(origins, directions, tree, first_hit=False, slot=False, one_child=False):
    N = origins.shape[0]
    t_best = torch.full((N,), math.inf, dtype=origins.dtype)
    face = torch.full((N,), -1, dtype=torch.int64)
    left, first, count = tree.left.tolist(), tree.first.tolist(), tree.count.tolist()

    def box(k, o, d):
        return ray_aabb(o, d, tree.boxes[k:k + 1, 0], tree.boxes[k:k + 1, 1])

    for k in range(N):
        o, d = origins[k:k + 1], directions[k:k + 1]
        stack = [0]
        while stack:
            node = stack.pop()
            hit, t_near, _ = box(node, o, d)
            if not bool(hit) or float(t_near) > float(t_best[k]):
                continue
            if left[node] < 0:
                a, c = first[node], count[node]
                t, h = ray_triangle(o.expand(c, 3), d.expand(c, 3), tree.tris[a:a + c])
                j = int(t.argmin())
                if bool(h[j]) and float(t[j]) < float(t_best[k]):
                    t_best[k], face[k] = t[j], (a + j if slot else tree.order[a + j])
                    if first_hit:
                        break
            elif one_child:                                               # only the box entered first
                kids = [(float(box(c, o, d)[1]), c) for c in (left[node], left[node] + 1) if bool(box(c, o, d)[0])]
                stack += [min(kids)[1]] if kids else []
            else:
                stack += [left[node], left[node] + 1]
    return t_best, face


def area_light(points, normals, samples, light_normal, area, tris, cos_light=True, r2_power=1, scale=True,
               clamp=True, shadows=True, unit=True):
    N, S, _ = samples.shape
    F = tris.shape[0]
    to_light = samples - points[:, None]
    r2 = (to_light ** 2).sum(-1)
    u = to_light / r2.sqrt()[..., None] if unit else to_light
    n = normals / normals.norm(dim=1, keepdim=True)
    n_light = light_normal / light_normal.norm()
    cos_p, cos_l = (u * n[:, None]).sum(-1), -(u @ n_light)
    if clamp:
        cos_p, cos_l = cos_p.clamp_min(0), cos_l.clamp_min(0)
    w = cos_p * (cos_l if cos_light else 1.0) / r2 ** r2_power
    if shadows:
        t, hit = ray_triangle(points.repeat_interleave(S * F, 0), to_light.reshape(-1, 3).repeat_interleave(F, 0),
                              tris.repeat(N * S, 1, 1))
        w = w * ~(hit & (t > 1e-6) & (t < 1 - 1e-6)).view(N, S, F).any(-1)
    return (area / S if scale else 1 / S) * w.sum(1)


def error_slope(estimate, exact, sample_counts, seeds, square=True, pooled=True, fit="lstsq"):
    per = [torch.stack([((estimate(S, s) - exact) ** 2).mean() for s in seeds]) for S in sample_counts]
    if pooled:
        rmse = torch.stack([p.mean() for p in per])
        rmse = rmse.sqrt() if square else rmse
    else:
        rmse = torch.stack([p.sqrt().mean() for p in per])
    x, y = torch.log(torch.tensor(sample_counts, dtype=torch.float64)), rmse.log()
    if fit == "ends":
        return rmse, float((y[-1] - y[0]) / (x[-1] - x[0]))
    slope = float(((x - x.mean()) * (y - y.mean())).sum() / ((x - x.mean()) ** 2).sum())
    return rmse, (-slope if fit == "positive" else slope)


SOLUTIONS = {"7.1": ray_triangle, "7.2": ray_aabb, "7.3": shadow_ray, "7.4": closest_hit, "7.5": area_light,
             "7.6": error_slope}


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
    ("7.2", slab_with(planes=False), 1, ["0 / 0 = NaN", "d == 0"]),
    ("7.2", slab_with(closed=False), 1, ["touches the box at one point"]),
    ("7.2", slab_with(clamp=True), 1, ["do not clamp it to 0"]),
    ("7.2", slab_with(inside_ok=False), 1, ["origin inside the box"]),
    ("7.3", lambda p, l, t: ~shadow_ray(p, l, t), 0, ["swapped"]),
    ("7.3", lambda p, l, t: shadow_ray(p, l, t, t_max=False), 1, ["beyond the light", "0 < t < 1"]),
    ("7.3", lambda p, l, t: shadow_ray(p, l, t, eps=-1e-9), 1, ["shadow acne", "t <= 1e-06"]),
    ("7.3", lambda p, l, t: shadow_ray(p, l, t, t_min=False), 0, ["behind the point"]),
    ("7.4", lambda o, d, tree: closest_hit(o, d, tree, first_hit=True), 0, ["not the nearest", "keep popping"]),
    ("7.4", lambda o, d, tree: closest_hit(o, d, tree, slot=True), 0, ["slot", "tree.order[s]"]),
    ("7.4", lambda o, d, tree: closest_hit(o, d, tree, one_child=True), 0, ["push both"]),
    ("7.5", lambda *a: area_light(*a, cos_light=False), 0, ["light's cosine is missing"]),
    ("7.5", lambda *a: area_light(*a, r2_power=0), 0, ["1 / r² is missing"]),
    ("7.5", lambda *a: area_light(*a, scale=False), 0, ["area is missing", "A / S"]),
    ("7.5", lambda *a: area_light(*a, clamp=False), 2, ["negative cosines count", "clamp"]),
    ("7.5", lambda *a: area_light(*a, shadows=False), 0, ["nothing is shadowed"]),
    ("7.5", lambda *a: area_light(*a, unit=False), 0, ["1 / r² is missing", "unit vectors"]),
    ("7.6", lambda *a: error_slope(*a, square=False), 0, ["mean squared error", "square root"]),
    ("7.6", lambda *a: error_slope(*a, pooled=False), 0, ["averaged", "pool"]),
    ("7.6", lambda *a: error_slope(*a, fit="ends"), 0, ["first and last points", "least squares"]),
    ("7.6", lambda *a: error_slope(*a, fit="positive"), 0, ["sign is flipped"]),
]


def test_lecture_07_has_six_tasks_with_points_by_difficulty():
    assert [(t.id, t.name, t.points) for t in tasks_for_lecture(7)] == [
        ("7.1", "ray_triangle", 3), ("7.2", "ray_aabb", 2), ("7.3", "shadow_ray", 2), ("7.4", "bvh_closest_hit", 5),
        ("7.5", "area_light", 4), ("7.6", "error_slope", 3)]
    assert {task for task, *_ in MISTAKES} == set(REFERENCES)


(test_the_reference_scores_full_marks, test_a_students_solution_scores_full_marks,
 test_a_typical_mistake_loses_points_with_a_useful_message) = contract(REFERENCES, SOLUTIONS, MISTAKES)


CALLING_THE_PACKAGE = {
    "7.1": lambda o, d, tris: raytrace.moller_trumbore(o, d, tris)[::2],
    "7.3": lambda p, light, tris: raytrace.visible(p, light, raytrace.BVH(raytrace.Hits)),
}


@pytest.mark.parametrize("task_id", sorted(CALLING_THE_PACKAGE))
def test_calling_the_reference_scores_zero(task_id):
    result = run_check(task_id, CALLING_THE_PACKAGE[task_id])
    assert result.points == 0 and "the package function this task re-implements" in result.message


def test_the_watertight_test_is_not_allowed_for_7_1():
    result = run_check("7.1", lambda o, d, tris: raytrace.intersect_triangles(o, d, tris)[::2])
    assert result.points == 0 and "calls course.intersect.intersect_triangles" in result.message


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


def closest_hit_with_bvh(origins, directions, tree):
    faces = torch.arange(tree.tris.shape[0] * 3).view(-1, 3)
    mesh = type("M", (), {"verts": tree.tris.reshape(-1, 3), "faces": faces})()
    hits = raytrace.BVH(mesh).intersect(origins, directions)
    return hits.t, torch.where(hits.face_id >= 0, tree.order[hits.face_id.clamp_min(0)], hits.face_id)


def area_light_with_visible(points, normals, samples, light_normal, area, tris):
    mesh = type("M", (), {"verts": tris.reshape(-1, 3), "faces": torch.arange(tris.shape[0] * 3).view(-1, 3)})()
    return raytrace.visible(points, samples, raytrace.BVH(mesh)) * area


def test_a_traversal_that_calls_bvh_intersect_scores_zero():
    result = run_check("7.4", closest_hit_with_bvh)
    assert result.points == 0 and "calls course.bvh.BVH.intersect, the package function" in result.message


@pytest.mark.parametrize("task_id, impl, name", [
    ("7.3", shadow_ray_with_bvh, "course.bvh.BVH"),
    ("7.5", area_light_with_visible, "course.raytrace.visible"),
    ("7.2", slab_via_package, "course.intersect._slab")])
def test_a_package_function_that_does_the_tasks_work_scores_zero(task_id, impl, name):
    result = run_check(task_id, impl)
    assert result.points == 0
    assert result.message.startswith(f"{TASKS[task_id].name} calls {name}, which does this task's work for you")
