"""course.learning.table: the rows of lecture 13's Table 1 (baselines, per-shape scores, the paired table)."""
import math

import pytest
import torch

from course.learning.data import make_dataset, voxelize
from course.learning.table import (cluster_shapes, input_views, oracle_shapes, retrieve_shape, score_predictions,
                                   table_rows)
from course.mesh import Mesh
from course.models import icosphere


@pytest.fixture(scope="module")
def data():
    return make_dataset(2, families=("box", "cone", "capsule"), views=3, size=16, dtype=torch.float64)


@pytest.fixture(scope="module")
def grids(data):
    return torch.stack([voxelize(m, 16) for m in data.meshes])


def test_a_training_image_retrieves_its_own_shape_under_both_protocols(data):
    assert torch.equal(retrieve_shape(data, data.images[:, 0], "first"), torch.arange(6))
    for view in range(3):
        assert torch.equal(retrieve_shape(data, data.images[:, view], "all"), torch.arange(6))
    views = input_views(data, "all", seed=3)
    assert views.shape == (6,) and int(views.min()) >= 0 and int(views.max()) < 3
    assert torch.equal(views, input_views(data, "all", seed=3)) and int(input_views(data, "first").abs().sum()) == 0
    with pytest.raises(ValueError, match="protocol"):
        input_views(data, "random")
    with pytest.raises(ValueError, match="images must be"):
        retrieve_shape(data, torch.zeros(2, 8, 8, 3))


def test_the_oracle_finds_each_shape_itself_and_clusters_are_seeded(grids):
    assert torch.equal(oracle_shapes(grids, grids), torch.arange(6))
    labels, reps = cluster_shapes(grids, 3, seed=1)
    again = cluster_shapes(grids, 3, seed=1)
    assert torch.equal(labels, again[0]) and torch.equal(reps, again[1])
    assert all(int(labels[int(r)]) == c for c, r in enumerate(reps))    # a representative is its cluster's member
    every, own = cluster_shapes(grids, 6)
    assert sorted(own.tolist()) == list(range(6))                       # k = N: each shape its own cluster
    with pytest.raises(ValueError, match="at most"):
        cluster_shapes(grids, 7)


def test_scores_of_a_shape_against_itself_and_an_empty_grid(data, grids):
    same = score_predictions({"itself": list(data.meshes),
                              "looked up": [(k, data.meshes, grids) for k in range(6)],
                              "empty": [(torch.zeros(16, 16, 16, dtype=torch.bool), None)] * 6},
                             data, test_grids=grids, resolution=16, samples=400)
    for method in ("itself", "looked up"):
        assert bool((same[method]["iou"] == 1).all()) and float(same[method]["chamfer"].max()) < 1e-12
        assert bool((same[method]["fscore"] == 1).all())
    assert bool((same["empty"]["iou"] == 0).all()) and bool((same["empty"]["fscore"] == 0).all())
    sphere = icosphere(2, 0.6, dtype=torch.float64)
    far = score_predictions({"sphere": [sphere] * 6}, data, test_grids=grids, resolution=16, samples=400)
    assert bool((far["sphere"]["iou"] < 1).all())
    with pytest.raises(ValueError, match="2 predictions for 6"):
        score_predictions({"short": [sphere] * 2}, data, test_grids=grids)


def test_the_table_pairs_each_method_with_the_baseline(data):
    scores = {"mesh": {"iou": torch.tensor([0.5, 0.6, 0.7, 0.8, 0.9, 1.0], dtype=torch.float64)},
              "other": {"iou": torch.tensor([0.4, 0.6, 0.7, 0.6, 1.0, 0.9], dtype=torch.float64)}}
    rows = table_rows(scores, data)
    assert [r["family"] for r in rows] == ["box", "cone", "capsule", "mean"]
    box, mean = rows[0], rows[-1]
    assert box["n"] == 2 and box["iou_mesh"] == pytest.approx(0.55) and box["iou_other_diff"] == pytest.approx(-0.05)
    d = torch.tensor([-0.1, 0.0, 0.0, -0.2, 0.1, -0.1], dtype=torch.float64)
    assert mean["iou_other_diff"] == pytest.approx(float(d.mean()))
    assert mean["iou_other_se"] == pytest.approx(float(d.std()) / math.sqrt(6))
    assert "iou_mesh_diff" not in mean
