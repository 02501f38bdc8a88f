"""Figures and animations of fits (course.viz.fit): frames are (H, W, 3) uint8 shown like ``viz.show_image``,
GIFs round-trip through Pillow, figures show what they say, and bad inputs raise ValueErrors naming the problem."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402
from PIL import Image  # noqa: E402

from course import models, viz  # noqa: E402
from course.viz import fit as viz_fit  # noqa: E402
from course.camera import Camera  # noqa: E402
from course.inverse import FitHistory, fit_silhouettes, sphere_views  # noqa: E402
from course.shading import linear_to_srgb  # noqa: E402


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


def image_history(n=4, size=(12, 10), channels=None):
    """A history of n distinct images: silhouettes (H, W) or colours (H, W, C) with a moving bright square."""
    snaps = []
    for k in range(n):
        a = torch.zeros(size if channels is None else (*size, channels), dtype=torch.float64)
        a[k:k + 3, k:k + 3] = 1.0
        snaps.append(a)
    return FitHistory(loss=[1.0 / (k + 1) for k in range(3 * n)], snapshot_steps=[3 * k for k in range(n)],
                      snapshots=snaps, metrics={"rotation_deg": [30.0 - k for k in range(3 * n + 1)]})


@pytest.fixture(scope="module")
def mesh_fit():
    target = models.icosphere(1, 0.8, dtype=torch.float64)
    cams = sphere_views(2, size=16, dtype=torch.float64)
    return fit_silhouettes(target, cams, steps=4, subdivisions=1, snapshot_every=2, progress=False,
                           held_out=sphere_views(2, size=16, dtype=torch.float64)), target


# ------------------------------------------------------------------------------------------- frames

def test_silhouette_frames_are_grey_uint8_and_not_gamma_encoded():
    h = image_history()
    h.snapshots[0][0, 5] = 0.5                                             # a mid grey stays 128, not sRGB's 188
    frames = viz_fit.history_frames(h)
    assert len(frames) == 4
    assert all(f.shape == (12, 10, 3) and f.dtype == np.uint8 for f in frames)
    assert np.array_equal(frames[0][..., 0], frames[0][..., 1]) and np.array_equal(frames[0][..., 0], frames[0][..., 2])
    assert frames[0][0, 0, 0] == 255 and frames[0][5, 5, 0] == 0 and frames[0][0, 5, 0] == 128


def test_colour_frames_are_srgb_encoded_like_show_image():
    img = torch.rand(6, 5, 3, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    img[0, 0], img[0, 1] = -0.2, 1.3                                        # out of range: clipped
    frame = viz_fit.image_to_frame(img)
    expected = np.round(255 * linear_to_srgb(img.clamp(0, 1)).numpy()).astype(np.uint8)
    assert frame.dtype == np.uint8 and np.abs(frame.astype(int) - expected.astype(int)).max() <= 1
    raw = viz_fit.image_to_frame(img, srgb=False)
    assert raw[0, 0].tolist() == [0, 0, 0] and raw[0, 1].tolist() == [255, 255, 255]
    assert raw[2, 2, 1] == int(255 * float(img[2, 2, 1]) + 0.5)             # no encoding
    rgba = torch.cat([img, torch.ones(6, 5, 1, dtype=torch.float64)], -1)
    assert np.array_equal(viz_fit.image_to_frame(rgba), frame)            # alpha dropped
    u8 = (np.arange(30, dtype=np.uint8).reshape(6, 5))
    assert np.array_equal(viz_fit.image_to_frame(u8)[..., 2], u8)          # uint8 passes through


def test_texture_snapshots_and_fit_results_are_accepted():
    h = image_history(3, size=(8, 8), channels=3)
    result = type("Fit", (), {"history": h})()                               # anything with .history
    frames = viz_fit.history_frames(result)
    assert len(frames) == 3 and frames[0].shape == (8, 8, 3)


def test_vertex_snapshots_render_through_mesh_renderer(mesh_fit):
    fit, target = mesh_fit
    cam = Camera.look_at((0.0, 0.5, 3.0), fov_y=40, width=20, height=18, dtype=torch.float64)
    render = viz_fit.mesh_renderer(fit.mesh.faces, cam)
    frames = viz_fit.history_frames(fit, render)
    assert fit.history.snapshot_steps == [0, 2, 4] and len(frames) == 3
    assert all(f.shape == (18, 20, 3) and f.dtype == np.uint8 for f in frames)
    assert frames[0][0, 0].tolist() == [255, 255, 255]                     # white background
    assert frames[0][9, 10].max() < 255                                     # the shaded sphere in the middle
    assert render(target).shape == (18, 20, 3)                             # a whole Mesh, with its own faces


def test_frames_bad_inputs(mesh_fit):
    fit, _ = mesh_fit
    with pytest.raises(ValueError, match="no snapshots"):
        viz_fit.history_frames(FitHistory(loss=[1.0]))
    with pytest.raises(ValueError, match="vertices.*render="):
        viz_fit.history_frames(fit)
    mixed = image_history()
    mixed.snapshots[2] = torch.zeros(7, 7)
    with pytest.raises(ValueError, match="mixed shapes"):
        viz_fit.history_frames(mixed)
    nan = image_history()
    nan.snapshots[1][0, 0] = float("nan")
    with pytest.raises(ValueError, match="snapshot 1 contains NaN"):
        viz_fit.history_frames(nan)
    with pytest.raises(ValueError, match="FitHistory"):
        viz_fit.history_frames([torch.zeros(4, 4)])
    with pytest.raises(ValueError, match="render must be"):
        viz_fit.history_frames(image_history(), render="phong")
    with pytest.raises(ValueError, match=r"\(H, W\)"):
        viz_fit.image_to_frame(torch.zeros(4, 4, 2))
    with pytest.raises(ValueError, match="camera"):
        viz_fit.mesh_renderer(fit.mesh.faces, "camera")
    with pytest.raises(ValueError, match="faces"):
        viz_fit.mesh_renderer(fit.mesh.faces[:, :2], sphere_views(1, size=8)[0])


# --------------------------------------------------------------------------------------------- GIFs

def test_gif_round_trips_with_pillow(tmp_path):
    frames = viz_fit.history_frames(image_history(4, size=(12, 10)))
    path = viz_fit.save_gif(frames, tmp_path / "fit.gif", fps=10, scale=1)
    assert path == tmp_path / "fit.gif"
    with Image.open(path) as im:
        assert im.format == "GIF" and im.n_frames == 4 and im.size == (10, 12)
        assert im.info["loop"] == 0 and im.info["duration"] == 100
        im.seek(1)
        back = np.asarray(im.convert("RGB"))
    assert np.array_equal(back, frames[1])                                  # two grey levels: lossless


def test_gif_scale_and_labels(tmp_path):
    h = image_history(3, size=(16, 16))
    path = viz_fit.save_fit_gif(h, tmp_path / "labelled.gif")                # default scale: at least 128 px
    plain = viz_fit.save_gif(viz_fit.history_frames(h), tmp_path / "plain.gif")
    with Image.open(path) as a, Image.open(plain) as b:
        assert a.size == (128, 128) and a.n_frames == 3
        a.seek(2), b.seek(2)
        la, lb = np.asarray(a.convert("RGB")), np.asarray(b.convert("RGB"))
    assert not np.array_equal(la[:16, :64], lb[:16, :64])                   # "step 6" drawn in the corner
    assert np.array_equal(la[64:], lb[64:])                                 # and nowhere else
    assert np.array_equal(lb[::8, ::8], viz_fit.history_frames(h)[2])       # nearest-neighbour enlargement


def test_gif_bad_inputs(tmp_path):
    frames = viz_fit.history_frames(image_history(2))
    with pytest.raises(ValueError, match="non-empty"):
        viz_fit.save_gif([], tmp_path / "x.gif")
    with pytest.raises(ValueError, match="mixed shapes"):
        viz_fit.save_gif([frames[0], np.zeros((5, 5, 3), np.uint8)], tmp_path / "x.gif")
    with pytest.raises(ValueError, match="fps"):
        viz_fit.save_gif(frames, tmp_path / "x.gif", fps=0)
    with pytest.raises(ValueError, match="labels"):
        viz_fit.save_gif(frames, tmp_path / "x.gif", labels=["one"])
    with pytest.raises(ValueError, match="scale"):
        viz_fit.save_gif(frames, tmp_path / "x.gif", scale=0)
    assert not (tmp_path / "x.gif").exists()


def test_show_gif_embeds_the_bytes(tmp_path):
    pytest.importorskip("IPython")
    path = viz_fit.save_gif(viz_fit.history_frames(image_history(2)), tmp_path / "a.gif")
    shown = viz_fit.show_gif(path)
    assert shown.data == path.read_bytes() and shown.format == "gif"
    with pytest.raises(ValueError, match="no GIF"):
        viz_fit.show_gif(tmp_path / "missing.gif")


# ------------------------------------------------------------------------------------------ figures

def test_plot_history_panels_and_twin_axis():
    assert matplotlib.get_backend().lower() == "agg"
    h = image_history()
    fig = viz_fit.plot_history(h, title="camera")
    assert len(fig.axes) == 2                                               # loss, rotation_deg
    loss_ax, metric_ax = fig.axes
    np.testing.assert_allclose(loss_ax.lines[0].get_ydata(), h.loss)
    assert loss_ax.get_yscale() == "log" and loss_ax.get_title() == "camera"
    assert len(metric_ax.lines[0].get_xdata()) == 13                        # steps + 1: the final state too
    fig2, ax = plt.subplots()
    assert viz_fit.plot_history(h, ax=ax, log=False) is fig2
    assert ax.get_yscale() == "linear" and len(fig2.axes) == 2              # a twin y axis for the metric
    assert len(viz_fit.plot_history(h, metrics=()).axes) == 1
    h.metrics["held_out_psnr"] = [10.0, 20.0, 25.0, 26.0]                  # one per snapshot: at snapshot_steps
    fig = viz_fit.plot_history(h, metrics=["held_out_psnr"])
    np.testing.assert_array_equal(fig.axes[1].lines[0].get_xdata(), h.snapshot_steps)
    h.loss[3] = -1.0                                                        # a log scale cannot show it
    assert viz_fit.plot_history(h, metrics=()).axes[0].get_yscale() == "linear"


def test_plot_history_bad_inputs():
    with pytest.raises(ValueError, match="empty"):
        viz_fit.plot_history(FitHistory())
    with pytest.raises(ValueError, match="unknown or empty metric 'iou'.*rotation_deg"):
        viz_fit.plot_history(image_history(), metrics=["iou"])


def test_fit_figure_shows_three_images(mesh_fit):
    fit, target = mesh_fit
    cam = sphere_views(1, size=16, dtype=torch.float64)[0]
    render = viz_fit.mesh_renderer(fit.mesh.faces, cam)
    fig = viz_fit.fit_figure(target, fit.history.snapshots[0], fit.mesh, render=render,
                             captions=("", f"IoU {fit.start_iou:.3f}", f"IoU {fit.iou:.3f}"), suptitle="fit")
    assert [ax.get_title() for ax in fig.axes] == ["target", "start", "result"]
    assert fig.axes[2].get_xlabel() == f"IoU {fit.iou:.3f}"
    shown = fig.axes[1].images[0].get_array()
    assert shown.shape == (16, 16, 3)
    assert np.array_equal(shown, viz_fit.image_to_frame(render(fit.history.snapshots[0])))
    sil = torch.zeros(8, 8)
    colour = torch.full((4, 6, 3), 0.5)
    fig = viz_fit.fit_figure(sil, sil, colour, titles=None)                # sizes may differ; images need no render
    assert fig.axes[2].images[0].get_array().shape == (4, 6, 3)


def test_fit_figure_bad_inputs(mesh_fit):
    fit, target = mesh_fit
    with pytest.raises(ValueError, match="start is a mesh or vertices"):
        viz_fit.fit_figure(torch.zeros(8, 8), fit.history.snapshots[0], torch.zeros(8, 8))
    with pytest.raises(ValueError, match="target is a mesh"):
        viz_fit.fit_figure(target, torch.zeros(8, 8), torch.zeros(8, 8))
    with pytest.raises(ValueError, match="titles"):
        viz_fit.fit_figure(torch.zeros(8, 8), torch.zeros(8, 8), torch.zeros(8, 8), titles=("a", "b"))


def test_viz_re_exports_the_fit_figures():
    for name in viz_fit.__all__:
        if name != "image_to_frame":
            assert getattr(viz, name) is getattr(viz_fit, name) and name in viz.__all__
