"""Lectures 07 and 09's figures (course.viz.raytrace, course.viz.gradients): each draws what its docstring says."""
import math

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402
from matplotlib.colors import to_rgb  # noqa: E402

from course import viz  # noqa: E402
from course.viz.raytrace import BACKGROUND, CASTER_COLOURS  # noqa: E402


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


def test_lit_fraction_grid_paints_receiver_grey_casters_in_colour_background_pale():
    labels = torch.tensor([[0, 0, 1], [0, 2, -1]])
    frac = torch.tensor([[0.25, 1.0, 0.7], [0.0, 0.3, 0.9]], dtype=torch.float64)
    fig = viz.lit_fraction_grid([frac, 1 - frac], labels, titles=["a", "b"], casters=["sphere", "torus"])
    ax0, ax1 = fig.axes[:2]
    shown = ax0.get_images()[0].get_array()
    np.testing.assert_allclose(shown[0, 0], [0.25] * 3)                      # the receiver: grey = lit fraction
    np.testing.assert_allclose(shown[1, 0], [0.0] * 3)
    np.testing.assert_allclose(shown[0, 2], to_rgb(CASTER_COLOURS[0]))        # caster 1, whatever its fraction
    np.testing.assert_allclose(shown[1, 1], to_rgb(CASTER_COLOURS[1]))
    np.testing.assert_allclose(shown[1, 2], to_rgb(BACKGROUND))
    np.testing.assert_allclose(ax1.get_images()[0].get_array()[0, 0], [0.75] * 3)
    assert [ax0.get_title(), ax1.get_title()] == ["a", "b"]
    assert [t.get_text() for t in ax0.get_legend().get_texts()] == ["sphere", "torus", "background"]


def test_full_gradient_ms_scales_finite_differences_to_every_vertex():
    assert viz.full_gradient_ms({"ms": 10.0, "note": "6 of 642 vertices"}) == pytest.approx(10.0 * 642 / 6)
    assert viz.full_gradient_ms({"ms": 10.0, "note": "6 of 1,280 vertices"}) == pytest.approx(10.0 * 1280 / 6)
    assert viz.full_gradient_ms({"ms": 10.0, "note": ""}) == 10.0


def test_plot_error_cost_one_line_per_family_errors_floored_exact_dashed():
    rows = [dict(method="exact", family="exact", param="", ms=100.0, rel=0.0, note=""),
            dict(method="reynolds", family="reynolds", param="order 1", ms=10.0, rel=0.0, note=""),
            dict(method="edge", family="edge sampling", param="1,000 smp", ms=5.0, rel=0.1, note=""),
            dict(method="edge", family="edge sampling", param="10,000 smp", ms=20.0, rel=0.03, note=""),
            dict(method="fd", family="FD float64", param="h=1e-05", ms=3.0, rel=1e-8, note="1 of 10 vertices"),
            dict(method="soft", family="soft (other image)", param="σ=1e-04", ms=1.0, rel=math.nan, note="")]
    fig = viz.plot_error_cost({"scene": rows})
    ax = fig.axes[0]
    lines = {line.get_label(): line for line in ax.lines}
    assert lines["exact (reference)"].get_linestyle() == "--"
    np.testing.assert_allclose(lines["reynolds, order 1"].get_ydata(), [1e-16])    # 0 drawn at the floor
    np.testing.assert_allclose(lines["edge sampling"].get_xdata(), [5.0, 20.0])
    np.testing.assert_allclose(lines["FD float64, h=1e-05"].get_xdata(), [30.0])   # scaled to all vertices
    assert not any("soft" in label for label in lines)                            # NaN errors: not drawn
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
