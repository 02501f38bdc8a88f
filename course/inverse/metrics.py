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
* ``f_score(pred, target, threshold=0.02)``: Tatarchenko et al.'s F-score (CVPR 2019, "What do single-view 3D
  reconstruction networks learn?"): precision, the fraction of the prediction's samples within ``threshold`` of
  the target's, recall the reverse, and their harmonic mean. The threshold is in world units: 0.02 is their 1 %
  of the side of the reconstructed volume, here the cube [-1, 1]³; distances to the other *surface*
  (``surface_distance``, exact point-to-triangle), not to its samples. Unlike the mean distance of Chamfer it cannot
  be dominated by a few far-off parts, and unlike IoU it does not reward volume in place of surface.
* ``shape_metrics(pred, target)``: Chamfer and normal consistency, and the number of pairs of faces of ``pred`` that pass through each
  other (``fit.self_intersections``).

Samples are seeded (``seed``, the same for both surfaces), 20,000 a side by default, in float64. The nearest
sample is searched on a grid of cells (``_nearest``), with the same answer as comparing every pair
(``_nearest_brute``), the first of equally near samples included.
"""
from __future__ import annotations

import math

import torch

from ..tensors import _check_count, _check_real

__all__ = ["sample_surface", "chamfer_distance", "normal_consistency", "f_score", "surface_distance", "surface_scores",
           "shape_metrics"]

BLOCK = 1024             # rows of the distance matrix at a time (BLOCK × n float64 values)
PAIRS = 1 << 21          # candidate pairs of the grid search at a time (about 100 MB of working memory)


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


def _squared(x, y):
    """(N, M) squared distances between the rows of x (N, 3) and y (M, 3), one formula for every search here."""
    d = x[:, None, :] - y[None, :, :]
    return d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2]


def _nearest_brute(x, y):
    """For each row of x (N, 3) the index of the nearest row of y (M, 3) (the first of equals) and the squared
    distance (``_squared``'s formula), over every pair, in blocks of rows. The distances are first taken fast as
    |x|² + |y|² - 2 x·y (a matrix product), whose rounding error is below a slack of 64 ε (|x|² + |y|²); only
    the pairs within twice that slack of a row's smallest are computed again exactly, so the answer is exact."""
    xx, yy = (x * x).sum(1), (y * y).sum(1)
    reach = 128 * torch.finfo(torch.float64).eps * (xx + yy.max())          # (N,) twice the slack, per row
    index, dist = [], []
    for lo in range(0, x.shape[0], BLOCK):
        xb = x[lo:lo + BLOCK]
        fast = (xb @ y.T).mul_(-2.0).add_(yy).add_(xx[lo:lo + BLOCK, None])  # (B, M) close to the squares
        near = fast <= (fast.min(dim=1).values + reach[lo:lo + BLOCK])[:, None]
        row, col = torch.nonzero(near, as_tuple=True)                      # the few pairs that may be nearest
        d = xb[row] - y[col]
        exact = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
        best = torch.full((xb.shape[0],), torch.inf, dtype=torch.float64).scatter_reduce(0, row, exact, "amin")
        first = torch.full((xb.shape[0],), y.shape[0], dtype=torch.int64).scatter_reduce(
            0, row, torch.where(exact == best[row], col, y.shape[0]), "amin")
        index.append(first)
        dist.append(best)
    return torch.cat(index), torch.cat(dist)


def _nearest_on_grid(x, y, cell):
    """``_nearest_brute`` among the points of y in the cell (cubes of side ``cell``) of each x and the 26 around
    it; a row whose best is farther than ``cell`` (or that found none) may have a nearer y elsewhere: +inf.

    The candidates are listed pair by pair (x, a y of a neighbouring cell), never padded to the fullest cell's
    count, and taken in blocks of about ``PAIRS`` pairs, so memory stays bounded however unevenly y is spread."""
    n, m = x.shape[0], y.shape[0]
    lo = torch.minimum(x.min(0).values, y.min(0).values)
    dims = ((torch.maximum(x.max(0).values, y.max(0).values) - lo) / cell).floor().long() + 1

    def cell_of(points):
        return ((points - lo) / cell).floor().long().minimum(dims - 1).clamp(min=0)

    def key(ijk):
        return (ijk[..., 0] * dims[1] + ijk[..., 1]) * dims[2] + ijk[..., 2]

    y_keys = key(cell_of(y))
    order = y_keys.argsort(stable=True)                                     # y by cell, then by index
    keys = y_keys[order]
    offsets = torch.stack(torch.meshgrid(*[torch.arange(-1, 2)] * 3, indexing="ij"), -1).reshape(27, 3)
    around = cell_of(x)[:, None, :] + offsets                               # (N, 27, 3) neighbouring cells
    inside = ((around >= 0) & (around < dims)).all(-1)
    k = key(around.clamp(min=0).minimum(dims - 1))
    first = torch.searchsorted(keys, k)                                     # (N, 27) where each cell's run starts
    count = torch.where(inside, torch.searchsorted(keys, k, right=True) - first, 0)   # and its length
    per_row = count.sum(1)                                                  # (N,) candidates of each x
    index, dist = torch.full((n,), m, dtype=torch.int64), torch.full((n,), torch.inf, dtype=torch.float64)
    ends = torch.cumsum(per_row, 0)
    start = 0
    while start < n:
        stop = max(start + 1, int(torch.searchsorted(ends, ends[start] - per_row[start] + PAIRS, right=True)))
        c, f = count[start:stop].reshape(-1), first[start:stop].reshape(-1)
        run_start = torch.cumsum(c, 0) - c                                  # each run's place in the list
        pos = torch.arange(int(c.sum())) - run_start.repeat_interleave(c) + f.repeat_interleave(c)
        candidate = order[pos]                                              # the y of each pair
        row = torch.arange(stop - start).repeat_interleave(27).repeat_interleave(c)   # and its x, in the block
        d = x[start:stop][row] - y[candidate]
        d = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]      # _squared's formula
        best = torch.full((stop - start,), torch.inf, dtype=torch.float64).scatter_reduce(0, row, d, "amin")
        index[start:stop] = torch.full((stop - start,), m, dtype=torch.int64).scatter_reduce(
            0, row, torch.where(d == best[row], candidate, m), "amin")     # the first of equals
        dist[start:stop] = torch.where(best <= cell * cell, best, torch.inf)
        start = stop
    return index, dist


def _nearest(x, y):
    """For each row of x (N, 3) the index of the nearest row of y (M, 3) (the first of equals) and the distance,
    exactly as ``_nearest_brute`` finds them, searched on grids first.

    y's points are binned into cubic cells about two sample spacings wide; each x looks only at the points in its
    own cell and the 26 around it. Every y closer to x than one cell lies there, so when the best of them is
    closer than a cell it is the nearest of all (``_nearest_on_grid``). The x left over (far from the other
    surface) look again on cells twice and four times as wide, and those still left over against every y. On two fits of
    one surface, 20,000 samples a side, that is a small fraction of the 20,000² distances of the brute force."""
    index, dist = torch.empty(x.shape[0], dtype=torch.int64), torch.full((x.shape[0],), torch.inf,
                                                                             dtype=torch.float64)
    left = torch.arange(x.shape[0])
    spread = float((torch.maximum(x.max(0).values, y.max(0).values)
                    - torch.minimum(x.min(0).values, y.min(0).values)).norm())
    for cell in (spread * scale / math.sqrt(y.shape[0]) for scale in (2.0, 4.0, 8.0)):
        if not left.numel() or cell <= 0:
            break
        found, d = _nearest_on_grid(x[left], y, cell)
        done = torch.isfinite(d)
        index[left[done]], dist[left[done]] = found[done], d[done]
        left = left[~done]
    if left.numel():
        index[left], dist[left] = _nearest_brute(x[left], y)
    return index, dist.sqrt()


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


def f_score(pred, target, *, threshold: float = 0.02, samples: int = 20000, seed: int = 0) -> float:
    """The F-score at ``threshold`` (world units) of two surfaces: ``2 P R / (P + R)``, P the fraction of
    ``samples`` seeded points on the prediction within ``threshold`` of the target's surface, R the fraction of
    points on the target within it of the prediction's; 0 when both are 0. Distances are to the surface itself
    (``surface_distance``), not to the other side's samples, so a threshold finer than the samples' spacing
    still measures the surfaces."""
    return surface_scores(pred, target, threshold=threshold, samples=samples, seed=seed)["fscore"]


def surface_scores(pred, target, *, threshold: float = 0.02, samples: int = 20000, seed: int = 0) -> dict:
    """``{"fscore", "chamfer"}`` from one set of samples and their exact distances to the other surface: the
    F-score at ``threshold`` (``f_score``) and a point-to-surface Chamfer distance, the mean distance of each
    side's samples to the other *surface*, the two means averaged and divided by the target's bounding-box
    diagonal (``chamfer_distance`` measures to the other side's samples instead, which adds about their
    spacing)."""
    threshold = _check_real(threshold, "threshold", low=0, low_open=True)
    p, _ = sample_surface(pred, samples, torch.Generator().manual_seed(int(seed)))
    t, _ = sample_surface(target, samples, torch.Generator().manual_seed(int(seed)))
    to_target = surface_distance(p, target, on_surface=t)
    to_pred = surface_distance(t, pred, on_surface=p)
    precision = float((to_target <= threshold).double().mean())
    recall = float((to_pred <= threshold).double().mean())
    verts, _ = _mesh_arrays(target, "target")
    diagonal = float((verts.max(0).values - verts.min(0).values).norm())
    return {"fscore": 0.0 if precision + recall == 0 else 2 * precision * recall / (precision + recall),
            "chamfer": float((to_target.mean() + to_pred.mean()) / 2) / diagonal}


def surface_distance(points, mesh, on_surface=None) -> torch.Tensor:
    """(N,) float64 the distance from each of ``points`` (N, 3) to the nearest point of ``mesh``'s triangles.

    Exact: each point's distance to its nearest vertex (or to the nearest of ``on_surface``, (M, 3) points known
    to lie on the mesh, such as its samples: a tighter bound on a coarse mesh) bounds the answer from above, so only triangles whose
    bounding sphere reaches within that bound can hold a nearer point; for those pairs the triangle's closest
    point is found (Ericson, Real-Time Collision Detection, 5.1.5: the vertex, edge or face region the point projects
    into), and the least distance kept. The triangles are culled by spheres around them (centroid and farthest
    corner): one ``cdist`` per block of about ``PAIRS`` (point, triangle) pairs."""
    verts, faces = _mesh_arrays(mesh, "mesh")
    x = torch.as_tensor(points, dtype=torch.float64)
    if x.ndim != 2 or x.shape[-1] != 3:
        raise ValueError(f"points must be (N, 3), got shape {tuple(x.shape)}")
    tri = verts[faces]                                                  # (F, 3, 3)
    centre = tri.mean(1)                                                # (F, 3) a sphere around each triangle
    radius = (tri - centre[:, None]).norm(dim=-1).max(1).values         # (F,)
    corners = verts[faces.unique()]                                     # the vertices of some triangle
    if on_surface is not None:
        corners = torch.cat([corners, torch.as_tensor(on_surface, dtype=torch.float64).reshape(-1, 3)])
    slack = 1e-9 * (1 + float(x.abs().max()) + float(corners.abs().max()))   # cdist's rounding, generously
    out = torch.empty(x.shape[0], dtype=torch.float64)
    rows = max(1, PAIRS // max(faces.shape[0], corners.shape[0]))
    for start in range(0, x.shape[0], rows):
        p = x[start:start + rows]                                       # (n, 3)
        bound = torch.cdist(p, corners).min(1).values                   # (n,) to the nearest corner
        reach = torch.cdist(p, centre) - radius                         # (n, F) no nearer than this
        i, f = torch.nonzero(reach <= bound[:, None] + slack, as_tuple=True)
        near = _closest_on_triangles(p[i], tri[f, 0], tri[f, 1], tri[f, 2])
        d = (p[i] - near).norm(dim=-1)
        out[start:start + rows] = bound.scatter_reduce(0, i, d, reduce="amin")
    return out


def _closest_on_triangles(p, a, b, c):
    """(K, 3) the point of triangle (a, b, c) nearest to p, each (K, 3), for K pairs, by Ericson's regions (the
    last of the list that holds wins); a degenerate triangle falls to its vertices and edges."""
    dot = lambda u, v: (u * v).sum(-1)                                  # noqa: E731
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = dot(ab, ap), dot(ac, ap)
    bp, cp = p - b, p - c
    d3, d4, d5, d6 = dot(ab, bp), dot(ac, bp), dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    safe = lambda den: torch.where(den == 0, torch.ones_like(den), den)  # noqa: E731
    denom = safe(va + vb + vc)
    result = a + ab * (vb / denom)[..., None] + ac * (vc / denom)[..., None]       # inside the face
    t_bc = (d4 - d3) / safe((d4 - d3) + (d5 - d6))
    regions = [                                                          # the last that holds wins: reverse order
        ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), b + (c - b) * t_bc[..., None]),       # edge bc
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + ac * (d2 / safe(d2 - d6))[..., None]),       # edge ac
        ((d6 >= 0) & (d5 <= d6), c.expand_as(result)),                                     # vertex c
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + ab * (d1 / safe(d1 - d3))[..., None]),       # edge ab
        ((d3 >= 0) & (d4 <= d3), b.expand_as(result)),                                     # vertex b
        ((d1 <= 0) & (d2 <= 0), a.expand_as(result)),                                      # vertex a
    ]
    for mask, point in regions:
        result = torch.where(mask[..., None], point, result)
    return result


def shape_metrics(pred, target, *, samples: int = 20000, seed: int = 0) -> dict:
    """``chamfer`` (fraction of the target's diagonal), ``normal_consistency`` and ``self_intersections`` (pairs
    of faces of ``pred`` that cross each other), from one set of samples."""
    from .common import self_intersections
    chamfer, normals = _metrics(pred, target, samples, seed)
    return dict(chamfer=chamfer, normal_consistency=normals,
                self_intersections=int(self_intersections(pred).shape[0]))
