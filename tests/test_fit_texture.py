"""Tests of course.inverse.texture: texture and vertex-colour fits improve held-out PSNR, recover a known texture,
touch only what the views see, are seeded, agree with render(), and reject bad inputs. Small images (32²)."""
import math

import pytest
import torch

from course import models
from course.inverse import FitHistory, sphere_views
from course.inverse.texture import (ColorFit, TextureFit, fit_texture, fit_texture_from_images, fit_vertex_colors,
                                fit_vertex_colors_from_images, render_texture, render_vertex_colors,
                                seen_texels, seen_vertices, smooth_vertex_colors)
from course.inverse.losses import psnr
from course.mesh import Mesh
from course.raster import rasterize

SIZE = 32


@pytest.fixture(scope="module")
def teapot():
    return models.teapot(4, dtype=torch.float64)


@pytest.fixture(scope="module")
def known(teapot):
    """The teapot wearing a seeded random 16 x 16 texture, its renders from 8 training views."""
    gen = torch.Generator().manual_seed(0)
    texture = torch.rand(16, 16, 3, generator=gen, dtype=torch.float64)
    mesh = Mesh(teapot.verts, teapot.faces, uvs=teapot.uvs, texture=texture)
    cams = sphere_views(8, offset=1.9, size=SIZE, dtype=torch.float64)
    return mesh, cams, render_texture(mesh, cams)


@pytest.fixture(scope="module")
def texture_fit():
    return fit_texture_from_images(size=SIZE, steps=60, texture_size=16, snapshot_every=20, progress=False)


@pytest.fixture(scope="module")
def color_on_texture_fit():
    return fit_vertex_colors_from_images(size=SIZE, steps=60, snapshot_every=20, progress=False)


# ------------------------------------------------------------------------------------------ texture

def test_texture_fit_improves_held_out_psnr(texture_fit):
    r = texture_fit
    assert isinstance(r, TextureFit) and isinstance(r.history, FitHistory)
    assert r.psnr > r.start_psnr + 5, (r.start_psnr, r.psnr)
    assert r.per_view_psnr.shape == (16,)
    assert math.isclose(r.psnr, float(r.per_view_psnr.mean()))
    assert r.history.loss[-1] < r.history.loss[0]
    assert 0 <= r.held_out_unseen < 0.05


def test_texture_history_and_range(texture_fit):
    r = texture_fit
    h = r.history
    assert len(h.loss) == 60 and len(h.metrics["train_psnr"]) == 60
    assert h.snapshot_steps == [0, 20, 40, 60] and len(h.metrics["held_out_psnr"]) == 4
    assert all(s.shape == (16, 16, 3) for s in h.snapshots)
    assert torch.all(h.snapshots[0] == 0.5)                                 # a flat grey start
    assert torch.equal(h.snapshots[-1], r.texture)
    assert math.isclose(h.metrics["held_out_psnr"][-1], r.psnr)
    assert r.texture.dtype == torch.float64 and not r.texture.requires_grad
    assert r.texture.min() >= 0 and r.texture.max() <= 1


def test_fitting_from_the_true_texture_reproduces_render_exactly(known):
    # the loop's cached lookups are bit-identical to course.render.render(): PSNR +inf, loss 0
    mesh, cams, images = known
    r = fit_texture(mesh, images, cams, init=mesh.texture, steps=1, progress=False)
    assert math.isinf(r.start_psnr) and r.history.loss[0] == 0.0


def test_recovers_known_texture_on_seen_texels(known):
    mesh, cams, images = known
    r = fit_texture(mesh, images, cams, texture_size=16, steps=200, lr=0.05, progress=False)
    assert r.seen.any()
    error = (r.texture - mesh.texture).abs().amax(-1)                       # (16, 16)
    assert float(error[r.seen].max()) < 1e-3, float(error[r.seen].max())


def test_gradient_reaches_only_seen_texels(known):
    mesh, cams, images = known
    cams, images = cams[:2], images[:2]
    seen = seen_texels(mesh, cams, 64)
    assert 0.05 < float(seen.double().mean()) < 0.9                          # a 64² texture: many unseen
    # oracle: autograd through the public render() of the training loss
    texture = torch.full((64, 64, 3), 0.5, dtype=torch.float64, requires_grad=True)
    render_texture(mesh, cams, texture).sub(images).pow(2).sum().backward()
    reached = texture.grad.abs().amax(-1) > 0
    assert not (reached & ~seen).any()
    assert float((reached == seen).double().mean()) > 0.99
    r = fit_texture(mesh, images, cams, texture_size=64, steps=10, progress=False)
    assert torch.equal(r.seen, seen)
    assert torch.all(r.texture[~seen] == 0.5)                                # never touched
    assert (r.texture[seen] != 0.5).any()


def test_seeded_runs_identical(known):
    mesh, cams, images = known
    run = lambda seed: fit_texture(mesh, images, cams, texture_size=8, steps=5, init="random", seed=seed,
                                   progress=False)
    a, b, c = run(3), run(3), run(4)
    assert torch.equal(a.texture, b.texture) and a.history.loss == b.history.loss
    assert not torch.equal(a.texture, c.texture)


def test_float32(known):
    mesh, cams, images = known
    mesh32 = mesh.to(dtype=torch.float32)
    cams32 = sphere_views(8, offset=1.9, size=SIZE)
    held = sphere_views(4, size=SIZE)
    r = fit_texture(mesh32, images.float(), cams32, texture_size=16, steps=40, held_out=held,
                    held_out_images=render_texture(mesh32, held), progress=False)
    assert r.texture.dtype == torch.float32
    assert r.psnr > r.start_psnr + 10


# ------------------------------------------------------------------------------------- vertex colours

def test_smooth_vertex_colors(teapot):
    a, b = smooth_vertex_colors(teapot, 0), smooth_vertex_colors(teapot, 1)
    assert a.shape == (teapot.num_verts, 3) and a.dtype == torch.float64
    assert torch.equal(a, smooth_vertex_colors(teapot, 0)) and not torch.equal(a, b)
    assert a.min() >= 0.1 and a.max() <= 0.9
    # the copies of a seam vertex (same position) get the same colour
    _, inverse = torch.unique(teapot.verts, dim=0, return_inverse=True)
    first = torch.zeros(int(inverse.max()) + 1, 3, dtype=a.dtype).index_copy(0, inverse, a)
    assert torch.allclose(first[inverse], a)


def test_vertex_color_fit_on_vertex_colored_target(teapot):
    target = smooth_vertex_colors(teapot, 1)
    r = fit_vertex_colors_from_images(teapot, target, size=SIZE, steps=60, snapshot_every=30, progress=False)
    assert isinstance(r, ColorFit)
    assert r.psnr > r.start_psnr + 10 and r.psnr > 30, (r.start_psnr, r.psnr)
    assert r.colors.shape == (teapot.num_verts, 3) and r.colors.min() >= 0 and r.colors.max() <= 1
    assert r.history.snapshot_steps == [0, 30, 60]
    assert all(s.shape == (SIZE, SIZE, 3) for s in r.history.snapshots)      # renders of held-out view 0
    # seen vertices are recovered; unseen ones keep the grey start
    assert torch.all(r.colors[~r.seen] == 0.5)
    assert float((r.colors - target).abs()[r.seen].median()) < 0.02


def test_vertex_colors_plateau_below_texture(texture_fit, color_on_texture_fit):
    r = color_on_texture_fit
    assert r.psnr > r.start_psnr                                            # it learns the mean colours...
    assert r.psnr < texture_fit.psnr - 3, (r.psnr, texture_fit.psnr)        # ...but not the checker
    tail = r.history.metrics["held_out_psnr"]
    assert tail[-1] - tail[-2] < 0.5                                         # a plateau, not slow progress


def test_vertex_renders_match_render(teapot):
    cams = sphere_views(3, size=SIZE, dtype=torch.float64)
    colors = smooth_vertex_colors(teapot, 2)
    images = render_vertex_colors(teapot, cams, colors)
    r = fit_vertex_colors(teapot, images, cams, init=colors, steps=1, progress=False)
    assert math.isinf(r.start_psnr) and r.history.loss[0] == 0.0
    seen = seen_vertices(teapot, cams)
    assert torch.equal(seen, r.seen) and seen.any() and not seen.all()


# -------------------------------------------------------------------------------------------- inputs

def test_bad_inputs_raise(known, teapot):
    mesh, cams, images = known
    fit = lambda **kw: fit_texture(**{"mesh": mesh, "images": images, "cameras": cams, "steps": 1,
                                      "progress": False, **kw})
    cases = [
        (dict(images=images[..., :2]), "shape"),
        (dict(images=images[:3]), "cameras"),
        (dict(images=images[:, :16]), "pixels"),
        (dict(images=images.clone().index_fill_(0, torch.tensor([1]), float("nan"))), "NaN"),
        (dict(images=images * 2), r"\[0, 1\]"),
        (dict(cameras=[]), "non-empty"),
        (dict(cameras=cams[0]), "non-empty"),
        (dict(mesh=Mesh(mesh.verts, mesh.faces)), "uvs"),
        (dict(mesh="teapot"), "Mesh"),
        (dict(texture_size=0), "texture_size"),
        (dict(init="white"), "init"),
        (dict(init=torch.zeros(4, 4)), "init"),
        (dict(steps=-1), "steps"),
        (dict(lr=0.0), "lr"),
        (dict(snapshot_every=0), "snapshot_every"),
        (dict(held_out=cams), "held_out_images"),
        (dict(held_out_images=images), "held_out"),
    ]
    for kwargs, message in cases:
        with pytest.raises(ValueError, match=message):
            fit(**kwargs)
    with pytest.raises(ValueError, match="target_colors"):
        fit_vertex_colors_from_images(teapot, torch.zeros(5, 3), size=8, steps=1, progress=False)
    with pytest.raises(ValueError, match="n_views"):
        fit_texture_from_images(teapot, n_views=0, size=8, steps=1, progress=False)
    with pytest.raises(ValueError, match="images"):
        fit_vertex_colors(teapot, images[:2], cams, steps=1, progress=False)


def test_per_view_psnr_is_losses_psnr_of_render(texture_fit):
    # the reported metric equals course.inverse.losses.psnr of render() images over the object pixels
    mesh = models.teapot(dtype=torch.float64)
    held = sphere_views(16, size=SIZE, dtype=torch.float64)
    pred, target = render_texture(mesh, held, texture_fit.texture), render_texture(mesh, held)
    masks = torch.stack([rasterize(mesh, c).mask for c in held])
    expected = torch.stack([psnr(p, t, mask=m) for p, t, m in zip(pred, target, masks)])
    assert torch.allclose(texture_fit.per_view_psnr, expected, rtol=0, atol=1e-9)


def test_views_that_miss_the_mesh_raise(known):
    mesh, cams, images = known
    away = sphere_views(1, size=SIZE, target=(50.0, 0.0, 0.0), dtype=torch.float64)
    with pytest.raises(ValueError, match="no part of the mesh"):
        fit_texture(mesh, images, cams, held_out=away, held_out_images=images[:1], steps=1, progress=False)
