"""Lecture 14's fits through the exact penumbra (course.shadows.area_fit): an area light's position and size from a
noisy picture of its soft shadow, started 35° and 2× its size away (target: within 2° and 5 %), and a flat
occluder's shape from its soft shadow (a hexagon becomes the target triangle: IoU from 0.48 to over 0.95)."""
import math

import torch

from course.shadows.area_fit import (fit_area_light, fit_occluder, light_angle, penumbra_picture, polygon_iou,
                                     polygon_mesh, square_light)

F64 = torch.float64


def test_the_light_is_found_from_its_penumbra():
    occ = polygon_mesh(torch.tensor([[-0.3, -0.25], [0.3, -0.3], [0.25, 0.3], [-0.35, 0.2]], dtype=F64), 0.8)
    centre, half = torch.tensor([0.3, 2.0, -0.2], dtype=F64), 0.4
    target = penumbra_picture(square_light(centre, half), occ, 32, noise=0.02)
    o = occ.verts.mean(0)
    a = math.radians(35)
    turn = torch.tensor([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]], dtype=F64)
    start = o + turn @ (centre - o)
    assert light_angle(start, centre, o) >= 30
    fitted, fitted_half, history = fit_area_light(target, occ, start, 2 * half)
    assert light_angle(fitted, centre, o) < 2
    assert abs(fitted_half / half - 1) < 0.05
    at_truth = float(((penumbra_picture(square_light(centre, half), occ, 32) - target) ** 2).mean())
    assert history.loss[-1] <= 1.01 * at_truth                            # down to the noise: what it can tell


def test_the_occluder_is_found_from_its_soft_shadow():
    light = square_light(torch.tensor([0.2, 2.0, 0.1], dtype=F64), 0.3)
    triangle = torch.tensor([[-0.45, -0.35], [0.5, -0.25], [0.0, 0.5]], dtype=F64)
    target = penumbra_picture(light, polygon_mesh(triangle, 0.8), 32, noise=0.01)
    angles = torch.arange(6, dtype=F64) * 2 * math.pi / 6
    start = torch.stack([0.1 + 0.3 * torch.cos(angles), 0.05 + 0.3 * torch.sin(angles)], 1)
    assert polygon_iou(start, triangle) < 0.5
    xz, history = fit_occluder(target, light, start, 0.8, steps=60, lr=0.01)
    assert polygon_iou(xz, triangle) > 0.95
    assert history.loss[-1] < 0.06 * history.loss[0]


def test_polygon_iou():
    square = torch.tensor([[0.0, 0], [1, 0], [1, 1], [0, 1]], dtype=F64)
    half = torch.tensor([[0.0, 0], [0.5, 0], [0.5, 1], [0, 1]], dtype=F64)
    assert abs(polygon_iou(square, square) - 1) < 1e-12
    assert abs(polygon_iou(square, half) - 0.5) < 0.01
