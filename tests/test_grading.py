"""Grading: every task's check (the reference scores full marks, typical mistakes lose points with a message a
student can act on), the helpers and check-cell API, and the command-line grader on five tiny notebooks run in
real workers (correct, released exercise, wrong, broken, cheating)."""
import csv
import json
import logging
import signal
import threading
import time
from pathlib import Path

import pytest
import torch

from course import camera, mesh, raster, shading
from course.grading import (TASKS, Result, check, cli, compare, generator, grade_notebook, run_check,
                            summarize_exception, tasks_for_lecture)
from course.grading.registry import calls_reference

FIXTURES = Path(__file__).resolve().parent / "fixtures"


# ------------------------------------------------------------------------- references and mistakes

REFERENCES = {
    "1.1": camera.axis_angle_to_matrix,
    "1.2": camera.look_at,
    "1.3": camera.world_to_camera,
    "2.1": camera.project_points,
    "2.2": camera.pixel_rays,
    "2.3": lambda points, K, R, t: camera.project_points(points, K, R, t, orthographic=True),
    "3.1": raster.inside_triangle,
    "3.2": raster.barycentric_2d,
    "3.3": raster.zbuffer_resolve,
    "3.4": raster.perspective_correct_bary,
    "4.1": shading.lambert,
    "4.2": shading.blinn_phong,
    "4.3": lambda texture, uv: shading.sample_texture(texture, uv, mode="bilinear"),
    "1.4": lambda verts, faces: mesh.Mesh(verts, faces).vertex_normals(),
    "2.4": raster.clip_polygon_near,
    "4.4": shading.mip_level,
}

NAMES = {"1.1": "rodrigues", "1.2": "look_at", "1.3": "world_to_camera", "2.1": "project_points",
         "2.2": "pixel_rays", "2.3": "project_orthographic", "3.1": "inside_triangle", "3.2": "barycentric",
         "3.3": "zbuffer_resolve", "3.4": "perspective_correct", "4.1": "lambert", "4.2": "blinn_phong",
         "4.3": "sample_bilinear", "1.4": "vertex_normals", "2.4": "clip_near", "4.4": "mip_level",
         "5.1": "clip_polygon", "5.2": "halfplane_pixel_area", "5.3": "segment_pixels", "5.4": "supersample",
         "5.5": "convergence",
         "6.1": "light_space", "6.2": "depth_bias", "6.3": "pcf", "6.4": "acne_bias",
         "7.1": "ray_triangle", "7.2": "ray_aabb", "7.3": "shadow_ray", "7.4": "bvh_closest_hit",
         "7.5": "area_light", "7.6": "error_slope",
         "8.1": "nmr_edge_gradients", "8.2": "soft_coverage", "8.3": "soft_blend", "8.4": "sigma_for_blur",
         "9.1": "best_step", "9.2": "boundary_term", "9.3": "triangle_term", "9.4": "edge_sample",
         "10.1": "silhouette_iou_loss", "10.2": "smoothness_loss", "10.3": "fit_pose", "10.4": "staircase",
         "11.1": "gram_matrix", "11.2": "style_loss", "11.3": "random_directions", "11.4": "deep_dream_step",
         "11.5": "compare_runs",
         "12.1": "project_onto_plane", "12.2": "shadow_velocity", "12.3": "variance_lit", "12.4": "light_step",
         "12.5": "tight_distribution",
         "13.1": "voxel_iou", "13.2": "multiview_iou_loss", "13.3": "view_eyes", "13.4": "train_step",
         "13.5": "visual_hull",
         "14.1": "lambert_form_factor", "14.2": "project_from_point", "14.3": "clip_polygon", "14.4": "edge_derivative",
         "15.1": "covariance_2d", "15.2": "composite_pixel", "15.3": "swap_jump", "15.4": "ray_density"}
WITHOUT_REFERENCE = {"7.5", "7.6"}       # no package function does their work: they forbid the ones that help
LECTURES_TESTED_HERE = ("1.", "2.", "3.", "4.")           # lectures 05-15: tests/test_grading_NN.py


def rodrigues_dividing_by_theta(w):
    theta = w.norm()
    k = w / theta                                                          # NaN at θ = 0
    zero = torch.zeros((), dtype=w.dtype)
    K = torch.stack([torch.stack([zero, -k[2], k[1]]), torch.stack([k[2], zero, -k[0]]),
                     torch.stack([-k[1], k[0], zero])])
    return torch.eye(3, dtype=w.dtype) + torch.sin(theta) * K + (1 - torch.cos(theta)) * K @ K


def look_at_flipping(*rows):
    def look_at(eye, target, up):
        R, _ = camera.look_at(eye, target, up)
        R = R.clone()
        R[list(rows)] *= -1
        return R, -R @ eye
    return look_at


def edges(tri, p):
    e = lambda a, b: (b[0] - a[0]) * (p[:, 1] - a[1]) - (b[1] - a[1]) * (p[:, 0] - a[0])   # noqa: E731
    return torch.stack([e(tri[0], tri[1]), e(tri[1], tri[2]), e(tri[2], tri[0])])


def barycentric_by_abs_area(tri, p):
    e = raster.edge_function
    w = torch.stack([e(tri[1], tri[2], p), e(tri[2], tri[0], p), e(tri[0], tri[1], p)], -1)
    return w / e(tri[0], tri[1], tri[2]).abs()


def barycentric_nan_when_degenerate(tri, p):
    e = raster.edge_function
    w = torch.stack([e(tri[1], tri[2], p), e(tri[2], tri[0], p), e(tri[0], tri[1], p)], -1)
    return w / e(tri[0], tri[1], tri[2])


def zbuffer_last_writer_wins(pixel_index, depth, face_id, num_pixels):
    face_map = torch.full((num_pixels,), -1, dtype=torch.int64)
    depth_map = torch.full((num_pixels,), float("inf"), dtype=depth.dtype)
    for p, d, f in zip(pixel_index.tolist(), depth.tolist(), face_id.tolist()):
        if d <= depth_map[p]:
            face_map[p], depth_map[p] = f, d
    return face_map, depth_map


def zbuffer_empty_as_zero(pixel_index, depth, face_id, num_pixels):
    face_map, depth_map = raster.zbuffer_resolve(pixel_index, depth, face_id, num_pixels)
    return face_map.clamp_min(0), depth_map.nan_to_num(posinf=0.0)


def blinn_phong_without_mask(n, l, v, s):
    h = (l + v) / (l + v).norm(dim=-1, keepdim=True)
    return (n * h).sum(-1).clamp_min(0) ** s


def sample_texture_at(du, dv, flip_v=False):
    def sample_bilinear(texture, uv):
        Ht, Wt = texture.shape[:2]
        v = 1 - uv[:, 1] if flip_v else uv[:, 1]
        return shading.sample_texture(texture, torch.stack([uv[:, 0] + du / Wt, v + dv / Ht], -1))
    return sample_bilinear


def sample_without_clamping(texture, uv):
    Ht, Wt = texture.shape[:2]
    x, y = uv[:, 0] * Wt - 0.5, (1 - uv[:, 1]) * Ht - 0.5
    c, r = x.floor().long(), y.floor().long()
    fx, fy = (x - c)[:, None], (y - r)[:, None]
    top = texture[r, c] * (1 - fx) + texture[r, c + 1] * fx
    return top * (1 - fy) + (texture[r + 1, c] * (1 - fx) + texture[r + 1, c + 1] * fx) * fy


def inside_top_right(tri, p):                          # the left-edge test's sign flipped
    e = raster.edge_function
    area = e(tri[0], tri[1], tri[2])
    t = tri[[0, 2, 1]] if area < 0 else tri
    inside = torch.full((len(p),), bool(area != 0))
    for k in range(3):
        a, b = t[k], t[(k + 1) % 3]
        owned = bool(b[1] > a[1] or (b[1] == a[1] and b[0] > a[0]))
        inside &= (e(a, b, p) > 0) | ((e(a, b, p) == 0) & owned)
    return inside


def face_cross(verts, faces):
    v0, v1, v2 = verts[faces].unbind(1)
    return torch.linalg.cross(v1 - v0, v2 - v0, dim=-1)              # (F, 3), length = twice the area


def summed_normals(verts, faces, per_face):
    return torch.zeros_like(verts).index_add(0, faces.reshape(-1), per_face.repeat_interleave(3, 0))


def unit(x):
    return x / x.norm(dim=-1, keepdim=True).clamp_min(1e-30)


def normals_last_write_wins(verts, faces):
    n = torch.zeros_like(verts)
    for k in range(3):
        n[faces[:, k]] += face_cross(verts, faces)                   # repeated indices: one add survives
    return unit(n)


def clip_with(keep, crossing):
    def clip_near(tri, near):
        inside, polygon = keep(tri[:, 2], near).tolist(), []
        for a in range(3):
            b = (a + 1) % 3
            if inside[a]:
                polygon.append(tri[a])
            if inside[a] != inside[b]:
                polygon.append(crossing(tri[a], tri[b], near))
        return torch.stack(polygon) if polygon else tri.new_zeros((0, 3))
    return clip_near


def camera_crossing(a, b, near):
    p = a + (near - a[2]) / (b[2] - a[2]) * (b - a)
    return torch.cat([p[:2], p.new_tensor([near])])


def screen_crossing(a, b, near):                            # interpolated in 1/z: wrong
    return a + (1 / near - 1 / a[2]) / (1 / b[2] - 1 / a[2]) * (b - a)


def clip_as_triangles(tri, near):
    p = raster.clip_polygon_near(tri, near)
    return torch.stack([p[[0, 1, 2]], p[[0, 2, 3]]]) if len(p) == 4 else p.reshape(-1, 3, 3)


def footprint(d, size, scale=(1, 0)):
    return d * torch.tensor([size[scale[0]], size[scale[1]]], dtype=d.dtype)


def mip_from(lengths, pick=torch.maximum, clamp=True):
    def mip_level(dx, dy, size):
        rho = pick(lengths(footprint(dx, size)), lengths(footprint(dy, size)))
        return torch.log2(rho).clamp_min(0) if clamp else torch.log2(rho)
    return mip_level


def length(d):
    return d.norm(dim=-1)


P, WC, PR = camera.project_points, camera.world_to_camera, camera.pixel_rays

MISTAKES = [  # task, implementation, points it earns, words its message must contain
    ("1.1", lambda w: camera.axis_angle_to_matrix(w).T, 0, ["transpose of the rotation", "-θ"]),
    ("1.1", rodrigues_dividing_by_theta, 1, ["rodrigues([0, 0, 0])", "NaN", "return the identity"]),
    ("1.1", lambda w: camera.axis_angle_to_matrix(w).float(), 1, ["dtype float64 in, float32 out"]),
    ("1.1", lambda w: camera.axis_angle_to_matrix(w)[None], 0, ["shape (3, 3) expected, got (1, 3, 3)"]),
    ("1.2", look_at_flipping(1), 1, ["your look_at returns a left-handed frame: det(R) = -1", "+y points up"]),
    ("1.2", look_at_flipping(0), 1, ["left-handed frame: det(R) = -1", "+x points left"]),
    ("1.2", look_at_flipping(1, 2), 1, ["OpenGL", "+y down, +z forward"]),
    ("1.2", lambda e, t, u: (camera.look_at(e, t, u)[0].T, camera.look_at(e, t, u)[1]), 0, ["returns Rᵀ"]),
    ("1.2", lambda e, t, u: (camera.look_at(e, t, u)[0], -e), 1, ["t = -R @ eye"]),
    ("1.2", lambda e, t, u: camera.look_at(e, t, u)[0], 0, ["look_at should return a tuple (R, t), got Tensor"]),
    ("1.3", lambda p, R, t: p @ R + t, 0, ["you applied Rᵀ"]),
    ("1.3", lambda p, R, t: p @ R.T, 0, ["the translation t is missing"]),
    ("1.3", lambda p, R, t: torch.stack([R @ x + t for x in p]), 1, ["float64: RuntimeError", "line"]),
    ("2.1", lambda *a: (P(*a)[0][:, [1, 0]], P(*a)[1]), 1, ["pixels are (row, column)"]),
    ("2.1", lambda *a: (P(*a, orthographic=True)[0], P(*a)[1]), 1, ["no perspective divide"]),
    ("2.1", lambda p, K, R, t: (P(p, K, R, t)[0], WC(p, R, t).norm(dim=1)), 1, ["not the distance"]),
    ("2.1", lambda *a: (P(*a)[0] - a[1][:2, 2], P(*a)[1]), 1, ["principal point is missing"]),
    ("2.1", lambda *a: (P(*a)[0], P(*a)[1][:, None]), 1, ["depth: shape (8,) expected, got (8, 1)"]),
    ("2.2", lambda K, R, t, w, h: PR(K + torch.tensor([[0, 0, .5], [0, 0, .5], [0, 0, 0]], dtype=K.dtype), R, t, w, h),
     1, ["missing half-pixel offset", "(j + 0.5, i + 0.5)"]),
    ("2.2", lambda *a: (PR(*a)[0], 2 * PR(*a)[1]), 1, ["not unit length", "normalise"]),
    ("2.2", lambda K, R, t, w, h: PR(K, R, t, h, w), 0, ["shape (4, 5, 3) expected, got (5, 4, 3)", "(H, W, 3)"]),
    ("2.2", lambda K, R, t, w, h: (t.expand(h, w, 3), PR(K, R, t, w, h)[1]), 1, ["camera centre -Rᵀ t, not t"]),
    ("2.3", lambda *a: P(*a), 0, ["you divided by depth"]),
    ("3.1", lambda tri, p: (edges(tri, p) >= 0).all(0), 1, ["every point is outside", "either winding"]),
    ("3.1", lambda tri, p: (edges(tri, p) >= 0).all(0) | (edges(tri, p) <= 0).all(0), 2, ["inside both"]),
    ("3.1", lambda tri, p: (edges(tri, p) > 0).all(0) | (edges(tri, p) < 0).all(0), 2, ["inside neither"]),
    ("3.1", lambda tri, p: raster.inside_triangle(tri, p).float(), 2, ["dtype bool expected, got float32"]),
    ("3.2", lambda tri, p: raster.barycentric_2d(tri, p)[:, [1, 2, 0]], 0, ["weights in the wrong order"]),
    ("3.2", barycentric_by_abs_area, 0, ["signs flipped", "signed area"]),
    ("3.2", barycentric_nan_when_degenerate, 1, ["zero-area triangle returns NaN or inf"]),
    ("3.3", lambda pi, d, f, n: (raster.zbuffer_resolve(pi, -d, f, n)[0], raster.zbuffer_resolve(pi, d, f, n)[1]),
     1, ["kept the farthest fragment"]),
    ("3.3", zbuffer_last_writer_wins, 2, ["ties go to the lower face id"]),
    ("3.3", zbuffer_empty_as_zero, 1, ["has no fragment, so face_map must be -1"]),
    ("3.3", lambda *a: (raster.zbuffer_resolve(*a)[0].int(), raster.zbuffer_resolve(*a)[1]), 2,
     ["dtype int64 expected, got int32"]),
    ("3.4", lambda b, z: raster.perspective_correct_bary(b, 1 / z), 0, ["you weighted by z"]),
    ("3.4", lambda b, z: b / z, 0, ["normalise", "sum to 1"]),
    ("3.4", lambda b, z: b.clone(), 0, ["returned bary_screen unchanged"]),
    ("4.1", lambda n, l, a: a * (n * l).sum(-1, keepdim=True), 0, ["clamp, max(0, n·l)"]),
    ("4.1", lambda n, l, a: a * (n * l).sum(-1, keepdim=True).abs(), 0, ["not |n·l|"]),
    ("4.1", lambda n, l, a: shading.lambert(n, -l, a), 0, ["toward the light"]),
    ("4.1", lambda n, l, a: shading.lambert(n, l, a).sum(-1), 0, ["shape (12, 3) expected, got (12,)"]),
    ("4.2", blinn_phong_without_mask, 0, ["n·l <= 0", "return 0 there"]),
    ("4.2", shading.phong, 0, ["that is Phong's r·v"]),
    ("4.2", lambda *a: shading.blinn_phong(*a)[:, None], 0, ["shape (13,) expected, got (13, 1)"]),
    ("4.3", sample_texture_at(0, 0, flip_v=True), 0, ["v is flipped"]),
    ("4.3", sample_texture_at(0.5, -0.5), 0, ["missing half-texel offset"]),
    ("4.3", lambda tex, uv: shading.sample_texture(tex, uv, mode="nearest"), 1, ["nearest lookup"]),
    ("4.3", sample_without_clamping, 1, ["IndexError", "line"]),
    ("1.4", lambda v, f: unit(summed_normals(v, f, unit(face_cross(v, f)))), 1, ["averaged unit face normals"]),
    ("1.4", lambda v, f: -mesh.Mesh(v, f).vertex_normals(), 0, ["point inward", "counter-clockwise"]),
    ("1.4", lambda v, f: summed_normals(v, f, face_cross(v, f)), 0, ["normalise", "unit vectors"]),
    ("1.4", normals_last_write_wins, 0, ["index_add"]),
    ("1.4", lambda v, f: summed_normals(v, f, face_cross(v, f)) / summed_normals(v, f, face_cross(v, f)).norm(
        dim=-1, keepdim=True), 2, ["vertex 4 has no face of nonzero area", "NaN", "zero normal"]),
    ("2.4", clip_with(lambda z, near: z <= near, camera_crossing), 0, ["kept the part behind the near plane"]),
    ("2.4", lambda tri, near: raster.clip_polygon_near(tri, near).flip(0), 0, ["other way round"]),
    ("2.4", clip_with(lambda z, near: z >= near, screen_crossing), 0, ["interpolated in 1/z", "camera space"]),
    ("2.4", clip_with(lambda z, near: z > near, camera_crossing), 2, ["exactly on the near plane", "z >= near"]),
    ("2.4", lambda tri, near: raster.clip_polygon_near(tri, near) if (tri[:, 2] >= near).any() else tri, 2,
     ["every vertex is behind", "empty (0, 3) polygon"]),
    ("2.4", clip_as_triangles, 0, ["return the clipped polygon (P, 3)", "not triangles"]),
    ("2.4", lambda tri, near: torch.roll(raster.clip_polygon_near(tri, near), 1, 0).float(), 2,
     ["dtype float64 in, float32 out"]),
    ("3.1", inside_top_right, 2, ["takes right edges instead of left ones", "runs upward on screen"]),
    ("4.4", lambda dx, dy, size: shading.mip_level(dx, dy, (1, 1)), 0, ["texture size", "in texels"]),
    ("4.4", lambda dx, dy, size: shading.mip_level(dx, dy, size[::-1]), 0, ["Wt and Ht are swapped"]),
    ("4.4", mip_from(length, pick=torch.minimum), 0, ["longer side of the pixel's footprint"]),
    ("4.4", mip_from(length, clamp=False), 1, ["clamp λ at 0"]),
    ("4.4", mip_from(lambda d: d.abs().amax(-1)), 0, ["length of each derivative vector"]),
    ("4.4", lambda dx, dy, size: shading.mip_level(dx, dy, size).floor(), 0, ["unrounded"]),
]


def test_the_registry_holds_the_fixed_tasks():
    assert {t.id: t.name for t in TASKS.values()} == NAMES
    assert all(1 <= t.points <= 6 for t in TASKS.values())               # points by difficulty
    for lecture in range(5, 14):                                            # 05-13: at least four tasks each
        assert len(tasks_for_lecture(lecture)) >= 4, lecture
    assert [t.id for t in tasks_for_lecture(1)] == ["1.1", "1.2", "1.3", "1.4"]
    assert {t.id for t in TASKS.values() if not t.reference} == WITHOUT_REFERENCE   # the others name what they
                                                                            # re-implement
    here = {t for t in TASKS if t.startswith(LECTURES_TESTED_HERE)}
    assert {task for task, *_ in MISTAKES} == set(REFERENCES) == here     # a mistake for every task


@pytest.mark.parametrize("task_id", sorted(REFERENCES))
def test_the_reference_scores_full_marks(task_id):
    result = run_check(task_id, REFERENCES[task_id], allow_reference=True)
    assert (result.points, result.message) == (TASKS[task_id].points, "")


@pytest.mark.parametrize("task_id, impl, points, words", MISTAKES,
                         ids=[f"{m[0]}-{m[3][0][:30]}" for m in MISTAKES])
def test_a_typical_mistake_loses_points_with_a_useful_message(task_id, impl, points, words):
    result = run_check(task_id, impl, allow_reference=True)           # the mistakes are written with the references
    assert result.points == points, result.message
    for word in words:
        assert word in result.message
    assert "\n" not in result.message


# ------------------------------------------------------------------------- calling the reference

def rodrigues(w):                                          # written out, as a student would
    theta = w.norm()
    if theta < 1e-12:
        return torch.eye(3, dtype=w.dtype)
    kx, ky, kz = (w / theta).unbind(0)
    zero = torch.zeros_like(kx)
    K = torch.stack([torch.stack([zero, -kz, ky]), torch.stack([kz, zero, -kx]), torch.stack([-ky, kx, zero])])
    return torch.eye(3, dtype=w.dtype) + torch.sin(theta) * K + (1 - torch.cos(theta)) * K @ K


def barycentric_with_edge_function(tri, p):                # another package function: allowed
    e = raster.edge_function
    area = e(tri[0], tri[1], tri[2])
    w = torch.stack([e(tri[1], tri[2], p), e(tri[2], tri[0], p), e(tri[0], tri[1], p)], -1)
    return torch.full_like(w, 1 / 3) if area == 0 else w / area


def inside_via_attribute(tri, p):
    return raster.inside_triangle(tri, p)


def inside_via_import(tri, p):
    from course.raster import inside_triangle as covered
    return covered(tri, p)


def inside_via_package(tri, p):
    import course
    return course.raster.inside_triangle(tri, p)


def inside_via_default(tri, p, covered=raster.inside_triangle):
    return covered(tri, p)


def inside_via_helper(tri, p):
    return inside_via_attribute(tri, p)


def make_inside_via_closure():
    covered = raster.inside_triangle

    def inside_triangle(tri, p):
        return covered(tri, p)
    return inside_triangle


class InsideObject:
    def __call__(self, tri, p):
        return raster.inside_triangle(tri, p)


def fresh_module_function():
    """A function whose global is a module named course.raster that is not the one imported here, as in the
    grader, which re-imports course after the notebook ran."""
    import types
    stale = types.ModuleType("course.raster")

    def inside_triangle(tri, p):                          # a stand-in with the reference's name and module
        return raster.inside_triangle(tri, p)
    inside_triangle.__module__, inside_triangle.__qualname__ = "course.raster", "inside_triangle"
    stale.inside_triangle = inside_triangle
    namespace = {"raster": stale}
    exec("def inside(tri, p):\n    return raster.inside_triangle(tri, p)", namespace)
    return namespace["inside"], inside_triangle


CALLING_THE_REFERENCE = [
    ("3.1", raster.inside_triangle), ("3.1", inside_via_attribute), ("3.1", inside_via_import),
    ("3.1", inside_via_package), ("3.1", inside_via_default), ("3.1", inside_via_helper),
    ("3.1", make_inside_via_closure()), ("3.1", InsideObject()), ("3.1", fresh_module_function()[0]),
    ("3.1", fresh_module_function()[1]), ("3.2", lambda tri, p: raster.barycentric_2d(tri, p)),
    ("4.3", lambda texture, uv: shading.sample_texture(texture, uv)),
    ("1.4", lambda verts, faces: mesh.Mesh(verts, faces).vertex_normals()),
    ("2.3", lambda points, K, R, t: camera.project_points(points, K, R, t, orthographic=True)),
] + [(task_id, REFERENCES[task_id]) for task_id in sorted(REFERENCES)]


@pytest.mark.parametrize("task_id, impl", CALLING_THE_REFERENCE,
                         ids=[f"{t}-{getattr(f, '__name__', type(f).__name__)}" for t, f in CALLING_THE_REFERENCE])
def test_a_function_that_calls_the_reference_scores_zero_and_is_told_why(task_id, impl):
    module, qualname = TASKS[task_id].reference
    result = run_check(task_id, impl)
    assert result.points == 0
    assert result.message.startswith(f"{TASKS[task_id].name} calls {module}.{qualname}, the package function this "
                                     "task re-implements: write it yourself")


def test_other_package_functions_and_own_code_are_allowed():
    assert run_check("3.2", barycentric_with_edge_function).points == 2
    assert run_check("1.1", rodrigues).points == 2
    assert not calls_reference(barycentric_with_edge_function, "course.raster", "barycentric_2d")
    assert not calls_reference(lambda verts, faces: mesh.Mesh(verts, faces).face_normals(), "course.mesh",
                               "Mesh.vertex_normals")


# ------------------------------------------------------------------------ references of the new tasks

@pytest.mark.parametrize("z, count", [((2.0, -0.5, 0.1), 3), ((-1.0, 1.5, 3.0), 4), ((-1.0, -0.2, 0.4), 0),
                                      ((1.0, 2.0, 0.7), 3)])
def test_clip_polygon_near_is_the_rasterizers_clipping(z, count):
    tri = torch.tensor([[0.2, -0.3, z[0]], [1.0, 0.4, z[1]], [-0.6, 0.8, z[2]]], dtype=torch.float64)
    polygon = raster.clip_polygon_near(tri, 0.5)
    assert polygon.shape == (count, 3) and (polygon[:, 2] >= 0.5).all()
    if 0 < count and (tri[:, 2] < 0.5).any():                             # what rasterize draws: the same points
        triangles, _ = raster._clip_near(tri, torch.tensor([[0, 1, 2]]), torch.tensor([0]), 0.5)
        drawn = {tuple(v.tolist()) for v in triangles.reshape(-1, 3)}
        assert drawn == {tuple(v.tolist()) for v in polygon}


def test_mip_level_counts_texels_along_the_longer_footprint():
    dx = torch.tensor([[2 / 128, 0.0], [0.0, 0.0], [0.5 / 128, 0.0], [0.0, 1 / 64]], dtype=torch.float64)
    dy = torch.tensor([[0.0, 8 / 64], [0.0, 0.0], [0.0, 0.5 / 64], [0.0, 0.0]], dtype=torch.float64)
    assert shading.mip_level(dx, dy, (64, 128)).tolist() == [3.0, 0.0, 0.0, 0.0]
    assert shading.mip_level(dx.float(), dy.float(), (64, 128)).dtype == torch.float32


def test_calling_your_own_function_is_fine():
    def project_points(points, K, R, t):                   # the student's 2.1
        cam = points @ R.T + t
        return cam[:, :2] / cam[:, 2:] @ K[:2, :2].T + K[:2, 2], cam[:, 2]

    def project_orthographic(points, K, R, t):             # calls the student's own, not the package's
        cam = points @ R.T + t
        return cam[:, :2] @ K[:2, :2].T + K[:2, 2], project_points(points, K, R, t)[1]
    assert run_check("2.3", project_orthographic).points == 2


# ------------------------------------------------------------------------------------------ helpers

def test_compare_says_what_differs():
    x = torch.arange(3.0)
    assert compare(x.clone(), x) is None
    assert compare(x.numpy(), x) is None                                   # numpy results are fine
    assert compare(x[None], x, name="t") == "t: shape (3,) expected, got (1, 3)"
    assert compare(x, x.double()) == "result: dtype float64 in, float32 out (keep the input's dtype)"
    assert compare(x, x.double(), check_dtype=False) is None
    assert "NaN at 1 of 3 entries (first at index 2)" in compare(torch.tensor([0, 1, float("nan")]), x)
    assert "largest error 0.5 at index 1 (got 1.5, expected 1)" in compare(x + torch.tensor([0, 0.5, 0]), x)
    assert "1 of 3 values differ (first at index 2: got False, expected True)" in compare(
        torch.tensor([True, False, False]), torch.tensor([True, False, True]))
    assert compare([0.0, 1.0, 2.0], x) == "result: expected a tensor, got a list of 3 (stack it into one tensor)"
    assert "did you forget to return" in compare(None, x)


def test_generator_is_seeded():
    assert torch.equal(torch.rand(4, generator=generator(3)), torch.rand(4, generator=generator(3)))


def test_summarize_exception_names_the_students_line():
    def student(x):
        return x @ torch.ones(2)
    try:
        student(torch.ones(3))
    except RuntimeError as exc:
        text = summarize_exception(exc)
    assert text.startswith("RuntimeError: ") and "in student: `return x @ torch.ones(2)`" in text
    assert "\n" not in text


# ------------------------------------------------------------------------------- run_check and check

def not_started(axis_angle):
    # YOUR CODE HERE
    raise NotImplementedError()


def spins(axis_angle):
    while True:
        pass


def test_not_attempted_scores_zero_with_a_hint():
    result = run_check("1.1", not_started)
    assert (result.points, result.max_points) == (0, 2)
    assert result.message.startswith("not attempted yet")


def test_a_library_not_implemented_error_is_an_error_not_a_stub():
    result = run_check("1.1", lambda w: logging.Handler().emit(None))
    assert result.points == 0 and "NotImplementedError" in result.message
    assert "not attempted" not in result.message


def test_an_exception_scores_zero_with_a_one_line_summary():
    result = run_check("1.1", lambda w: 1 / 0)
    assert result.points == 0 and "ZeroDivisionError: division by zero (line" in result.message


@pytest.mark.parametrize("in_thread", [False, True])
def test_a_hang_is_stopped(in_thread):
    box = {}
    start = time.perf_counter()
    if in_thread:                                                          # no SIGALRM outside the main thread
        worker = threading.Thread(target=lambda: box.update(r=run_check("1.1", spins, timeout=0.3)))
        worker.start()
        worker.join(10)
    else:
        box["r"] = run_check("1.1", spins, timeout=0.3)
    assert time.perf_counter() - start < 5
    assert box["r"].points == 0 and box["r"].message.startswith("stopped after 0.3 s")
    assert not any(t.name == "course-check" for t in threading.enumerate())   # the runaway thread was stopped


def test_an_outer_alarm_survives_a_check():
    fired = []
    previous = signal.signal(signal.SIGALRM, lambda *args: fired.append(True))   # e.g. pytest-timeout's
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.3)
        run_check("1.1", rodrigues, timeout=5)
        time.sleep(0.5)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    assert fired


def test_check_prints_one_line_or_two(capsys):
    result = check("1.1", rodrigues)
    assert capsys.readouterr().out == "Task 1.1 rodrigues: 2/2\n"
    assert isinstance(result, Result) and result.points == 2
    check("1.1", not_started)
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "Task 1.1 rodrigues: 0/2" and lines[1].startswith("    not attempted yet")
    assert len(lines) == 2


def test_check_never_crashes_and_is_deterministic(capsys):
    check("9.9", not_started)
    check("1.1", 42)
    check("3.2", lambda tri, p: torch.rand(len(p), 3))
    first = capsys.readouterr().out
    check("9.9", not_started)
    check("1.1", 42)
    check("3.2", lambda tri, p: torch.rand(len(p), 3))
    assert capsys.readouterr().out.splitlines()[:4] == first.splitlines()[:4]
    assert first.startswith("Task 9.9 not_started: 0/0\n    could not check: ValueError: unknown task '9.9'")
    assert "Task 1.1 rodrigues: 0/2\n    rodrigues is not a function (got int)" in first


def test_a_printed_result_is_not_displayed_again(capsys):
    check("1.1", rodrigues)._ipython_display_()
    run_check("1.1", rodrigues)._ipython_display_()
    assert capsys.readouterr().out.splitlines() == ["Task 1.1 rodrigues: 2/2",
                                                   "Result(task='1.1', name='rodrigues', points=2, max_points=2, message='')"]


def test_a_tensor_subclass_cannot_fake_equality():
    class Liar(torch.Tensor):
        def __eq__(self, other):
            return torch.ones_like(other, dtype=torch.bool)
    assert run_check("1.1", lambda w: torch.zeros(3, 3, dtype=w.dtype).as_subclass(Liar)).points == 0


# -------------------------------------------------------------------------- the command-line grader

def grade(notebooks, tmp_path, *options):
    json_path, csv_path = tmp_path / "grades.json", tmp_path / "grades.csv"
    code = cli([str(FIXTURES / n) for n in notebooks] + ["--json", str(json_path), "--csv", str(csv_path)]
               + list(options))
    assert code == 0
    return json.loads(json_path.read_text()), list(csv.reader(csv_path.read_text().splitlines()))


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    """Four notebooks graded in one run, with a generous cell time limit."""
    notebooks = ["solutions/01_demo.ipynb", "exercises/01_demo.ipynb", "submissions/01_wrong.ipynb",
                 "submissions/01_cheater.ipynb"]
    data, rows = grade(notebooks, tmp_path_factory.mktemp("grades"), "--timeout", "120")
    by_name = {Path(k).parent.name + "/" + Path(k).name: {r["task"]: r for r in v} for k, v in data.items()}
    return data, rows, by_name


@pytest.mark.timeout(300)
def test_json_and_csv_have_the_gradebook_shape(graded):
    data, rows, _ = graded
    assert len(data) == 4
    for results in data.values():
        assert [r["task"] for r in results] == ["1.1", "1.2", "1.3", "1.4"]
        assert all(set(r) == {"task", "points", "max_points", "message"} for r in results)
    assert rows[0] == ["notebook", "1.1", "1.2", "1.3", "1.4", "total"] and len(rows) == 5
    assert rows[1][1:] == ["2", "3", "2", "3", "10"]


def test_the_solution_scores_full_marks(graded):
    results = graded[2]["solutions/01_demo.ipynb"]
    assert {t: (r["points"], r["max_points"]) for t, r in results.items()} == {"1.1": (2, 2), "1.2": (3, 3),
                                                                              "1.3": (2, 2), "1.4": (3, 3)}


def test_the_released_exercise_scores_zero_on_every_task(graded):
    results = graded[2]["exercises/01_demo.ipynb"]
    assert sorted(results) == ["1.1", "1.2", "1.3", "1.4"]
    assert all(r["points"] == 0 and r["message"].startswith("not attempted") for r in results.values())


def test_a_wrong_solution_gets_partial_marks_and_the_reasons(graded):
    results = graded[2]["submissions/01_wrong.ipynb"]
    assert results["1.1"]["points"] == 0 and "transpose of the rotation" in results["1.1"]["message"]
    assert results["1.2"]["points"] == 1
    assert "your look_at returns a left-handed frame: det(R) = -1" in results["1.2"]["message"]
    assert results["1.3"]["points"] == 2
    assert results["1.4"]["points"] == 1 and "you averaged unit face normals" in results["1.4"]["message"]


def test_fake_lines_and_monkeypatching_gain_nothing_and_a_deleted_check_cell_is_reported(graded):
    results = graded[2]["submissions/01_cheater.ipynb"]
    assert [r["points"] for r in results.values()] == [0, 0, 0, 0]
    assert results["1.2"]["message"].startswith("look_at calls course.camera.look_at, the package function")
    assert results["1.3"]["message"] == "check cell missing"


WRONG_ANSWERS = {                                  # each loses points with an honest check
    "1.1": "def rodrigues(axis_angle):\n    return torch.eye(3, dtype=axis_angle.dtype)",
    "1.2": "def look_at(eye, target, up):\n    return torch.eye(3, dtype=eye.dtype), -eye",
    "1.3": "def world_to_camera(points, R, t):\n    return points",
    "1.4": "def vertex_normals(verts, faces):\n    return torch.zeros_like(verts)",
}

# Patches of the checks' own modules: every comparison passes, every part scores, 1.3 is replaced outright.
PATCH_CHECKS = """\
import course.grading.helpers, course.grading.lecture01, course.grading.registry
full_marks = lambda *parts: (sum(points for points, _, _ in parts), "")
course.grading.helpers.grade_parts = full_marks
course.grading.helpers.compare = lambda *args, **kwargs: None
course.grading.lecture01.grade_parts = full_marks
course.grading.lecture01.compare = lambda *args, **kwargs: None
course.grading.lecture01._diagnose = lambda *args, **kwargs: None
registry = course.grading.registry
registry.TASKS["1.3"] = registry.Task("1.3", "world_to_camera", 2, lambda impl: (2, ""))
"""


@pytest.mark.timeout(300)
def test_patching_the_check_modules_in_a_notebook_gains_nothing(tmp_path, monkeypatch):
    import nbformat
    from nbformat.v4 import new_code_cell, new_notebook

    from course.grading import lecture01
    from course.grading.registry import Task
    answers = {}
    for source in WRONG_ANSWERS.values():
        exec(source, {"torch": torch}, answers)
    honest = {task_id: run_check(task_id, answers[TASKS[task_id].name]).points for task_id in WRONG_ANSWERS}
    assert all(points < TASKS[task_id].points for task_id, points in honest.items())
    with monkeypatch.context() as patch:                       # in the process they run in, the patches work
        patch.setattr(lecture01, "grade_parts", lambda *parts: (sum(p for p, _, _ in parts), ""))
        patch.setattr(lecture01, "compare", lambda *args, **kwargs: None)
        patch.setattr(lecture01, "_diagnose", lambda *args, **kwargs: None)
        patch.setitem(TASKS, "1.3", Task("1.3", "world_to_camera", 2, lambda impl: (2, "")))
        assert all(run_check(task_id, answers[TASKS[task_id].name]).points == TASKS[task_id].points
                   for task_id in WRONG_ANSWERS)

    nb = new_notebook(metadata={"kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"}})
    nb.cells = [new_code_cell("import torch\nfrom course.grading import check"), new_code_cell(PATCH_CHECKS)]
    for task_id, source in WRONG_ANSWERS.items():
        nb.cells += [new_code_cell(source), new_code_cell(f'check("{task_id}", {TASKS[task_id].name})')]
    path = tmp_path / "01_patched.ipynb"
    nbformat.write(nb, str(path))
    results = grade_notebook(path, timeout=120)                # the checks run in the grader, not the notebook
    assert {r.task: r.points for r in results} == honest


@pytest.mark.timeout(120)
def test_endless_loops_and_syntax_errors_are_graded_without_hanging(tmp_path):
    start = time.perf_counter()
    data, _ = grade(["submissions/01_broken.ipynb"], tmp_path, "--timeout", "2")
    assert time.perf_counter() - start < 60
    results = {r["task"]: r for r in next(iter(data.values()))}
    assert results["1.1"]["points"] == 0 and "rodrigues is not defined" in results["1.1"]["message"]
    assert results["1.2"]["points"] == 3                                   # cells after the loop still ran
    assert results["1.3"]["points"] == 0 and results["1.3"]["message"].startswith("stopped after 2 s")


def test_notebooks_without_tasks_are_not_run(tmp_path, capsys):
    assert grade_notebook(tmp_path / "notes.ipynb") == [] and grade_notebook(tmp_path / "99_x.ipynb") == []
    assert cli([str(tmp_path / "01_missing.ipynb")]) == 2
    assert "no such notebook" in capsys.readouterr().err
