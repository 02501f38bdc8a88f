"""The data lecture 13 learns from: shapes of ``course.learning.shapes``' families, their rendered views, their voxels.

* ``make_dataset(n_per_family, families=..., seed=0, split="train", views=2, size=32)`` a ``ShapeSet``:
  n shapes of each family with their family labels, and per shape and view a hard silhouette
  (``raster.rasterize(...).mask``) and a flat-shaded image (``fit.shaded_face_colors`` at the visible face,
  one sample per pixel centre, on a grey background). The views are the same cameras for every shape
  (``view_cameras``: 30° above the horizon, azimuths a golden angle apart, 3.2 units away, 40° field of view,
  so the unit sphere every shape fits in stays inside the frame).
* Splits by seed: shape i of family f in split s is ``make_shape(f, shape_seed(seed, s, f, i))``, a seed
  drawn from ``numpy.random.SeedSequence((seed, s, f, i))``, so train, val and test never share a shape
  and each can grow without changing the others. ``HELD_OUT`` families are left out of all three and
  form their own split for a test of generalisation (``make_splits``).
* ``voxelize(mesh, resolution)`` occupancy on an R³ grid over the cube [-1, 1]³ by *ray parity*: a ray along
  +z through each (x, y) column of voxel centres; a voxel centre is inside when an odd number of the mesh's
  faces are crossed before it. The crossings use a half-open edge rule (the rasterizer's top-left rule,
  lecture 03) with each edge's function evaluated in one fixed vertex order, so a ray through a shared edge
  or vertex counts one crossing, never zero or two. Exact for a closed mesh; ``voxel_iou`` compares two grids.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np
import torch

from ..camera import Camera
from ..inverse.shaded import shaded_face_colors
from ..mesh import Mesh
from ..raster import rasterize
from .shapes import FAMILIES, aspect_ratio, make_shape
from ..tensors import _check_count, _check_device, _check_real

__all__ = ["ShapeSet", "SPLITS", "HELD_OUT", "BACKGROUND", "shape_seed", "view_cameras", "make_dataset", "make_splits",
           "render_views", "voxelize", "voxelize_all", "voxel_iou", "silhouette_iou_table", "aspect_ratios"]

SPLITS = ("train", "val", "test", "held_out")
HELD_OUT = ("torus",)                     # the family no model sees in training (a ring: a hole in every view)
BACKGROUND = (0.5, 0.5, 0.5)              # linear grey: darker than lit faces, brighter than shadowed ones


@dataclass(frozen=True)
class ShapeSet:
    """Shapes of procedural families and their renderings. N shapes, Nv views of H × W pixels.

    meshes:      list of N ``Mesh`` (closed, outward, fitting the unit sphere).
    labels:      (N,) int64, index into ``families``.
    families:    the family names, in label order.
    seeds:       (N,) int64, the seed ``make_shape`` built each mesh from.
    silhouettes: (N, Nv, H, W) float, 1 where the mesh covers the pixel centre, else 0.
    images:      (N, Nv, H, W, 3) float linear RGB, flat-shaded on ``BACKGROUND``.
    cameras:     list of Nv ``Camera``, the views (the same for every shape).
    """
    meshes: list
    labels: torch.Tensor
    families: tuple
    seeds: torch.Tensor
    silhouettes: torch.Tensor
    images: torch.Tensor
    cameras: list

    def __len__(self) -> int:
        return len(self.meshes)


def shape_seed(seed: int, split: str, family: str, index: int) -> int:
    """The seed of shape ``index`` of ``family`` in ``split`` of the dataset with ``seed``: 63 bits from
    ``SeedSequence((seed, split number, family number, index))``; numbers are positions in SPLITS / FAMILIES."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    if family not in FAMILIES:
        raise ValueError(f"family must be one of {FAMILIES}, got {family!r}")
    key = (_check_count(seed, "seed", minimum=0), SPLITS.index(split), FAMILIES.index(family),
           _check_count(index, "index", minimum=0))
    return int(np.random.SeedSequence(key).generate_state(1, np.uint64)[0] >> np.uint64(1))


def render_views(mesh: Mesh, cameras) -> tuple[torch.Tensor, torch.Tensor]:
    """(silhouettes (Nv, H, W), images (Nv, H, W, 3)) of ``mesh`` from each camera, one sample per pixel centre.

    The silhouette is ``rasterize(...).mask`` (back faces kept); the image shows each visible face in its
    ``fit.shaded_face_colors`` (Lambert under a light fixed in the world, so a face keeps its colour in
    every view) over ``BACKGROUND``. No antialiasing and no gradient: data, not a differentiable render.
    """
    with torch.no_grad():
        colors = shaded_face_colors(mesh)                                 # (F, 3)
        background = colors.new_tensor(BACKGROUND)
        sils, images = [], []
        for camera in cameras:
            face_id = rasterize(mesh, camera).face_id                     # (H, W), -1 on the background
            hit = face_id >= 0
            images.append(torch.where(hit[..., None], colors[face_id.clamp(min=0)], background))
            sils.append(hit.to(colors.dtype))
        return torch.stack(sils), torch.stack(images)


def _check_families(families) -> tuple:
    if isinstance(families, str) or not hasattr(families, "__iter__"):
        raise ValueError(f"families must be a sequence of names from {FAMILIES}, got {families!r}")
    families = tuple(families)
    unknown = [f for f in families if f not in FAMILIES]
    if not families or unknown or len(set(families)) != len(families):
        raise ValueError(f"families must be distinct names from {FAMILIES}, got {families!r}")
    return families


def view_cameras(n: int, *, size: int = 32, elevation: float = 30.0, distance: float = 3.2, fov_y: float = 40.0,
                 dtype=None, device=None) -> list:
    """``n`` cameras ``elevation`` degrees above the horizon looking at the origin, camera k at azimuth k × 137.5°
    (the golden angle), ``distance`` away, ``fov_y`` degrees of vertical field of view, size × size pixels.

    Why not evenly spaced: two views 180° apart see nearly mirrored outlines (for a shape symmetric under a
    half-turn, exactly mirrored), which pins down little in depth; golden-angle azimuths spread the first n
    views for every n (0° and 137.5° for two, with +z at azimuth 0 and +x at 90°, as ``fit.circle_views``).
    Distance 3.2 and a 40° field of view keep the unit sphere (every shape) inside the frame with the border
    pixels' centres clear from 11 pixels up: its outline lies ``tan(asin(1 / 3.2)) / tan(20°)`` = 90.4 % of
    the half-width out.
    """
    n, size = _check_count(n, "views"), _check_count(size, "size")
    distance = _check_real(distance, "distance", low=1, low_open=True)  # outside the unit sphere
    elevation = math.radians(_check_real(elevation, "elevation", low=-90, high=90, low_open=True, high_open=True))
    cameras = []
    for k in range(n):
        azimuth = math.radians(k * 180.0 * (3 - math.sqrt(5)))                 # the golden angle, ≈ 137.5°
        eye = distance * np.array([math.cos(elevation) * math.sin(azimuth), math.sin(elevation),
                                   math.cos(elevation) * math.cos(azimuth)])
        cameras.append(Camera.look_at(eye, (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), fov_y=fov_y, width=size, height=size,
                                      dtype=dtype or torch.get_default_dtype(), device=device))
    return cameras


def _cameras(views, size, dtype, device):
    """The view cameras: ``views`` an int (that many ``view_cameras``) or a list of Camera."""
    if isinstance(views, (list, tuple)):
        if not views or not all(isinstance(c, Camera) for c in views) or len({(c.height, c.width) for c in views}) != 1:
            raise ValueError("views must be a positive integer or a non-empty list of cameras of one image size")
        return list(views)
    return view_cameras(views, size=size, dtype=dtype, device=device)


def make_dataset(n_per_family: int, *, families=FAMILIES, seed: int = 0, split: str = "train", views=2,
                 size: int = 32, dtype=None, device=None, progress: bool = False) -> ShapeSet:
    """``n_per_family`` shapes of each of ``families`` and their views, ordered by family, then index.

    split: "train", "val", "test" or "held_out": which seeds (``shape_seed``); any family may be asked for
    in any split, ``make_splits`` keeps the held-out families out of the first three.
    views: the number of ``view_cameras`` (30° up, azimuths a golden angle apart) or a list of Camera.
    size: the image side in pixels when ``views`` is a number. dtype, device: of meshes, images and cameras
    (default: torch's default dtype, the CPU). progress: show a progress bar. Cost: a few milliseconds per
    shape with two views at 32² on one CPU core.
    """
    n = _check_count(n_per_family, "n_per_family")
    families = _check_families(families)
    dtype = dtype or torch.get_default_dtype()
    device = _check_device(device)
    cameras = _cameras(views, size, dtype, device)
    from tqdm.auto import tqdm
    disable = (not progress) or os.environ.get("TQDM_DISABLE", "").lower() not in ("", "0", "false")
    meshes, labels, seeds, sils, images = [], [], [], [], []
    for label, family in enumerate(families):
        for i in tqdm(range(n), desc=f"{split} {family}", disable=disable, leave=False):
            s = shape_seed(seed, split, family, i)
            mesh = make_shape(family, s, dtype=dtype, device=device)
            sil, image = render_views(mesh, cameras)
            meshes.append(mesh), labels.append(label), seeds.append(s), sils.append(sil), images.append(image)
    return ShapeSet(meshes, torch.tensor(labels, device=device), families, torch.tensor(seeds, device=device),
                    torch.stack(sils), torch.stack(images), cameras)


def make_splits(n_train: int, n_val: int, n_test: int, *, held_out=HELD_OUT, seed: int = 0, views=2,
                size: int = 32, dtype=None, device=None, progress: bool = False) -> dict:
    """``{"train", "val", "test", "held_out"}`` ShapeSets: the first three over the families not in
    ``held_out`` (n_train, n_val, n_test shapes per family), the last over ``held_out`` (n_test per family)."""
    n_train, n_val, n_test = (_check_count(n, name) for n, name in ((n_train, "n_train"), (n_val, "n_val"),
                                                                    (n_test, "n_test")))
    held_out = _check_families(held_out)
    seen = tuple(f for f in FAMILIES if f not in held_out)
    if not seen:
        raise ValueError("held_out leaves no family to train on")
    common = dict(seed=seed, views=views, size=size, dtype=dtype, device=device, progress=progress)
    counts = {"train": (n_train, seen), "val": (n_val, seen), "test": (n_test, seen), "held_out": (n_test, held_out)}
    return {split: make_dataset(n, families=fams, split=split, **common) for split, (n, fams) in counts.items()}


# ---- voxels ------------------------------------------------------------------------------------------------

def _edge_values(p: torch.Tensor, q: torch.Tensor, ip: torch.Tensor, iq: torch.Tensor, points: torch.Tensor):
    """(F, N) the 2D edge function of edge p → q (each (F, 2), vertex ids ip, iq (F,)) at points (N, 2).

    Evaluated from the lower vertex id to the higher and the sign fixed afterwards, so the two faces that
    share an edge compute bit-identical magnitudes: their verdicts on a point on the edge agree exactly.
    """
    swap = (ip > iq)[:, None]                                          # (F, 1)
    a, b = torch.where(swap, q, p), torch.where(swap, p, q)            # (F, 2) lower id first
    e = ((b[:, None, 0] - a[:, None, 0]) * (points[None, :, 1] - a[:, None, 1])
         - (b[:, None, 1] - a[:, None, 1]) * (points[None, :, 0] - a[:, None, 0]))  # (F, N)
    return torch.where(swap, -e, e)


def _includes_edge(p: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
    """(F, 1) True where a point exactly on the edge p → q (of a counter-clockwise triangle) counts as inside:
    edges heading down (dy < 0), or level and heading left. A shared edge is walked one way by each of two
    neighbours that lie on its two sides, so exactly one of them takes it (the top-left rule's idea)."""
    d = q - p                                                          # (F, 2)
    return ((d[:, 1] < 0) | ((d[:, 1] == 0) & (d[:, 0] < 0)))[:, None]


def _column_crossings(verts: torch.Tensor, faces: torch.Tensor, xy: torch.Tensor):
    """(hit (F, N) bool, z (F, N)) whether each face crosses the +z ray through each column point xy (N, 2),
    and the z of the crossing. Faces seen edge-on (zero area in xy) never count: their neighbours do."""
    tri = verts[faces]                                                 # (F, 3, 3)
    p2 = tri[..., :2]                                                  # (F, 3, 2) dropped z
    area = ((p2[:, 1, 0] - p2[:, 0, 0]) * (p2[:, 2, 1] - p2[:, 0, 1])
            - (p2[:, 1, 1] - p2[:, 0, 1]) * (p2[:, 2, 0] - p2[:, 0, 0]))  # (F,) twice the signed xy area
    ccw = area > 0
    order = torch.where(ccw[:, None], faces.new_tensor([0, 1, 2]), faces.new_tensor([0, 2, 1]))  # CCW in xy
    p2, ids, z = p2.gather(1, order[..., None].expand(-1, -1, 2)), faces.gather(1, order), tri[..., 2].gather(1, order)
    hit = (area != 0)[:, None]
    weights = []
    for k in range(3):                                                 # weight of vertex k: the opposite edge
        i, j = (k + 1) % 3, (k + 2) % 3
        e = _edge_values(p2[:, i], p2[:, j], ids[:, i], ids[:, j], xy)  # (F, N)
        hit = hit & ((e > 0) | ((e == 0) & _includes_edge(p2[:, i], p2[:, j])))
        weights.append(e)
    total = area.abs()[:, None].clamp(min=torch.finfo(verts.dtype).tiny)
    depth = sum(w * z[:, k, None] for k, w in enumerate(weights)) / total  # (F, N) z at the crossing
    return hit, depth


def voxelize(mesh, resolution: int = 32) -> torch.Tensor:
    """(R, R, R) bool occupancy of a closed mesh on the grid of voxel centres over [-1, 1]³, by ray parity.

    Entry [i, j, k] is the voxel centred at ``(x_i, y_j, z_k)``, ``x_i = -1 + (i + 0.5) 2 / R`` (the same for
    y and z). For each (x_i, y_j) column a ray runs along +z; a centre is inside when the number of faces the
    ray crosses below its z is odd. Computed in float64; a mesh that is not closed gives a meaningless result
    (check ``shapes.boundary_edges``). Cost: F × R² crossing tests, then each column's crossings sorted and
    the centres counted against them, in chunks.
    """
    R = _check_count(resolution, "resolution")
    if not isinstance(mesh, Mesh):
        raise ValueError(f"mesh must be a Mesh, got {type(mesh).__name__}")
    verts, faces = mesh.verts.detach().double(), mesh.faces
    centres = -1 + (torch.arange(R, dtype=torch.float64, device=verts.device) + 0.5) * (2 / R)  # (R,)
    xy = torch.stack(torch.meshgrid(centres, centres, indexing="ij"), -1).reshape(-1, 2)  # (R², 2) column i, j
    occupancy = torch.zeros(R * R, R, dtype=torch.bool, device=verts.device)
    chunk = max(1, 2 ** 17 // max(1, faces.shape[0]))                 # columns per chunk: ~128K crossing tests
    for start in range(0, R * R, chunk):
        hit, depth = _column_crossings(verts, faces, xy[start:start + chunk])  # (F, n) each
        crossings = torch.where(hit, depth, torch.inf).T.sort(1).values.contiguous()  # (n, F) ascending per column
        below = torch.searchsorted(crossings, centres.expand(crossings.shape[0], R).contiguous())  # (n, R) crossings
        occupancy[start:start + chunk] = below % 2 == 1                # below each centre: odd means inside
    return occupancy.reshape(R, R, R)


def voxelize_all(meshes, resolution: int = 32, *, progress: bool = False) -> torch.Tensor:
    """(N, R, R, R) bool ``voxelize`` of each of ``meshes``; progress: a tqdm bar (``TQDM_DISABLE=1`` hides it)."""
    from tqdm.auto import tqdm
    disable = (not progress) or os.environ.get("TQDM_DISABLE", "").lower() not in ("", "0", "false")
    grids = [voxelize(m, resolution) for m in tqdm(meshes, desc="voxelize", disable=disable, leave=False)]
    if not grids:
        raise ValueError("meshes is empty")
    return torch.stack(grids)


def voxel_iou(a, b) -> float:
    """|a ∩ b| / |a ∪ b| of two occupancy grids of one shape (any shape; bool or 0 / 1); 1.0 when both are empty."""
    a, b = torch.as_tensor(a).bool(), torch.as_tensor(b).bool()
    if a.shape != b.shape:
        raise ValueError(f"the grids must have the same shape, got {tuple(a.shape)} and {tuple(b.shape)}")
    union = int((a | b).sum())
    return 1.0 if union == 0 else int((a & b).sum()) / union


# ---- how varied the data is --------------------------------------------------------------------------------

def silhouette_iou_table(dataset: ShapeSet, view: int = 0) -> torch.Tensor:
    """(Nf, Nf) float64 the mean silhouette IoU of pairs of shapes, one of family a and one of family b, in
    ``view``; the diagonal averages distinct pairs within a family. High within and low across: the families
    are told apart by their outline; a within-family value near 1 would mean the family hardly varies."""
    view = _check_count(view, "view", minimum=0)
    if view >= dataset.silhouettes.shape[1]:
        raise ValueError(f"view must be below the number of views, {dataset.silhouettes.shape[1]}, got {view}")
    masks = dataset.silhouettes[:, view].reshape(len(dataset), -1).double()  # (N, H W) 0 / 1
    inter = masks @ masks.T                                            # (N, N) pixels in both
    area = masks.sum(1)
    union = area[:, None] + area[None, :] - inter
    pair_iou = torch.where(union > 0, inter / union.clamp(min=1), torch.ones_like(union))
    onehot = torch.nn.functional.one_hot(dataset.labels, len(dataset.families)).double()  # (N, Nf)
    sums = onehot.T @ pair_iou @ onehot                                # (Nf, Nf) summed over the pairs
    counts = onehot.sum(0)
    pairs = counts[:, None] * counts[None, :] - torch.diag(counts)     # distinct pairs (no shape with itself)
    sums = sums - torch.diag(onehot.T @ torch.diagonal(pair_iou))      # drop the self-pairs (IoU 1)
    return sums / pairs.clamp(min=1)


def aspect_ratios(dataset: ShapeSet) -> dict:
    """``{family: (N_f,) float64}`` each shape's bounding-box height over width (``shapes.aspect_ratio``)."""
    ratios = torch.tensor([aspect_ratio(m) for m in dataset.meshes], dtype=torch.float64)
    return {family: ratios[dataset.labels == label] for label, family in enumerate(dataset.families)}
