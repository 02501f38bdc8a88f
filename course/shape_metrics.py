"""How close a fitted mesh is to its target in 3D, not only in its silhouettes (lecture 10).

A silhouette's IoU rewards the visual hull: a crumpled surface inside the right outline scores as well as a
smooth one. These metrics look at the surfaces themselves, through points sampled on them:

* ``sample_surface(mesh, n, generator)``: n points uniform on the surface (a face chosen with probability
  proportional to its area, a point uniform in it), with the face's unit normal at each.
* ``chamfer_distance(pred, target)``: for every sample of one surface the distance to the nearest sample of the
  other, averaged, in both directions, the two means averaged, and divided by the target's bounding-box
  diagonal (so 0.005 reads "half a percent of the object's size").
* ``normal_consistency(pred, target)``: at those nearest pairs, ``|n · n'|`` averaged the same way: 1 when the
  surfaces face the same way everywhere, lower where one is crumpled (the absolute value: a face wound the
  other way is not a different surface).
* ``shape_metrics(pred, target)``: both, and the number of pairs of faces of ``pred`` that pass through each
  other (``fit.self_intersections``).

Samples are seeded (``seed``, the same for both surfaces), 20,000 a side by default, in float64. The nearest
sample is found by brute force in blocks of rows (``torch.cdist``): 20,000² distances, a second or two.
"""
from __future__ import annotations

import torch

from .tensors import _check_count

__all__ = ["sample_surface", "chamfer_distance", "normal_consistency", "shape_metrics"]

BLOCK = 1024             # rows of the distance matrix at a time (BLOCK × n float64 values)


def _mesh_arrays(mesh, name):
    verts = torch.as_tensor(mesh.verts).detach().double()
    faces = torch.as_tensor(mesh.faces).long()
    if verts.dim() != 2 or verts.shape[-1] != 3 or not torch.isfinite(verts).all():
        raise ValueError(f"{name}.verts must be finite (V, 3), got shape {tuple(verts.shape)}")
    if faces.dim() != 2 or faces.shape[-1] != 3 or faces.numel() == 0:
        raise ValueError(f"{name}.faces must be a non-empty (F, 3) array, got shape {tuple(faces.shape)}")
    if int(faces.min()) < 0 or int(faces.max()) >= verts.shape[0]:
        raise ValueError(f"{name}.faces holds indices outside [0, {verts.shape[0]})")
    return verts, faces


def sample_surface(mesh, n: int = 20000, generator: torch.Generator | None = None):
    """(n, 3) points uniform on the surface and (n, 3) unit normals of their faces, float64. A face is chosen
    with probability proportional to its area, then a point uniform in it (barycentrics from two uniforms by the
    square-root rule). Raises ValueError for a mesh whose faces all have zero area."""
    n = _check_count(n, "n")
    verts, faces = _mesh_arrays(mesh, "mesh")
    a, b, c = (verts[faces[:, k]] for k in range(3))
    cross = torch.linalg.cross(b - a, c - a, dim=-1)
    area = cross.norm(dim=1)
    if float(area.sum()) <= 0:
        raise ValueError("mesh has no area to sample: every face is degenerate")
    g = generator if generator is not None else torch.Generator().manual_seed(0)
    face = torch.multinomial(area / area.sum(), n, replacement=True, generator=g)
    u = torch.rand(n, 2, dtype=torch.float64, generator=g)
    r = u[:, 0].sqrt()
    w0, w1, w2 = 1 - r, r * (1 - u[:, 1]), r * u[:, 1]
    points = w0[:, None] * a[face] + w1[:, None] * b[face] + w2[:, None] * c[face]
    return points, cross[face] / area[face, None]


def _nearest(x, y):
    """For each row of x (N, 3) the index of the nearest row of y (M, 3), and the distance."""
    index, dist = [], []
    for lo in range(0, x.shape[0], BLOCK):
        d = torch.cdist(x[lo:lo + BLOCK], y)
        best = d.min(dim=1)
        index.append(best.indices)
        dist.append(best.values)
    return torch.cat(index), torch.cat(dist)


def _metrics(pred, target, samples, seed):
    """Chamfer (fraction of the target's diagonal) and normal consistency from one set of samples."""
    p, pn = sample_surface(pred, samples, torch.Generator().manual_seed(int(seed)))
    t, tn = sample_surface(target, samples, torch.Generator().manual_seed(int(seed)))
    i, d_pt = _nearest(p, t)
    j, d_tp = _nearest(t, p)
    verts, _ = _mesh_arrays(target, "target")
    diagonal = float((verts.max(0).values - verts.min(0).values).norm())
    chamfer = float((d_pt.mean() + d_tp.mean()) / 2) / diagonal
    normals = float(((pn * tn[i]).sum(1).abs().mean() + (tn * pn[j]).sum(1).abs().mean()) / 2)
    return chamfer, normals


def chamfer_distance(pred, target, *, samples: int = 20000, seed: int = 0) -> float:
    """Symmetric Chamfer distance between surface samples, as a fraction of the target's bounding-box
    diagonal: ``(mean_p min_t |p - t| + mean_t min_p |t - p|) / 2 / diagonal`` (distances, not squared)."""
    return _metrics(pred, target, samples, seed)[0]


def normal_consistency(pred, target, *, samples: int = 20000, seed: int = 0) -> float:
    """``|n · n'|`` between every sample's face normal and its nearest sample's on the other surface, averaged
    in both directions: 1 for surfaces that face alike everywhere."""
    return _metrics(pred, target, samples, seed)[1]


def shape_metrics(pred, target, *, samples: int = 20000, seed: int = 0) -> dict:
    """``chamfer`` (fraction of the target's diagonal), ``normal_consistency`` and ``self_intersections`` (pairs
    of faces of ``pred`` that cross each other), from one set of samples."""
    from .fit import self_intersections
    chamfer, normals = _metrics(pred, target, samples, seed)
    return dict(chamfer=chamfer, normal_consistency=normals,
                self_intersections=int(self_intersections(pred).shape[0]))
