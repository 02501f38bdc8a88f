"""The checks of lecture 1's graded tasks (cameras): 1.1 rodrigues, 1.2 look_at, 1.3 world_to_camera.

Each check runs the student's function next to the package's reference on fixed, seeded-random and stress
inputs and says what to fix, recognising the typical mistakes of the task. ``import course.grading``
imports this module, which registers its checks in ``course.grading.TASKS``; nothing here is public.
"""
from __future__ import annotations

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
