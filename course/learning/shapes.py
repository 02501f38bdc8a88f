"""Procedural shape families: closed meshes made from a seed, the data lecture 13 learns from (no download).

Seven families, each a closed, manifold, outward-wound triangle mesh of 336 to 480 faces, centred on its
bounding box and scaled so its farthest vertex lies on the unit sphere. Every shape stands along +y (the
families are aligned, as ShapeNet's categories are in Kato et al. 2018); what varies is drawn from the seed:

* ``box``      a rectangular prism, random width / height / depth, yaw, twist about y and taper.
* ``cylinder`` an elliptic cylinder, random height and eccentricity, a slight barrel or waist.
* ``cone``     a cone on an elliptic base, random height, the apex off-centre, bumps around the base.
* ``capsule``  a cylinder with hemispherical ends, random length and an elliptic section.
* ``vase``     a random smooth profile revolved about y (a lathe), flat base and lid, angular bumps.
* ``star``     a star polygon (3, 4 or 6 points, deep or shallow notches) extruded, twisted and tapered.
* ``torus``    a ring in the xz plane, random tube radius, an elliptic tube, bumps along the ring.

How a shape is built (``_tube``, ``_torus_grid``): all but the torus are *generalised cylinders*, a stack of K
rings of M points each (a star-shaped cross-section scaled, rotated and lifted per ring) closed by a pole
below the first ring and one above the last. Flat ends put an inner ring at half scale in the end's plane,
so the end is a fan of quads around its pole rather than of slivers. Ring point j sits at angle
``θ_j = 2π j / M`` measured from +z toward +x; the quads (k, j), (k, j+1), (k+1, j+1), (k+1, j) then have
normals ``∂p/∂θ × ∂p/∂k``, which point away from the axis when the rings rise: outward, counter-clockwise
seen from outside (DESIGN.md's front faces). The poles' fans are wound to match. The torus is a periodic
(u, v) grid wound the same way. Every edge is shared by exactly two faces (``tests/test_shapes.py`` checks
that, positive signed volume, determinism and variety for many seeds).

Randomness: ``make_shape(family, seed)`` draws everything from ``numpy.random.default_rng(seed)``; the
same seed gives bit-identical vertices on one machine. The dataset (``course.learning.data``) derives each
shape's seed from (dataset seed, split, family, index).
"""
from __future__ import annotations

import math

import numpy as np
import torch

from ..mesh import Mesh
from ..tensors import _check_count, _check_device, _check_dtype

__all__ = ["FAMILIES", "make_shape", "signed_volume", "boundary_edges", "aspect_ratio"]

FAMILIES = ("box", "cylinder", "cone", "capsule", "vase", "star", "torus")
M_AROUND = 24            # points per ring: a multiple of 4 (box) and of 2 × 3, 4, 6 (star), so corners are ring points


# ---- cross-sections: radius as a function of the angle θ (from +z toward +x) ------------------------------

def _polygon_radius(theta: np.ndarray, radii: np.ndarray, phase: float = 0.0) -> np.ndarray:
    """(M,) the distance from the centre to a star-shaped polygon along each angle ``theta`` (M,).

    The polygon has n = len(radii) corners, corner i at angle ``phase + 2π i / n`` and distance radii[i]. On
    the side from corner a (angle α, radius ra) to b (β, rb), the polar equation of the line through them is
    ``r(θ) = ra rb sin(β - α) / (ra sin(θ - α) + rb sin(β - θ))``, exact at the corners.
    """
    n = len(radii)
    step = 2 * math.pi / n
    rel = np.mod(theta - phase, 2 * math.pi)                         # (M,) angle past corner 0
    a = np.minimum((rel // step).astype(int), n - 1)                 # (M,) the corner before θ
    alpha, beta = phase + a * step, phase + (a + 1) * step
    ra, rb = radii[a], radii[(a + 1) % n]
    t = phase + rel
    return ra * rb * math.sin(step) / (ra * np.sin(t - alpha) + rb * np.sin(beta - t))


def _ring(theta: np.ndarray, radius: np.ndarray, y: float, sx: float, sz: float, turn: float) -> np.ndarray:
    """(M, 3) one ring: the section ``radius(θ)`` (M,) scaled by (sx, sz), turned by ``turn`` about y, at height y.

    The turn rotates the scaled section (a twist), so a rectangle stays a rectangle; it keeps θ increasing
    around the ring, which keeps the winding outward.
    """
    x, z = sx * radius * np.sin(theta), sz * radius * np.cos(theta)  # (M,) each, before the turn
    c, s = math.cos(turn), math.sin(turn)
    return np.stack([c * x + s * z, np.full_like(x, y), -s * x + c * z], axis=1)


# ---- mesh builders -----------------------------------------------------------------------------------------

def _tube(rings: np.ndarray, bottom: np.ndarray, top: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(verts (K M + 2, 3), faces (2 K M, 3)) closing K rings of M points with a pole below and one above.

    rings: (K, M, 3), ring k above ring k - 1, points at increasing θ. Vertex 0 is the bottom pole, vertex
    1 + k M + j ring k's point j, the last vertex the top pole.
    """
    K, M, _ = rings.shape
    verts = np.concatenate([bottom[None], rings.reshape(-1, 3), top[None]])
    ids = 1 + np.arange(K * M).reshape(K, M)                          # (K, M) vertex id of ring point (k, j)
    nxt = np.roll(ids, -1, axis=1)                                    # (K, M) the point at j + 1
    a, b, c, d = ids[:-1], nxt[:-1], nxt[1:], ids[1:]                # quad corners, each (K - 1, M)
    sides = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    top_id = len(verts) - 1
    bottom_fan = np.stack([np.zeros(M, int), nxt[0], ids[0]], 1)     # normal -y
    top_fan = np.stack([np.full(M, top_id), ids[-1], nxt[-1]], 1)    # normal +y
    return verts, np.concatenate([bottom_fan, sides, top_fan])


def _torus_grid(major: float, minor: np.ndarray, squash: float, n_major: int, n_minor: int):
    """(verts (U V, 3), faces (2 U V, 3)) a torus around y: ring angle u, tube angle v, tube radius minor[u].

    ``p(u, v) = ((R + r cos v) sin u, squash r sin v, (R + r cos v) cos u)``; faces are wound along
    ``∂p/∂u × ∂p/∂v``, which points out of the tube.
    """
    u = 2 * math.pi * np.arange(n_major) / n_major
    v = 2 * math.pi * np.arange(n_minor) / n_minor
    r = minor[:, None]                                                # (U, 1)
    ring = major + r * np.cos(v)[None]                                # (U, V) distance from the y axis
    height = np.broadcast_to(squash * r * np.sin(v)[None], ring.shape)  # (U, V)
    verts = np.stack([ring * np.sin(u)[:, None], height, ring * np.cos(u)[:, None]], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    a = i * n_minor + j
    b = ((i + 1) % n_major) * n_minor + j                             # one step in u
    c = ((i + 1) % n_major) * n_minor + (j + 1) % n_minor
    d = i * n_minor + (j + 1) % n_minor                               # one step in v
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return verts, faces


def _extrusion(theta, section, heights, scales, turns, sx, sz, caps=True):
    """(verts, faces) of a section ``section`` (M,) swept through ``heights`` (K,), scaled and turned per ring.

    With ``caps`` the first and last ring get a half-scale ring in their plane (a flat end); the poles sit
    on the axis at the end heights.
    """
    rings = [_ring(theta, section * s, y, sx, sz, t) for y, s, t in zip(heights, scales, turns)]
    if caps:
        rings = ([_ring(theta, section * 0.5 * scales[0], heights[0], sx, sz, turns[0])] + rings
                 + [_ring(theta, section * 0.5 * scales[-1], heights[-1], sx, sz, turns[-1])])
    return _tube(np.stack(rings), np.array([0.0, heights[0], 0.0]), np.array([0.0, heights[-1], 0.0]))


# ---- the families ------------------------------------------------------------------------------------------

def _theta() -> np.ndarray:
    return 2 * math.pi * np.arange(M_AROUND) / M_AROUND


def _box(rng):
    """Width, depth in [0.4, 2] × height in [0.4, 2], a yaw, a twist up to ±60° and a taper down to 0.6."""
    w, h, d = rng.uniform(0.4, 2.0, size=3)
    yaw, twist, taper = rng.uniform(0, math.pi / 2), rng.uniform(-1.05, 1.05), rng.uniform(0.6, 1.0)
    section = _polygon_radius(_theta(), np.full(4, math.sqrt(2) / 2), phase=math.pi / 4)  # the unit square
    t = np.linspace(0, 1, 6)
    return _extrusion(_theta(), section, h * (t - 0.5), 1 - (1 - taper) * t, yaw + twist * t, w, d)


def _cylinder(rng):
    """Radius 1, height in [0.5, 3], eccentricity (depth / width) in [0.6, 1], a barrel or waist of ±20 %."""
    h, ecc, bulge = rng.uniform(0.5, 3.0), rng.uniform(0.6, 1.0), rng.uniform(-0.2, 0.2)
    t = np.linspace(0, 1, 6)
    scales = 1 + bulge * np.sin(math.pi * t)
    return _extrusion(_theta(), np.ones(M_AROUND), h * (t - 0.5), scales, np.full(6, rng.uniform(0, math.pi)),
                      1.0, ecc)


def _cone(rng):
    """Base radius 1 (eccentricity in [0.7, 1]), height in [0.6, 3], apex off-centre by up to 0.3, bumps."""
    h, ecc, lean = rng.uniform(0.6, 3.0), rng.uniform(0.7, 1.0), rng.uniform(-0.3, 0.3, size=2)
    bumps, k, phase = rng.uniform(0, 0.15), rng.integers(3, 7), rng.uniform(0, 2 * math.pi)
    theta = _theta()
    section = 1 + bumps * np.sin(k * theta + phase)
    t = np.linspace(0, 0.85, 6)                                       # the last ring below the apex
    rings = [_ring(theta, section * 0.5, -h / 2, 1.0, ecc, 0.0)]      # the flat base's inner ring
    for tk in t:
        ring = _ring(theta, section * (1 - tk), h * (tk - 0.5), 1.0, ecc, 0.0)
        ring[:, [0, 2]] += tk * lean                                   # lean toward the apex
        rings.append(ring)
    apex = np.array([lean[0], h / 2, lean[1]])
    return _tube(np.stack(rings), np.array([0.0, -h / 2, 0.0]), apex)


def _capsule(rng):
    """Radius 1 (eccentricity in [0.7, 1]), a straight part of length in [0.3, 3] between two hemispheres."""
    length, ecc = rng.uniform(0.3, 3.0), rng.uniform(0.7, 1.0)
    phi = np.linspace(-math.pi / 2, math.pi / 2, 8)[1:-1]             # (6,) latitudes of one hemisphere's rings
    lower, upper = phi[phi < 0], phi[phi > 0]
    heights = np.concatenate([np.sin(lower) - length / 2, [-length / 2, length / 2], np.sin(upper) + length / 2])
    scales = np.concatenate([np.cos(lower), [1.0, 1.0], np.cos(upper)])
    theta = _theta()
    rings = np.stack([_ring(theta, np.full(M_AROUND, s), y, 1.0, ecc, 0.0) for y, s in zip(heights, scales)])
    return _tube(rings, np.array([0.0, -1 - length / 2, 0.0]), np.array([0.0, 1 + length / 2, 0.0]))


def _vase(rng):
    """A lathe: radius profile ``r(t) = 0.6 + Σ a_i sin(i π t + φ_i)`` over 8 heights, height in [1, 3], bumps."""
    h = rng.uniform(1.0, 3.0)
    t = np.linspace(0, 1, 8)
    amps, phases = rng.uniform(-0.35, 0.35, size=3) / np.arange(1, 4), rng.uniform(0, 2 * math.pi, size=3)
    profile = 0.6 + sum(a * np.sin((i + 1) * math.pi * t + p) for i, (a, p) in enumerate(zip(amps, phases)))
    profile = np.clip(profile, 0.15, None)                            # never pinch to the axis
    bumps, k = rng.uniform(0, 0.12), rng.integers(4, 9)
    section = 1 + bumps * np.sin(k * _theta())
    return _extrusion(_theta(), section, h * (t - 0.5), profile, np.zeros(8), 1.0, 1.0)


def _star(rng):
    """A star of 3, 4 or 6 points extruded to a height in [0.3, 2], twisted and tapered. Its inner radius is
    0.45 to 0.8 times cos(π / n), the radius at which the notches would straighten into a plain n-gon (a
    4-point star with inner radius 0.71 is a square: a box). Its 2n corners must be ring points (2n divides
    M_AROUND), else the section would cut them off."""
    n = int(rng.choice([3, 4, 6]))
    inner, h = rng.uniform(0.45, 0.8) * math.cos(math.pi / n), rng.uniform(0.3, 2.0)
    twist, taper, yaw = rng.uniform(-1.0, 1.0), rng.uniform(0.5, 1.0), rng.uniform(0, math.pi)
    radii = np.tile([1.0, inner], n)                                  # 2n corners, outer and inner in turn
    section = _polygon_radius(_theta(), radii)
    t = np.linspace(0, 1, 5)
    return _extrusion(_theta(), section, h * (t - 0.5), 1 - (1 - taper) * t, yaw + twist * t, 1.0, 1.0)


def _torus(rng):
    """Ring radius 1, tube radius in [0.15, 0.6], tube squashed in y by [0.6, 1.4], bumps along the ring."""
    minor, squash = rng.uniform(0.15, 0.6), rng.uniform(0.6, 1.4)
    bumps, k, phase = rng.uniform(0, 0.3), rng.integers(2, 6), rng.uniform(0, 2 * math.pi)
    u = 2 * math.pi * np.arange(20) / 20
    return _torus_grid(1.0, minor * (1 + bumps * np.sin(k * u + phase)), squash, 20, 10)


_BUILDERS = {"box": _box, "cylinder": _cylinder, "cone": _cone, "capsule": _capsule, "vase": _vase,
             "star": _star, "torus": _torus}


# ---- the public API ----------------------------------------------------------------------------------------

def _normalise(verts: np.ndarray) -> np.ndarray:
    """(V, 3) ``verts`` with their bounding box centred at the origin and the farthest vertex at distance 1."""
    centred = verts - (verts.min(0) + verts.max(0)) / 2
    return centred / np.linalg.norm(centred, axis=1).max()


def make_shape(family: str, seed: int, *, dtype=None, device=None) -> Mesh:
    """One shape of ``family`` (a name in ``FAMILIES``) drawn from ``seed`` (a non-negative int).

    Returns a closed, outward-wound Mesh of a few hundred faces (V 170-242, F 336-480), centred on its
    bounding box and fitting the unit sphere (max vertex distance 1). Same seed, same vertices.
    dtype: float dtype of the vertices (default: torch's default dtype); device: where they live.
    """
    if family not in _BUILDERS:
        raise ValueError(f"family must be one of {FAMILIES}, got {family!r}")
    seed = _check_count(seed, "seed", minimum=0)
    dtype = _check_dtype(dtype) or torch.get_default_dtype()
    device = _check_device(device)
    verts, faces = _BUILDERS[family](np.random.default_rng(seed))
    verts = torch.as_tensor(_normalise(verts), dtype=dtype, device=device)
    return Mesh(verts, torch.as_tensor(faces, dtype=torch.int64, device=device))


def signed_volume(mesh) -> float:
    """The enclosed volume ``Σ_f v0 · (v1 × v2) / 6`` (divergence theorem), in float64.

    Positive for a closed mesh whose faces are counter-clockwise seen from outside, negative when they
    are all wound inward; for an open mesh it depends on the origin and means little.
    """
    verts = torch.as_tensor(mesh.verts).detach().double()
    v0, v1, v2 = verts[mesh.faces].unbind(1)                          # each (F, 3)
    return float((v0 * torch.linalg.cross(v1, v2, dim=-1)).sum() / 6)


def boundary_edges(faces) -> torch.Tensor:
    """(E, 2) the undirected edges (sorted vertex pairs) that break "closed and consistently wound": empty when fine.

    faces: (F, 3) int64. A closed mesh wound one way uses every directed edge (a, b) exactly once and its
    reverse (b, a) exactly once (the neighbour walks the edge the other way). An edge with no reverse is a
    hole's border; a directed edge used twice means two neighbours disagree on the winding, or a
    non-manifold edge shared by more than two faces.
    """
    faces = torch.as_tensor(faces).long()
    directed = torch.cat([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])  # (3F, 2)
    n = int(faces.max()) + 1 if faces.numel() else 1
    keys, reverse = directed[:, 0] * n + directed[:, 1], directed[:, 1] * n + directed[:, 0]  # (3F,) each
    unique, counts = torch.unique(keys, return_counts=True)
    once = counts[torch.searchsorted(unique, keys)] == 1              # (3F,) this direction used once
    bad = directed[~(once & torch.isin(reverse, keys))]
    return torch.unique(bad.sort(1).values, dim=0) if bad.numel() else bad.new_zeros(0, 2)


def aspect_ratio(mesh) -> float:
    """Height over width of the bounding box: ``(y extent) / max(x extent, z extent)``, > 1 tall, < 1 flat."""
    verts = torch.as_tensor(mesh.verts).detach().double()
    extent = verts.max(0).values - verts.min(0).values
    return float(extent[1] / torch.maximum(extent[0], extent[2]))
