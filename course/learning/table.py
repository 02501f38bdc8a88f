"""Kato et al.'s Table 1 made on the course's families: every row, every baseline, paired against the mesh network.

Kato, Ushiku and Harada (CVPR 2018) report single-image reconstruction as voxel IoU per ShapeNet category for
their mesh network (trained through their renderer), a voxel network (Yan et al. 2016, the same silhouette
supervision) and retrieval; Tatarchenko et al. (CVPR 2019, "What do single-view 3D reconstruction networks
learn?") showed that such networks can be matched by baselines that only look shapes up, and asked for the
F-score beside IoU. This module computes each row on the same test shapes and input images:

* ``mesh``: ``reconstruction.MeshReconstructor``'s mesh; ``voxel``: ``voxels.VoxelReconstructor``'s grid (and
  its surface, ``voxels.voxel_mesh``, for the surface metrics);
* ``retrieval``: the training shape whose image is nearest the input (sum of squared differences) among the
  training images an input can be: view 0 of each shape when every input is view 0, all views of every shape
  when the input can be any view (``retrieve_shape``), returned as it is;
* ``clustering`` (Tatarchenko et al.'s): the training shapes grouped by k-means on their 32³ occupancy
  (``cluster_shapes``), each cluster represented by the member nearest its centroid; a test input gets the
  representative of the cluster of its retrieved shape (the nearest image stands in for their image classifier);
* ``oracle``: the training shape with the best voxel IoU against the true shape, which no method that returns a
  training shape can beat: the ceiling of every lookup;
* ``sphere``: the untrained network's template, the same for every input: the floor.

``score_predictions`` gives per-shape voxel IoU at 32³, and from 1,000 samples a side and their exact distances to
the other surface (``inverse.metrics.surface_scores``) the Chamfer distance (point to surface, a fraction of the
target's diagonal) and the F-score at a threshold (0.02 is Tatarchenko et al.'s 1 % of the volume's side); ``table_rows`` the per-family means with the
paired standard error of each row's difference from the mesh network's (the same shapes, so the shapes'
difficulty cancels). ``python -m course bench learn`` runs it all.
"""
from __future__ import annotations

import math
import os

import torch

from ..inverse.metrics import surface_scores
from ..mesh import Mesh
from ..tensors import _check_count, _check_real
from .data import voxel_iou, voxelize

__all__ = ["INPUT_VIEWS", "input_views", "retrieve_shape", "cluster_shapes", "oracle_shapes", "score_predictions",
           "table_rows", "novelty_rows", "METHODS"]

INPUT_VIEWS = ("first", "all")
METHODS = ("mesh", "voxel", "retrieval", "clustering", "oracle", "sphere")


def input_views(dataset, protocol: str, seed: int = 0) -> torch.Tensor:
    """(N,) int64 which view of each shape of ``dataset`` is its input image: 0 for every shape ("first"), or a
    view drawn uniformly for each shape by a generator seeded with ``seed`` ("all")."""
    if protocol not in INPUT_VIEWS:
        raise ValueError(f"protocol must be one of {INPUT_VIEWS}, got {protocol!r}")
    N, Nv = dataset.silhouettes.shape[:2]
    if protocol == "first":
        return torch.zeros(N, dtype=torch.long)
    return torch.randint(Nv, (N,), generator=torch.Generator().manual_seed(_check_count(seed, "seed", minimum=0)))


def retrieve_shape(train, images: torch.Tensor, protocol: str = "first") -> torch.Tensor:
    """(B,) int64 the training shape whose image is nearest each of ``images`` (B, H, W, 3): among view 0 of every
    training shape ("first"), or among every view of every training shape ("all": the pose must match too)."""
    if protocol not in INPUT_VIEWS:
        raise ValueError(f"protocol must be one of {INPUT_VIEWS}, got {protocol!r}")
    if images.ndim != 4 or images.shape[1:] != train.images.shape[2:]:
        raise ValueError(f"images must be (B, {', '.join(map(str, train.images.shape[2:]))}) like the training "
                         f"set's views, got shape {tuple(images.shape)}")
    N, Nv = train.images.shape[:2]
    pool = train.images[:, :1] if protocol == "first" else train.images
    flat = pool.reshape(-1, images[0].numel()).double()                # (N or N Nv, H W 3)
    nearest = torch.cdist(images.reshape(images.shape[0], -1).double(), flat).argmin(1)
    return nearest // pool.shape[1]


def cluster_shapes(grids: torch.Tensor, k: int, *, iterations: int = 50, seed: int = 0):
    """(labels (N,), representatives (k,)) k-means of N occupancy grids (N, R, R, R) as vectors of 0s and 1s:
    seeded k-means++ starts, Lloyd's iterations until nothing moves (at most ``iterations``); each cluster is
    represented by its member nearest its centroid (a shape of the training set, so it has a mesh). An empty
    cluster keeps its last centroid and its representative is the shape nearest it."""
    k = _check_count(k, "k")
    x = grids.reshape(grids.shape[0], -1).double()
    N = x.shape[0]
    if k > N:
        raise ValueError(f"k must be at most the number of shapes ({N}), got {k}")
    g = torch.Generator().manual_seed(_check_count(seed, "seed", minimum=0))
    centres = x[torch.randint(N, (1,), generator=g)]
    nearest = (x - centres[0]).square().sum(1).sqrt()                 # distance to the nearest centre so far
    while centres.shape[0] < k:                                        # k-means++: far shapes more likely
        d2 = nearest.square()                                          # (sums of 0s and 1s: exact integers)
        pick = torch.multinomial(d2 / d2.sum(), 1, generator=g) if float(d2.sum()) > 0 else torch.randint(
            N, (1,), generator=g)
        centres = torch.cat([centres, x[pick]])
        nearest = torch.minimum(nearest, (x - x[pick]).square().sum(1).sqrt())
    labels = torch.full((N,), -1, dtype=torch.long)
    for _ in range(_check_count(iterations, "iterations")):
        new = torch.cdist(x, centres).argmin(1)
        if torch.equal(new, labels):
            break
        labels = new
        for c in range(k):
            members = labels == c
            if bool(members.any()):
                centres[c] = x[members].mean(0)
    d = torch.cdist(centres, x)                                        # (k, N)
    member = labels[None] == torch.arange(k)[:, None]
    representatives = torch.where(member, d, torch.inf).argmin(1)
    empty = ~member.any(1)
    representatives[empty] = d[empty].argmin(1)
    return labels, representatives


def oracle_shapes(train_grids: torch.Tensor, test_grids: torch.Tensor) -> torch.Tensor:
    """(B,) int64 for each test grid (B, R, R, R) the training grid (N, R, R, R) of highest voxel IoU (the first
    of equals)."""
    a = train_grids.reshape(train_grids.shape[0], -1).double()
    b = test_grids.reshape(test_grids.shape[0], -1).double()
    both = b @ a.T                                                     # (B, N) |A ∩ B|
    union = b.sum(1, keepdim=True) + a.sum(1)[None] - both
    iou = torch.where(union > 0, both / union.clamp(min=1), torch.ones_like(both))
    return iou.argmax(1)


def score_predictions(predictions: dict, test, *, test_grids=None, resolution: int = 32, samples: int = 1000,
                      threshold: float = 0.02, progress: bool = False) -> dict:
    """``{method: {"iou": (B,), "chamfer": (B,), "fscore": (B,)}}`` float64 per test shape.

    predictions: ``{method: list of B predictions}``, each a ``Mesh`` (voxelized at ``resolution`` for the IoU),
    a pair (grid (R, R, R) bool, Mesh or None) for a method that predicts voxels (IoU on the grid itself; the
    surface metrics on the mesh, or Chamfer 1 and F-score 0 when the grid is empty), or an index into a list of
    meshes given as ``(index, meshes, grids)`` to share the work of methods that return training shapes.
    """
    threshold = _check_real(threshold, "threshold", low=0, low_open=True)
    B = len(test)
    grids = [voxelize(m, resolution) for m in test.meshes] if test_grids is None else test_grids
    from tqdm.auto import tqdm
    disable = (not progress) or os.environ.get("TQDM_DISABLE", "").lower() not in ("", "0", "false")
    out, cache = {}, {}
    for method, preds in predictions.items():
        if len(preds) != B:
            raise ValueError(f"{method}: {len(preds)} predictions for {B} test shapes")
        scores = {"iou": [], "chamfer": [], "fscore": []}
        for n, pred in enumerate(tqdm(preds, desc=f"score {method}", disable=disable, leave=False)):
            if isinstance(pred, tuple) and len(pred) == 3:             # (index, meshes, grids): a looked-up shape
                k, meshes, lookup_grids = pred
                key = (id(meshes), int(k), n)
                if key not in cache:
                    cache[key] = _surface_scores(meshes[int(k)], test.meshes[n], samples, threshold)
                grid, surface = lookup_grids[int(k)], cache[key]
            elif isinstance(pred, tuple):                              # (grid, mesh or None): a voxel prediction
                grid, mesh = pred
                surface = (1.0, 0.0) if mesh is None else _surface_scores(mesh, test.meshes[n], samples, threshold)
            else:
                grid = voxelize(Mesh(pred.verts.detach().double(), pred.faces), resolution)
                surface = _surface_scores(pred, test.meshes[n], samples, threshold)
            scores["iou"].append(voxel_iou(grid, grids[n]))
            scores["chamfer"].append(surface[0])
            scores["fscore"].append(surface[1])
        out[method] = {key: torch.tensor(v, dtype=torch.float64) for key, v in scores.items()}
    return out


def _surface_scores(pred, target, samples, threshold):
    pred = Mesh(pred.verts.detach().double(), pred.faces)
    target = Mesh(target.verts.detach().double(), target.faces)
    scores = surface_scores(pred, target, threshold=threshold, samples=samples)
    return scores["chamfer"], scores["fscore"]


def table_rows(scores: dict, test, *, split: str = "test", baseline: str = "mesh") -> list:
    """One row per family of ``test`` and a last ("mean") over all its shapes, each method's mean of each metric
    and, for every other method, the paired difference from ``baseline`` with its standard error (the standard
    deviation of the per-shape differences over √n: the shapes are shared, so their difficulty cancels).

    Row keys: split, family, n, then ``{metric}_{method}`` and ``{metric}_{method}_diff`` / ``_se``."""
    rows = []
    groups = [(f, (test.labels == k).nonzero()[:, 0]) for k, f in enumerate(test.families)]
    for family, members in groups + [("mean", torch.arange(len(test)))]:
        row = {"split": split, "family": family, "n": int(members.numel())}
        for metric in next(iter(scores.values()), {}):
            row.update(_paired(scores, members, metric, baseline))
        rows.append(row)
    return rows


def _paired(scores: dict, members: torch.Tensor, metric: str, baseline: str) -> dict:
    """``{metric}_{method}``: each method's mean over ``members``; for the others also ``_diff`` and ``_se``, the
    mean paired difference from ``baseline`` and its standard error (NaN for one shape)."""
    out = {}
    for method, metrics in scores.items():
        v = metrics[metric][members]
        out[f"{metric}_{method}"] = float(v.mean())
        if method != baseline and baseline in scores:
            d = v - scores[baseline][metric][members]
            out[f"{metric}_{method}_diff"] = float(d.mean())
            out[f"{metric}_{method}_se"] = (float(d.std(unbiased=True)) / math.sqrt(d.numel())
                                            if d.numel() > 1 else float("nan"))
    return out


def novelty_rows(scores: dict, *, bins: int = 3, baseline: str = "mesh", metric: str = "iou") -> list:
    """The test shapes split by how near their nearest training twin is: sorted by the oracle's IoU (the best
    IoU of any training shape, which depends on the data alone, not on any method) and cut into ``bins``
    groups of (nearly) equal size, nearest twins last. One row per group: its oracle-IoU range, n, each
    method's mean ``metric`` and, for the others, the paired difference from ``baseline`` ± its standard
    error. A diversity axis that needs no retraining: where the training set holds no near-twin, a lookup has
    nothing close to return, and a network that generalizes should gain on it."""
    if "oracle" not in scores:
        raise ValueError("novelty_rows needs the oracle's scores (the nearest training shape's IoU)")
    bins = _check_count(bins, "bins")
    near = scores["oracle"]["iou"]
    order = near.argsort()
    rows = []
    for k, members in enumerate(order.tensor_split(bins)):
        if members.numel() == 0:
            continue
        rows.append({"bin": k, "n": int(members.numel()), "oracle_low": float(near[members].min()),
                     "oracle_high": float(near[members].max()), **_paired(scores, members, metric, baseline)})
    return rows
