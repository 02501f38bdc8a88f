"""A first shape from silhouettes: the visual hull, carved in a voxel grid and meshed by surface nets (lecture 10).

A mesh fit that starts from a sphere has to grow every part of the object out of it; a teapot's handle is a loop,
and a sphere can only grow two horns toward each other, never close the loop (a surface cannot change its genus
by moving its vertices). Carving starts from what the silhouettes already say, in one pass and with no gradient:

* ``hull_field(masks, cameras, resolution, radius)``: a grid of ``resolution``³ points over the cube
  ``[-radius, radius]³``; at each point, the smallest value over the views of the mask at the point's projection
  (bilinear between pixel centres; 0 outside the image or behind the camera). A point lies inside the visual hull
  where every view sees it inside the silhouette: where the field is above ``level`` (0.5). This is Laurentini's
  visual hull (1994), the largest shape with these silhouettes: it keeps every concavity no view can see into
  (the hollow above a teapot's lid), but the hole of the handle is seen through from the side, so it is carved.
* ``surface_nets(field, radius, level)``: the level surface of a grid as a closed triangle mesh (Gibson's surface
  nets, 1998): one vertex in every cell whose corners lie on both sides of the level, placed at the mean of the
  points where the cell's edges cross it (linear interpolation of the field along each edge); and for every grid
  edge that crosses the level, a quad joining the four cells around it, split into two triangles, wound
  counter-clockwise seen from outside (the side where the field is below the level). Simpler than marching
  cubes (no case table) and its vertices are better spread. The grid is padded with "outside", so the surface
  closes. Where two pieces of the solid touch along one edge of the grid only (a square of the grid inside on one
  diagonal, outside on the other), four faces would share a mesh edge; such squares are joined first (the outside
  corners moved just inside), so every edge of the mesh has exactly two faces.
* ``relax(mesh)``: two iterations of Taubin's smoothing, which lifts the nearly flat triangles surface nets leave.
* ``carve(masks, cameras, resolution, radius)``: all three: the visual hull as a Mesh.

``radius`` defaults to the largest sphere about the origin that every camera sees whole (its distance to the
origin times the sine of its narrower half field of view), where a fit's views are aimed. The cost is
``resolution``³ projections per view: 48³ points and 12 views, a tenth of a second.
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from ..camera import Camera
from ..mesh import Mesh
from ..tensors import _check_count, _check_real

__all__ = ["hull_field", "surface_nets", "relax", "carve", "view_radius"]


def view_radius(cameras) -> float:
    """The radius of the largest sphere about the origin that every (perspective) camera sees whole."""
    radius = math.inf
    for cam in cameras:
        fx, fy = float(cam.K[0, 0]), float(cam.K[1, 1])
        half = min(math.atan(cam.width / 2 / fx), math.atan(cam.height / 2 / fy))
        radius = min(radius, float(cam.eye.detach().double().norm()) * math.sin(half))
    return radius


def _check_masks(masks, cameras):
    if not isinstance(cameras, (list, tuple)) or len(cameras) == 0 or not all(isinstance(c, Camera) for c in cameras):
        raise ValueError("cameras must be a non-empty list of Camera")
    if any(c.orthographic for c in cameras):
        raise ValueError("carving needs perspective cameras")
    masks = torch.as_tensor(masks) if not isinstance(masks, (list, tuple)) else torch.stack(list(masks))
    if masks.dim() != 3 or masks.shape[0] != len(cameras):
        raise ValueError(f"masks must be (N, H, W), one per camera ({len(cameras)}), got shape {tuple(masks.shape)}")
    for k, c in enumerate(cameras):
        if tuple(masks.shape[1:]) != (c.height, c.width):
            raise ValueError(f"masks are {tuple(masks.shape[1:])} but camera {k} renders {(c.height, c.width)}")
    masks = masks.detach().double()
    if not torch.isfinite(masks).all() or masks.min() < 0 or masks.max() > 1:
        raise ValueError("masks must hold finite values in [0, 1]")
    return masks


def hull_field(masks, cameras, resolution: int = 48, radius: float | None = None) -> torch.Tensor:
    """(resolution, resolution, resolution) float64: at each grid point (x, y, z indices over ``[-radius,
    radius]³``) the smallest mask value over the views at its projection. masks: (N, H, W) in [0, 1], one per
    camera (coverage, e.g. ``fit.hard_silhouettes``); cameras: N perspective ``Camera``."""
    masks = _check_masks(masks, cameras)
    n = _check_count(resolution, "resolution", minimum=2)
    radius = view_radius(cameras) if radius is None else _check_real(radius, "radius", low=0, low_open=True)
    axis = torch.linspace(-radius, radius, n, dtype=torch.float64)
    points = torch.stack(torch.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    field = torch.ones(points.shape[0], dtype=torch.float64)
    for mask, cam in zip(masks, cameras):
        cam = cam.to(device=torch.device("cpu"), dtype=torch.float64)
        pixels, depth = cam.project(points)
        # pixel x in [0, W] spans the image; grid_sample's -1..1 are the outer edges (align_corners=False)
        grid = torch.stack([pixels[:, 0] / cam.width * 2 - 1, pixels[:, 1] / cam.height * 2 - 1], -1)
        seen = F.grid_sample(mask[None, None], grid[None, None], align_corners=False, padding_mode="zeros")
        field = torch.minimum(field, torch.where(depth > 0, seen[0, 0, 0], 0.0))
    return field.view(n, n, n)


def surface_nets(field, radius: float, level: float = 0.5) -> Mesh:
    """The surface ``field = level`` of a grid over ``[-radius, radius]³`` as a closed Mesh (float64), outward
    (counter-clockwise seen from where the field is below ``level``). Raises ValueError when no grid point lies
    above the level."""
    field = torch.as_tensor(field).detach().double()
    if field.dim() != 3 or len(set(field.shape)) != 1 or field.shape[0] < 2:
        raise ValueError(f"field must be a cubic grid (n, n, n), n >= 2, got shape {tuple(field.shape)}")
    if not torch.isfinite(field).all():
        raise ValueError("field contains NaN or inf")
    radius = _check_real(radius, "radius", low=0, low_open=True)
    level = _check_real(level, "level")
    n = field.shape[0]
    step = 2 * radius / (n - 1)
    f = F.pad(field - level, (1, 1) * 3, value=-1.0)                    # outside beyond the grid: closed
    if not (f > 0).any():
        raise ValueError(f"no grid point lies above level {level}: nothing to mesh")
    f = _join_diagonals(f)
    inside = f > 0
    N = n + 2
    corners = torch.stack([inside[i:N - 1 + i, j:N - 1 + j, k:N - 1 + k]
                           for i in (0, 1) for j in (0, 1) for k in (0, 1)], -1)
    active = corners.any(-1) & ~corners.all(-1)                             # cells the surface passes through
    cell = torch.nonzero(active)                                            # (A, 3)
    vertex = torch.full(active.shape, -1, dtype=torch.long)
    vertex[active] = torch.arange(cell.shape[0])
    total = torch.zeros(cell.shape[0], 3, dtype=torch.float64)
    count = torch.zeros(cell.shape[0], dtype=torch.float64)
    for a in range(3):                                                      # the cell's 4 edges along axis a
        b, c = (x for x in range(3) if x != a)
        for db in (0, 1):
            for dc in (0, 1):
                p0 = cell.clone()
                p0[:, b] += db
                p0[:, c] += dc
                p1 = p0.clone()
                p1[:, a] += 1
                f0, f1 = f[p0[:, 0], p0[:, 1], p0[:, 2]], f[p1[:, 0], p1[:, 1], p1[:, 2]]
                crosses = (f0 > 0) != (f1 > 0)
                t = torch.where(crosses, f0 / torch.where(crosses, f0 - f1, 1.0), 0.0)
                total += torch.where(crosses[:, None], p0.double() + t[:, None] * (p1 - p0).double(), 0.0)
                count += crosses
    verts = (total / count[:, None] - 1) * step - radius                    # padded index → world
    faces = []
    for a in range(3):                                                      # grid edges along a that cross
        b, c = (x for x in range(3) if x != a)
        lower = [slice(1, N - 1)] * 3
        lower[a] = slice(0, N - 1)
        upper = list(lower)
        upper[a] = slice(1, N)
        start_in, end_in = inside[tuple(lower)], inside[tuple(upper)]
        crossing = start_in != end_in
        p = torch.nonzero(crossing)
        p[:, b] += 1
        p[:, c] += 1

        def around(db, dc):
            q = p.clone()
            q[:, b] -= db
            q[:, c] -= dc
            return vertex[q[:, 0], q[:, 1], q[:, 2]]

        v00, v10, v11, v01 = around(1, 1), around(0, 1), around(0, 0), around(1, 0)
        tri = torch.cat([torch.stack([v00, v10, v11], 1), torch.stack([v00, v11, v01], 1)])
        # (b, c) turn counter-clockwise about +a for a = x, z; for a = y the pair (x, z) turns the other way.
        # The outside is toward +a where the edge starts inside.
        outward_plus = start_in[crossing].repeat(2) ^ (a == 1)
        faces.append(torch.where(outward_plus[:, None], tri, tri[:, [0, 2, 1]]))
    return Mesh(verts, torch.cat(faces))


def _join_diagonals(f):
    """``f`` with no grid square whose corners are inside and outside in a checkerboard (inside on one
    diagonal only): there, four quads would meet at one mesh edge (two sheets of surface touching). Each outside
    corner of such a square is moved just inside (``f`` = a millionth of the field's range), joining the two
    inside corners through the square; repeated until none is left (the solid grows by at most a few points
    where a part is one cell thin, e.g. a thin handle seen at 48³)."""
    tiny = 1e-6 * float(f.abs().max())
    while True:
        inside = f > 0
        fix = torch.zeros_like(inside)
        for p, q in ((0, 1), (0, 2), (1, 2)):
            n = inside.shape[0]
            a = inside.narrow(p, 0, n - 1).narrow(q, 0, n - 1)
            b = inside.narrow(p, 1, n - 1).narrow(q, 0, n - 1)
            c = inside.narrow(p, 0, n - 1).narrow(q, 1, n - 1)
            d = inside.narrow(p, 1, n - 1).narrow(q, 1, n - 1)
            checker = (a == d) & (b == c) & (a != b)
            for corner, dp, dq in ((a, 0, 0), (b, 1, 0), (c, 0, 1), (d, 1, 1)):
                view = fix.narrow(p, dp, n - 1).narrow(q, dq, n - 1)
                view |= checker & ~corner
        if not fix.any():
            return f
        f = torch.where(fix, torch.full_like(f, tiny), f)


def relax(mesh, iterations: int = 2) -> Mesh:
    """Taubin's smoothing without shrinking (1995): each iteration moves every vertex halfway to the mean of its
    neighbours (λ = 0.5), then back a little further away from it (μ = -0.53). Surface nets leave some
    triangles almost flat (a cell's vertex near the diagonal of a quad: areas a millionth of the median), whose
    normals, and so their shading's gradient, blow up; two iterations make the smallest a fiftieth of the
    median and move the surface by well under a cell."""
    iterations = _check_count(iterations, "iterations", minimum=0)
    verts, faces = mesh.verts.detach(), mesh.faces
    edges = torch.cat([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges = torch.unique(torch.sort(edges, dim=1).values, dim=0)
    i, j = torch.cat([edges[:, 0], edges[:, 1]]), torch.cat([edges[:, 1], edges[:, 0]])
    degree = torch.zeros(verts.shape[0], dtype=verts.dtype).index_add_(0, i, torch.ones_like(i, dtype=verts.dtype))
    for _ in range(iterations):
        for weight in (0.5, -0.53):
            mean = torch.zeros_like(verts).index_add_(0, i, verts[j]) / degree.clamp(min=1)[:, None]
            verts = verts + weight * (mean - verts)
    return Mesh(verts, faces)


def carve(masks, cameras, resolution: int = 48, radius: float | None = None, level: float = 0.5,
          iterations: int = 2) -> Mesh:
    """The visual hull of ``masks`` seen by ``cameras`` as a closed Mesh: ``surface_nets(hull_field(...))``,
    then ``relax``-ed (``iterations``)."""
    masks = _check_masks(masks, cameras)
    radius = view_radius(cameras) if radius is None else radius
    return relax(surface_nets(hull_field(masks, cameras, resolution, radius), radius, level), iterations)
