"""Losses and metrics for inverse rendering (lecture 10): silhouettes, mesh regularisers, images.

Shapes: V vertices, F faces, E edges, N views, H x W image, C channels.

**Silhouettes** (Kato, Ushiku and Harada, "Neural 3D Mesh Renderer", CVPR 2018). A soft silhouette ŝ
(H, W) holds coverage in [0, 1]. Kato et al. fit a mesh by maximising the soft intersection over union
with the target s; we minimise ``L_sl = 1 - |ŝ ⊙ s|₁ / |ŝ + s - ŝ ⊙ s|₁`` (their negative IoU plus 1, so
a perfect fit scores 0), summed over views. ``iou`` is the metric: the same ratio on binary masks.

**Mesh regularisers.** Silhouettes say nothing about the surface between views, and a mesh fitted to
them alone grows spikes and folds. Kato et al.'s smoothness loss penalises bent interior edges,
``L_sm = Σ (cos θᵢ + 1)²`` with θᵢ the dihedral angle (180° when flat); with unit face normals,
``cos θᵢ = -n₁·n₂``. The Laplacian loss pulls each vertex towards a weighted mean of its neighbours;
the edge-length loss keeps edges of similar length, so triangles do not collapse into slivers. Edges are
found from the connectivity (vertex indices), never by welding positions: a mesh with uv seams (the
teapot) has two copies of each seam vertex, and its seams count as boundaries here.

**Images.** L1 and L2 (mean absolute and mean squared error) as losses; PSNR as a metric. Colours are
linear RGB in [0, 1], so the peak signal is 1.

Every function validates its inputs and raises a ValueError naming the argument (wrong shape, shapes that
differ, NaN / inf). Results keep the dtype and device of the first input (float32 or float64).
"""
from __future__ import annotations

import torch

from ..mesh import Mesh, _safe_normalize
from ..tensors import _as_faces, _check_real, as_tensor

__all__ = ["silhouette_iou_loss", "iou", "interior_edges", "smoothness_loss", "laplacian_loss",
           "edge_length_loss", "l1_loss", "l2_loss", "psnr"]

_COT_MAX = 1e3  # sin α is clamped to >= 1 / _COT_MAX, so a cotangent weight never exceeds 1000 (α ≈ 0.06°)


# ---- silhouettes -----------------------------------------------------------------------------
def silhouette_iou_loss(pred, target, reduction: str = "sum") -> torch.Tensor:
    """Kato et al.'s silhouette loss ``1 - |ŝ ⊙ s|₁ / |ŝ + s - ŝ ⊙ s|₁``, per view, then summed over views.

    Args:
        pred: (H, W) or (N, H, W) soft silhouettes ŝ in [0, 1] (the rendered ones).
        target: the same shape, target silhouettes s in [0, 1].
        reduction: ``"sum"`` over views (Kato et al.), ``"mean"`` over views, or ``"none"`` for the (N,)
            per-view losses. An (H, W) input gives a scalar whatever the reduction.

    Both silhouettes empty (a union below the square root of the dtype's smallest normal number, 1e-19 in
    float32) is a perfect match: loss 0 by convention, with zero gradient, never 0 / 0. One empty and the
    other not: loss 1.
    """
    if reduction not in ("sum", "mean", "none"):
        raise ValueError(f'reduction must be "sum", "mean" or "none", got {reduction!r}')
    pred, target = _silhouettes(pred, target)
    intersection = (pred * target).sum(dim=(-2, -1))                   # (N,) or () |ŝ ⊙ s|₁
    union = (pred + target - pred * target).sum(dim=(-2, -1))          # (N,) or () |ŝ + s - ŝ ⊙ s|₁
    nonempty = union > torch.finfo(union.dtype).tiny ** 0.5            # 1 / union² stays finite in backward
    ratio = intersection / torch.where(nonempty, union, torch.ones_like(union))
    loss = torch.where(nonempty, 1 - ratio, torch.zeros_like(ratio))  # (N,) or ()
    if reduction == "none":
        return loss
    return loss.sum() if reduction == "sum" else loss.mean()


def iou(pred, target, threshold: float = 0.5) -> torch.Tensor:
    """Intersection over union of the binary masks ``pred > threshold`` and ``target > threshold``.

    Args:
        pred: (H, W) or (N, H, W) silhouettes in [0, 1]: soft coverage, 0 / 1 values or bools.
        target: the same shape.
        threshold: a pixel is inside when its value is strictly above it (0.5: more than half covered).

    Returns a scalar for (H, W) inputs and (N,) per-view values for (N, H, W); 1.0 where both masks are
    empty (nothing to miss). A metric, not a loss: thresholding has no useful gradient.
    """
    threshold = _check_real(threshold, "threshold", low=0, high=1)
    pred, target = _silhouettes(pred, target)
    inside_pred, inside_target = pred > threshold, target > threshold
    intersection = (inside_pred & inside_target).sum(dim=(-2, -1)).to(pred.dtype)  # (N,) or ()
    union = (inside_pred | inside_target).sum(dim=(-2, -1)).to(pred.dtype)          # (N,) or ()
    return torch.where(union > 0, intersection / union.clamp(min=1), torch.ones_like(union))


def _silhouettes(pred, target):
    """(pred, target) as tensors in pred's dtype, after checking their shapes, agreement, values and range."""
    pred = as_tensor(pred, name="pred")
    target = as_tensor(target, dtype=pred.dtype, device=pred.device, name="target")
    for x, name in ((pred, "pred"), (target, "target")):
        if x.ndim not in (2, 3) or x.numel() == 0:
            raise ValueError(f"{name} must be an (H, W) silhouette or (N, H, W) views, not empty, got shape "
                             f"{tuple(x.shape)}")
        _check_finite(x, name)
        if x.numel() and (x.min() < 0 or x.max() > 1):
            raise ValueError(f"{name} must hold coverage in [0, 1], got values in "
                             f"[{float(x.min()):g}, {float(x.max()):g}]")
    if pred.shape != target.shape:
        raise ValueError(f"pred and target must have the same shape, got {tuple(pred.shape)} and {tuple(target.shape)}")
    return pred, target


# ---- mesh regularisers -----------------------------------------------------------------------
def interior_edges(faces) -> tuple[torch.Tensor, torch.Tensor]:
    """The edges shared by exactly two faces, found by vertex index (positions are never compared).

    Args:
        faces: (F, 3) integer vertex indices.

    Returns ``(edges, face_pairs)``: (E, 2) the two vertex indices of each edge, smaller first, and
    (E, 2) the two faces that share it. Boundary edges (one face) and non-manifold edges (three or more)
    are left out.
    """
    faces = _check_faces(faces)
    ends = _face_edges(faces).reshape(-1, 2).sort(dim=1).values               # (3F, 2) one row per face side
    _, edge_id, count = torch.unique(ends, dim=0, return_inverse=True, return_counts=True)
    shared = count[edge_id] == 2                                              # (3F,) sides of interior edges
    order = torch.argsort(edge_id[shared], stable=True)                       # the two sides of an edge adjacent
    face_of_side = torch.arange(faces.shape[0], device=faces.device).repeat_interleave(3)  # (3F,)
    return ends[shared][order][::2], face_of_side[shared][order].view(-1, 2)


def smoothness_loss(verts, faces=None) -> torch.Tensor:
    """Kato et al.'s smoothness loss ``Σᵢ (cos θᵢ + 1)² = Σᵢ (1 - n₁·n₂)²`` over the interior edges.

    θᵢ is the dihedral angle at edge i (180° on a flat surface) and n₁, n₂ are the unit normals of its two
    faces, so each term is 0 where the surface is flat and 4 where it folds back onto itself. The two faces
    must wind the same way (every mesh here does); see ``interior_edges`` for which edges count.

    Args:
        verts: (V, 3) vertex positions, or a ``Mesh`` (then leave ``faces`` out).
        faces: (F, 3) integer vertex indices.

    A zero-area face has a zero normal (``Mesh.face_normals``), so each of its edges adds exactly 1, with a
    finite (zero) gradient through that normal. A mesh without interior edges scores 0.
    """
    mesh = _as_mesh(verts, faces)
    normals = mesh.face_normals()                                             # (F, 3) unit, or 0 if degenerate
    _, pairs = interior_edges(mesh.faces)                                     # (E, 2) face indices
    cos_normals = (normals[pairs[:, 0]] * normals[pairs[:, 1]]).sum(dim=-1)   # (E,) n₁·n₂ = -cos θ
    return ((1 - cos_normals) ** 2).sum()


def laplacian_loss(verts, faces=None, weights: str = "uniform") -> torch.Tensor:
    """Mean over vertices of ``|δᵢ|²``, with ``δᵢ = Σⱼ wᵢⱼ (vⱼ - vᵢ) / Σⱼ wᵢⱼ`` over the neighbours j of i.

    δᵢ points from vertex i to a weighted mean of its neighbours, and pulling it to zero smooths the
    surface. At an interior vertex of a flat patch δ is zero with cotangent weights whenever no angle is
    obtuse, with uniform weights only on a regular grid; boundary vertices are always pulled inwards.
    Normalising by Σ wᵢⱼ keeps δ a length for both weightings (PyTorch3D's ``"cot"``), rather than Meyer
    et al.'s division by the vertex's Voronoi area.

    Args:
        verts: (V, 3) vertex positions, or a ``Mesh`` (then leave ``faces`` out).
        faces: (F, 3) integer vertex indices.
        weights: ``"uniform"``: wᵢⱼ = 1 per edge, so δᵢ = mean of the neighbours - vᵢ. ``"cotangent"``:
            wᵢⱼ = (cot αᵢⱼ + cot βᵢⱼ) / 2 with α, β the angles opposite edge ij in its two faces (one on a
            boundary), the weights of Pinkall and Polthier 1993 and Meyer et al. 2003.

    Guards for the cotangent weights, so every value and gradient stays finite: an obtuse angle would give
    a negative weight (and Σ wᵢⱼ near 0 could blow δ up), so its cotangent is clamped to 0; a degenerate
    (zero-area) triangle would give cot = ±inf, so sin α is clamped to at least 1e-3 (cot at most 1000, an
    angle of 0.06°, with zero gradient past the clamp); two corners at one point give cot = 0. A vertex
    whose weights are all 0 (or that no face uses) gets δ = 0 and still counts in the mean.
    """
    if weights not in ("uniform", "cotangent"):
        raise ValueError(f'weights must be "uniform" or "cotangent", got {weights!r}')
    mesh = _as_mesh(verts, faces)
    v = mesh.verts
    if weights == "uniform":
        ends = _unique_edges(mesh.faces)                                      # (E, 2)
        w = v.new_ones(ends.shape[0])                                         # (E,)
    else:
        ends = _face_edges(mesh.faces).reshape(-1, 2)                         # (3F, 2) side opposite each corner
        corner = v[mesh.faces.reshape(-1)]                                    # (3F, 3)
        a = _safe_normalize(v[ends[:, 0]] - corner)                          # (3F, 3) unit sides of the angle,
        b = _safe_normalize(v[ends[:, 1]] - corner)                          # zero if two corners coincide
        sin = torch.linalg.cross(a, b, dim=-1).pow(2).sum(-1).clamp(min=_COT_MAX ** -2).sqrt()  # (3F,) >= 1e-3
        w = 0.5 * ((a * b).sum(-1) / sin).clamp(min=0)                       # (3F,) cot α / 2 = cos α / (2 sin α)
    i = torch.cat([ends[:, 0], ends[:, 1]])                                   # each edge seen from both ends
    j = torch.cat([ends[:, 1], ends[:, 0]])
    w = torch.cat([w, w])
    total = v.new_zeros(v.shape[0]).index_add(0, i, w)                        # (V,) Σⱼ wᵢⱼ
    pull = torch.zeros_like(v).index_add(0, i, w[:, None] * (v[j] - v[i]))    # (V, 3) Σⱼ wᵢⱼ (vⱼ - vᵢ)
    delta = pull / total.clamp(min=torch.finfo(v.dtype).eps)[:, None]         # (V, 3)
    return delta.pow(2).sum(-1).mean()


def edge_length_loss(verts, faces=None, target_length=None) -> torch.Tensor:
    """Mean squared deviation of the edge lengths ℓₑ from their mean (or from ``target_length``).

    ``mean((ℓₑ - mean ℓ)²)``, the variance of the lengths, is zero when all edges are equally long at
    any size, so it keeps triangles even without shrinking the mesh. With ``target_length`` it is
    ``mean((ℓₑ - target_length)²)``. Every edge counts once, however many faces share it.

    Args:
        verts: (V, 3) vertex positions, or a ``Mesh`` (then leave ``faces`` out).
        faces: (F, 3) integer vertex indices.
        target_length: a float, or None for the mean length.

    A zero-length edge (two vertices at one point) has a finite, zero gradient.
    """
    mesh = _as_mesh(verts, faces)
    ends = _unique_edges(mesh.faces)                                          # (E, 2)
    d = mesh.verts[ends[:, 1]] - mesh.verts[ends[:, 0]]                       # (E, 3)
    length = d.pow(2).sum(-1).clamp(min=torch.finfo(d.dtype).tiny).sqrt()     # (E,) sqrt'(0) would be inf
    target = length.mean() if target_length is None else _check_real(target_length, "target_length", low=0)
    return (length - target).pow(2).mean()


def _face_edges(faces: torch.Tensor) -> torch.Tensor:
    """(F, 3, 2): side k of a face joins corners k+1 and k+2, so it lies opposite corner k."""
    return torch.stack([faces[:, [1, 2, 0]], faces[:, [2, 0, 1]]], dim=-1)


def _unique_edges(faces: torch.Tensor) -> torch.Tensor:
    """(E, 2) every edge once, smaller vertex index first."""
    return torch.unique(_face_edges(faces).reshape(-1, 2).sort(dim=1).values, dim=0)


def _as_mesh(verts, faces) -> Mesh:
    """A Mesh from a Mesh or from (verts, faces); Mesh validates shapes, indices and NaN."""
    if isinstance(verts, Mesh):
        if faces is not None:
            raise ValueError("pass either a Mesh or verts and faces, not a Mesh and faces")
        return verts
    if faces is None:
        raise ValueError("faces is missing: pass a Mesh, or verts (V, 3) and faces (F, 3)")
    return Mesh(verts, faces)


def _check_faces(faces) -> torch.Tensor:
    """(F, 3) int64: integer indices only (a float index is refused, never rounded), none negative."""
    try:
        return _as_faces(faces, "faces")
    except (TypeError, ValueError) as err:
        raise ValueError(f"faces must be (F, 3) integer vertex indices: {err}") from None


# ---- images ----------------------------------------------------------------------------------
def l1_loss(pred, target) -> torch.Tensor:
    """Mean absolute difference ``mean |pred - target|``. pred: (...) any shape, e.g. (H, W, C); target: the same."""
    pred, target = _images(pred, target)
    return (pred - target).abs().mean()


def l2_loss(pred, target) -> torch.Tensor:
    """Mean squared difference ``mean (pred - target)²``. pred: (...) any shape, e.g. (H, W, C); target: the same."""
    pred, target = _images(pred, target)
    return (pred - target).pow(2).mean()


def psnr(pred, target, mask=None) -> torch.Tensor:
    """Peak signal-to-noise ratio ``10 log₁₀(1 / MSE)`` in dB, for colours in [0, 1] (peak 1).

    Args:
        pred: (H, W, C) or (N, H, W, C) image(s).
        target: the same shape.
        mask: (H, W) or (N, H, W) (pred's shape without C), bool or 0 / 1: the pixels to compare, usually
            where the target or the result shows the object (``target_mask | pred_mask``), so a large
            empty background does not inflate the score. None: every pixel.

    The MSE averages over the selected pixels and all their channels. Identical images give +inf.
    Raises a ValueError when the mask selects no pixel.
    """
    pred, target = _images(pred, target)
    if pred.ndim not in (3, 4):
        raise ValueError(f"pred must be an (H, W, C) image or (N, H, W, C) images, got shape {tuple(pred.shape)}")
    squared = (pred - target).pow(2)                                          # (N, H, W, C) or (H, W, C)
    if mask is not None:
        try:
            mask = torch.as_tensor(mask, device=pred.device)
        except (TypeError, ValueError, RuntimeError):
            raise TypeError(f"mask must be a bool or 0 / 1 array, got {type(mask).__name__}") from None
        if mask.shape != pred.shape[:-1]:
            raise ValueError(f"mask must have the image's shape without channels, {tuple(pred.shape[:-1])}, "
                             f"got {tuple(mask.shape)}")
        _check_finite(mask, "mask")
        if mask.dtype != torch.bool and not bool(((mask == 0) | (mask == 1)).all()):
            raise ValueError("mask must hold 0 / 1 (or bools): the pixels to compare, not weights")
        if not (mask != 0).any():
            raise ValueError("mask selects no pixel: PSNR over nothing is undefined")
        squared = squared[mask != 0]                                          # (P, C) the selected pixels
    return -10 * torch.log10(squared.mean())                                  # 10 log₁₀(1 / MSE)


def _images(pred, target):
    pred = as_tensor(pred, name="pred")
    target = as_tensor(target, dtype=pred.dtype, device=pred.device, name="target")
    if pred.shape != target.shape:
        raise ValueError(f"pred and target must have the same shape, got {tuple(pred.shape)} and {tuple(target.shape)}")
    if pred.numel() == 0:
        raise ValueError(f"pred and target are empty, shape {tuple(pred.shape)}")
    _check_finite(pred, "pred")
    _check_finite(target, "target")
    return pred, target


def _check_finite(x: torch.Tensor, name: str) -> None:
    if x.is_complex():
        raise TypeError(f"{name} must hold real numbers, got dtype {x.dtype}")
    if not torch.isfinite(x.detach()).all():
        raise ValueError(f"{name} contains NaN or inf")
