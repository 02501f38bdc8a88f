"""Lecture 05's figures (course.viz, section "lecture 05: added figures"): each draws what its docstring says,
in the coordinates the lecture relies on (y down inside a pixel)."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402

from course import antialias, coverage, viz  # noqa: E402


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


def test_plot_signal_samples_draws_the_signal_curves_and_markers():
    x = torch.linspace(0, 4, 81, dtype=torch.float64)
    centres = torch.arange(4, dtype=torch.float64) + 0.5
    ax = viz.plot_signal_samples(x, torch.sin(x), {"samples": (centres, torch.sin(centres))},
                                 curves={"alias": torch.cos(x)}, xlabel="x", title="t")
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["signal", "alias", "samples"]
    markers = [line for line in ax.lines if line.get_label() == "samples"][0]
    np.testing.assert_allclose(markers.get_xdata(), centres.numpy())
    assert ax.get_xlim() == (0.0, 4.0) and ax.get_title() == "t"


def test_plot_pixel_samples_puts_the_offsets_in_a_unit_square_with_y_down():
    fig = viz.plot_pixel_samples({"regular": antialias.regular_offsets(2)}, k=2)
    ax = fig.axes[0]
    assert ax.get_ylim()[0] > ax.get_ylim()[1]                              # y grows downward
    samples = [line for line in ax.lines if line.get_marker() == "o"][0]
    np.testing.assert_allclose(np.c_[samples.get_xdata(), samples.get_ydata()], antialias.regular_offsets(2).numpy())
    assert ax.get_title() == "regular"


def test_plot_pixel_pieces_fills_each_piece_and_labels_its_area():
    square = torch.tensor([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], dtype=torch.float64)
    line = torch.tensor([1.0, 0.0, -0.25], dtype=torch.float64)            # x >= 0.25
    piece = coverage.clip_polygon(square, line)
    ax = viz.plot_pixel_pieces([piece, square[:2]], colors=torch.tensor([[1.0, 0.5, 0.0], [0.0, 0.0, 1.0]]),
                               lines=[line], title="p")
    polygons = [p for p in ax.patches if isinstance(p, matplotlib.patches.Polygon)]
    assert len(polygons) == 1                                               # two vertices: no piece drawn
    assert [t.get_text() for t in ax.texts] == ["0.750"]
    dashed = [line for line in ax.lines if line.get_linestyle() == "--"][0]
    np.testing.assert_allclose(dashed.get_xdata(), [0.25, 0.25])            # x = 0.25, drawn vertically
    assert ax.get_ylim()[0] > ax.get_ylim()[1]
