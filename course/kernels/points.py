"""The z-buffer asked at arbitrary points, as a compiled loop (twin of ``boundary._visible_at``, lecture 09).

The boundary term of a visibility gradient needs, at points just beside every edge, the face the z-buffer
shows there. The torch version lists (point, triangle) pairs through ``scan.pixel_triangle_pairs`` and
tests them all at once; here the triangles are first sorted into the pixels that hold a point (a bucket per
pixel, bounding boxes widened by a few rounding errors, so no triangle that covers a point is left out), and
then each point tests the triangles of its pixel::

    for each point:
        for each triangle in its pixel's bucket:
            inside (the edge functions, the top-left rule)?  in front of the far plane?
            keep the nearest (the largest q = 1/z, or the least z for an orthographic camera); ties: lower face id

The tests are ``_visible_at``'s, operation by operation, so the faces are the same.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from .zbuffer import _plane

__all__ = ["visible_at", "warm_up"]


@numba.njit(cache=True, error_model="numpy", inline="always")
def _covers(xy, t, px, py):
    """Top-left coverage of the point (px, py) by screen triangle t (positive area): ``scan._sample_inside``."""
    for c in range(3):
        ax, ay = xy[t, c, 0], xy[t, c, 1]
        bx, by = xy[t, (c + 1) % 3, 0], xy[t, (c + 1) % 3, 1]
        e = (ax - px) * (by - py) - (ay - py) * (bx - px)                  # scan.edge_function
        if e > 0:
            continue
        if e == 0 and (by - ay < 0 or (by == ay and bx > ax)):             # scan._is_top_left
            continue
        return False
    return True


@numba.njit(cache=True, error_model="numpy", inline="always")
def _box(xy, t, width, height):
    """The pixels triangle t's bounding box reaches, widened by a few rounding errors: columns c0..c1, rows
    r0..r1 (empty when it lies off the image)."""
    x0, x1 = min(xy[t, 0, 0], xy[t, 1, 0], xy[t, 2, 0]), max(xy[t, 0, 0], xy[t, 1, 0], xy[t, 2, 0])
    y0, y1 = min(xy[t, 0, 1], xy[t, 1, 1], xy[t, 2, 1]), max(xy[t, 0, 1], xy[t, 1, 1], xy[t, 2, 1])
    slack = 1e-9 * (1 + max(abs(x0), abs(x1), abs(y0), abs(y1)))
    c0, c1 = max(math.floor(x0 - slack), 0.0), min(math.floor(x1 + slack), width - 1.0)
    r0, r1 = max(math.floor(y0 - slack), 0.0), min(math.floor(y1 + slack), height - 1.0)
    return int(c0), int(c1), int(r0), int(r1)


@numba.njit(cache=True, error_model="numpy")
def _buckets(xy, slot_of, n_slots, width, height):
    """The triangles whose widened bounding boxes reach each bucket: slot_of (H*W,) the bucket of each pixel
    (-1: none wanted). Returns start (n_slots + 1,) and bucket: bucket k holds bucket[start[k]:start[k + 1]]."""
    start = np.zeros(n_slots + 1, np.int64)                                 # bucket sizes, then offsets
    for t in range(xy.shape[0]):
        c0, c1, r0, r1 = _box(xy, t, width, height)
        for r in range(r0, r1 + 1):
            for c in range(c0, c1 + 1):
                k = slot_of[r * width + c]
                if k >= 0:
                    start[k + 1] += 1
    for k in range(n_slots):
        start[k + 1] += start[k]
    bucket = np.empty(start[n_slots], np.int64)
    fill = start[:n_slots].copy()
    for t in range(xy.shape[0]):
        c0, c1, r0, r1 = _box(xy, t, width, height)
        for r in range(r0, r1 + 1):
            for c in range(c0, c1 + 1):
                k = slot_of[r * width + c]
                if k >= 0:
                    bucket[fill[k]] = t
                    fill[k] += 1
    return start, bucket


@numba.njit(cache=True, error_model="numpy")
def visible_at(xy, q, face, px, py, width, height, orthographic, far, out):
    """xy (T, 3, 2) float64 screen triangles (positive area), q (T, 3) their screen-affine q (1/z, or z),
    face (T,) face ids; px, py (N,) float64 points. Writes out (N,): the face nearest at each point, -1 for
    none or outside the image."""
    n_pix = width * height
    cell = np.full(px.shape[0], -1, np.int64)
    slot_of = np.full(n_pix, -1, np.int64)                                  # a bucket for each pixel with a point
    for i in range(px.shape[0]):                                            # the pixel of each point
        col, row = math.floor(px[i]), math.floor(py[i])
        if 0 <= col < width and 0 <= row < height:
            cell[i] = int(row) * width + int(col)
            slot_of[cell[i]] = cell[i]
    start, bucket = _buckets(xy, slot_of, n_pix, width, height)
    for i in range(px.shape[0]):
        out[i] = -1
        p = cell[i]
        if p < 0:
            continue
        best, best_face = -math.inf, -1
        for k in range(start[p], start[p + 1]):
            t = bucket[k]
            if not _covers(xy, t, px[i], py[i]):
                continue
            qa, xa, ya, qx, qy = _plane(xy, q, t)                           # scan._plane_at
            qp = qa + qx * (px[i] - xa) + qy * (py[i] - ya)
            depth = qp if orthographic else 1 / qp
            if not depth <= far:
                continue
            near = -qp if orthographic else qp                              # larger: nearer
            if near > best or (near == best and face[t] < best_face):
                best, best_face = near, face[t]
        out[i] = best_face


def warm_up():
    """Compile ``visible_at`` (or load it from the cache)."""
    xy = np.array([[[0.0, 0.0], [4.0, 0.0], [0.0, 4.0]]])
    for ortho in (False, True):
        visible_at(xy, np.ones((1, 3)), np.zeros(1, np.int64), np.array([1.2, 9.0]), np.array([1.1, 0.5]), 4, 4,
                   ortho, 10.0, np.empty(2, np.int64))
