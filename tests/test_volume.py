"""Volume rendering (course.volume): NeRF's quadrature against the emission-absorption integral in closed form for
voxel-constant fields (exact for a constant medium at any sample count, converging as 1/samples otherwise), the
closed form against a fine Riemann sum along single rays, autograd against central differences, bad input named."""
import math

import pytest
import torch

from course.camera import Camera
from course.volume import exact_volume, render_volume

F64 = torch.float64
LO, HI = torch.tensor([-1.0, -1.0, -1.0], dtype=F64), torch.tensor([1.0, 1.0, 1.0], dtype=F64)
BG = (0.2, 0.3, 0.4)


def grid(seed, n=5, scale=3.0):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(n, n, n, generator=g, dtype=F64) * scale, torch.rand(n, n, n, 3, generator=g, dtype=F64)


def cam(width=16, height=12):
    return Camera.look_at((1.5, 1.2, 3.0), (0.0, 0.0, 0.0), fov_y=40.0, width=width, height=height, dtype=F64)


def test_a_constant_medium_is_exact_at_any_sample_count():
    sigma, colors = torch.full((3, 3, 3), 0.7, dtype=F64), torch.rand(1, 1, 1, 3, dtype=F64).expand(3, 3, 3, 3)
    exact = exact_volume(sigma, colors, LO, HI, cam(), BG)
    for n in (1, 3, 17):
        assert float((render_volume(sigma, colors, LO, HI, cam(), n, BG, mode="nearest") - exact).abs().max()) < 1e-14


def test_the_quadrature_converges_to_the_closed_form_as_one_over_samples():
    sigma, colors = grid(0)
    exact = exact_volume(sigma, colors, LO, HI, cam(), BG)
    errors = [float((render_volume(sigma, colors, LO, HI, cam(), n, BG, mode="nearest") - exact).abs().mean())
              for n in (32, 128, 512)]
    for a, b in zip(errors, errors[1:]):
        assert 3.0 < a / b < 5.5, errors                                    # 4x the samples: about 4x less error
    assert errors[-1] < 1e-3


def test_the_closed_form_is_the_integral_along_a_ray():
    """One pixel's ray, integrated by a midpoint Riemann sum with the voxel lookup. The sum's own error comes from
    the few steps that straddle a voxel wall: at most about (the jumps) x (the step) / 2, 1e-4 here, and not
    monotone in the step (it depends on where the samples fall beside each wall); both sums land within 1e-5."""
    from course.volume import ray_box, sample_grid
    sigma, colors = grid(1)
    c = cam(4, 3)
    exact = exact_volume(sigma, colors, LO, HI, c, BG).reshape(-1, 3)[5]
    origins, directions = c.rays()
    o, d = origins.reshape(-1, 3)[5].to(F64), directions.reshape(-1, 3)[5].to(F64)
    d = d / d.norm()
    s_in, s_out = ray_box(o[None], d[None], LO, HI)
    errors = []
    for n in (50_000, 200_000):
        ds = float(s_out - s_in) / n
        s = float(s_in) + (torch.arange(n, dtype=F64) + 0.5) * ds
        p = o + s[:, None] * d
        sig = sample_grid(sigma[..., None], p, LO, HI, "nearest")[:, 0]
        col = sample_grid(colors, p, LO, HI, "nearest")
        T = torch.exp(-torch.cumsum(sig, 0) * ds + sig * ds / 2)             # at each step's middle
        value = ((T[:, None] * sig[:, None] * col).sum(0) * ds
                 + math.exp(-float(sig.sum()) * ds) * torch.tensor(BG, dtype=F64))
        errors.append(float((value - exact).abs().max()))
    assert max(errors) < 1e-5, errors


def test_autograd_is_the_derivative():
    sigma, colors = grid(2, n=3)
    c = cam(6, 5)
    weights = torch.rand(5, 6, 3, generator=torch.Generator().manual_seed(3), dtype=F64)
    leaves = [sigma.clone().requires_grad_(), colors.clone().requires_grad_()]
    loss = lambda s, k: (render_volume(s, k, LO, HI, c, 16, BG) * weights).sum()
    grads = torch.autograd.grad(loss(*leaves), leaves)
    for which, g in enumerate(grads):
        base = [sigma, colors]
        for index in [(0, 1, 2), (1, 1, 1), (2, 0, 1)]:
            full = index + ((0,) if which == 1 else ())
            e = torch.zeros_like(base[which])
            e[full] = 1e-6
            plus, minus = list(base), list(base)
            plus[which], minus[which] = base[which] + e, base[which] - e
            fd = float((loss(*plus) - loss(*minus)) / 2e-6)
            assert abs(float(g[full]) - fd) < 1e-7 * max(1.0, abs(fd)), (which, full, float(g[full]), fd)


@pytest.mark.parametrize("bad, match", [
    (dict(density=-torch.ones(2, 2, 2)), "density must be >= 0"),
    (dict(density=torch.ones(2, 2)), "density must have shape"),
    (dict(colors=torch.ones(2, 2, 2)), "colors must have shape"),
    (dict(hi=torch.tensor([1.0, -2.0, 1.0])), "lo < hi"),
])
def test_bad_input_is_named(bad, match):
    args = dict(density=torch.ones(2, 2, 2, dtype=F64), colors=torch.ones(2, 2, 2, 3, dtype=F64), lo=LO, hi=HI)
    args.update(bad)
    with pytest.raises(ValueError, match=match):
        render_volume(camera=cam(), **args)
