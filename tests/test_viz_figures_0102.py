"""The figures added for lectures 01-02: each draws what its docstring promises, at the right coordinates."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402

from course import viz  # noqa: E402
from course.camera import Camera  # noqa: E402


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def test_plot_vectors_2d_draws_one_labelled_arrow_per_vector():
    ax = viz.plot_vectors_2d([1.0, 0.0], {"tangent": [0.0, 1.0], "normal": [1.0, 0.0]},
                             curve=np.array([[1.0, -1.0], [1.0, 1.0]]))
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["surface", "tangent", "normal"]
    tips = sorted(tuple(np.round(a.xy, 6)) for a in ax.texts)               # arrows are annotations
    assert tips == [(1.0, 1.0), (2.0, 0.0)]
    assert ax.get_aspect() == 1.0                                           # right angles look right


def test_plot_pinhole_puts_the_image_point_at_f_times_offset_over_depth():
    ax = viz.plot_pinhole(4.0, 1.0, focal=2.0)
    points = [tuple(np.round(np.asarray(line.get_xydata())[0], 6)) for line in ax.lines
              if len(line.get_xydata()) == 1]
    assert (2.0, 0.5) in points                                             # x = f X / Z = 2 · 1 / 4
    assert (4.0, 1.0) in points and (0.0, 0.0) in points                    # the point and the pinhole
    assert (-2.0, -0.5) in points                                           # the inverted image behind


def test_plot_frustum_3d_planes_lie_at_near_and_far_depth():
    cam = Camera.look_at([2.0, 1.5, 3.0], [0.0, 0.0, 0.0], fov_y=35.0, width=128, height=96,
                         dtype=torch.float64)
    ax = viz.plot_frustum_3d(cam.K, cam.R, cam.t, cam.width, cam.height, near=1.0, far=3.0)

    def depth(line, k):                                                     # plot axes are (x, z, y)
        x, z, y = (np.asarray(v, dtype=np.float64)[k] for v in line.get_data_3d())
        return float(cam.to_camera(torch.tensor([[x, y, z]]))[0, 2])

    rays = [line for line in ax.lines if line.get_linestyle() == "--"]      # camera centre → near corners
    edges = [line for line in ax.lines if line.get_linestyle() == "-"]      # near corners → far corners
    assert len(rays) == 4 and len(edges) == 4
    assert all(abs(depth(r, 0)) < 1e-9 and abs(depth(r, 1) - 1.0) < 1e-9 for r in rays)
    assert all(abs(depth(e, 0) - 1.0) < 1e-9 and abs(depth(e, 1) - 3.0) < 1e-9 for e in edges)
    assert len(ax.collections) >= 2                                         # the two filled planes


def test_plot_frustum_side_splits_points_into_inside_and_clipped():
    K = torch.tensor([[10.0, 0.0, 5.0], [0.0, 10.0, 5.0], [0.0, 0.0, 1.0]], dtype=torch.float64)
    points = torch.tensor([[0.0, 0.0, 2.0],                                 # inside
                           [0.0, 0.0, 0.5],                                 # before the near plane
                           [0.0, 0.0, 9.0],                                 # beyond the far plane
                           [0.0, 2.0, 2.0],                                 # below the bottom edge
                           [0.0, 0.0, -2.0]], dtype=torch.float64)         # behind the camera
    ax = viz.plot_frustum_side(K, 10, near=1.0, far=5.0, points_cam=points)
    clipped, inside = [c for c in ax.collections if c.get_label() in ("clipped", "inside")]
    assert len(inside.get_offsets()) == 1 and len(clipped.get_offsets()) == 4
    assert ax.yaxis_inverted()                                              # camera +y drawn downward
