"""course.learning.mvtn: multi-view classification with views learned through the soft rasterizer (lecture 13). A few
steps only; whether learned views help is the bench's question (``bench learn --parts mvtn``)."""
import math

import pytest
import torch

from course.learning.mvtn import (MODES, MultiViewClassifier, MVTNSettings, evaluate_mvtn, make_mvtn_data,
                                  plot_view_directions, random_rotation, train_mvtn, view_directions)
from course.learning.data import view_cameras

SMALL = dict(size=16, views=3)


@pytest.fixture(scope="module")
def data():
    return make_mvtn_data(2, 1)


def test_the_views_start_on_a_circle_and_match_the_dataset_cameras():
    model = MultiViewClassifier(MVTNSettings(views=4, size=32))
    azimuth, elevation = model.view_angles()
    torch.testing.assert_close(azimuth, torch.tensor([0.0, 90.0, 180.0, 270.0]))
    torch.testing.assert_close(elevation, torch.full((4,), 30.0))
    cam = model.cameras(azimuth[:1], elevation[:1])[0]                      # azimuth 0: view_cameras' view 0
    ref = view_cameras(1, size=32, dtype=torch.float32)[0]
    for a, b in ((cam.R, ref.R), (cam.t, ref.t), (cam.K, ref.K)):
        torch.testing.assert_close(a, b, atol=1e-5, rtol=0)
    d = view_directions(torch.tensor([90.0]), torch.tensor([0.0]))
    torch.testing.assert_close(d, torch.tensor([[1.0, 0.0, 0.0]]), atol=1e-7, rtol=0)  # +x at 90°


@pytest.mark.parametrize("mode", ["learned", "predicted"])
def test_gradients_reach_the_views(data, mode):
    train, _ = data
    model = MultiViewClassifier(MVTNSettings(mode=mode, **SMALL))
    scores = model(train.meshes[:6])
    torch.nn.functional.cross_entropy(scores, train.labels[:6]).backward()
    if mode == "learned":
        grads = [model.azimuth.grad, model.elevation_raw.grad]
    else:                                                                   # the head starts at zero: its
        grads = [model.view_net["head"].weight.grad]                        # weights get the gradient first
    for g in grads:
        assert g is not None and bool(torch.isfinite(g).all()) and float(g.abs().max()) > 0


def test_sphere_views_spread_over_the_sphere_and_stay_fixed():
    model = MultiViewClassifier(MVTNSettings(mode="sphere", views=8, size=16))
    assert not model.azimuth.requires_grad and not model.elevation_raw.requires_grad
    azimuth, elevation = model.view_angles()
    z = torch.sin(torch.deg2rad(elevation.double()))                          # equal-area bands: 1 - (2k+1)/N
    torch.testing.assert_close(z, 1 - (2 * torch.arange(8, dtype=torch.float64) + 1) / 8, atol=1e-6, rtol=0)
    d = view_directions(azimuth, elevation)
    gaps = torch.cdist(d, d) + 9 * torch.eye(8)
    assert float(gaps.min()) > 0.6                                            # no two views close together


def test_rotated_data_turns_each_shape_by_its_own_rotation():
    upright, _ = make_mvtn_data(1, 1)
    turned, _ = make_mvtn_data(1, 1, rotate=True)
    for a, b, seed in zip(upright.meshes, turned.meshes, turned.seeds):
        R = random_rotation(int(seed))
        torch.testing.assert_close(R @ R.T, torch.eye(3, dtype=torch.float64), atol=1e-12, rtol=0)
        assert abs(float(torch.linalg.det(R)) - 1) < 1e-12
        torch.testing.assert_close(b.verts, a.verts @ R.float().T)
        assert torch.equal(a.faces, b.faces)
    assert not torch.equal(random_rotation(1), random_rotation(2))


def test_fixed_views_get_no_gradient_and_predicted_views_are_per_object(data):
    train, _ = data
    fixed = MultiViewClassifier(MVTNSettings(mode="fixed", **SMALL))
    assert not fixed.azimuth.requires_grad and not fixed.elevation_raw.requires_grad
    predicted = MultiViewClassifier(MVTNSettings(mode="predicted", **SMALL))
    azimuth, elevation = predicted.view_angles(train.meshes[:4])
    assert azimuth.shape == elevation.shape == (4, 3)


def test_training_lowers_the_loss_and_moves_the_views(data):
    train, test = data
    before = MultiViewClassifier(MVTNSettings(mode="learned", **SMALL)).view_angles()
    model, losses = train_mvtn(train, settings=MVTNSettings(mode="learned", **SMALL), steps=12, batch=12, lr=3e-3,
                               view_lr=2.0)                                  # the whole set each step
    assert losses[-1] < losses[0] - 0.3, losses
    moved = (model.view_angles()[0] - before[0]).detach().abs().max()
    assert 0 < float(moved) <= 12 * 2.0 * 1.05                               # Adam: about view_lr a step at most
    accuracy = evaluate_mvtn(model, test)
    assert 0 <= accuracy <= 1 and math.isclose(accuracy * len(test), round(accuracy * len(test)))


def test_fixed_training_is_seeded(data):
    train, _ = data
    runs = [train_mvtn(train, settings=MVTNSettings(mode="fixed", **SMALL), steps=3, batch=4, seed=0)[1]
            for _ in range(2)]
    assert runs[0] == runs[1]


def test_the_view_plot(tmp_path):
    model = MultiViewClassifier(MVTNSettings(**SMALL))
    fig = plot_view_directions({"start": model.view_angles()}, tmp_path / "views.png")
    assert (tmp_path / "views.png").stat().st_size > 0
    import matplotlib.pyplot as plt
    plt.close(fig)


def test_bad_input(data):
    train, _ = data
    with pytest.raises(ValueError, match="mode must be"):
        MultiViewClassifier(MVTNSettings(mode="random"))
    with pytest.raises(ValueError, match="multiple of 8"):
        MultiViewClassifier(MVTNSettings(size=20))
    with pytest.raises(ValueError, match="elevation"):
        MultiViewClassifier(MVTNSettings(elevation=90.0))
    model = MultiViewClassifier(MVTNSettings(**SMALL))
    with pytest.raises(ValueError, match="images must be"):
        model.classify(torch.zeros(2, 4, 16, 16))
    with pytest.raises(ValueError, match="meshes must be"):
        model([])
    with pytest.raises(ValueError, match="classes"):
        train_mvtn(train, settings=MVTNSettings(classes=3, **SMALL), steps=1)
    assert MODES == ("fixed", "sphere", "learned", "predicted")
