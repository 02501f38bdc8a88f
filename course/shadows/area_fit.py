"""Fits through the exact penumbra (lecture 14): an area light's position and size from a picture of its soft
shadow, and an occluder's shape from its soft shadow.

The picture: the floor y = 0 seen straight down by an orthographic camera, ``n × n`` pixels over
``[-extent, extent]²``, each pixel the floor's radiance at its centre, ``albedo · (ambient + power · F(x))`` with F
the exact form factor of the light past the occluders (``area.light_form_factor``). Everything is a smooth function
of the light's corners and the occluders' vertices between the clipping decisions, so plain gradient descent
(Adam) on the squared difference of two pictures moves the light and the occluder.

* ``fit_area_light``: a square light facing down, ``centre`` (3,) and half side ``half``, recovered from a target
  picture (optionally with noise, ``penumbra_picture(noise=...)``). The light's radiosity (power per unit area,
  the ``POWER`` in ``ambient + POWER · F``) is known, so the open floor's brightness tells the light's angular
  size; a light farther away and larger in proportion lights the open floor nearly alike, and only the shadow
  tells them apart (at one angular size the farther light casts the smaller shadow and the narrower penumbra).
  Reported: the angle between the fitted and the true light's direction seen from the occluder's centre, and
  the relative error of the size.
* ``fit_occluder``: a flat polygon at a known height (its vertices' x and z free, a fan of triangles) moved until
  its soft shadow matches a target's; reported: the picture's error and the polygons' IoU (on a fine grid).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from ..mesh import Mesh
from .area import light_form_factor

__all__ = ["square_light", "floor_points", "penumbra_picture", "light_angle", "fit_area_light", "polygon_mesh",
           "polygon_iou", "fit_occluder", "FitHistory"]

AMBIENT = 0.05
POWER = 12.0             # the light's radiosity (× the floor's albedo): a form factor F adds 12 F to a pixel
                         # (the floor under the light sees F ≈ 0.05)


def square_light(centre, half) -> torch.Tensor:
    """(4, 3) a horizontal square light of half side ``half`` around ``centre`` (3,), facing down (its corners
    counter-clockwise about -y), differentiable in both."""
    c = torch.as_tensor(centre, dtype=torch.float64)
    h = torch.as_tensor(half, dtype=torch.float64)
    signs = torch.tensor([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], dtype=torch.float64)
    return c + h * signs


def floor_points(n: int = 32, extent: float = 1.5):
    """(n², 3) pixel centres of the floor seen straight down (rows along z, columns along x) and their normals."""
    t = (torch.arange(n, dtype=torch.float64) + 0.5) / n * 2 * extent - extent
    z, x = torch.meshgrid(t, t, indexing="ij")
    points = torch.stack([x.reshape(-1), torch.zeros(n * n, dtype=torch.float64), z.reshape(-1)], 1)
    normals = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64).expand(n * n, 3)
    return points, normals


def penumbra_picture(light, occluders, n: int = 32, extent: float = 1.5, *, noise: float = 0.0,
                     seed: int = 0) -> torch.Tensor:
    """(n, n) the floor's radiance ``ambient + power · F`` at the pixel centres (module docstring), plus Gaussian
    noise of standard deviation ``noise`` (seeded): a photograph's grain."""
    points, normals = floor_points(n, extent)
    image = (AMBIENT + POWER * light_form_factor(points, normals, light, occluders)).view(n, n)
    if noise:
        g = torch.Generator().manual_seed(seed)
        image = image + noise * torch.randn(n, n, generator=g, dtype=torch.float64)
    return image


def light_angle(centre_a, centre_b, origin) -> float:
    """The angle (degrees) between the directions from ``origin`` to two light centres."""
    a = torch.as_tensor(centre_a, dtype=torch.float64) - torch.as_tensor(origin, dtype=torch.float64)
    b = torch.as_tensor(centre_b, dtype=torch.float64) - torch.as_tensor(origin, dtype=torch.float64)
    cos = float((a @ b) / (a.norm() * b.norm()))
    return math.degrees(math.acos(max(-1.0, min(1.0, cos))))


@dataclass
class FitHistory:
    """What a fit did: the loss (mean squared picture difference) at every step, and the parameters at every
    ``record`` steps, as float64 tensors."""
    loss: list
    params: list


def _light_of(params, o):
    """The light (centre (3,), half side) of the unknowns ``(azimuth, elevation, log distance, log angular
    size)`` around the occluders' centre o: the direction ``(cos e sin a, sin e, cos e cos a)``."""
    azimuth, elevation, log_distance, log_size = params
    distance = log_distance.exp()
    u = torch.stack([torch.cos(elevation) * torch.sin(azimuth), torch.sin(elevation),
                     torch.cos(elevation) * torch.cos(azimuth)])
    return o + distance * u, distance * log_size.exp()


def fit_area_light(target, occluders, start_centre, start_half, *, steps: int = 120, polish: int = 20,
                   lr: float = 0.05, extent: float = 1.5):
    """Fit the light until ``penumbra_picture`` of it matches ``target`` (n, n). The unknowns: the light's
    direction from the occluders' centre o (azimuth and elevation), its log distance and its log angular size
    (half side / distance): a light farther away and larger in proportion lights the open floor alike, and
    only the shadow's magnification and its penumbra's width tell them apart, so the loss has a long, narrow
    valley, and in these coordinates it is nearly straight. ``steps`` of Adam bring the light into it; then
    ``polish`` iterations of L-BFGS (strong-Wolfe line search) go down its floor, where Adam's steps, a fixed
    size per coordinate, zig-zag across it. Returns (centre, half, history), history one entry per step."""
    n = target.shape[0]
    points, normals = floor_points(n, extent)
    o = occluders.verts.detach().double().mean(0)
    offset = torch.as_tensor(start_centre, dtype=torch.float64) - o
    distance = offset.norm()
    params = [torch.atan2(offset[0], offset[2]), torch.asin(offset[1] / distance), distance.log(),
              torch.tensor(math.log(float(start_half)), dtype=torch.float64) - distance.log()]
    params = [p.detach().clone().requires_grad_() for p in params]
    opt = torch.optim.Adam(params, lr=lr, betas=(0.9, 0.99))
    history = FitHistory([], [])

    def closure():
        opt.zero_grad()
        centre, half = _light_of(params, o)
        picture = (AMBIENT + POWER * light_form_factor(points, normals, square_light(centre, half),
                                                       occluders)).view(n, n)
        loss = ((picture - target) ** 2).mean()
        loss.backward()
        return loss
    for step in range(steps + polish):
        if step == steps:
            opt = torch.optim.LBFGS(params, lr=1.0, max_iter=1, line_search_fn="strong_wolfe", tolerance_grad=0.0,
                                    tolerance_change=0.0)
        with torch.no_grad():
            centre, half = _light_of(params, o)
        history.params.append((centre.clone(), float(half)))
        history.loss.append(float(opt.step(closure).detach()))
    with torch.no_grad():
        centre, half = _light_of(params, o)
    return centre, float(half), history


def polygon_mesh(xz, height) -> Mesh:
    """A flat polygon at y = ``height`` with vertices ``xz`` (K, 2) in order, as a fan of K - 2 triangles."""
    K = xz.shape[0]
    verts = torch.stack([xz[:, 0], torch.full_like(xz[:, 0], float(height)), xz[:, 1]], 1)
    faces = torch.tensor([[0, i, i + 1] for i in range(1, K - 1)])
    return Mesh(verts, faces)


def polygon_iou(a, b, n: int = 400, extent: float = 1.5) -> float:
    """The intersection over union of two simple polygons (K, 2) in the plane, by the even-odd rule on an
    n × n grid of points over ``[-extent, extent]²``."""
    t = (torch.arange(n, dtype=torch.float64) + 0.5) / n * 2 * extent - extent
    Y, X = torch.meshgrid(t, t, indexing="ij")
    p = torch.stack([X.reshape(-1), Y.reshape(-1)], 1)

    def inside(poly):
        poly = torch.as_tensor(poly, dtype=torch.float64).detach()
        start, end = poly, poly.roll(-1, 0)                                    # each edge
        crosses = ((start[:, 1] > p[:, None, 1]) != (end[:, 1] > p[:, None, 1]))
        x = start[:, 0] + (p[:, None, 1] - start[:, 1]) * (end[:, 0] - start[:, 0]) / (end[:, 1] - start[:, 1] + 1e-300)
        return ((crosses & (p[:, None, 0] < x)).sum(1) % 2) == 1
    ia, ib = inside(a), inside(b)
    return float((ia & ib).sum()) / max(float((ia | ib).sum()), 1.0)


def fit_occluder(target, light, start_xz, height, *, steps: int = 150, lr: float = 0.02, extent: float = 1.5,
                 record: int = 10):
    """Gradient descent (Adam) on a flat occluder's vertices (K, 2) at ``height`` until its soft shadow's
    ``penumbra_picture`` under ``light`` matches ``target`` (n, n). Returns (xz, history)."""
    n = target.shape[0]
    points, normals = floor_points(n, extent)
    xz = torch.as_tensor(start_xz, dtype=torch.float64).clone().requires_grad_()
    opt = torch.optim.Adam([xz], lr=lr)
    history = FitHistory([], [])
    for step in range(steps):
        opt.zero_grad()
        picture = (AMBIENT + POWER * light_form_factor(points, normals, light, polygon_mesh(xz, height))).view(n, n)
        loss = ((picture - target) ** 2).mean()
        loss.backward()
        history.loss.append(float(loss.detach()))
        if step % record == 0:
            history.params.append(xz.detach().clone())
        opt.step()
    return xz.detach(), history
