"""The checks of lecture 2's graded tasks (projection): 2.1 project_points, 2.2 pixel_rays,
2.3 project_orthographic, 2.4 clip_near.

Each check runs the student's function next to the package's reference on fixed, seeded-random and stress
inputs and says what to fix, recognising the typical mistakes of the task. ``import course.grading``
imports this module, which registers its checks in ``course.grading.TASKS``; nothing here is public.
"""
from __future__ import annotations

import torch

from .helpers import (_call, _close, _diagnose, _fmt, _index, _num, _ref, _shape, _unpack, compare, generator,
                      grade_parts, require, to_tensor)
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


@task("2.1", "project_points", points=3, reference=("course.camera", "project_points"))
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


@task("2.3", "project_orthographic", points=2, reference=("course.camera", "project_points"))
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


@task("2.2", "pixel_rays", points=3, reference=("course.camera", "pixel_rays"))
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


# --------------------------------------------------------------------------- 2.4 near-plane clipping

def _clip(tri, keep, crossing) -> torch.Tensor:
    """Sutherland–Hodgman against one plane, with the rule ``keep`` (3,) and the ``crossing(a, b)`` given:
    the reference's walk, used to build the wrong answers of typical mistakes (float64)."""
    polygon = []
    for a in range(3):
        b = (a + 1) % 3
        if keep[a]:
            polygon.append(tri[a])
        if keep[a] != keep[b]:
            polygon.append(crossing(tri[a], tri[b]))
    return torch.stack(polygon) if polygon else tri.new_zeros((0, 3))


def _crossing_in(space: str, near: float, set_z: bool):
    """The edge a → b meets z = near: interpolated along the edge in camera space, or in 1/z (on screen)."""
    def crossing(a, b):
        if space == "camera":
            s = (near - a[2]) / (b[2] - a[2])
        else:
            s = (1 / near - 1 / a[2]) / (1 / b[2] - 1 / a[2])
        p = a + s * (b - a)
        return torch.cat([p[:2], p.new_tensor([near])]) if set_z else p
    return crossing


def _rotations(polygon: torch.Tensor) -> list[torch.Tensor]:
    return [torch.roll(polygon, -k, dims=0) for k in range(max(len(polygon), 1))]


def _same_polygon(got: torch.Tensor, want: torch.Tensor) -> bool:
    """Loosely the same polygon, starting at any vertex (the start is free, the order is not)."""
    return got.shape == want.shape and any(_close(r, want) for r in _rotations(got.to(torch.float64)))


def _clip_variants(tri, near) -> list:
    t = tri.to(torch.float64)
    z = t[:, 2]
    ref = _ref("course.raster", "clip_polygon_near")(t, near)
    camera = _crossing_in("camera", near, True)
    variants = [(_clip(t, (z <= near).tolist(), camera), "you kept the part behind the near plane: keep the "
                 "vertices with z >= near (in front of the camera) and drop the rest"),
                (ref.flip(0), "the polygon runs the other way round: walk the edges v0 → v1 → v2 → v0 and keep "
                 "the input's order, which decides whether the face is front- or back-facing"),
                (_clip(t, (z > near).tolist(), camera), "a vertex exactly on the near plane is kept: in front "
                 "means z >= near")]
    for set_z in (True, False):
        variants.append((_clip(t, (z >= near).tolist(), _crossing_in("screen", near, set_z)),
                         "the crossing points are interpolated in 1/z, as on screen; interpolate along the edge "
                         "in camera space, where it is straight: s = (near - z_a) / (z_b - z_a), "
                         "p = a + s (b - a)"))
    return variants


def _clip_problem(got, tri, near, name, check_dtype) -> str | None:
    """None when ``got`` is the clipped polygon (any start vertex), else what is wrong with it."""
    expected = _ref("course.raster", "clip_polygon_near")(tri, near)
    in_front = int((tri[:, 2] >= near).sum())
    try:
        g = to_tensor(got, name)
    except Exception as failure:                                          # a list of triangles, None, ...
        return str(failure)
    if g.dim() == 3 and tuple(g.shape[1:]) == (3, 3):
        return (f"{name}: return the clipped polygon (P, 3), its vertices in order, not triangles "
                f"{_shape(g.shape)}")
    if g.dim() != 2 or g.shape[-1] != 3:
        return compare(g, expected, name=name, check_dtype=check_dtype)
    if check_dtype and g.dtype != expected.dtype:
        return compare(g, expected, name=name, check_dtype=True)
    if _same_polygon(g, expected) and not g.isnan().any():
        return None
    if len(g) != len(expected) and in_front == 0:
        return f"{name}: every vertex is behind the near plane (z < near): return an empty (0, 3) polygon"
    if len(g) != len(expected) and in_front == 3:
        return f"{name}: every vertex is in front of the near plane: return the triangle as it is"
    for alternative, explanation in _clip_variants(tri, near):
        if _same_polygon(g, alternative) and not _same_polygon(expected.to(torch.float64), alternative):
            return f"{name}: {explanation}"
    if len(g) != len(expected):
        return (f"{name}: {len(expected)} vertices expected ({in_front} in front of the plane, plus one crossing "
                f"for each edge that crosses it), got {len(g)}")
    best = min(_rotations(g), key=lambda r: float((r.to(torch.float64) - expected.to(torch.float64)).abs().max()))
    return compare(best, expected, name=name, check_dtype=False)


_CLIP_ONE = [[0.2, -0.3, 2.0], [1.0, 0.4, -0.5], [-0.6, 0.8, 0.1]]       # only v0 in front of z = 0.5
_CLIP_TWO = [[0.3, 0.1, -1.0], [1.2, -0.4, 1.5], [-0.5, 0.6, 3.0]]       # v1 and v2 in front


@task("2.4", "clip_near", points=3, reference=("course.raster", "clip_polygon_near"))
def _check_clip_near(impl):
    def run(tri, near, check_dtype=False):
        tri = torch.as_tensor(tri, dtype=torch.float32) if not isinstance(tri, torch.Tensor) else tri
        name = f"clip_near({_fmt(tri)}, near={_num(near)})"
        require(_clip_problem(_call(impl, tri, near), tri, near, name, check_dtype))

    def both_windings(vertices):
        tri = torch.tensor(vertices)
        for order in ([0, 1, 2], [1, 2, 0], [0, 2, 1], [2, 1, 0]):      # every vertex first, both windings
            run(tri[order], 0.5)

    def stress():
        f64 = lambda v: torch.tensor(v, dtype=torch.float64)             # noqa: E731
        run(f64([[0.1, 0.2, -1.0], [0.5, 0.1, -0.2], [0.3, 0.6, 0.4]]), 0.5, True)      # all behind
        run(f64([[0.1, 0.2, 1.0], [0.5, 0.1, 2.0], [0.3, 0.6, 0.7]]), 0.5, True)        # all in front
        run(f64([[0.1, 0.2, 0.5], [0.5, 0.1, -2.0], [0.3, 0.6, 0.0]]), 0.5, True)       # one on the plane
        run(f64([[0.1, 0.2, 0.5], [0.5, 0.1, 2.0], [0.3, 0.6, -1.0]]), 0.5, True)       # on, in front, behind
        run(f64([[3e3, -2e3, 4e4], [-1e3, 5e2, -3e4], [2e2, 1e3, 2e-3]]), 1e-3, True)   # huge and tiny
        run(f64([[0.2, 0.1, 1.0 - 1e-9], [0.9, -0.4, 1.0 + 1e-9], [-0.3, 0.5, 5.0]]), 1.0, True)  # grazing
    return grade_parts((1, "one vertex in front", lambda: both_windings(_CLIP_ONE)),
                       (1, "two vertices in front", lambda: both_windings(_CLIP_TWO)),
                       (1, "all behind, all in front, vertices on the plane, huge coordinates, float64", stress))
