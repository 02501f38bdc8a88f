"""Bundled models: primitives, a checker texture and the Utah teapot. Nothing is downloaded.

All meshes follow the course conventions: +y up, faces counter-clockwise seen from outside (so every
face normal points out), uvs with u right and v up. Every function takes ``dtype`` (default: torch's default
dtype, float32 unless ``torch.set_default_dtype`` changed it) and ``device``.

Closed surfaces stay crack-free: where a uv seam needs two copies of a vertex (torus, teapot), the
copies sit at bit-identical positions, so a rasterizer sees no gap.
"""
from __future__ import annotations

import functools
import itertools
from pathlib import Path

import numpy as np
import torch

from .mesh import Mesh
from .tensors import _check_count, _check_device, _check_dtype, _check_real

__all__ = ["cube", "icosphere", "plane", "torus", "checker_texture", "teapot", "default_scene_mesh"]

_DATA = Path(__file__).parent / "data"


def _to_mesh(verts, faces, dtype, device, uvs=None, texture=None) -> Mesh:
    """A Mesh from numpy arrays (the texture may already be a tensor), in ``dtype`` on ``device``."""
    dtype = _check_dtype(dtype) or torch.get_default_dtype()
    device = _check_device(device)

    def as_float(x):
        return None if x is None else torch.as_tensor(x, dtype=dtype, device=device)

    faces = torch.as_tensor(np.asarray(faces, dtype=np.int64), device=device)
    return Mesh(as_float(verts), faces, uvs=as_float(uvs), texture=as_float(texture))


def _orient_outward(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3) faces of a convex mesh around the origin, each reordered to be counter-clockwise from outside."""
    v0, v1, v2 = (verts[faces[:, k]] for k in range(3))
    inward = np.einsum("fi,fi->f", np.cross(v1 - v0, v2 - v0), v0 + v1 + v2) < 0
    faces = faces.copy()
    faces[inward] = faces[inward][:, [0, 2, 1]]
    return faces


def _grid_faces(rows: int, cols: int) -> np.ndarray:
    """(2 * rows * cols, 3) faces of a (rows + 1) x (cols + 1) vertex grid stored row by row.

    Quad corners a = (i, j), b = (i, j + 1), c = (i + 1, j + 1), d = (i + 1, j) become triangles
    (a, b, c) and (a, c, d); their normals point along d(position)/d(column) x d(position)/d(row).
    """
    i, j = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    a = (i * (cols + 1) + j).reshape(-1)
    b, c, d = a + 1, a + cols + 2, a + cols + 1
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


# ---- primitives ------------------------------------------------------------------------------
def cube(size: float = 2.0, *, dtype=None, device=None) -> Mesh:
    """Axis-aligned cube centred at the origin with edge ``size``: 8 shared vertices, 12 faces.

    The corners are shared so the cube is closed (every edge in exactly two faces), which
    rasterization tests rely on. The price: `Mesh.vertex_normals` rounds the corners; use
    `Mesh.face_normals` for flat-shaded sides. No uvs (a shared corner has no single uv).
    """
    size = _check_real(size, "size", low=0, low_open=True)
    verts = np.array(list(itertools.product((-1.0, 1.0), repeat=3))) * (size / 2)  # index = 4x + 2y + z bits
    quads = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]]  # -x +x -y +y -z +z
    faces = np.array([[q[0], q[1], q[2]] for q in quads] + [[q[0], q[2], q[3]] for q in quads])
    return _to_mesh(verts, _orient_outward(verts, faces), dtype, device)


def _icosahedron() -> tuple[np.ndarray, np.ndarray]:
    """(verts (12, 3) on the unit sphere, faces (20, 3) outward)."""
    phi = (1 + 5 ** 0.5) / 2
    base = [(0.0, a, b * phi) for a in (-1, 1) for b in (-1, 1)]
    verts = np.array([np.roll(p, k) for k in range(3) for p in base])  # cyclic permutations of (0, ±1, ±phi)
    verts /= np.linalg.norm(verts, axis=1, keepdims=True)
    dist = np.linalg.norm(verts[:, None] - verts[None], axis=-1)
    edge = dist[dist > 0].min()
    is_edge = np.isclose(dist, edge)
    faces = np.array([t for t in itertools.combinations(range(12), 3)  # triangles: 3 mutually adjacent corners
                      if is_edge[t[0], t[1]] and is_edge[t[1], t[2]] and is_edge[t[0], t[2]]])
    return verts, _orient_outward(verts, faces)


def _subdivide_sphere(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split each face into 4 at its edge midpoints, pushed onto the unit sphere (vectorised)."""
    V, F = len(verts), len(faces)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])  # (3F, 2): ab, bc, ca
    edges.sort(axis=1)
    keys, first, inverse = np.unique(edges[:, 0] * V + edges[:, 1], return_index=True, return_inverse=True)
    ends = edges[first]  # (E, 2) each undirected edge once
    mid = verts[ends[:, 0]] + verts[ends[:, 1]]
    mid /= np.linalg.norm(mid, axis=1, keepdims=True)
    ab, bc, ca = (V + inverse.reshape(3, F))  # each (F,): index of the new vertex on that edge
    a, b, c = faces.T
    children = np.stack([np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1),
                         np.stack([ca, bc, c], 1), np.stack([ab, bc, ca], 1)], 1)  # (F, 4, 3) same winding
    return np.concatenate([verts, mid]), children.reshape(-1, 3)


def icosphere(subdivisions: int = 3, radius: float = 1.0, *, dtype=None, device=None) -> Mesh:
    """Sphere from an icosahedron split ``subdivisions`` times: 20 * 4**s faces, 10 * 4**s + 2 vertices.

    Closed and outward-facing; subdivisions 3, 5, 7 give 1280, 20480 and 327680 faces. No uvs.
    """
    subdivisions = _check_count(subdivisions, "subdivisions", minimum=0)
    radius = _check_real(radius, "radius", low=0, low_open=True)
    verts, faces = _icosahedron()
    for _ in range(subdivisions):
        verts, faces = _subdivide_sphere(verts, faces)
    return _to_mesh(verts * radius, faces, dtype, device)


def plane(size: float = 2.0, subdivisions: int = 1, *, dtype=None, device=None) -> Mesh:
    """Square of side ``size`` in the xz plane (y = 0), facing +y, split into subdivisions² quads.

    uvs: u runs along +x and v along -z, so seen from above (+x right) the texture is not mirrored
    and its top row lies toward -z.
    """
    n = _check_count(subdivisions, "subdivisions")
    size = _check_real(size, "size", low=0, low_open=True)
    v, u = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")  # rows: v, cols: u
    verts = np.stack([(u - 0.5) * size, np.zeros_like(u), (0.5 - v) * size], -1).reshape(-1, 3)
    uvs = np.stack([u, v], -1).reshape(-1, 2)
    return _to_mesh(verts, _grid_faces(n, n), dtype, device, uvs=uvs)  # normal: +x cross -z = +y


def torus(major: float = 1.0, minor: float = 0.35, n_major: int = 48, n_minor: int = 24,
          *, dtype=None, device=None) -> Mesh:
    """Ring torus around the y axis: tube radius ``minor`` at distance ``major``, with uvs.

    u goes once around the y axis (counter-clockwise seen from above), v once around the tube.
    The u = 1 and v = 1 seam vertices copy the u = 0 / v = 0 positions exactly (closed, crack-free).
    """
    n_major, n_minor = _check_count(n_major, "n_major", minimum=3), _check_count(n_minor, "n_minor", minimum=3)
    minor = _check_real(minor, "minor", low=0, low_open=True)
    major = _check_real(major, "major", low=0, low_open=True)
    if not major > minor:
        raise ValueError(f"major must be larger than minor (a ring torus, with a hole), got major={major:g}, "
                         f"minor={minor:g}")
    rows, cols = np.meshgrid(np.arange(n_minor + 1), np.arange(n_major + 1), indexing="ij")
    theta = 2 * np.pi * (cols % n_major) / n_major  # angle around the y axis; modulo: seam copies are exact
    phi = 2 * np.pi * (rows % n_minor) / n_minor  # angle around the tube
    ring = major + minor * np.cos(phi)
    verts = np.stack([ring * np.cos(theta), minor * np.sin(phi), -ring * np.sin(theta)], -1).reshape(-1, 3)
    uvs = np.stack([cols / n_major, rows / n_minor], -1).reshape(-1, 2)
    return _to_mesh(verts, _grid_faces(n_minor, n_major), dtype, device, uvs=uvs)


def checker_texture(size: int = 256, checks: int = 8, *, dtype=None, device=None) -> torch.Tensor:
    """(size, size, 3) colourful checkerboard whose orientation shows in every render.

    Red grows with u (left to right), green with v (bottom to top), blue marks the dark checks, and
    a white square sits in the check at uv (0, 0), the bottom-left corner of the image (row size-1,
    column 0). Texel (row r, col c) has its centre at u = (c + 0.5) / size, v = 1 - (r + 0.5) / size.
    """
    size, checks = _check_count(size, "size"), _check_count(checks, "checks")
    dtype, device = _check_dtype(dtype), _check_device(device)
    centres = (np.arange(size) + 0.5) / size
    v, u = np.meshgrid(1 - centres, centres, indexing="ij")  # (size, size) each; row 0 is the top, v = 1
    cu, cv = np.floor(u * checks), np.floor(v * checks)
    dark = (cu + cv) % 2 == 1
    image = np.stack([0.15 + 0.85 * u, 0.15 + 0.85 * v, np.full_like(u, 0.2)], -1)  # (size, size, 3)
    image[dark] = 0.45 * image[dark] + np.array([0.0, 0.0, 0.45])
    marker = (np.abs(u * checks - 0.5) < 0.3) & (np.abs(v * checks - 0.5) < 0.3)
    image[marker] = 1.0
    return torch.as_tensor(image, dtype=dtype or torch.get_default_dtype(), device=device)


# ---- the Utah teapot ---------------------------------------------------------------------------
# Patches that share a ring (4 around the teapot's axis) or a tube (2 around the handle / spout);
# u runs once around each group, so the texture wraps without a jump except at one seam.
_TEAPOT_GROUPS = [(0, 4), (4, 4), (8, 4), (12, 2), (14, 2), (16, 2), (18, 2), (20, 4), (24, 4), (28, 4)]


@functools.lru_cache(maxsize=1)
def _teapot_control_points() -> np.ndarray:
    """(32, 4, 4, 3) Bezier control points of Newell's teapot, z up (from data/teapot_patches.txt)."""
    rows = [line.split() for line in (_DATA / "teapot_patches.txt").read_text().splitlines()
            if line.strip() and not line.startswith("#")]
    n_patches = int(rows[0][1])
    patches = np.array(rows[1:1 + n_patches], dtype=np.int64) - 1  # one-based in the file
    points = np.array(rows[2 + n_patches:], dtype=np.float64)
    return points[patches].reshape(n_patches, 4, 4, 3)


def _bernstein(t: np.ndarray) -> np.ndarray:
    """(N, 4) cubic Bernstein weights at parameters t (N,)."""
    t = t[:, None]
    return np.concatenate([(1 - t) ** 3, 3 * t * (1 - t) ** 2, 3 * t ** 2 * (1 - t), t ** 3], axis=1)


def _weld(verts: np.ndarray, uvs: np.ndarray, faces: np.ndarray):
    """Merge vertices equal in position and uv; drop faces with two corners at one position."""
    pos_key = np.round(verts * 2 ** 20).astype(np.int64)
    key = np.concatenate([pos_key, np.round(uvs * 2 ** 20).astype(np.int64)], axis=1)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    faces = inverse.reshape(-1)[faces]
    _, pos_id = np.unique(pos_key, axis=0, return_inverse=True)
    p = pos_id.reshape(-1)[first][faces]  # (F, 3) position ids: a pole triangle repeats one
    keep = (p[:, 0] != p[:, 1]) & (p[:, 1] != p[:, 2]) & (p[:, 0] != p[:, 2])
    faces = faces[keep]
    used = np.unique(faces)                                     # vertices only a dropped pole face used
    remap = np.full(len(first), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return verts[first][used], uvs[first][used], remap[faces]


def teapot(resolution: int = 8, *, dtype=None, device=None) -> Mesh:
    """The Utah teapot (Newell 1975): 32 bicubic Bezier patches, each a resolution x resolution grid.

    Turned from the data's z up to +y up (spout toward +x), centred on its bounding box and scaled
    to fit the unit sphere. Faces are counter-clockwise from outside; the zero-area triangles at the
    lid and bottom poles are removed. uvs run once around each ring of patches (u, counter-clockwise
    seen from above) and along each patch (v, upward on the body); the texture is `checker_texture`.
    Like the original, the surface is not closed: the lid floats in the rim's opening, and the
    spout and handle pass into the body.
    """
    n = _check_count(resolution, "resolution")
    control = _teapot_control_points() @ np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]).T  # z up -> y up
    weights = _bernstein(np.linspace(0, 1, n + 1))  # (n+1, 4)
    grid = np.einsum("ir,jc,prcx->pijx", weights, weights, control)  # (32, n+1, n+1, 3): rows t, cols s
    s = np.linspace(0, 1, n + 1)
    grid_faces = _grid_faces(n, n)  # normal d/ds x d/dt: outward for Newell's patch order
    verts, uvs, faces = [], [], []
    for first, count in _TEAPOT_GROUPS:
        for k in range(count):
            t_, s_ = np.meshgrid(s, s, indexing="ij")
            u, v = 1 - (k + s_) / count, 1 - t_  # both flipped: u x v keeps the outward orientation
            faces.append(grid_faces + len(verts) * (n + 1) ** 2)
            verts.append(grid[first + k].reshape(-1, 3))
            uvs.append(np.stack([u, v], -1).reshape(-1, 2))
    verts, uvs, faces = _weld(np.concatenate(verts), np.concatenate(uvs), np.concatenate(faces))
    lo, hi = verts.min(0), verts.max(0)
    verts = verts - (lo + hi) / 2
    verts /= np.linalg.norm(verts, axis=1).max()
    return _to_mesh(verts, faces, dtype, device, uvs=uvs, texture=checker_texture(dtype=dtype, device=device))


def default_scene_mesh(*, dtype=None, device=None) -> Mesh:
    """The mesh `python -m course render` draws when given none: the textured teapot."""
    return teapot(dtype=dtype, device=device)
