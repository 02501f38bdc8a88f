"""The checks of lecture 1's graded tasks: 1.1 rodrigues, 1.2 look_at, 1.3 world_to_camera, 1.4 vertex_normals.

Each check runs the student's function next to the package's reference on fixed, seeded-random and stress
inputs and says what to fix, recognising the typical mistakes of the task. ``import course.grading``
imports this module, which registers its checks in ``course.grading.TASKS``; nothing here is public.
"""
from __future__ import annotations

import itertools
import math

import torch

from .helpers import (_call, _close, _diagnose, _fmt, _num, _ref, _unpack, compare, generator, grade_parts, require,
                      to_tensor)
from .registry import task

__all__: list[str] = []          # nothing public: the checks are reached through course.grading.TASKS


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


@task("1.1", "rodrigues", points=2, reference=("course.camera", "axis_angle_to_matrix"))
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


@task("1.2", "look_at", points=3, reference=("course.camera", "look_at"))
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


def _world_to_camera_problem(got, points, R, t, expected, name, check_dtype):
    p, R, t = points.to(torch.float64), R.to(torch.float64), t.to(torch.float64)
    return _diagnose(got, expected, name, [
        (p @ R + t, "you applied Rᵀ: with one point per row, x_cam = points @ R.T + t"),
        (p @ R.T, "the translation t is missing: x_cam = R @ x_world + t"),
        ((p - t) @ R, "that is the inverse transform (camera to world); world to camera is R @ x_world + t"),
        ((p + t) @ R.T, "rotate first, then translate: x_cam = R @ x_world + t")], check_dtype=check_dtype)


@task("1.3", "world_to_camera", points=2, reference=("course.camera", "world_to_camera"))
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


# ------------------------------------------------------------------------------- 1.4 vertex normals

def _fan_mesh(dtype):
    """Vertex 0 shared by a big face and a sliver in different planes, plus a closed asymmetric
    tetrahedron (vertices 4-7): area weighting, not the plain mean, decides vertex 0's normal."""
    verts = torch.tensor([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 0.0, -3.0], [0.05, 0.6, 0.0],
                          [1.0, 1.0, 1.0], [2.3, 1.2, 0.8], [1.4, 2.6, 1.1], [1.6, 1.5, 2.4]], dtype=dtype)
    faces = torch.tensor([[0, 1, 2], [0, 3, 1], [4, 6, 5], [4, 5, 7], [5, 6, 7], [4, 7, 6]])
    return verts, faces


def _octahedron(dtype):
    """A regular octahedron, rotated off the axes: every face has the same area, so weighting can't matter;
    faces counter-clockwise seen from outside."""
    verts = torch.cat([torch.eye(3), -torch.eye(3)]).to(torch.float64)      # +x +y +z -x -y -z
    faces = []
    for sx, sy, sz in itertools.product((1, -1), repeat=3):
        i, j, k = (0 if sx > 0 else 3), (1 if sy > 0 else 4), (2 if sz > 0 else 5)
        faces.append([i, j, k] if sx * sy * sz > 0 else [i, k, j])
    R = _ref("course.camera", "axis_angle_to_matrix")(torch.tensor([0.3, -0.5, 0.8], dtype=torch.float64))
    return (verts @ R.T).to(dtype), torch.tensor(faces)


def _degenerate_mesh(dtype):
    """Far from the origin, in float64: a zero-area face beside real ones, a vertex only a zero-area face
    uses (6), and a vertex no face uses (8). Both get a zero normal."""
    verts = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0],
                          [0.5, 0.5, 0.0], [2.0, 2.0, 2.0], [1.0, 1.0, 1.0], [3.0, 3.0, 3.0],
                          [9.0, 9.0, 9.0]], dtype=torch.float64) + 1e3
    faces = torch.tensor([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3], [1, 4, 2], [5, 6, 7]])
    return verts.to(dtype), faces


def _normals_variants(verts, faces):
    """The typical wrong vertex normals, each with what to fix."""
    v = verts.to(torch.float64)
    v0, v1, v2 = v[faces].unbind(1)                                       # (F, 3) each
    cross = torch.linalg.cross(v1 - v0, v2 - v0, dim=-1)                  # (F, 3), length = 2 area
    unit = lambda x: x / x.norm(dim=-1, keepdim=True).clamp_min(1e-300)  # noqa: E731
    per_corner = lambda n: torch.zeros_like(v).index_add(0, faces.reshape(-1), n.repeat_interleave(3, 0))  # noqa: E731
    summed = per_corner(cross)
    last_write = torch.zeros_like(v)
    for k in range(3):
        last_write[faces[:, k]] += cross                                  # repeated indices: one add survives
    return [(unit(per_corner(unit(cross))), "you averaged unit face normals: weight each face by its area — "
             "sum the unnormalised cross products (v1 - v0) × (v2 - v0), whose length is twice the area, "
             "then normalise the sum"),
            (-unit(summed), "your normals point inward: a face whose vertices run counter-clockwise seen from "
             "outside has the normal (v1 - v0) × (v2 - v0), not (v2 - v0) × (v1 - v0)"),
            (unit(last_write), "`normals[faces[:, k]] += ...` adds only once to a vertex that appears several "
             "times in faces[:, k] (in-place indexed adds keep one of the repeated writes): use "
             "index_add / index_add_"),
            (summed, "normalise the summed cross products: vertex normals are unit vectors"),
            (summed / 2, "normalise the summed area-weighted normals: vertex normals are unit vectors")]


def _normals_problem(got, verts, faces, name, check_dtype) -> str | None:
    expected = _ref("course.mesh", "Mesh")(verts, faces).vertex_normals()
    message = _diagnose(got, expected, name, _normals_variants(verts, faces), check_dtype=check_dtype)
    if message is None:
        return None
    g = to_tensor(got, name)
    empty = expected.abs().sum(-1) == 0                                   # vertices that get a zero normal
    if g.shape == expected.shape and g.is_floating_point():
        bad = ~torch.isfinite(g).all(-1)
        if bad.any() and (bad & empty).any():
            vertex = int((bad & empty).nonzero()[0])
            return (f"{name}: vertex {vertex} has no face of nonzero area, and its normal is NaN or inf: give it a "
                    "zero normal (guard the division by the length)")
        if (g[empty] != 0).any() and bool(torch.isfinite(g).all()):
            vertex = int((empty & (g != 0).any(-1)).nonzero()[0])
            return f"{name}: vertex {vertex} has no face of nonzero area: its normal must be zero"
    return message


@task("1.4", "vertex_normals", points=3, reference=("course.mesh", "Mesh.vertex_normals"))
def _check_vertex_normals(impl):
    def run(verts, faces, name, check_dtype=False):
        require(_normals_problem(_call(impl, verts, faces), verts, faces, name, check_dtype))

    def equal_areas():
        verts, faces = _octahedron(torch.float32)
        run(verts, faces, "vertex_normals of a rotated regular octahedron (6 vertices, 8 faces)")

    def weighted():
        verts, faces = _fan_mesh(torch.float32)
        run(verts, faces, "vertex_normals where a big face and a sliver share vertex 0")
        g = generator(14)
        run(torch.randn(12, 3, generator=g), torch.randint(0, 12, (20, 3), generator=g),
            "vertex_normals of 20 random faces on 12 vertices")

    def stress():
        verts, faces = _degenerate_mesh(torch.float64)
        run(verts, faces, "vertex_normals with a zero-area face and an unused vertex, coordinates near 1e3 "
            "(float64)", check_dtype=True)
        verts, faces = _fan_mesh(torch.float64)
        run(verts * 1e-4, faces, "vertex_normals of a mesh 1e-4 across (float64)", check_dtype=True)
    return grade_parts((1, "faces of equal area", equal_areas), (1, "area weighting", weighted),
                       (1, "zero-area faces, unused vertices, float64", stress))
