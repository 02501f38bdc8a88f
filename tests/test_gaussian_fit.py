"""Gaussians fitted to lecture 10's shaded teapot views (course.inverse.gaussians.fit_gaussians), at a small size:
the held-out PSNR climbs from the start's, densification clones and splits, pruning removes the faint ones. The
full-size run (64², 1200 steps: 32.6 dB from the hull, 31.0 dB from random points) is in the issue's note and
lecture 15."""
import torch

from course import models
from course.inverse.gaussians import _densify, fit_gaussians
from course.inverse.shaded import shaded_data


def test_a_small_fit_learns_the_held_out_views():
    data = shaded_data(models.teapot(6, dtype=torch.float64), n_views=12, size=24, resolution=24)
    fit = fit_gaussians(data, n=600, steps=120, densify_every=40, densify_until=80, eval_every=0, grad_threshold=1e-4)
    assert fit.psnr > fit.start_psnr + 8, (fit.start_psnr, fit.psnr)
    assert [s for s, _ in fit.counts] == [40, 80]
    means, scales, rotations, opacities, colors = fit.params
    assert means.shape[0] == fit.counts[-1][1] and bool((scales > 0).all())
    assert torch.allclose(rotations.norm(dim=1), torch.ones(means.shape[0], dtype=torch.float64))


def test_densify_clones_small_splits_large_and_prunes_faint():
    g = torch.Generator().manual_seed(0)
    n = 4
    raw = [torch.zeros(n, 3, dtype=torch.float64),
           torch.log(torch.tensor([[0.01] * 3, [0.2] * 3, [0.01] * 3, [0.01] * 3], dtype=torch.float64)),
           torch.tensor([[1.0, 0, 0, 0]] * n, dtype=torch.float64),
           torch.tensor([0.0, 0.0, 0.0, -10.0], dtype=torch.float64),              # the last: opacity 4.5e-5
           torch.rand(n, 3, generator=g, dtype=torch.float64)]
    grads = torch.tensor([1.0, 1.0, 0.0, 0.0], dtype=torch.float64)            # 0 hot and small, 1 hot and large
    out = _densify(raw, grads, torch.ones(n, dtype=torch.float64), 0.5, 0.06, 0.005, g)
    # kept: 0 and 2 (3 pruned, 1 replaced by its two halves); added: the clone of 0 and the two halves of 1
    assert out[0].shape[0] == 5
    assert sorted(round(float(s), 4) for s in out[1].exp().amax(1)) == [0.01, 0.01, 0.01, 0.125, 0.125]
    assert all(p.requires_grad for p in out)


def test_a_small_density_grid_learns_the_held_out_views():
    from course.inverse.volume_fit import fit_density_grid
    data = shaded_data(models.teapot(6, dtype=torch.float64), n_views=12, size=24, resolution=24, hull=False)
    fit = fit_density_grid(data, resolution=12, steps=60, samples=24, eval_every=0)
    assert fit.psnr > fit.start_psnr + 8, (fit.start_psnr, fit.psnr)
    assert bool((fit.density >= 0).all()) and fit.colors.shape == (12, 12, 12, 3)
