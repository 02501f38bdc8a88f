"""Lecture 03's figures (course.viz, section "lecture 03: added figures"): each draws what its docstring says,
in image coordinates, with the labels and legend entries the lecture relies on."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402

from course import raster, viz  # noqa: E402

TRI = torch.tensor([[1.2, 0.7], [6.3, 2.1], [2.5, 5.8]], dtype=torch.float64)   # asymmetric, clockwise on screen


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


def texts(ax):
    return [t.get_text() for t in ax.texts]


def legend_labels(ax):
    return [t.get_text() for t in ax.get_legend().get_texts()]


def test_draw_triangle_outlines_and_names_the_corners():
    _, ax = plt.subplots()
    line = viz.draw_triangle(ax, TRI, color="tab:orange", label="tri", edge=(0, 1))
    x, y = line.get_data()
    np.testing.assert_allclose(np.c_[x, y], np.vstack([TRI.numpy(), TRI.numpy()[:1]]))   # closed outline
    labels = [t for t in ax.texts if t.get_text().startswith("v")]
    assert [t.get_text() for t in labels] == ["v0", "v1", "v2"]
    for t, p in zip(labels, TRI.numpy()):                                   # anchored at its corner
        np.testing.assert_allclose(t.xy, p)
    arrows = [t for t in ax.texts if t.get_text() == ""]                    # the edge arrow v0 → v1
    assert len(arrows) == 1 and np.allclose(arrows[0].xy, TRI[1]) and np.allclose(arrows[0].xyann, TRI[0])


def test_plot_edge_function_is_drawn_over_the_whole_image():
    fine = torch.stack(torch.meshgrid(torch.arange(70) + 0.5, torch.arange(80) + 0.5, indexing="ij")[::-1], -1) / 10
    e = raster.edge_function(TRI[0], TRI[1], fine)                          # (70, 80) over 8 × 7 pixels
    ax = viz.plot_edge_function(e, TRI, 8, 7, edge=(0, 1), title="E")
    image = ax.images[-1]
    assert image.get_extent() == [0, 8, 7, 0]                               # row 0 at the top, pixel units
    assert image.get_clim() == (-float(e.abs().max()), float(e.abs().max()))   # white is zero
    assert {"v0", "v1", "v2"} <= set(texts(ax))


def test_plot_raster_legend_tells_outlines_from_fills():
    values = torch.zeros(7, 8)
    values[2, 3] = 1.0
    ax = viz.plot_raster_legend(values, tris=TRI[None], tri_labels=["triangle"], tri_colors=["tab:red"],
                                fill_labels={1.0: "covered"}, vertex_labels=True, legend_loc="below")
    assert legend_labels(ax) == ["covered", "triangle"]
    swatch = ax.get_legend().legend_handles[0]
    image = ax.images[-1]
    np.testing.assert_allclose(swatch.get_facecolor(), image.cmap(image.norm(1.0)))   # the fill's own colour
    assert {"v0", "v1", "v2"} <= set(texts(ax))
    assert viz.plot_raster_legend(values, tris=TRI[None]).get_legend() is None      # nothing named: no legend


def test_plot_clip_side_draws_camera_space_side_view():
    near = 0.5
    verts = torch.tensor([[0.3, -0.4, 2.0], [-0.5, 0.3, -0.3], [0.6, 0.5, 0.2]])
    pieces, _ = raster._clip_near(verts, torch.tensor([[0, 1, 2]]), torch.tensor([0]), near)
    ax = viz.plot_clip_side(verts, pieces, near)
    assert ax.get_ylim()[0] > ax.get_ylim()[1]                              # camera y points down
    assert ax.get_xlabel().startswith("z")
    filled = [p for p in ax.patches if p.get_label().startswith("clipped triangle")]
    assert len(filled) == len(pieces) == 1
    np.testing.assert_allclose(filled[0].get_xy()[:3], pieces[0][:, [2, 1]].numpy())   # (z, y) per corner
    assert "clipped triangle 0" in legend_labels(ax) and "original triangle" in legend_labels(ax)


def test_plot_zbuffer_keys_rings_the_smallest_key():
    pixel = torch.tensor([0, 0, 1, 1])
    depth = torch.tensor([2.0, 1.0, 3.0, 3.0])
    face = torch.tensor([0, 1, 5, 2])                                       # pixel 1: a tie, face 2 wins
    keys = raster._depth_keys(depth, face)
    ax = viz.plot_zbuffer_keys(pixel, depth, face, keys)
    rings = [line for line in ax.lines if line.get_markersize() == 16]
    kept = sorted((float(line.get_ydata()[0]), round(float(line.get_xdata()[0]))) for line in rings)
    assert kept == [(1.0, 0), (3.0, 1)]
    labels = texts(ax)
    assert any(t.startswith("face 2") and t.endswith("00000002") for t in labels)
    ring_x = {round(float(line.get_xdata()[0]), 2) for line in rings}
    tie_dot = [line for line in ax.lines if line.get_markersize() == 8 and float(line.get_ydata()[0]) == 3.0]
    assert len({float(line.get_xdata()[0]) for line in tie_dot}) == 2       # the tie drawn side by side
    assert any(abs(x - float(tie_dot[1].get_xdata()[0])) < 1e-9 for x in ring_x)   # face 2, listed second
