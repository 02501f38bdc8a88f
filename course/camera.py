"""Cameras: rotations, homogeneous transforms, ``look_at`` and the pinhole model.

The one projection equation of the course (lecture 02)::

    λ [x, y, 1]ᵀ = K [R | t] [X, 1]ᵀ,      K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]  (pixels)

World space is right-handed with +y up. Camera space is OpenCV's: +x right, +y down, +z forward, so a point
in front of the camera has positive depth ``z``. ``x_cam = R @ x_world + t``. Pixel (row i, column j) covers
[j, j+1) × [i, i+1) in image coordinates, so its centre is (j + 0.5, i + 0.5).

An orthographic camera drops the division by depth: ``x = fx * X_cam + cx`` (fx in pixels per world unit).
Every function keeps its input's dtype and device, and gradients flow through K, R and t.
"""
from __future__ import annotations

import math

import torch

from .tensors import _check_count, _check_dtype, _check_finite, _check_flag, _check_real, _check_shape, as_tensor

__all__ = [
    "axis_angle_to_matrix", "euler_to_matrix", "homogeneous", "transform_points",
    "look_at", "world_to_camera", "project_points", "pixel_rays", "intrinsics_from_fov", "Camera",
]


# ---------------------------------------------------------------------------------------------- rotations

def axis_angle_to_matrix(axis_angle) -> torch.Tensor:
    """Rodrigues' formula: rotation by ``|ω|`` radians about the unit axis ``ω / |ω|``.

    axis_angle: (..., 3). Returns (..., 3, 3). ``R = I + sin θ [k]ₓ + (1 - cos θ) [k]ₓ²``.
    Near θ = 0 the Taylor series is used so the result and its gradient stay finite.
    """
    w = as_tensor(axis_angle, name="axis_angle")
    if w.shape[-1:] != (3,):
        raise ValueError(f"axis_angle must have shape (..., 3), got {tuple(w.shape)}")
    _check_finite(w, "axis_angle")
    theta2 = (w * w).sum(-1, keepdim=True)[..., None]                       # (..., 1, 1)
    small = theta2 < 1e-8
    theta2_safe = torch.where(small, torch.ones_like(theta2), theta2)
    theta = theta2_safe.sqrt()
    a = torch.where(small, 1 - theta2 / 6, torch.sin(theta) / theta)       # sin θ / θ
    b = torch.where(small, 0.5 - theta2 / 24, (1 - torch.cos(theta)) / theta2_safe)  # (1 - cos θ) / θ²
    zero = torch.zeros_like(w[..., 0])
    wx, wy, wz = w.unbind(-1)
    cross = torch.stack([zero, -wz, wy, wz, zero, -wx, -wy, wx, zero], -1).reshape(w.shape[:-1] + (3, 3))
    eye = torch.eye(3, dtype=w.dtype, device=w.device).expand_as(cross)
    return eye + a * cross + b * (cross @ cross)


def euler_to_matrix(angles, order: str = "xyz") -> torch.Tensor:
    """Rotation from Euler angles in radians, applied in ``order`` about the fixed world axes.

    angles: (3,), the angle for each letter of ``order``. ``order="xyz"`` gives ``R = Rz @ Ry @ Rx``
    (rotate about x first). Returns (3, 3).
    """
    a = as_tensor(angles, name="angles")
    _check_shape(a, (3,), "angles")
    if not isinstance(order, str) or sorted(order) != ["x", "y", "z"]:
        raise ValueError(f"order must be a permutation of 'xyz', got {order!r}")
    axes = {"x": 0, "y": 1, "z": 2}
    R = torch.eye(3, dtype=a.dtype, device=a.device)
    for angle, letter in zip(a.unbind(0), order):
        axis = torch.zeros(3, dtype=a.dtype, device=a.device)
        axis[axes[letter]] = 1
        R = axis_angle_to_matrix(axis * angle) @ R
    return R


# ------------------------------------------------------------------------------------- rigid transforms

def homogeneous(R, t) -> torch.Tensor:
    """The 4×4 matrix ``[[R, t], [0, 0, 0, 1]]``. R: (3, 3), t: (3,). Returns (4, 4)."""
    R = as_tensor(R, name="R")
    t = as_tensor(t, dtype=R.dtype, device=R.device, name="t")
    _check_shape(R, (3, 3), "R")
    _check_shape(t, (3,), "t")
    bottom = torch.tensor([[0.0, 0.0, 0.0, 1.0]], dtype=R.dtype, device=R.device)
    return torch.cat([torch.cat([R, t[:, None]], 1), bottom], 0)


def transform_points(M, points) -> torch.Tensor:
    """Apply a 4×4 homogeneous transform. M: (4, 4), points: (N, 3). Returns (N, 3).

    The last row of M may be projective; the result is divided by the homogeneous coordinate.
    """
    M = as_tensor(M, name="M")
    p = as_tensor(points, dtype=M.dtype, device=M.device, name="points")
    _check_shape(M, (4, 4), "M")
    _check_shape(p, (None, 3), "points")
    ph = torch.cat([p, torch.ones_like(p[:, :1])], 1) @ M.T                 # (N, 4)
    if bool((ph[:, 3] == 0).any()):
        k = int((ph[:, 3] == 0).nonzero()[0, 0])
        raise ValueError(f"M sends point {k} to infinity (homogeneous w = 0): points must stay off M's "
                         "vanishing plane")
    return ph[:, :3] / ph[:, 3:]


def look_at(eye, target, up=(0.0, 1.0, 0.0)):
    """World-to-camera rotation and translation of a camera at ``eye`` looking at ``target``.

    eye, target, up: (3,) world space. Returns ``R`` (3, 3) and ``t`` (3,) with ``x_cam = R @ x_world + t``,
    in OpenCV camera axes: the rows of R are the camera's +x (right), +y (down) and +z (forward) axes in world
    coordinates, so det(R) = +1, and ``t = -R @ eye``.
    """
    eye = as_tensor(eye, name="eye")
    target = as_tensor(target, dtype=eye.dtype, device=eye.device, name="target")
    up = as_tensor(up, dtype=eye.dtype, device=eye.device, name="up")
    for v, name in ((eye, "eye"), (target, "target"), (up, "up")):
        _check_shape(v, (3,), name)
    forward = target - eye
    # the same point when their difference is within a few roundings of the coordinates (at any scale: eye
    # and target 3e-15 apart near the origin are a direction; 1e3 apart at 1e20 are rounding)
    scale = max(float(eye.detach().abs().max()), float(target.detach().abs().max()))
    if float(forward.detach().abs().max()) <= 4 * torch.finfo(eye.dtype).eps * scale:
        raise ValueError("look_at: eye and target are the same point (within rounding of their coordinates), "
                         "the viewing direction is undefined")
    # a power of two first (exact: the same bits as without it), so that |v|² neither overflows nor underflows
    pow2 = lambda v: v * 2.0 ** -math.frexp(float(v.detach().abs().max()))[1]   # noqa: E731
    forward = pow2(forward)
    z = forward / forward.norm()                                            # camera +z: forward
    if not bool((up.detach() != 0).any()):
        raise ValueError("look_at: up must be a non-zero vector, got (0, 0, 0)")
    up = pow2(up)
    right = torch.linalg.cross(z, up)                                       # forward × up points right
    if right.norm() <= 1e-9 * up.norm():
        raise ValueError("look_at: up is parallel to the viewing direction; choose another up vector")
    x = right / right.norm()                                                # camera +x: right
    y = torch.linalg.cross(z, x)                                            # camera +y: down (z × x)
    R = torch.stack([x, y, z], 0)
    return R, -R @ eye


def world_to_camera(points_world, R, t) -> torch.Tensor:
    """``x_cam = R @ x_world + t`` for every point. points_world: (N, 3), R: (3, 3), t: (3,). Returns (N, 3)."""
    R = as_tensor(R, name="R")
    p = as_tensor(points_world, dtype=R.dtype, device=R.device, name="points")
    t = as_tensor(t, dtype=R.dtype, device=R.device, name="t")
    _check_shape(p, (None, 3), "points")
    _check_shape(R, (3, 3), "R")
    _check_shape(t, (3,), "t")
    return p @ R.T + t


# Tolerances of the camera checks (see ``_check_intrinsics`` and ``Camera``).
K_ROW_TOLERANCE = 1e-4      # |K[2] - (0, 0, 1)| per entry: far above rounding and gradcheck's steps
ROTATION_TOLERANCE = 1e-2   # max |R Rᵀ - I|: admits the finite-difference steps (1e-3) image_gradient takes
                            # on R's entries, refuses a scaled, sheared or transposed-K matrix


def _check_rotation(R: torch.Tensor, name: str = "R") -> None:
    """R (3, 3) must be a rotation: orthonormal to ``ROTATION_TOLERANCE`` and det R > 0 (detached value)."""
    r = R.detach().double()
    err = float((r @ r.T - torch.eye(3, dtype=torch.float64, device=r.device)).abs().max())
    if err > ROTATION_TOLERANCE:
        raise ValueError(f"{name} must be a rotation matrix (orthonormal rows), but R Rᵀ differs from the "
                         f"identity by {err:.3g}: build R with look_at or axis_angle_to_matrix")
    if float(torch.linalg.det(r)) <= 0:
        raise ValueError(f"{name} must be a rotation, det R = +1, but det R = {float(torch.linalg.det(r)):.3g}: "
                         "it mirrors the scene (swap two rows to fix the handedness)")


# ------------------------------------------------------------------------------------------- projection

def intrinsics_from_fov(fov_y: float, width: int, height: int, dtype=None, device=None) -> torch.Tensor:
    """K (3, 3) for a vertical field of view ``fov_y`` in degrees, square pixels, principal point at the centre.

    width, height: the image size in pixels, positive integers. dtype: a floating torch.dtype (default:
    torch's default dtype)."""
    fov_y = _check_real(fov_y, "fov_y", low=0, high=180, low_open=True, high_open=True)
    width, height = _check_count(width, "width"), _check_count(height, "height")
    dtype = _check_dtype(dtype)
    f = 0.5 * height / math.tan(math.radians(fov_y) / 2)
    return torch.tensor([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]],
                        dtype=dtype or torch.get_default_dtype(), device=device)


def _check_intrinsics(K: torch.Tensor, name: str = "K") -> None:
    """K must be (3, 3), finite, with last row (0, 0, 1) (to ``K_ROW_TOLERANCE``) and non-zero fx, fy and
    ``fx fy - K[0, 1] K[1, 0]`` (an invertible pinhole). Checked on the detached value (K may require grad)."""
    _check_shape(K, (3, 3), name)
    k = K.detach().double()
    row = k[2] - torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64, device=k.device)
    if float(row.abs().max()) > K_ROW_TOLERANCE:
        raise ValueError(f"{name}'s last row must be (0, 0, 1), got {[round(float(v), 6) for v in k[2]]}: "
                         f"K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] in pixels")
    a = k[:2, :2] / k[:2, :2].abs().max().clamp_min(torch.finfo(torch.float64).tiny)   # any scale: 1e-250 too
    if float(k[0, 0]) == 0 or float(k[1, 1]) == 0 or float(a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]) == 0:
        raise ValueError(f"{name} has a zero focal length (fx = K[0, 0] = {float(k[0, 0]):g}, "
                         f"fy = K[1, 1] = {float(k[1, 1]):g}): the camera would be degenerate")


def project_points(points_world, K, R, t, orthographic: bool = False):
    """Project world points to pixel coordinates: ``λ [x, y, 1]ᵀ = K (R X + t)``.

    points_world: (N, 3); K: (3, 3); R: (3, 3); t: (3,). Returns ``pixels`` (N, 2) as (x, y) = (column, row)
    image coordinates (pixel centres at half-integers) and ``depth`` (N,), the camera-space z. Points with
    depth <= 0 are behind a perspective camera; their pixels are meaningless (the rasterizer clips them).
    """
    K = as_tensor(K, name="K")
    _check_intrinsics(K)
    p_cam = world_to_camera(points_world, as_tensor(R, dtype=K.dtype, device=K.device, name="R"),
                            as_tensor(t, dtype=K.dtype, device=K.device, name="t"))   # (N, 3)
    depth = p_cam[:, 2]
    if _check_flag(orthographic, "orthographic"):
        xy1 = torch.cat([p_cam[:, :2], torch.ones_like(depth)[:, None]], 1)    # no division by depth
    else:
        xy1 = p_cam / depth[:, None]                                           # (X/Z, Y/Z, 1)
    pixels = xy1 @ K.T                                                         # (N, 3), last column 1
    return pixels[:, :2], depth


def pixel_rays(K, R, t, width: int, height: int, orthographic: bool = False):
    """One ray through the centre of every pixel, in world space.

    K: (3, 3); R: (3, 3); t: (3,). Returns ``origins`` (H, W, 3) and unit ``directions`` (H, W, 3).
    Pixel (i, j) is sampled at its centre (j + 0.5, i + 0.5): note the half-pixel offset.
    """
    K = as_tensor(K, name="K")
    R = as_tensor(R, dtype=K.dtype, device=K.device, name="R")
    t = as_tensor(t, dtype=K.dtype, device=K.device, name="t")
    _check_intrinsics(K), _check_shape(R, (3, 3), "R"), _check_shape(t, (3,), "t")
    width, height = _check_count(width, "width"), _check_count(height, "height")
    ys = torch.arange(height, dtype=K.dtype, device=K.device) + 0.5          # row centres
    xs = torch.arange(width, dtype=K.dtype, device=K.device) + 0.5           # column centres
    y, x = torch.meshgrid(ys, xs, indexing="ij")                             # (H, W)
    pix = torch.stack([x, y, torch.ones_like(x)], -1)                        # (H, W, 3)
    cam = pix @ torch.linalg.inv(K).T                                        # (X/Z, Y/Z, 1) or (X, Y, 1)
    eye = -R.T @ t                                                           # camera centre in world
    if _check_flag(orthographic, "orthographic"):
        origins_cam = torch.cat([cam[..., :2], torch.zeros_like(cam[..., :1])], -1)
        origins = origins_cam @ R + eye                                      # R.T @ (o - t) = o @ R - R.T t
        dirs = R[2].expand_as(origins)                                       # camera +z in world
    else:
        dirs = cam @ R                                                       # R.T @ d
        dirs = dirs / dirs.norm(dim=-1, keepdim=True)
        origins = eye.expand_as(dirs)
    return origins.contiguous(), dirs.contiguous()


class Camera:
    """A pinhole (or orthographic) camera: intrinsics ``K`` (3, 3), pose ``R`` (3, 3), ``t`` (3,), image size
    ``width`` × ``height`` in pixels, and ``near`` / ``far`` clipping depths (camera-space z).

    ``x_cam = R @ x_world + t``; gradients flow through K, R and t (make them require grad yourself).

    Checked at construction (a ``ValueError`` naming the argument, never a failure later): K (3, 3) finite with
    last row (0, 0, 1) (to 1e-4) and non-zero fx, fy; R (3, 3) finite and a rotation, ``max |R Rᵀ - I| <=
    1e-2`` and ``det R > 0`` (checked on the detached value, so R may require grad; the tolerance admits the
    finite-difference steps taken on R's entries, build R with ``axis_angle_to_matrix`` or ``look_at`` to stay
    exact); t (3,) finite; width and height positive integers (not bools, not floats); ``0 < near < far``
    (``0 <= near`` for an orthographic camera), near finite, far may be +inf.
    """

    def __init__(self, K, R, t, width: int, height: int, near: float = 0.1, far: float = 100.0,
                 orthographic: bool = False):
        self.K = as_tensor(K, name="K")
        self.R = as_tensor(R, dtype=self.K.dtype, device=self.K.device, name="R")
        self.t = as_tensor(t, dtype=self.K.dtype, device=self.K.device, name="t")
        _check_intrinsics(self.K), _check_shape(self.R, (3, 3), "R"), _check_shape(self.t, (3,), "t")
        _check_rotation(self.R)
        self.width, self.height = _check_count(width, "width"), _check_count(height, "height")
        self.orthographic = _check_flag(orthographic, "orthographic")
        near = _check_real(near, "near", low=0, low_open=not self.orthographic)
        far = _check_real(far, "far", allow_inf=True)
        if not near < far:
            raise ValueError(f"need near < far, got near={near:g}, far={far:g}")
        self.near, self.far = near, far

    @classmethod
    def look_at(cls, eye, target=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), *, fov_y: float | None = None,
                ortho_height: float | None = None, width: int, height: int, near: float = 0.1,
                far: float = 100.0, dtype=None, device=None) -> "Camera":
        """A camera at ``eye`` looking at ``target``; square pixels, principal point at the image centre.

        Perspective with ``fov_y`` (vertical field of view, degrees), or orthographic with ``ortho_height``
        (the world-space height the image spans). Exactly one of the two.
        """
        if (fov_y is None) == (ortho_height is None):
            raise ValueError("give exactly one of fov_y (perspective) or ortho_height (orthographic)")
        width, height = _check_count(width, "width"), _check_count(height, "height")
        eye = as_tensor(eye, dtype=dtype, device=device, name="eye")
        R, t = look_at(eye, target, up)
        if fov_y is not None:
            K = intrinsics_from_fov(fov_y, width, height, dtype=eye.dtype, device=eye.device)
        else:
            f = height / _check_real(ortho_height, "ortho_height", low=0, low_open=True)
            K = torch.tensor([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]], dtype=eye.dtype, device=eye.device)
        return cls(K, R, t, width, height, near=near, far=far, orthographic=ortho_height is not None)

    @property
    def dtype(self) -> torch.dtype:
        return self.K.dtype

    @property
    def device(self) -> torch.device:
        return self.K.device

    @property
    def eye(self) -> torch.Tensor:
        """The camera centre in world space, (3,): ``-Rᵀ t``."""
        return -self.R.T @ self.t

    def to_camera(self, points_world) -> torch.Tensor:
        """World (N, 3) → camera space (N, 3)."""
        return world_to_camera(points_world, self.R, self.t)

    def project(self, points_world):
        """World points (N, 3) → pixel coordinates (N, 2) and camera-space depth (N,)."""
        return project_points(points_world, self.K, self.R, self.t, orthographic=self.orthographic)

    def rays(self):
        """Per-pixel-centre ray origins (H, W, 3) and unit directions (H, W, 3) in world space."""
        return pixel_rays(self.K, self.R, self.t, self.width, self.height, orthographic=self.orthographic)

    def to(self, device=None, dtype=None) -> "Camera":
        """A copy on another device and/or dtype."""
        conv = dict(device=device, dtype=_check_dtype(dtype))
        return Camera(self.K.to(**conv), self.R.to(**conv), self.t.to(**conv), self.width, self.height,
                      self.near, self.far, self.orthographic)

    def __repr__(self) -> str:
        kind = "orthographic" if self.orthographic else "perspective"
        return (f"Camera({kind}, {self.width}x{self.height}, fx={float(self.K[0, 0]):.4g}, "
                f"eye={[round(float(v), 4) for v in self.eye]}, near={self.near:g}, far={self.far:g})")
