"""Camera: rotations against independent formulas, look_at, projection, rays, gradients, errors."""
import math

import numpy as np
import pytest
import torch

from course.camera import (Camera, axis_angle_to_matrix, euler_to_matrix, homogeneous, intrinsics_from_fov,
                           look_at, pixel_rays, project_points, transform_points, world_to_camera)


def test_rodrigues_quarter_turns():
    Rz = axis_angle_to_matrix(torch.tensor([0.0, 0.0, math.pi / 2]))
    assert torch.allclose(Rz @ torch.tensor([1.0, 0, 0]), torch.tensor([0.0, 1, 0]), atol=1e-6)  # x → y
    Rx = axis_angle_to_matrix(torch.tensor([math.pi / 2, 0.0, 0.0]))
    assert torch.allclose(Rx @ torch.tensor([0.0, 1, 0]), torch.tensor([0.0, 0, 1]), atol=1e-6)  # y → z


def test_rodrigues_is_a_rotation_and_matches_matrix_exponential():
    g = torch.Generator().manual_seed(0)
    w = torch.randn(50, 3, generator=g, dtype=torch.float64)
    R = axis_angle_to_matrix(w)
    eye = torch.eye(3, dtype=torch.float64).expand(50, 3, 3)
    assert torch.allclose(R @ R.transpose(1, 2), eye, atol=1e-12)
    assert torch.allclose(torch.linalg.det(R), torch.ones(50, dtype=torch.float64))
    wx = torch.zeros(50, 3, 3, dtype=torch.float64)
    wx[:, 0, 1], wx[:, 0, 2], wx[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    wx = wx - wx.transpose(1, 2)
    assert torch.allclose(R, torch.linalg.matrix_exp(wx), atol=1e-12)


def test_rodrigues_small_angles_finite_gradient():
    w = torch.tensor([1e-12, 0.0, 0.0], dtype=torch.float64, requires_grad=True)
    axis_angle_to_matrix(w).sum().backward()
    assert torch.isfinite(w.grad).all()
    assert torch.allclose(axis_angle_to_matrix(torch.zeros(3)), torch.eye(3))
    assert torch.autograd.gradcheck(axis_angle_to_matrix, (torch.tensor([0.3, -0.2, 0.9], dtype=torch.float64,
                                                                        requires_grad=True),))


def test_euler_order():
    a = torch.tensor([0.3, -0.5, 1.1], dtype=torch.float64)
    R = euler_to_matrix(a, "xyz")
    Rx = axis_angle_to_matrix(torch.tensor([0.3, 0, 0], dtype=torch.float64))
    Ry = axis_angle_to_matrix(torch.tensor([0, -0.5, 0], dtype=torch.float64))
    Rz = axis_angle_to_matrix(torch.tensor([0, 0, 1.1], dtype=torch.float64))
    assert torch.allclose(R, Rz @ Ry @ Rx)
    # "zyx": angle a[0] about z first, then a[1] about y, then a[2] about x
    Rz0 = axis_angle_to_matrix(torch.tensor([0, 0, 0.3], dtype=torch.float64))
    Rx2 = axis_angle_to_matrix(torch.tensor([1.1, 0, 0], dtype=torch.float64))
    assert torch.allclose(euler_to_matrix(a, "zyx"), Rx2 @ Ry @ Rz0)
    with pytest.raises(ValueError, match="permutation"):
        euler_to_matrix(a, "xxy")


def test_homogeneous_round_trip():
    R = axis_angle_to_matrix(torch.tensor([0.1, 0.2, 0.3]))
    t = torch.tensor([1.0, -2.0, 0.5])
    M = homogeneous(R, t)
    p = torch.randn(7, 3, generator=torch.Generator().manual_seed(1))
    assert torch.allclose(transform_points(M, p), world_to_camera(p, R, t), atol=1e-6)
    assert torch.allclose(transform_points(torch.linalg.inv(M), transform_points(M, p)), p, atol=1e-5)


def test_look_at_frame():
    eye, target = torch.tensor([2.0, 3.0, 4.0]), torch.tensor([0.5, 0.0, -1.0])
    R, t = look_at(eye, target)
    assert torch.allclose(R @ R.T, torch.eye(3), atol=1e-6) and torch.isclose(torch.linalg.det(R), torch.tensor(1.0))
    assert torch.allclose(R @ eye + t, torch.zeros(3), atol=1e-5)           # the eye is the camera origin
    fwd = R @ (target - eye)
    assert fwd[2] > 0 and torch.allclose(fwd[:2], torch.zeros(2), atol=1e-5)  # target straight ahead
    assert (R @ torch.tensor([0.0, 1.0, 0.0]))[1] < 0                       # world up is camera -y
    with pytest.raises(ValueError, match="parallel"):
        look_at((0.0, 5.0, 0.0), (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="same point"):
        look_at((1.0, 1.0, 1.0), (1.0, 1.0, 1.0))


def test_projection_equation():
    K = torch.tensor([[100.0, 0, 32], [0, 120.0, 24], [0, 0, 1]], dtype=torch.float64)
    R = axis_angle_to_matrix(torch.tensor([0.1, -0.2, 0.05], dtype=torch.float64))
    t = torch.tensor([0.1, 0.2, 3.0], dtype=torch.float64)
    X = torch.randn(20, 3, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    pix, depth = project_points(X, K, R, t)
    lam_xy1 = (K @ (R @ X.T + t[:, None])).T                                # λ [x, y, 1]
    assert torch.allclose(pix, lam_xy1[:, :2] / lam_xy1[:, 2:], atol=1e-12)
    assert torch.allclose(depth, lam_xy1[:, 2])
    pix_o, depth_o = project_points(X, K, R, t, orthographic=True)
    Xc = X @ R.T + t
    assert torch.allclose(pix_o, Xc[:, :2] * torch.tensor([100.0, 120.0], dtype=torch.float64)
                          + torch.tensor([32.0, 24.0], dtype=torch.float64))


def test_intrinsics_from_fov():
    K = intrinsics_from_fov(90.0, 64, 48)
    assert torch.allclose(K, torch.tensor([[24.0, 0, 32], [0, 24.0, 24], [0, 0, 1]]))
    with pytest.raises(ValueError, match="fov_y"):
        intrinsics_from_fov(180.0, 4, 4)


def test_rays_are_unit_and_orthographic_rays_parallel():
    cam = Camera.look_at((1.0, 1.0, 3.0), (0.0, 0.0, 0.0), fov_y=50, width=6, height=4)
    o, d = cam.rays()
    assert o.shape == d.shape == (4, 6, 3)
    assert torch.allclose(d.norm(dim=-1), torch.ones(4, 6), atol=1e-6)
    assert torch.allclose(o, cam.eye.expand(4, 6, 3))
    ortho = Camera.look_at((1.0, 1.0, 3.0), (0.0, 0.0, 0.0), ortho_height=2.0, width=6, height=4)
    o, d = ortho.rays()
    assert torch.allclose(d, d[0, 0].expand(4, 6, 3))
    assert torch.allclose((o[0, 1] - o[0, 0]).norm(), torch.tensor(0.5))     # 2 units over 4 rows: 0.5 / px


def test_gradients_flow_through_K_R_t():
    cam = Camera.look_at((0.2, 0.1, 3.0), (0.0, 0.0, 0.0), fov_y=50, width=8, height=8, dtype=torch.float64)
    K, R, t = (x.clone().requires_grad_() for x in (cam.K, cam.R, cam.t))
    X = torch.randn(5, 3, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    assert torch.autograd.gradcheck(lambda K, R, t: project_points(X, K, R, t), (K, R, t))
    assert torch.autograd.gradcheck(lambda K, R, t: pixel_rays(K, R, t, 3, 2), (K, R, t))


def test_dtype_and_numpy_inputs_kept():
    cam = Camera.look_at(np.array([0.0, 0.0, 3.0]), (0.0, 0.0, 0.0), fov_y=50, width=8, height=8)
    assert cam.dtype == torch.float64                                       # numpy float64 stays float64
    pix, depth = cam.project(np.zeros((1, 3)))
    assert pix.dtype == torch.float64 and torch.allclose(pix, torch.tensor([[4.0, 4.0]], dtype=torch.float64))
    cam32 = cam.to(dtype=torch.float32)
    assert cam32.project(torch.zeros(1, 3))[0].dtype == torch.float32


def test_bad_camera_inputs():
    with pytest.raises(ValueError, match=r"K must have shape \(3, 3\)"):
        Camera(torch.eye(2), torch.eye(3), torch.zeros(3), 4, 4)
    with pytest.raises(ValueError, match="height must be a positive integer"):
        Camera(torch.eye(3), torch.eye(3), torch.zeros(3), 4, -1)
    with pytest.raises(ValueError, match="near"):
        Camera(torch.eye(3), torch.eye(3), torch.zeros(3), 4, 4, near=0.0)
    with pytest.raises(ValueError, match="NaN"):
        Camera(torch.eye(3), torch.eye(3), torch.tensor([0.0, float("nan"), 0.0]), 4, 4)
    with pytest.raises(ValueError, match="exactly one"):
        Camera.look_at((0.0, 0.0, 3.0), width=4, height=4)
    with pytest.raises(ValueError, match=r"points must have shape \(N, 3\)"):
        project_points(torch.zeros(4, 2), torch.eye(3), torch.eye(3), torch.zeros(3))
