"""The lecture explorers (course.viz.explorers): every draw function runs headless at its defaults and with each
control at its ends, returns the line its notebook cell prints, the same line every time; bad values are named;
the explorer itself shows integer sliders, checkboxes and drop-downs, a still picture for viewers without
widgets, and greys its controls out while a slow picture is drawn. The bench runs through ``run(args)``."""
import argparse

import matplotlib

matplotlib.use("Agg")

import ipywidgets as widgets  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from course import viz  # noqa: E402
from course.bench import explorers as bench  # noqa: E402
from course.viz import explorers as E  # noqa: E402

# a drop-down option that computes a whole fit or synthesis is not re-run here (its default is)
COSTLY_OPTIONS = {"10 loss landscape", "11 style weight", "13 reconstruction views"}


def widget_tree(bundle):
    from ipywidgets.widgets import widget
    return widget._instances[bundle["application/vnd.jupyter.widget-view+json"]["model_id"]]


@pytest.mark.parametrize("name", list(E.EXPLORERS))
def test_each_draw_runs_at_its_defaults_and_its_ends_and_repeats_its_line(name):
    _, draw, controls, _ = E.EXPLORERS[name]
    first = draw()
    assert isinstance(first["line"], str) and first["line"]
    plt.close("all")
    assert draw()["line"] == first["line"]                                  # deterministic
    plt.close("all")
    moves = [m for m in bench.slider_moves(controls)
             if name not in COSTLY_OPTIONS or not isinstance(controls[next(iter(m))], list)]
    for values in moves:
        out = draw(**values)
        assert out["line"] and len(plt.get_fignums()) == 1, values          # one figure per redraw
        plt.close("all")


def test_the_defaults_of_the_explorers_match_their_draw_functions():
    import inspect
    for name, (_, draw, controls, _) in E.EXPLORERS.items():
        params = inspect.signature(draw).parameters
        assert list(params) == list(controls), name
        for key, spec in controls.items():
            default = spec if isinstance(spec, bool) else spec[0] if isinstance(spec, list) else spec[3]
            assert params[key].default == default, (name, key)


def test_fill_rule_line_and_the_top_left_rule():
    out = E.draw_fill_rule()
    assert out["line"] == "vertex (5.5, 5.5): A or B at 19 centres, both at 0; C in front at 2 of 4 shared centres"
    for x in (2.5, 3.5, 4.5, 5.5, 6.5):                                     # the shared edge through centres
        assert E.draw_fill_rule(x=x, y=x)["both"] == 0
    plt.close("all")


def test_edge_in_a_pixel_boundary_term_is_the_derivative():
    for offset, angle in [(0.5, 20.0), (0.2, -40.0), (0.9, 0.0), (1.5, 10.0)]:
        out = E.draw_edge(offset, angle)
        assert out["boundary"] == pytest.approx(out["autograd"], abs=1e-12)
    assert E.draw_edge()["line"] == "offset 0.5, tilt 20 deg: coverage 0.5, boundary term 1.0, autograd 1.0"
    plt.close("all")


def test_bvh_depth_and_finite_difference_agree_with_their_sources():
    world = E._rt_world()
    assert int(world[3].max()) == E.BVH_DEPTH
    assert E._fd_estimate(-5.0, E.F64) == pytest.approx(E._fd_exact(), rel=1e-8)


@pytest.mark.parametrize("draw, values", [(E.draw_supersampling, dict(k=3, jitter=True)),
                                           (E.draw_area_light, dict(size=0.5, samples=2)),
                                           (E.draw_soft, dict(log_sigma=-3.0, log_gamma=-1.0))])
def test_lectures_05_07_08_figures_carry_the_line_of_their_current_values(draw, values):
    for kwargs in ({}, values):                                             # the defaults, then moved controls
        out = draw(**kwargs)
        texts = [t.get_text().replace("\n", " ") for t in plt.gcf().texts]
        assert out["line"] in texts, (kwargs, texts)
        plt.close("all")


def test_lectures_05_07_08_colour_scales_and_legends():
    E.draw_supersampling()                                                  # coverage 0..1 on a colour map
    coverage, error = plt.gcf().axes[0].images[0], plt.gcf().axes[2].images[0]
    assert coverage.get_clim() == (0, 1) and coverage.get_cmap().name == "viridis"
    assert len(plt.gcf().axes) == 6 and error.get_clim()[0] == -error.get_clim()[1]   # a colour bar each
    plt.close("all")
    E.draw_area_light()                                                     # no surface: its own colour
    ax = plt.gcf().axes[0]
    names = [t.get_text() for t in ax.get_legend().get_texts()]
    assert names == ["no surface", "sphere", "torus"] and len(plt.gcf().axes) == 2
    pixels = ax.images[0].get_array().reshape(-1, 3)                        # the casters painted, not white
    for colour in ("tab:blue", "tab:orange"):
        assert (abs(pixels - matplotlib.colors.to_rgb(colour)).max(1) < 1e-6).sum() > 20
    plt.close("all")
    out = E.draw_soft()                                                     # clipped at a percentile
    lim = plt.gcf().axes[1].images[0].get_clim()[1]
    assert out["reach"] == pytest.approx(44 / 576) and 0.1 < lim < 1.0
    plt.close("all")
    assert E.draw_soft(log_gamma=-4.0)["reach"] == 0.0                      # round-off is not a gradient
    plt.close("all")


@pytest.mark.parametrize("draw, values", [(E.draw_edge, dict(offset=0.1, angle=-40.0)),
                                           (E.draw_finite_difference, dict(log_step=-8.0)),
                                           (E.draw_edge_sampling, dict(log_samples=1.0)),
                                           (E.draw_fit, dict(step=5)), (E.draw_loss_landscape, {})])
def test_lectures_09_10_figures_carry_the_line_of_their_current_values(draw, values):
    for kwargs in ({}, values):                                             # the defaults, then moved controls
        out = draw(**kwargs)
        texts = [t.get_text().replace("\n", " ") for t in plt.gcf().texts]
        assert out["line"] in texts, (kwargs, texts)
        plt.close("all")


def test_lecture_10_landscape_and_fit_say_where_the_loss_is_lowest():
    out = E.draw_loss_landscape()                                           # sigma 1e-4, a 3-degree grid
    assert out["lowest"] == 0.0 and out["end"] == 0.0 and out["loss30"] > out["loss0"]
    assert len(plt.gcf().axes[0].lines[0].get_xdata()) == 61
    plt.close("all")
    out = E.draw_fit()                                                      # the overshoot: lowest at step 17
    ax = plt.gcf().axes[2]
    assert ax.get_ylabel() == "loss (× 1e-3)" and ax.get_legend().get_texts()[0].get_text() == "lowest so far: step 17"
    assert out["phi"] < 0
    plt.close("all")


@pytest.mark.parametrize("draw, values, words", [
    (E.draw_fill_rule, dict(x=-1.0), "x must be a number in [0.0, 8]"),
    (E.draw_supersampling, dict(shape="cube"), "shape must be one of ['sliver', 'teapot']"),
    (E.draw_supersampling, dict(jitter=1), "jitter must be True or False"),
    (E.draw_shadow_map, dict(pcf=2), "pcf must be one of [1, 3, 5, 7, 9]"),
    (E.draw_bvh, dict(level=99), "level must be a number in [0, 14]"),
    (E.draw_soft, dict(log_sigma="big"), "log_sigma must be a number"),
    (E.draw_loss_landscape, dict(sigma=0.5), "sigma must be one of"),
    (E.draw_style_weight, dict(weight=0.5), "weight must be one of"),
    (E.draw_shadow_light, dict(elevation=0.0), "elevation must be a number in [15.0, 89.0]"),
])
def test_bad_values_are_named(draw, values, words):
    with pytest.raises(ValueError) as err:
        draw(**values)
    assert words in str(err.value)


@pytest.mark.parametrize("name", ["03 fill rule", "09 edge in a pixel", "10 fit snapshots"])
def test_an_explorer_cell_prints_its_line_and_carries_a_still_picture(name, shown, capsys):
    explore, draw, controls, live = E.EXPLORERS[name]
    explore()
    (bundle, options), = shown
    assert options == {"raw": True} and bundle["image/png"]                 # for viewers without widgets
    out = capsys.readouterr().out                   # (outside a kernel the Output widget's clearing shows as \x1b[2K)
    assert out.replace("\x1b[2K\r", "") == draw()["line"] + "\n"
    column = widget_tree(bundle).children[0]
    assert [c.description for c in column.children] == list(controls)
    assert all(c.continuous_update is live for c in column.children if hasattr(c, "continuous_update"))


def test_explorer_makes_int_sliders_checkboxes_and_dropdowns(shown):
    seen = []
    viz.explorer(lambda **v: seen.append(v), n=(1, 8, 1, 2), jitter=False, shape=["sliver", "teapot"],
                 scale=(0.0, 1.0, 0.1, 0.5))
    (bundle, _), = shown
    n, jitter, shape, scale = widget_tree(bundle).children[0].children
    assert isinstance(n, widgets.IntSlider) and (n.min, n.max, n.value) == (1, 8, 2)
    assert isinstance(jitter, widgets.Checkbox) and jitter.value is False
    assert isinstance(shape, widgets.Dropdown) and shape.value == "sliver" and list(shape.options) == ["sliver",
                                                                                                     "teapot"]
    assert isinstance(scale, widgets.FloatSlider)
    assert seen == [dict(n=2, jitter=False, shape="sliver", scale=0.5)]
    assert "image/png" not in bundle                                        # a still only when asked for


def test_a_slow_explorer_greys_its_controls_out_while_it_draws(shown):
    states, controls = [], []

    def draw(a=0.5, b=True):
        states.append([c.disabled for c in controls])
        plt.figure()

    draw.continuous_update = False
    viz.explorer(draw, a=(0.0, 1.0, 0.1, 0.5), b=True)
    (bundle, _), = shown
    controls += widget_tree(bundle).children[0].children
    controls[0].value = 0.7                                                 # a release: one redraw
    assert states[-1] == [True, True]
    assert [c.disabled for c in controls] == [False, False]                 # and back afterwards


def test_an_empty_dropdown_is_named(shown):
    with pytest.raises(ValueError, match="control 'shape': a list of options must not be empty"):
        viz.explorer(lambda **kw: None, shape=[])


def test_bench_runs_and_reports_rows(capsys):
    rows = bench.run(argparse.Namespace(repeat=1, only=["03", "09 edge in"]))
    assert [r["explorer"] for r in rows] == ["03 fill rule", "09 edge in a pixel"]
    assert all(r["first"] > 0 and r["median"] > 0 and r["moves"] == 2 * 2 + 2 * (r["explorer"] == "03 fill rule")
               for r in rows)
    out = capsys.readouterr().out
    assert "03 fill rule" in out and "median ms" in out
    assert bench.slider_moves(dict(k=(1, 8, 1, 2), jitter=False, shape=["a", "b", "c"])) == [
        {"k": 1}, {"k": 8}, {"jitter": True}, {"shape": "b"}, {"shape": "c"}]


def test_lecture_12_shadow_light_is_legible_linear_and_carries_its_line():
    import math

    import torch
    from course.shadows.gradients import shadowed_coverage
    for kwargs in ({}, dict(azimuth=-60.0, elevation=30.0)):               # the defaults, then moved controls
        out = E.draw_shadow_light(**kwargs)
        fig = plt.gcf()
        assert out["line"] in [t.get_text() for t in fig.texts], kwargs
        image, gradient = fig.axes[0].images[0], fig.axes[1].images[0]
        assert image.get_array().shape[:2] == (E.SHADOW_SIZE, E.SHADOW_SIZE) and E.SHADOW_SIZE >= 40
        assert len(fig.axes) == 3 and gradient.get_clim()[0] == -gradient.get_clim()[1]   # a colour bar, signed
        assert "red" in fig.axes[2].get_ylabel()
        plt.close("all")
    E.draw_shadow_light()                                                   # linear, as the lecture's images
    shown = plt.gcf().axes[0].images[0].get_array()
    a, e = math.radians(30.0), math.radians(60.0)
    light = -torch.tensor([math.cos(e) * math.sin(a), math.sin(e), math.cos(e) * math.cos(a)], dtype=torch.float64)
    mesh, camera, colors, _ = E._shadow_problem()
    expected = shadowed_coverage(mesh, camera, colors, light).clamp(0, 1).numpy()
    assert abs(shown - expected).max() < 1e-12
    plt.close("all")


def test_lecture_14_penumbra_is_legible_exact_and_carries_its_line():
    """The explorer's gradient image is the derivative of its picture: forward-mode autograd against central
    differences of the exact picture (float64, step 1e-6), at the defaults and with moved controls."""
    import torch
    from course.shadows.area import light_form_factor
    from course.shadows.area_fit import AMBIENT, POWER, floor_points, polygon_mesh, square_light
    for kwargs in ({}, dict(size=0.15, x=-0.6, height=2.7)):
        out = E.draw_penumbra(**kwargs)
        fig = plt.gcf()
        assert out["line"] in [t.get_text() for t in fig.texts], kwargs
        picture, gradient = fig.axes[0].images[0], fig.axes[1].images[0]
        assert picture.get_array().shape[:2] == (E.PENUMBRA_SIZE, E.PENUMBRA_SIZE) and E.PENUMBRA_SIZE >= 40
        assert len(fig.axes) == 3 and gradient.get_clim()[0] == -gradient.get_clim()[1]
        size, x, height = kwargs.get("size", 0.4), kwargs.get("x", 0.3), kwargs.get("height", 2.0)
        occluder = polygon_mesh(torch.tensor(E.PENUMBRA_OCCLUDER, dtype=torch.float64), 0.8)
        points, normals = floor_points(E.PENUMBRA_SIZE)

        def picture_at(cx):
            light = square_light(torch.tensor([cx, height, -0.2], dtype=torch.float64), size)
            return AMBIENT + POWER * light_form_factor(points, normals, light, occluder)
        fd = ((picture_at(x + 1e-6) - picture_at(x - 1e-6)) / 2e-6).view(E.PENUMBRA_SIZE, E.PENUMBRA_SIZE)
        shown = torch.as_tensor(gradient.get_array())
        assert float((shown - fd).abs().max()) < 1e-6 * max(1.0, float(fd.abs().max()))
        assert abs(out["gradient"] - float(fd.abs().sum())) < 1e-5 * out["gradient"]
        plt.close("all")


def test_lecture_15_gaussian_is_legible_and_its_gradient_is_autograds():
    """The explorer's derivative image against central differences of the splatted image (away from the swap),
    at the defaults and with moved controls; its line is in the figure."""
    import torch
    from course.splats import render_gaussians, swap_scene
    for kwargs in ({}, dict(scale=0.3, angle=-45.0, opacity=0.5, offset=0.25)):
        out = E.draw_gaussian(**kwargs)
        fig = plt.gcf()
        assert out["line"] in [t.get_text() for t in fig.texts], kwargs
        shown = torch.as_tensor(fig.axes[1].images[0].get_array())
        assert len(fig.axes) == 3 and shown.shape == (E.GAUSSIAN_SIZE, E.GAUSSIAN_SIZE)
        plt.close("all")
        params, camera, toward, swap = swap_scene(E.GAUSSIAN_SIZE)
        means, scales, rotations, opacities, colors = (p.clone() for p in params)
        import math
        half = math.radians(kwargs.get("angle", 30.0)) / 2
        rotations[1] = torch.cat([torch.tensor([math.cos(half)], dtype=torch.float64), math.sin(half) * camera.R[2]])
        scales[1] = kwargs.get("scale", 0.5) * torch.tensor([1.0, 0.4, 1.0], dtype=torch.float64)
        opacities[1] = kwargs.get("opacity", 0.8)

        def image(s):
            m = torch.stack([means[0], means[1] + s * toward])
            return render_gaussians(m, scales, rotations, opacities, colors, camera).sum(-1)
        s0, h = swap + kwargs.get("offset", -0.2), 1e-6
        fd = (image(s0 + h) - image(s0 - h)) / (2 * h)
        assert float((shown - fd).abs().max()) < 1e-5 * max(1.0, float(fd.abs().max()))
