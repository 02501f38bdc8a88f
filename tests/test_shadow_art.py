"""Shadow art (course.shadows.art): a flat occluder deformed until its shadow matches a target outline. Short
fits on small images: the shadow's IoU with the target rises for the exact gradient and the variance shadow
map; the gradient the fit uses matches central differences of its loss, and Reynolds matches exact."""
import pytest
import torch

from course.mesh import Mesh
from course.shadows.art import (ShadowArtSettings, fan_areas, fit_shadow_art, save_shadow_art_gif,
                               shadow_art_figure, shadow_art_problem, shadow_iou)
from course.shadows.art import CENTRE, _image_loss, _image_term
from course.shadows.gradients import shadowed_coverage

SHORT = ShadowArtSettings(steps=14, lr=0.05, blur=1.5)


@pytest.fixture(scope="module")
def star():
    return shadow_art_problem("star", 24, vertices=8)


def test_the_target_is_the_target_occluders_shadow(star):
    assert shadow_iou(star, star.target) == 1.0
    start = shadowed_coverage(star.mesh, star.camera, star.face_colors, star.light, star.ambient)
    assert 0.4 < shadow_iou(star, start) < 0.8                              # a disc: not yet a star
    assert torch.allclose(start[0, 0], star.face_colors[0])                 # the camera sees no occluder


@pytest.mark.parametrize("method", ["exact", "vsm"])
def test_the_shadow_moves_toward_the_target(star, method):
    fit = fit_shadow_art(star, method=method, settings=SHORT, frames=3)
    assert len(fit.losses) == SHORT.steps and len(fit.ious) == SHORT.steps + 1
    assert fit.iou > fit.start_iou + 0.1, fit.ious
    assert fit.snapshot_steps == [0, 7, 14] and len(fit.snapshots) == 3
    assert bool((fan_areas(fit.verts[CENTRE:][:, [0, 2]]) > 0).all())     # the fan did not fold
    assert torch.equal(fit.verts[:CENTRE], star.mesh.verts[:CENTRE])       # the floor stays


def test_deterministic(star):
    settings = ShadowArtSettings(steps=3)
    a, b = (fit_shadow_art(star, method="exact", settings=settings) for _ in range(2))
    assert torch.equal(a.verts, b.verts) and a.losses == b.losses and a.ious == b.ious


def test_the_gradient_is_the_losss_derivative():
    problem = shadow_art_problem("T", 16, vertices=5)
    settings = ShadowArtSettings()
    verts = problem.mesh.verts.clone()
    verts[CENTRE + 1:, 0] += torch.linspace(-0.1, 0.12, 5, dtype=torch.float64)   # no symmetry left
    loss, _, g = _image_term(problem, verts, 1.0, "exact", settings)
    _, _, g_reynolds = _image_term(problem, verts, 1.0, "reynolds", settings)
    assert torch.allclose(g_reynolds, g, rtol=1e-6, atol=1e-9 * float(g.abs().max()))

    def loss_at(v):
        image = shadowed_coverage(Mesh(v, problem.mesh.faces), problem.camera, problem.face_colors,
                                  problem.light, problem.ambient)
        return float(_image_loss(image, problem.target, 1.0))

    h = 1e-6
    for row, col in [(CENTRE + 1, 0), (CENTRE + 2, 2), (CENTRE + 4, 0), (CENTRE + 3, 1)]:
        plus, minus = verts.clone(), verts.clone()
        plus[row, col] += h
        minus[row, col] -= h
        fd = (loss_at(plus) - loss_at(minus)) / (2 * h)
        assert abs(fd - float(g[row, col])) <= 1e-5 * float(g.abs().max()), (row, col, fd, float(g[row, col]))
    assert float(g[CENTRE + 1:].abs().max()) > 0


def test_gif_and_figure(star, tmp_path):
    from PIL import Image
    import matplotlib.pyplot as plt
    fit = fit_shadow_art(star, method="exact", settings=ShadowArtSettings(steps=2), frames=3)
    path = save_shadow_art_gif(star, fit, tmp_path / "star.gif")
    with Image.open(path) as im:
        assert im.n_frames >= 2
    fig = shadow_art_figure(star, [fit])
    assert len(fig.axes) == 4                                               # target, start, result, IoU curve
    plt.close(fig)


def test_bad_input(star):
    with pytest.raises(ValueError, match="target must be one of"):
        shadow_art_problem("moon")
    with pytest.raises(ValueError, match="vertices"):
        shadow_art_problem("star", vertices=2)
    with pytest.raises(ValueError, match="method must be one of"):
        fit_shadow_art(star, method="soft")
    with pytest.raises(ValueError, match="steps"):
        fit_shadow_art(star, settings=ShadowArtSettings(steps=0))
    with pytest.raises(ValueError, match="lr"):
        fit_shadow_art(star, settings=ShadowArtSettings(lr=-1.0))
    with pytest.raises(ValueError, match="frames"):
        fit_shadow_art(star, frames=1)
    with pytest.raises(ValueError, match="ShadowArtProblem"):
        fit_shadow_art("star")
    with pytest.raises(ValueError, match="shape"):
        shadow_iou(star, star.target[:4])
    fit = fit_shadow_art(star, settings=ShadowArtSettings(steps=1))
    with pytest.raises(ValueError, match="frames >= 2"):
        save_shadow_art_gif(star, fit, "/tmp/never.gif")


def test_bench_rows(capsys):
    """``bench shadow-art``'s run(args) on a tiny setting: one row per method, printed as a table."""
    from argparse import Namespace
    from course.bench.shadow_art import run
    args = Namespace(targets=["star"], methods=["exact", "vsm"], size=16, steps=2, repeat=1, figure="", gif="")
    rows = run(args)
    assert [r["method"] for r in rows] == ["exact", "vsm"]
    assert all(r["steps"] == 2 and r["seconds"] > 0 and 0 < r["start_iou"] < 1 for r in rows)
    assert "final IoU" in capsys.readouterr().out
