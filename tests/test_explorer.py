"""viz.explorer: sliders stacked with bounded widths (usable from a 1024-px window up), the picture below
them at a larger scale, a readable note where widget state is missing, and clear errors."""
import matplotlib

matplotlib.use("Agg")

import ipywidgets as widgets  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from course import viz  # noqa: E402

SLIDERS = dict(azimuth=(-180.0, 180.0, 5.0, 30.0), elevation=(-80.0, 80.0, 5.0, 25.0),
               distance=(1.5, 10.0, 0.1, 4.0), focal=(40.0, 400.0, 5.0, 120.0))


def make(shown, draw=None, **kw):
    calls = []

    def record(**values):
        calls.append((values, plt.figure(figsize=(4, 4)).dpi))

    draw = draw or record
    viz.explorer(draw, **SLIDERS, **kw)
    (bundle, options), = shown
    return bundle, options, calls


def widget_tree(bundle):
    """The widget a display bundle shows (ipywidgets keeps every live widget by model id)."""
    from ipywidgets.widgets import widget
    return widget._instances[bundle["application/vnd.jupyter.widget-view+json"]["model_id"]]


def test_sliders_are_stacked_with_fixed_widths(shown):
    bundle, _, _ = make(shown)
    box = widget_tree(bundle)
    column, picture = box.children
    assert isinstance(column, widgets.VBox) and isinstance(picture, widgets.Output)
    sliders = column.children
    assert [s.description for s in sliders] == list(SLIDERS)                # one per row, in order
    for slider in sliders:                                                  # a track of 200 px or more
        assert slider.layout.width == "100%"
        assert (slider.layout.min_width, slider.layout.max_width) == ("360px", "560px")
        assert slider.style.description_width == "90px"
    assert isinstance(box, widgets.VBox)                                    # the picture below the sliders


def test_sliders_keep_their_range_default_and_continuous_update(shown):
    def draw(**values):
        pass
    draw.continuous_update = False
    bundle, _, _ = make(shown, draw)
    focal = widget_tree(bundle).children[0].children[3]
    assert (focal.min, focal.max, focal.step, focal.value) == (40.0, 400.0, 5.0, 120.0)
    assert focal.continuous_update is False


def test_the_picture_is_drawn_with_the_defaults_at_a_larger_scale(shown):
    base = plt.rcParams["figure.dpi"]
    _, _, calls = make(shown, figure_scale=2.0)
    assert calls == [({"azimuth": 30.0, "elevation": 25.0, "distance": 4.0, "focal": 120.0}, 2 * base)]
    assert plt.rcParams["figure.dpi"] == base                               # the scale is undone afterwards


def test_without_widget_state_a_front_end_shows_a_note_not_a_repr(shown):
    bundle, options, _ = make(shown)
    assert options == {"raw": True}
    assert "VBox" not in bundle["text/plain"]
    assert "azimuth, elevation, distance, focal" in bundle["text/plain"]


@pytest.mark.parametrize("spec, words", [((0.0, 1.0, 0.1), "expected (min, max, step, default)"),
                                         ((0.0, 1.0, 0.1, 2.0), "default 2.0 lies outside [0.0, 1.0]")])
def test_a_bad_slider_is_named(shown, spec, words):
    with pytest.raises(ValueError, match="slider 'focal'") as err:
        viz.explorer(lambda **kw: None, focal=spec)
    assert words in str(err.value) and not shown
