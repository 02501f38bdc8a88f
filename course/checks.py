"""The checks of the graded tasks of lectures 1–4, registered in ``course.grading.TASKS``.

Each check runs the student's function next to the package's reference (imported when the check runs, so a
fresh import is a fresh reference) on fixed, seeded-random and stress inputs, and says what to fix: besides
``compare``'s shape, dtype and value messages it recognises the typical mistakes of each task ("your look_at
returns a left-handed frame: det(R) = -1", "pixels are (row, column)", "v is flipped"). Points are split
between basic and stress cases.

``course.grading`` imports this module at its end, so ``import course.grading`` registers every task; the
functions here are private, reached only through the registry.
"""
from __future__ import annotations

import itertools
import math

import torch

from .grading import (_call, _close, _diagnose, _fmt, _index, _num, _ref, _shape, _unpack, compare, generator,
                      grade_parts, require, task, to_tensor)

__all__: list[str] = []          # nothing public: the checks are reached through course.grading.TASKS


# -------------------------------------------------------------------------------- lecture 1: cameras

def _frame_problem(R, R_ref, name: str, check_dtype: bool) -> tuple[str | None, str]:
    """A rotation compared with the reference: ``(message, kind)``, kind naming a recognised mistake:
    "transpose", "flip 1" (rows of R negated, here camera +y), "not a rotation", "left-handed" or ""."""
    message = compare(R, R_ref, name=name, check_dtype=check_dtype)
    if message is None:
        return None, ""
    g = to_tensor(R, name)
    if g.shape != (3, 3) or not g.is_floating_point() or not torch.isfinite(g).all() or _close(g, R_ref):
        return message, ""                                                # shape, dtype, NaN: said already
    g, e = g.to(torch.float64), R_ref.to(torch.float64)
    if _close(g, e.T):
        return message, "transpose"
    flipped = [i for i in range(3) if _close(g[i], -e[i])]
    if flipped and len(flipped) + sum(_close(g[i], e[i]) for i in range(3)) == 3:
        return message, "flip " + " ".join(map(str, flipped))
    error = float((g @ g.T - torch.eye(3, dtype=g.dtype)).abs().max())
    if error > 1e-3:
        return f"{name} is not a rotation: |R Rᵀ - I| = {error:.2g}", "not a rotation"
    det = torch.linalg.det(g)
    return (f"{name} is a left-handed frame: det(R) = {_num(det)}", "left-handed") if det < 0 else (message, "")


_AXIS_FLIPS = {0: "camera +x points left; it must point right (right = forward × up)",
               1: "camera +y points up, but OpenCV's camera +y points down (down = forward × right)",
               2: "camera +z points away from the target (forward = target - eye)"}


def _rotation_cases(dtype, stress: bool) -> list[torch.Tensor]:
    if stress:
        fixed = [[0.0, 0.0, 0.0], [1e-9, -2e-9, 0.0], [0.0, math.pi, 0.0], [-2.0, 1.0, 2.0],
                 [0.0, 0.0, 2 * math.pi]]
        return [torch.tensor(w, dtype=dtype) for w in fixed]
    fixed = [[0.0, 0.0, math.pi / 2], [math.pi / 3, 0.0, 0.0], [0.0, -0.7, 0.0], [0.3, -0.2, 0.9]]
    random = torch.randn(4, 3, generator=generator(11), dtype=torch.float64) * 1.2
    return [torch.tensor(w, dtype=dtype) for w in fixed] + [w.to(dtype) for w in random]


@task("1.1", "rodrigues", points=2)
def _check_rodrigues(impl):
    ref = _ref("course.camera", "axis_angle_to_matrix")

    def cases(dtype, stress):
        for w in _rotation_cases(dtype, stress):
            name = f"rodrigues({_fmt(w)})"
            got = _call(impl, w)
            message, kind = _frame_problem(got, ref(w), name, check_dtype=stress)
            if kind == "transpose":
                message = (f"{name} is the transpose of the rotation (a rotation by -θ): check the sign of "
                           "sin θ [k]ₓ")
            elif kind == "not a rotation":
                message += ": use the unit axis k = ω / |ω| and the angle θ = |ω|"
            elif message and not float(w.norm()) and "NaN" in message:
                message += ": at θ = 0 return the identity (don't divide by θ)"
            require(message)
    return grade_parts((1, "rotations", lambda: cases(torch.float32, False)),
                       (1, "zero and tiny angles, π, float64", lambda: cases(torch.float64, True)))


def _look_at_cases(dtype, stress: bool):
    if stress:
        raw = [([1200.0, -300.0, 2500.0], [1190.0, -301.0, 2497.0], [0.0, 5.0, 0.0]),     # far away, up not unit
               ([0.0, 2.0, 3.0], [0.1, -1.0, -2.0], [0.3, 1.0, -0.2])]                     # up not ⟂ forward
    else:
        raw = [([3.0, 2.0, 5.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
               ([0.0, 1.0, -4.0], [0.5, 0.0, 1.0], [0.0, 1.0, 0.0]),
               ([-2.0, 3.0, 1.0], [1.0, -1.0, 0.5], [0.2, 1.0, 0.1])]
        g = generator(12)
        raw += [((torch.randn(3, generator=g) * 3).tolist(), torch.randn(3, generator=g).tolist(), [0.0, 1.0, 0.0])
                for _ in range(2)]
    return [tuple(torch.tensor(v, dtype=dtype) for v in case) for case in raw]


def _look_at_name(eye, target, up) -> str:
    return f"look_at(eye={_fmt(eye)}, target={_fmt(target)}, up={_fmt(up)})"


def _look_at_message(message: str | None, kind: str) -> str | None:
    """The frame mistakes of look_at in the course's words (OpenCV axes: +x right, +y down, +z forward)."""
    if kind == "flip 1 2":
        return ("your look_at uses OpenGL's camera axes (+y up, -z forward); this course uses OpenCV's: "
                "+x right, +y down, +z forward")
    if kind.startswith("flip"):
        details = "; ".join(_AXIS_FLIPS[int(i)] for i in kind.split()[1:])
        handed = "returns a left-handed frame: det(R) = -1" if len(kind.split()) % 2 == 0 else "flips two axes"
        return f"your look_at {handed} — {details}"
    if kind == "left-handed":
        return "your look_at returns a left-handed frame: " + message.split(": ", 1)[1]
    if kind == "not a rotation":
        return message + ": normalise the forward, right and down vectors"
    if kind == "transpose":
        return ("your look_at returns Rᵀ (camera to world): R maps world to camera, its rows are the camera's "
                "x, y, z axes in world coordinates")
    return message


@task("1.2", "look_at", points=3)
def _check_look_at(impl):
    ref = _ref("course.camera", "look_at")

    def rotation(dtype, stress):
        for eye, target, up in _look_at_cases(dtype, stress):
            name = _look_at_name(eye, target, up)
            R, t = _unpack(_call(impl, eye, target, up), ("R", "t"), "look_at")
            require(_look_at_message(*_frame_problem(R, ref(eye, target, up)[0], f"{name} R", stress)))
            if stress:
                require(compare(t, ref(eye, target, up)[1], name=f"{name} t"))

    def translation():
        for eye, target, up in _look_at_cases(torch.float32, False):
            R, t = _unpack(_call(impl, eye, target, up), ("R", "t"), "look_at")
            own_R = R.shape == (3, 3) and R.is_floating_point() and bool(torch.isfinite(R).all())
            eye64 = eye.to(torch.float64)
            want = (-R.to(torch.float64) @ eye64).to(eye.dtype) if own_R else ref(eye, target, up)[1]
            require(_diagnose(t, want, f"{_look_at_name(eye, target, up)} t", [
                (-eye64, "t = -eye, but the eye must be rotated too: t = -R @ eye"),
                (eye64, "t must move the eye to the camera origin: t = -R @ eye"),
                (-want, "wrong sign: t = -R @ eye")]))
    return grade_parts((1, "R", lambda: rotation(torch.float32, False)), (1, "t", translation),
                       (1, "far cameras, tilted up vectors, float64", lambda: rotation(torch.float64, True)))


def _pose(dtype, eye=(1.5, 2.0, -6.0), target=(0.2, -0.3, 0.5)):
    R, t = _ref("course.camera", "look_at")(torch.tensor(eye, dtype=dtype), torch.tensor(target, dtype=dtype))
    return R, t


def _world_to_camera_problem(got, points, R, t, expected, name, check_dtype):
    p, R, t = points.to(torch.float64), R.to(torch.float64), t.to(torch.float64)
    return _diagnose(got, expected, name, [
        (p @ R + t, "you applied Rᵀ: with one point per row, x_cam = points @ R.T + t"),
        (p @ R.T, "the translation t is missing: x_cam = R @ x_world + t"),
        ((p - t) @ R, "that is the inverse transform (camera to world); world to camera is R @ x_world + t"),
        ((p + t) @ R.T, "rotate first, then translate: x_cam = R @ x_world + t")], check_dtype=check_dtype)


@task("1.3", "world_to_camera", points=2)
def _check_world_to_camera(impl):
    ref = _ref("course.camera", "world_to_camera")

    def cases(dtype, stress):
        g = generator(13)
        sizes, scale = ((1, 0, 257), 1e3) if stress else ((6, 6), 2.0)
        for n in sizes:
            R = _ref("course.camera", "axis_angle_to_matrix")(torch.randn(3, generator=g, dtype=torch.float64))
            R, t = R.to(dtype), (torch.randn(3, generator=g, dtype=torch.float64) * 3).to(dtype)
            points = (torch.randn(n, 3, generator=g, dtype=torch.float64) * scale).to(dtype)
            got = _call(impl, points, R, t)
            require(_world_to_camera_problem(got, points, R, t, ref(points, R, t),
                                             f"world_to_camera({n} point{'s' * (n != 1)})", check_dtype=stress))
    return grade_parts((1, "points", lambda: cases(torch.float32, False)),
                       (1, "one, zero and many points, float64", lambda: cases(torch.float64, True)))


# ------------------------------------------------------------------------------- lecture 2: projection

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


# ------------------------------------------------------------------------------ lecture 3: rasterization

_TRIANGLE = [[1.2, 0.7], [6.3, 2.1], [2.5, 5.8]]                        # asymmetric, so axis flips show


def _winding(tri: torch.Tensor) -> str:
    """How the vertices run as seen on screen (x right, y down)."""
    d1, d2 = tri[1] - tri[0], tri[2] - tri[0]
    return "clockwise" if float(d1[0] * d2[1] - d1[1] * d2[0]) > 0 else "counter-clockwise"


def _points_off_edges(tri: torch.Tensor, n: int, seed: int, low=-0.5, high=7.5) -> torch.Tensor:
    """Seeded points in a box around ``tri``, none within 1e-3 of an edge's line (where rounding decides)."""
    p = low + (high - low) * torch.rand(n, 2, generator=generator(seed), dtype=torch.float64)
    t = tri.to(torch.float64)
    keep = torch.ones(n, dtype=torch.bool)
    for k in range(3):
        a, b = t[k], t[(k + 1) % 3]
        d = b - a
        keep &= ((d[0] * (p[:, 1] - a[1]) - d[1] * (p[:, 0] - a[0])).abs() / d.norm()) > 1e-3
    return p[keep]


def _tiled_square() -> list[torch.Tensor]:
    """A 4×4 square cut into 2×2 cells, each split into two triangles along alternating diagonals, with
    alternating windings: every interior edge is shared by two triangles."""
    triangles = []
    for i, j in itertools.product(range(2), range(2)):
        x, y = 2.0 * i, 2.0 * j
        a, b, c, d = [x, y], [x + 2, y], [x + 2, y + 2], [x, y + 2]
        pair = ([a, b, c], [a, c, d]) if (i + j) % 2 == 0 else ([a, b, d], [b, c, d])
        triangles += [torch.tensor(pair[0]), torch.tensor(pair[1][::-1])]
    return triangles


@task("3.1", "inside_triangle", points=3)
def _check_inside_triangle(impl):
    ref = _ref("course.raster", "inside_triangle")

    def winding(order):
        tri = torch.tensor(_TRIANGLE)[order]
        points = _points_off_edges(tri, 80, seed=31).to(torch.float32)
        got, expected = _call(impl, tri, points), ref(tri, points)
        name = f"inside_triangle for a triangle whose vertices run {_winding(tri)} on screen"
        got_t = to_tensor(got, name)
        if got_t.shape == expected.shape and not got_t.bool().any() and expected.any():
            require(f"{name}: every point is outside; accept either winding (flip the edge-function signs "
                    "when the signed area is negative)")
        require(_diagnose(got, expected, name, [(~expected, "inside and outside are swapped: check the "
                                                 "signs of your edge functions")]))

    def shared_edges():
        grid = torch.arange(0.0, 4.01, 0.5)
        points = torch.stack(torch.meshgrid(grid, grid, indexing="xy"), -1).reshape(-1, 2)   # (81, 2)
        interior = ((points > 0) & (points < 4)).all(1)
        count = torch.zeros(len(points), dtype=torch.int64)
        for tri in _tiled_square():
            got = to_tensor(_call(impl, tri, points), "inside_triangle")
            if got.shape != (len(points),):
                require(compare(got, ref(tri, points), name="inside_triangle"))
            count += got.bool().to(torch.int64)
        for wrong, how in ((count > 1, "inside both"), (count == 0, "inside neither")):
            bad = (wrong & interior).nonzero()
            if len(bad):
                p = points[int(bad[0])]
                require(f"point ({_num(p[0])}, {_num(p[1])}) on an edge shared by two triangles is {how}: with "
                        "the top-left rule each shared edge belongs to exactly one triangle")
        for tri in _tiled_square():
            require(_diagnose(_call(impl, tri, points), ref(tri, points), "inside_triangle on the edges of "
                              f"triangle {_fmt(tri)} (top-left rule: points on a top or left edge are inside, "
                              "on a bottom or right edge outside)"))

    def zero_area_and_float64():
        line = torch.tensor([[0.0, 0.0], [2.0, 1.0], [4.0, 2.0]], dtype=torch.float64)
        on_line = torch.tensor([[1.0, 0.5], [2.0, 1.0], [3.0, 1.5], [1.0, 1.0]], dtype=torch.float64)
        require(compare(_call(impl, line, on_line), ref(line, on_line),
                        name="inside_triangle for a zero-area triangle (it covers nothing)"))
        tri = torch.tensor(_TRIANGLE, dtype=torch.float64) * 1e3 + 5e3
        points = _points_off_edges(tri / 1e3 - 5, 50, seed=32) * 1e3 + 5e3
        require(compare(_call(impl, tri, points), ref(tri, points), name="inside_triangle (float64, large "
                        "coordinates)"))
    return grade_parts((1, "one winding", lambda: winding([0, 1, 2])),
                       (1, "the other winding", lambda: winding([0, 2, 1])),
                       (1, "shared edges, zero area, float64", lambda: (shared_edges(), zero_area_and_float64())))


@task("3.2", "barycentric", points=2)
def _check_barycentric(impl):
    ref = _ref("course.raster", "barycentric_2d")

    def basic():
        for order in ([0, 1, 2], [0, 2, 1]):
            tri = torch.tensor(_TRIANGLE)[order]
            points = (torch.rand(40, 2, generator=generator(33)) * 9 - 1)          # inside and outside
            got, expected = _call(impl, tri, points), ref(tri, points)
            name = f"barycentric for a triangle whose vertices run {_winding(tri)} on screen"
            e64 = expected.to(torch.float64)
            variants = [(e64[:, p], "weights in the wrong order: column k is the weight of vertex tri[k] "
                         "(1 at tri[k], 0 on the opposite edge)")
                        for p in itertools.permutations(range(3)) if list(p) != [0, 1, 2]]
            variants.append((-e64, "signs flipped for this winding: divide by the signed area, which is "
                             "negative when the vertices run the other way"))
            message = _diagnose(got, expected, name, variants, atol=1e-4, rtol=1e-4)
            g = to_tensor(got, name)
            if message and g.shape == expected.shape and "wrong values" in message:
                sums = g.to(torch.float64).sum(-1)
                if torch.isfinite(sums).all() and (sums - 1).abs().max() > 1e-3:
                    message = f"{name}: the weights do not sum to 1: divide the edge functions by the area"
            require(message)

    def stress():
        line = torch.tensor([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]])
        points = torch.tensor([[0.5, 0.5], [1.0, 0.0], [3.0, 1.0]])
        got = to_tensor(_call(impl, line, points), "barycentric")
        if got.shape != (3, 3):
            require(compare(got, ref(line, points), name="barycentric for a zero-area triangle"))
        if not torch.isfinite(got).all():
            require("barycentric for a zero-area triangle returns NaN or inf: return finite weights (guard the "
                    "division by the area)")
        tri = torch.tensor(_TRIANGLE, dtype=torch.float64) + 1e4
        points = torch.rand(30, 2, generator=generator(34), dtype=torch.float64) * 9 - 1 + 1e4
        require(compare(_call(impl, tri, points), ref(tri, points), atol=1e-7, rtol=1e-7,
                        name="barycentric (float64, coordinates near 1e4)"))
    return grade_parts((1, "both windings", basic), (1, "zero-area triangle, float64", stress))


def _zbuffer_problems(out, pixel_index, depth, face_id, num_pixels, check_dtype) -> str | None:
    """One message for the first wrong pixel, in terms of the fragments that cover it."""
    face_map, depth_map = _unpack(out, ("face_map", "depth_map"), "zbuffer_resolve")
    ref_face, ref_depth = _ref("course.raster", "zbuffer_resolve")(pixel_index, depth, face_id, num_pixels)
    for got, expected, label in ((face_map, ref_face, "face_map"), (depth_map, ref_depth, "depth_map")):
        if got.shape != expected.shape or (check_dtype and got.dtype != expected.dtype):
            return compare(got, expected, name=f"zbuffer_resolve {label}", check_dtype=check_dtype)
    if not face_map.is_floating_point() or torch.isfinite(face_map).all():
        wrong = (face_map.to(torch.int64) != ref_face).nonzero()
        if len(wrong):
            p = int(wrong[0])
            return _zbuffer_pixel_message(p, int(face_map[p]), pixel_index, depth, face_id)
    message = compare(depth_map, ref_depth, name="zbuffer_resolve depth_map", check_dtype=check_dtype)
    if message and (torch.isinf(ref_depth) & ~torch.isinf(depth_map.to(torch.float64))).any():
        message += ": empty pixels have depth +inf"
    return message or compare(face_map, ref_face, name="zbuffer_resolve face_map", check_dtype=check_dtype)


def _zbuffer_pixel_message(p: int, got: int, pixel_index, depth, face_id) -> str:
    here = pixel_index == p
    fragments = sorted(zip(depth[here].tolist(), face_id[here].tolist()))       # (depth, face), nearest first
    if not fragments:
        return (f"zbuffer_resolve: pixel {p} has no fragment, so face_map must be -1 there (and depth_map +inf); "
                f"got face {got}")
    nearest_depth, nearest_face = fragments[0]
    if got == -1:
        return f"zbuffer_resolve: pixel {p} is covered (nearest: face {nearest_face}) but you left it empty"
    tied = sorted(f for d, f in fragments if d == nearest_depth)
    if got in tied:
        return (f"zbuffer_resolve: pixel {p}: faces {', '.join(map(str, tied))} are at the same depth "
                f"{_num(nearest_depth)}; ties go to the lower face id ({tied[0]}), you kept {got}")
    if got == fragments[-1][1]:
        return (f"zbuffer_resolve: pixel {p}: you kept the farthest fragment (face {got}, depth "
                f"{_num(fragments[-1][0])}); the z-buffer keeps the smallest depth (face {nearest_face})")
    return (f"zbuffer_resolve: pixel {p}: face {nearest_face} expected (depth {_num(nearest_depth)}), "
            f"got face {got}")


@task("3.3", "zbuffer_resolve", points=3)
def _check_zbuffer_resolve(impl):
    def run(pixel_index, depth, face_id, num_pixels, check_dtype=False):
        pixel_index, face_id = (torch.tensor(x, dtype=torch.int64) for x in (pixel_index, face_id))
        depth = torch.as_tensor(depth, dtype=torch.float32) if not isinstance(depth, torch.Tensor) else depth
        out = _call(impl, pixel_index, depth, face_id, num_pixels)
        require(_zbuffer_problems(out, pixel_index, depth, face_id, num_pixels, check_dtype))

    def stress():
        run([], torch.zeros(0), [], 4)                                    # nothing drawn: all empty
        g = generator(35)
        m = 300
        depth = (torch.randint(1, 12, (m,), generator=g) * 0.25).to(torch.float64)   # many exact ties
        run(torch.randint(0, 16, (m,), generator=g).tolist(), depth, torch.randperm(m, generator=g).tolist(),
            16, check_dtype=True)
    return grade_parts(
        (1, "nearest fragment", lambda: run([3, 0, 3, 4, 0, 3, 1, 4, 2],
                                            [2.0, 1.5, 0.7, 4.0, 3.0, 1.1, 0.9, 2.5, 5.0],
                                            [4, 1, 7, 2, 0, 3, 5, 6, 8], 5)),
        (1, "empty pixels and ties", lambda: run([2, 0, 2, 4, 0], [0.5, 1.0, 0.5, 2.0, 1.0], [8, 6, 3, 1, 2], 7)),
        (1, "no fragments, many fragments, int64 and float64", stress))


@task("3.4", "perspective_correct", points=2)
def _check_perspective_correct(impl):
    ref = _ref("course.raster", "perspective_correct_bary")

    def cases(dtype, stress):
        g = generator(36)
        b = torch.rand(8, 3, generator=g, dtype=torch.float64)
        b, z = b / b.sum(1, keepdim=True), 1 + 5 * torch.rand(8, 3, generator=g, dtype=torch.float64)
        if stress:
            b = torch.cat([b, torch.tensor([[1.0, 0, 0], [0, 0.3, 0.7], [0.2, 0.3, 0.5], [0.2, 0.3, 0.5]])])
            z = torch.cat([z, torch.tensor([[1e-3, 1e3, 1.0], [2.0, 1e-3, 1e3], [4.0, 4.0, 4.0],
                                            [1e-3, 1e-3, 1e3]])])
        b, z = b.to(dtype), z.to(dtype)
        b64, z64 = b.to(torch.float64), z.to(torch.float64)
        weighted = b64 * z64
        require(_diagnose(_call(impl, b, z), ref(b, z), f"perspective_correct({len(b)} fragments)", [
            (weighted / weighted.sum(1, keepdim=True), "you weighted by z; the weights are b_k / z_k, normalised"),
            (b64 / z64, "normalise: divide by Σ_j b_j / z_j so the weights sum to 1"),
            (b64, "returned bary_screen unchanged: divide each weight by its vertex's depth and normalise")],
            check_dtype=stress))
    return grade_parts((1, "fragments", lambda: cases(torch.float32, False)),
                       (1, "extreme depths, vertices, float64", lambda: cases(torch.float64, True)))


# ---------------------------------------------------------------------------------- lecture 4: shading

def _unit(n: int, seed: int, dtype=torch.float32) -> torch.Tensor:
    v = torch.randn(n, 3, generator=generator(seed), dtype=torch.float64)
    return (v / v.norm(dim=1, keepdim=True)).to(dtype)


@task("4.1", "lambert", points=2)
def _check_lambert(impl):
    ref = _ref("course.shading", "lambert")

    def run(normal, light, albedo, name, check_dtype):
        cos = (normal.to(torch.float64) * light.to(torch.float64)).sum(-1, keepdim=True)
        a = albedo.to(torch.float64)
        require(_diagnose(_call(impl, normal, light, albedo), ref(normal, light, albedo), name, [
            (a * cos, "negative where the light is behind the surface: clamp, max(0, n·l)"),
            (a * cos.abs(), "a light behind the surface gives 0, not |n·l|: clamp, max(0, n·l)"),
            (a * (-cos).clamp_min(0), "light_dir points toward the light: use n·l, not -n·l")],
            check_dtype=check_dtype))

    def stress():
        normal = torch.cat([_unit(10, 42, torch.float64), torch.tensor([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
                                                                       dtype=torch.float64)])
        light = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)                  # n·l = 1 and exactly 0
        run(normal, light, torch.tensor([0.9, 0.5, 0.2], dtype=torch.float64),
            "lambert with light_dir (3,) and albedo (3,), float64", True)
    return grade_parts((1, "per-point light and albedo", lambda: run(
                            _unit(12, 41), _unit(12, 43), torch.rand(12, 3, generator=generator(44)),
                            "lambert(12 normals)", False)),
                       (1, "broadcasting, grazing light, float64", stress))


@task("4.2", "blinn_phong", points=2)
def _check_blinn_phong(impl):
    ref = _ref("course.shading", "blinn_phong")

    def run(n, l, v, shininess, name, check_dtype):
        n64, l64, v64 = (x.to(torch.float64) for x in (n, l, v))
        h = l64 + v64
        unit_h = h / h.norm(dim=-1, keepdim=True)
        lit = (n64 * l64).sum(-1) > 0
        cos, cos_raw = (n64 * unit_h).sum(-1), (n64 * h).sum(-1)
        phong = _ref("course.shading", "phong")(n64, l64, v64, shininess)
        require(_diagnose(_call(impl, n, l, v, shininess), ref(n, l, v, shininess), name, [
            (cos.clamp_min(0) ** shininess, "a light behind the surface (n·l <= 0) makes no highlight: "
             "return 0 there"),
            (torch.where(lit, cos_raw.clamp_min(0) ** shininess, 0.0), "normalise the half vector: "
             "h = (l + v) / |l + v|"),
            (torch.where(lit, cos ** shininess, 0.0), "clamp n·h at 0 before raising it to the shininess"),
            (phong, "that is Phong's r·v; Blinn-Phong uses the half vector h = normalize(l + v)")],
            check_dtype=check_dtype))

    def basic():
        behind = torch.tensor([[0.0, 0.0, 1.0], [0.995, 0.0, -0.0998], [-0.6, 0.0, 0.8]])  # n; l just behind; v
        n, l, v = (torch.cat([_unit(12, seed), behind[k:k + 1]]) for k, seed in enumerate((48, 49, 50)))
        run(n, l, v, 8.0, "blinn_phong(13 points, shininess=8)", False)

    def stress():
        head_on = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64)            # n = l = v: the peak, 1
        n, l, v = (torch.cat([_unit(10, seed, torch.float64), head_on]) for seed in (45, 46, 47))
        for shininess in (1.0, 150.0):
            run(n, l, v, shininess, f"blinn_phong(shininess={_num(shininess)}), float64", True)
    return grade_parts((1, "highlights", basic), (1, "shininess 1 and 150, float64", stress))


def _texture_variants(sample, texture, uv) -> list:
    """Lookups with the usual mistakes, each written as the correct lookup at other uv."""
    Ht, Wt = texture.shape[:2]
    u, v = uv[:, 0], uv[:, 1]
    at = lambda uu, vv: sample(texture, torch.stack([uu, vv], -1)).to(torch.float64)   # noqa: E731
    return [(at(u, 1 - v), "v is flipped: v = 0 is the bottom of the image (its last row), v = 1 the top"),
            (at(u + 0.5 / Wt, v - 0.5 / Ht), "missing half-texel offset: texel (r, c) has its centre at "
             "u = (c + 0.5) / Wt, so the column coordinate is u·Wt - 0.5"),
            (at(u + 0.5 / Wt, 1 - v - 0.5 / Ht), "v is flipped (v = 0 is the bottom row) and the half-texel "
             "offset is missing (the column coordinate is u·Wt - 0.5)"),
            (at(v, u), "u and v are swapped: u picks the column, v the row"),
            (sample(texture, uv, mode="nearest").to(torch.float64), "that is a nearest lookup: blend the four "
             "nearest texels by the fractional position"),
            (at((u * (Wt - 1) + 0.5) / Wt, 1 - ((1 - v) * (Ht - 1) + 0.5) / Ht), "texel centres sit at "
             "u = (c + 0.5) / Wt, not c / (Wt - 1)")]


@task("4.3", "sample_bilinear", points=3)
def _check_sample_bilinear(impl):
    ref = _ref("course.shading", "sample_texture")
    sample = lambda tex, uv, mode="bilinear": ref(tex, uv, mode=mode)  # noqa: E731

    def run(texture, uv, name, check_dtype=False):
        variants = _texture_variants(sample, texture, uv)
        require(_diagnose(_call(impl, texture, uv), sample(texture, uv), name, variants, check_dtype=check_dtype))

    texture = torch.rand(4, 5, 3, generator=generator(51))                       # (Ht, Wt, C), not square

    def centres():
        rows, cols = torch.meshgrid(torch.arange(4.0), torch.arange(5.0), indexing="ij")
        uv = torch.stack([(cols + 0.5) / 5, 1 - (rows + 0.5) / 4], -1).reshape(-1, 2)
        run(texture, uv, "sample_bilinear at texel centres (must return the texels exactly)")
        run(texture, torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]),
            "sample_bilinear at the corners uv (0, 0), (1, 0), (0, 1), (1, 1) (the corner texels: (0, 0) is "
            "bottom-left)")

    def stress():
        g = generator(52)
        uv = torch.rand(30, 2, generator=g, dtype=torch.float64) * 2 - 0.5         # beyond [0, 1]: clamp
        run(texture.to(torch.float64), uv, "sample_bilinear with uv outside [0, 1] (clamp to the edge), float64",
            check_dtype=True)
        gray = torch.rand(3, 6, 1, generator=g)
        run(gray, torch.rand(10, 2, generator=g), "sample_bilinear of a one-channel (Ht, Wt, 1) texture")
    return grade_parts((1, "inside the texture", lambda: run(
                            texture, 0.12 + 0.76 * torch.rand(20, 2, generator=generator(53)),
                            "sample_bilinear(20 uv)")),
                       (1, "texel centres and corners", centres), (1, "clamping, one channel, float64", stress))
