"""The z-buffer as a compiled loop: one triangle, its rows, its pixels (twin of ``scan._zbuffer``, lecture 03).

The pseudocode of every rasterizer::

    for each triangle:
        for each row its y-extent reaches:
            the span of covered pixel centres, from the three edges (top-left rule on the boundary)
            for each pixel of the span:
                depth = 1 / q, q = 1/z affine on screen (z itself for an orthographic camera)
                if depth is nearer than the z-buffer's: keep this face

``nearest_faces`` runs it over the screen triangles of ``raster._screen_triangles`` and must give the face
ids of ``scan._zbuffer``. Coverage: the span of every (triangle, row) is computed with ``scan._spans``'
operations in its order (``_span`` below), so the same pixel centres are covered, bit for bit, and an edge
shared by two triangles still gives one to each side. Visibility: ``scan._zbuffer`` returns the face nearest
in float64, depths within ``scan.TIE_RTOL`` (relative) a tie that goes to the lower face id; here the float64
depths are compared directly, and every pixel where two depths come within ``NOTE_RTOL`` (far above
``TIE_RTOL``) of each other is noted, with both faces, for ``scan._NearTies.resolve`` to decide exactly as
the torch path does. (The loop compares q = 1/z rather than z, a division less per fragment: the order is
the same wherever the two are not within rounding of each other, and there they are noted. Along a span q
is evaluated as torch evaluates it, operation by operation: once at the end where it is least, then that
value plus qx times the whole number of pixels from it, so both paths hold the same q bit for bit.) Without a
near-tie the nearer face is nearer by more than a rounding error, and both paths pick it.
"""
from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["nearest_faces", "warm_up", "NOTE_RTOL"]

NOTE_RTOL = 1e-7                # keys this close (relative) are noted for the exact tie rule


@numba.njit(cache=True, error_model="numpy", inline="always")
def _sign(v):
    return (v > 0) - (v < 0)


@numba.njit(cache=True, error_model="numpy", inline="always")
def _span(x, y, row_y, width):
    """The first and last covered column of one triangle in one row (``scan._spans`` for one segment).

    x, y: (3,) the screen vertices (positive area); row_y: the row's centre. Along the row, edge a→b is
    ``E(px) = A px + r`` with ``A = a_y - b_y``: a left edge when A > 0 (the span starts right of its
    crossing), a right edge when A < 0. A centre exactly on a crossing belongs to the triangle only on a top
    or left edge. A horizontal edge keeps the whole row or none of it. Returns (first, last), float64;
    first > last when the row is empty.
    """
    first, last = -1e18, 1e18
    empty = False
    for k in range(3):
        ax, ay = x[k], y[k]
        bx, by = x[(k + 1) % 3], y[(k + 1) % 3]
        da, db = ay - row_y, by - row_y
        s = _sign(ay - by)                                                  # +1 left edge, -1 right edge
        if s == 0:                                                          # horizontal: inside or not at all
            tl = 1 if bx > ax else 0
            if min(max(2 * _sign(da) * _sign(ax - bx) + tl, 0), 1) == 0:
                empty = True
            continue
        tl = 1 if s > 0 else 0                                              # top-left: here, a left edge
        x0 = min(max((bx * da - ax * db) / (ay - by), -2.0), width + 2.0)  # the crossing, E(x0) = 0
        f, c = math.floor(x0 - 0.5), math.ceil(x0 - 0.5)
        on_centre = tl * (f + 1 - c)                                        # 1: a centre on a top-left edge
        if s > 0:
            first = max(first, f + 1 - on_centre)
        else:
            last = min(last, c - 1 + on_centre)
    first = max(first, 0.0)
    last = min(last, width - 1.0)
    if empty:
        last = first - 1
    return first, last


@numba.njit(cache=True, error_model="numpy", inline="always")
def _plane(xy, q, t):
    """Triangle t's affine q anchored at its corner of least |q| (``scan._plane``, operation by operation):
    returns (qa, xa, ya, qx, qy), q(px, py) = qa + qx (px - xa) + qy (py - ya)."""
    o, longest = 0, -1.0
    for k in range(3):                                                      # the corner opposite the longest edge
        sx = xy[t, (k + 2) % 3, 0] - xy[t, (k + 1) % 3, 0]
        sy = xy[t, (k + 2) % 3, 1] - xy[t, (k + 1) % 3, 1]
        if sx * sx + sy * sy > longest:
            o, longest = k, sx * sx + sy * sy
    k1, k2 = (o + 1) % 3, (o + 2) % 3
    e1x, e1y = xy[t, k1, 0] - xy[t, o, 0], xy[t, k1, 1] - xy[t, o, 1]
    e2x, e2y = xy[t, k2, 0] - xy[t, o, 0], xy[t, k2, 1] - xy[t, o, 1]
    d1, d2 = q[t, k1] - q[t, o], q[t, k2] - q[t, o]
    det = e1x * e2y - e1y * e2x                                             # twice the area, > 0
    qx, qy = (d1 * e2y - d2 * e1y) / det, (d2 * e1x - d1 * e2x) / det
    a = 0
    for k in range(1, 3):                                                   # torch's argmin: the first least
        if abs(q[t, k]) < abs(q[t, a]):
            a = k
    return q[t, a], xy[t, a, 0], xy[t, a, 1], qx, qy


@numba.njit(cache=True, error_model="numpy")
def nearest_faces(xy, q, face, width, height, orthographic, far, check_far, face_map, key_map, notes):
    """The z-buffer: the nearest face at every pixel centre, and the pixels to decide by the exact tie rule.

    xy: (T, 3, 2) float64 screen triangles (positive area); q: (T, 3) the screen-affine q at their corners
    (1/z, or z for an orthographic camera); face: (T,) int64 face ids; far: the far plane, applied to the
    float32 depth as ``scan._zbuffer`` does when ``check_far``. Fills face_map (H*W,) int64 (-1: no face)
    and key_map (H*W,) float64 (start: +inf), the nearest fragment's key: -q = -1/z for a perspective
    camera (larger q is nearer, and comparing q saves a division per fragment; 1/q rounds monotonically, so
    the order is depth's except between q's within a rounding error, which are near-ties), z itself for an
    orthographic one. notes (K, 2) int64: (pixel, face) pairs whose keys came within NOTE_RTOL (relative) of
    the pixel's nearest at the time. Returns the number of notes (more than K: the buffer was too small and
    the call must be repeated with a larger one).
    """
    n_notes = 0
    cap = notes.shape[0]
    far32 = np.float32(far)
    xs = np.empty(3, np.float64)
    ys = np.empty(3, np.float64)
    for t in range(xy.shape[0]):
        for k in range(3):
            xs[k], ys[k] = xy[t, k, 0], xy[t, k, 1]
        y_min, y_max = min(ys[0], ys[1], ys[2]), max(ys[0], ys[1], ys[2])
        r0 = int(max(math.ceil(y_min - 0.5), 0.0))                           # rows whose centres it reaches
        r1 = int(min(math.floor(y_max - 0.5), height - 1.0))
        qa, xa, ya, b, c = _plane(xy, q, t)
        f = face[t]
        for row in range(r0, r1 + 1):
            row_y = row + 0.5
            first, last = _span(xs, ys, row_y, width)
            col_a = first if b >= 0 else last                               # q at the span's end where it is
            q_a = qa + b * (col_a + 0.5 - xa) + c * (row_y - ya)            # least, then |qx| per pixel from it
            ia = int(col_a)                                                 # (scan._scan_convert's order)
            for col in range(int(first), int(last) + 1):
                q_here = q_a + b * np.float64(col - ia)
                if check_far:
                    q32 = np.float32(q_here)
                    d32 = q32 if orthographic else np.float32(1.0) / q32
                    if not d32 <= far32:
                        continue
                key = q_here if orthographic else -q_here                   # smaller: nearer
                p = row * width + col
                best = key_map[p]
                if best != math.inf and abs(key - best) <= NOTE_RTOL * abs(best):
                    if n_notes + 2 <= cap:                                  # a near-tie: both faces noted
                        notes[n_notes, 0], notes[n_notes, 1] = p, f
                        notes[n_notes + 1, 0], notes[n_notes + 1, 1] = p, face_map[p]
                    n_notes += 2
                if key < best or (key == best and f < face_map[p]):
                    key_map[p], face_map[p] = key, f
    return n_notes


def warm_up():
    """Compile ``nearest_faces`` (or load it from the cache)."""
    xy = np.array([[[0.0, 0.0], [4.0, 0.0], [0.0, 4.0]]])
    for ortho in (False, True):
        nearest_faces(xy, np.ones((1, 3)), np.zeros(1, np.int64), 4, 4, ortho, 10.0, True,
                      np.full(16, -1, np.int64), np.full(16, np.inf), np.empty((8, 2), np.int64))
