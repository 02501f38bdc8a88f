"""Barycentrics and depth of the visible faces, per pixel, as a compiled loop (twin of ``raster._surface_at``).

Used only where no gradient is recorded (plain tensors, or inside ``torch.no_grad()``): then the torch
version's chain of (M, 9) gathers and (M, 3) temporaries buys nothing, and this loop computes the same
numbers pixel by pixel. Each pixel's three affine functions ``w_k = A_k (x - cx) + B_k (y - cy) + C_k`` come
from ``raster._face_table`` (per face, in torch), and the arithmetic here is ``_surface_at``'s, operation by
operation in its order and dtype, so the barycentrics and depth are bit-identical to it (the tests compare
them). Wherever a gradient is recorded, ``_surface_at`` runs instead and autograd sees every step.
"""
from __future__ import annotations

import numba
import numpy as np

__all__ = ["faces_seen", "pixel_surface", "warm_up"]


@numba.njit(cache=True, error_model="numpy")
def faces_seen(face_map, n_faces):
    """The row of each face in a table of the faces some pixel sees (-1: unseen), and the number of rows."""
    row = np.full(n_faces, -1, np.int64)
    for p in range(face_map.shape[0]):
        if face_map[p] >= 0:
            row[face_map[p]] = 0
    n = 0
    for f in range(n_faces):                                                # rows in face order, as in torch
        if row[f] == 0:
            row[f] = n
            n += 1
    return row, n


@numba.njit(cache=True, error_model="numpy")
def pixel_surface(face_map, row_of_face, coef, z, xs, ys, consts, bary, depth):
    """face_map (H*W,) int64 (-1: no face); row_of_face (F,) the row of each face in coef (U, 9) and
    z (U, 3); xs (W,), ys (H,): the pixel centres' offsets x - cx, y - cy; consts (2,): 1 and the guard
    ``tiny`` for edge-on faces; all floats in one dtype. Writes bary (H*W, 3) and depth (H*W,) at covered
    pixels (the others are left as they are: 0 and +inf)."""
    W = xs.shape[0]
    one, tiny = consts[0], consts[1]
    for p in range(face_map.shape[0]):
        f = face_map[p]
        if f < 0:
            continue
        r = row_of_face[f]
        qx, qy = xs[p % W], ys[p // W]
        w1 = coef[r, 0] * qx + coef[r, 3] * qy + coef[r, 6]                 # (A x' + B y') + C, as in torch
        w2 = coef[r, 1] * qx + coef[r, 4] * qy + coef[r, 7]
        ws = coef[r, 2] * qx + coef[r, 5] * qy + coef[r, 8]
        s = tiny if abs(ws) < tiny else ws                                   # edge-on faces: finite
        b1, b2 = w1 / s, w2 / s
        bary[p, 0], bary[p, 1], bary[p, 2] = one - b1 - b2, b1, b2
        depth[p] = z[r, 0] + b1 * z[r, 1] + b2 * z[r, 2]


def warm_up():
    """Compile ``pixel_surface`` for float32 and float64 and ``faces_seen`` (or load them from the cache)."""
    faces_seen(np.zeros(1, np.int64), 1)
    for dt in (np.float32, np.float64):
        pixel_surface(np.zeros(1, np.int64), np.zeros(1, np.int64), np.ones((1, 9), dt), np.ones((1, 3), dt),
                      np.ones(1, dt), np.ones(1, dt), np.ones(2, dt), np.zeros((1, 3), dt), np.zeros(1, dt))
