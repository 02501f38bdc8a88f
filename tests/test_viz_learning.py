"""Lecture 13's explorer (course.viz.learning): the shipped network's mesh against its target from a view the
student turns. Registered with the other explorers (tests/test_explorers.py runs it at its defaults and its
controls' ends); here: its pinned line, the dot on its own IoU curve, the overlay's colours, bad values named,
and the cell's printed line and still picture."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from course import viz  # noqa: E402
from course.viz import explorers as E, learning as L  # noqa: E402

DEFAULT_LINE = ("torus, azimuth 0 deg, elevation 90 deg: silhouette IoU 0.669, network pixels / target's 1.08, "
                "target's pixels covered 0.83; network volume / target's 1.77")


def test_it_is_exported_and_registered():
    assert viz.reconstruction_view_explorer is L.reconstruction_view_explorer
    explore, draw, controls, live = E.EXPLORERS["13 reconstruction views"]
    assert draw is L.draw_reconstruction_view and controls["family"] == list(L.VIEW_FAMILIES) and not live


def test_the_line_at_the_defaults():
    out = L.draw_reconstruction_view()
    plt.close("all")
    assert out["line"] == DEFAULT_LINE


def test_the_view_lies_on_its_curve_and_the_overlay_counts_pixels():
    out = L.draw_reconstruction_view("box", 60.0, 30.0)
    plt.close("all")
    azimuths, curve = L._curve("box", 30.0)
    assert out["iou"] == curve[list(azimuths).index(60.0)]
    target, network = L._masks("box", 60.0, 30.0)
    assert out["iou"] == pytest.approx(int((target & network).sum()) / int((target | network).sum()), abs=0)
    assert out["pixels"] == pytest.approx(int(network.sum()) / int(target.sum()), abs=0)
    assert out["covered"] == pytest.approx(int((target & network).sum()) / int(target.sum()), abs=0)
    iou, p, c = out["iou"], out["pixels"], out["covered"]
    assert iou == pytest.approx(c / (1 + p - c), abs=1e-12)           # both / (target + network - both)
    assert L._iou(target, target) == 1.0 and L._iou(target & False, target & False) == 1.0   # empty: a match


def test_looking_straight_down_works_and_the_figure_carries_its_line():
    out = L.draw_reconstruction_view("star", 45.0, 90.0)
    fig = plt.gcf()
    assert out["line"] in [t.get_text() for t in fig.texts]                 # the line follows the controls
    plt.close("all")
    assert 0 < out["iou"] < 1


@pytest.mark.parametrize("values, words", [
    (dict(family="sphere"), "family must be one of"),
    (dict(azimuth=200.0), "azimuth must be a number in [-180.0, 180.0]"),
    (dict(elevation="up"), "elevation must be a number"),
])
def test_bad_values_are_named(values, words):
    with pytest.raises(ValueError) as err:
        L.draw_reconstruction_view(**values)
    assert words in str(err.value)


def test_the_cell_prints_its_line_and_carries_a_still_picture(shown, capsys):
    L.reconstruction_view_explorer()
    (bundle, options), = shown
    assert options == {"raw": True} and bundle["image/png"]
    assert capsys.readouterr().out.replace("\x1b[2K\r", "") == DEFAULT_LINE + "\n"
