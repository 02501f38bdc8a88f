"""The checks of lecture 2's graded tasks (projection): 2.1 project_points, 2.2 pixel_rays,
2.3 project_orthographic.

Each check runs the student's function next to the package's reference on fixed, seeded-random and stress
inputs and says what to fix, recognising the typical mistakes of the task. ``import course.grading``
imports this module, which registers its checks in ``course.grading.TASKS``; nothing here is public.
"""
from __future__ import annotations

import torch

from .helpers import _call, _diagnose, _index, _num, _ref, _shape, _unpack, generator, grade_parts, require
from .registry import task

__all__: list[str] = []          # nothing public: the checks are reached through course.grading.TASKS


def _pose(dtype, eye=(1.5, 2.0, -6.0), target=(0.2, -0.3, 0.5)):
    R, t = _ref("course.camera", "look_at")(torch.tensor(eye, dtype=dtype), torch.tensor(target, dtype=dtype))
    return R, t


def _scene(dtype, n=8, seed=21, ortho=False):
    """Points in front of a camera with an asymmetric K (fx ≠ fy, principal point off centre)."""
    K = torch.tensor([[12.0, 0.0, 16.5], [0.0, 10.0, 12.5], [0.0, 0.0, 1.0]] if ortho else
                     [[40.0, 0.0, 17.5], [0.0, 36.0, 11.0], [0.0, 0.0, 1.0]], dtype=dtype)
    R, t = _pose(dtype)
    points = torch.tensor([0.2, -0.3, 0.5], dtype=torch.float64) + torch.randn(
        n, 3, generator=generator(seed), dtype=torch.float64) * 0.8
    return points.to(dtype), K, R, t


def _projection_problems(out, points, K, R, t, orthographic: bool, name: str, check_dtype: bool):
    """Messages for pixels and depth, recognising the usual mistakes of either projection."""
    project = _ref("course.camera", "project_points")
    pixels, depth = _unpack(out, ("pixels", "depth"), name)
    ref_pixels, ref_depth = project(points, K, R, t, orthographic=orthographic)
    other = project(points, K, R, t, orthographic=not orthographic)[0].to(torch.float64)
    p64 = ref_pixels.to(torch.float64)
    principal = K[:2, 2].to(torch.float64)
    cam = _ref("course.camera", "world_to_camera")(points, R, t).to(torch.float64)
    pixel_variants = [
        (p64[:, [1, 0]], "pixels are (row, column); return (x, y) = (column, row)"),
        (p64 - principal, "the principal point is missing: add (cx, cy) = (K[0, 2], K[1, 2])"),
        (other, "you divided by depth: an orthographic camera has no perspective divide (x = fx X_cam + cx)"
         if orthographic else "no perspective divide: divide X_cam and Y_cam by the depth Z_cam before K"),
        (project(points, K, R.T, t, orthographic=orthographic)[0].to(torch.float64),
         "points are transformed with Rᵀ: x_cam = R @ x_world + t (points @ R.T + t)")]
    depth_variants = [(cam.norm(dim=1), "depth is the camera-space z, not the distance to the camera"),
                      (-cam[:, 2], "depth has the wrong sign: points in front of the camera have positive z")]
    return [_diagnose(pixels, ref_pixels, f"{name} pixels", pixel_variants, check_dtype=check_dtype),
            _diagnose(depth, ref_depth, f"{name} depth", depth_variants, check_dtype=check_dtype)]


def _projection_stress(dtype, ortho: bool):
    """Scene points plus extreme ones, given in camera space: near the camera plane (behind it for an
    orthographic camera, which has no divide to break) and very far away."""
    points, K, R, t = _scene(dtype, n=40, seed=22, ortho=ortho)
    extreme_cam = torch.tensor([[0.0, 0.0, 1e-7], [0.3, -0.2, 0.0], [0.1, 0.1, -2.0]] if ortho else
                               [[0.0, 0.0, 0.05], [0.01, -0.02, 0.2], [0.0, 0.0, 80.0]], dtype=torch.float64)
    extreme_cam = torch.cat([extreme_cam, torch.tensor([[150.0, -90.0, 900.0], [-4e3, 3e3, 2.5e4]],
                                                       dtype=torch.float64)])
    extreme = (extreme_cam - t.to(torch.float64)) @ R.to(torch.float64)      # back to world: Rᵀ (x_cam - t)
    return torch.cat([points, extreme.to(dtype)]), K, R, t


@task("2.1", "project_points", points=3)
def _check_project_points(impl):
    def part(which):
        scene = _scene(torch.float32)
        require(_projection_problems(_call(impl, *scene), *scene, False, "project_points", False)[which])

    def stress():
        scene = _projection_stress(torch.float64, ortho=False)
        for message in _projection_problems(_call(impl, *scene), *scene, False, "project_points", True):
            require(message)
    return grade_parts((1, "pixels", lambda: part(0)), (1, "depth", lambda: part(1)),
                       (1, "near and far points, huge coordinates, float64", stress))


@task("2.3", "project_orthographic", points=2)
def _check_project_orthographic(impl):
    def cases(stress):
        scene = _projection_stress(torch.float64, True) if stress else _scene(torch.float32, ortho=True)
        for message in _projection_problems(_call(impl, *scene), *scene, True, "project_orthographic", stress):
            require(message)
    return grade_parts((1, "pixels and depth", lambda: cases(False)),
                       (1, "points at and behind the camera plane, float64", lambda: cases(True)))


def _rays_problems(out, K, R, t, width, height, check_dtype) -> list[str | None]:
    """Messages for origins and directions, recognising swapped H/W, a missing half-pixel offset, ..."""
    rays = _ref("course.camera", "pixel_rays")
    origins, directions = _unpack(out, ("origins", "directions"), "pixel_rays")
    ref_origins, ref_dirs = rays(K, R, t, width, height)
    name = f"pixel_rays(width={width}, height={height})"
    R64, t64 = R.to(torch.float64), t.to(torch.float64)
    shift = K.clone()
    shift[:2, 2] += 0.5                                                   # a K that moves pixel centres by -½
    origin_variants = [(t64.expand(height, width, 3), "origins must be the camera centre -Rᵀ t, not t"),
                       (torch.zeros(height, width, 3, dtype=torch.float64),
                        "origins must be the camera centre -Rᵀ t, not the world origin"),
                       ((-R64 @ t64).expand(height, width, 3), "the camera centre is -Rᵀ t, not -R t")]
    dir_variants = [(rays(shift, R, t, width, height)[1], "missing half-pixel offset: pixel (i, j) is sampled "
                     "at its centre (j + 0.5, i + 0.5)"),
                    (rays(K, torch.eye(3, dtype=R.dtype), torch.zeros_like(t), width, height)[1],
                     "directions are in camera space: rotate them into the world with Rᵀ"),
                    (rays(K, R.T, t, width, height)[1], "rotated with R; camera to world is Rᵀ"),
                    (-ref_dirs.to(torch.float64), "directions point from the scene toward the camera")]
    messages = []
    for got, expected, label, variants in ((origins, ref_origins, "origins", origin_variants),
                                           (directions, ref_dirs, "directions", dir_variants)):
        if tuple(got.shape) == (width, height, 3) and width != height:
            messages.append(f"{name} {label}: shape {_shape(expected.shape)} expected, got {_shape(got.shape)}: "
                            "images are (H, W, 3), row index first")
        else:
            messages.append(_diagnose(got, expected, f"{name} {label}", variants, check_dtype=check_dtype))
    if messages[1] and directions.shape == ref_dirs.shape and directions.is_floating_point():
        norms = directions.to(torch.float64).norm(dim=-1)
        if torch.isfinite(norms).all() and (norms - 1).abs().max() > 1e-3:
            first = int((norms - 1).abs().flatten().argmax())
            messages[1] = (f"{name} directions are not unit length (|d| = {_num(norms.flatten()[first])} at "
                           f"pixel {_index(first, norms.shape)}): normalise them")
    return messages


@task("2.2", "pixel_rays", points=3)
def _check_pixel_rays(impl):
    def basic(which):
        R, t = _pose(torch.float32, eye=(0.5, 1.0, -3.0), target=(0.0, 0.0, 0.0))
        K = torch.tensor([[6.0, 0.0, 2.7], [0.0, 5.5, 1.9], [0.0, 0.0, 1.0]])
        require(_rays_problems(_call(impl, K, R, t, 5, 4), K, R, t, 5, 4, False)[which])

    def stress():
        R, t = _pose(torch.float64, eye=(4.0, -1.0, 2.0), target=(0.3, 0.2, -0.1))
        for width, height in ((7, 3), (1, 1)):
            K = torch.tensor([[9.0, 0.0, width * 0.45], [0.0, 7.0, height * 0.6], [0.0, 0.0, 1.0]],
                             dtype=torch.float64)
            for message in _rays_problems(_call(impl, K, R, t, width, height), K, R, t, width, height, True):
                require(message)
    return grade_parts((1, "origins", lambda: basic(0)), (1, "directions", lambda: basic(1)),
                       (1, "other sizes, float64", stress))
