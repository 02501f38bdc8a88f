"""Barycentrics and depth of the visible faces, per pixel, as a compiled loop (twin of ``raster._surface_at``).

Used only where no gradient is recorded (plain tensors, or inside ``torch.no_grad()``): then the torch
version's chain of (M, 9) gathers and (M, 3) temporaries buys nothing, and this loop computes the same
numbers pixel by pixel. Each pixel's three affine functions ``w_k = A_k (x - cx) + B_k (y - cy) + C_k`` come
from ``raster._face_table`` (per face, in torch), and the arithmetic here is ``_surface_at``'s, operation by
operation in its order and dtype, so the barycentrics and depth are bit-identical to it (the tests compare
them). Wherever a gradient is recorded, ``_surface_at`` runs instead and autograd sees every step.
"""
from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["faces_seen", "face_table", "pixel_surface", "sample_surface", "warm_up"]


@numba.njit(cache=True, error_model="numpy", inline="always")
def _mat3_row(M, i, x0, x1, x2):
    """Row i of ``raster._mat3(M, x)``: (x0 M[i, 0] + x1 M[i, 1]) + x2 M[i, 2]."""
    return x0 * M[i, 0] + x1 * M[i, 1] + x2 * M[i, 2]


@numba.njit(cache=True, error_model="numpy")
def face_table(used, verts, faces, R64, t64, R, Minv, omk, scale, orthographic, coef, z):
    """``raster._face_table`` face by face. used (U,) face ids; verts (V, 3) in the output dtype; R64, t64 the
    camera's R and t in float64, R in the output dtype; Minv (3, 3) = K⁻¹ᵀ and omk (1,) = 1 - K22, both
    formed in torch; scale (1,) written here: ``raster._scale_for`` of the largest |v0|, |e1|, |e2| (a first pass,
    as ``_face_table`` takes it). Writes coef (U, 9) and z (U, 3), every operation in ``_face_table``'s order and
    dtype."""
    v0 = np.empty(3, verts.dtype)                                           # float64, rounded to the dtype
    e1 = np.empty(3, verts.dtype)
    e2 = np.empty(3, verts.dtype)
    c = np.empty((3, 3), verts.dtype)
    m = 0.0
    for u in range(used.shape[0]):                                          # the largest magnitude
        f = used[u]
        a, b, d = faces[f, 0], faces[f, 1], faces[f, 2]
        for i in range(3):
            v0[i] = _mat3_row(R64, i, np.float64(verts[a, 0]), np.float64(verts[a, 1]),
                              np.float64(verts[a, 2])) + t64[i]
            e1[i] = _mat3_row(R, i, verts[b, 0] - verts[a, 0], verts[b, 1] - verts[a, 1], verts[b, 2] - verts[a, 2])
            e2[i] = _mat3_row(R, i, verts[d, 0] - verts[a, 0], verts[d, 1] - verts[a, 1], verts[d, 2] - verts[a, 2])
            m = max(m, abs(np.float64(v0[i])), abs(np.float64(e1[i])), abs(np.float64(e2[i])))
    s = 1.0                                                                 # raster._scale_for
    if 0 < m < math.inf and not (2.0 ** -32 <= m <= 2.0 ** 32):
        s = 2.0 ** -math.frexp(m)[1]
    scale[0] = s
    for u in range(used.shape[0]):
        f = used[u]
        a, b, d = faces[f, 0], faces[f, 1], faces[f, 2]
        for i in range(3):                                                  # camera-space v0, in float64
            v0[i] = _mat3_row(R64, i, np.float64(verts[a, 0]), np.float64(verts[a, 1]),
                              np.float64(verts[a, 2])) + t64[i]
        for i in range(3):                                                  # the edges, rotated only
            e1[i] = _mat3_row(R, i, verts[b, 0] - verts[a, 0], verts[b, 1] - verts[a, 1], verts[b, 2] - verts[a, 2])
            e2[i] = _mat3_row(R, i, verts[d, 0] - verts[a, 0], verts[d, 1] - verts[a, 1], verts[d, 2] - verts[a, 2])
        z[u, 0], z[u, 1], z[u, 2] = v0[2], e1[2], e2[2]                     # unscaled
        if scale[0] != 1:
            for i in range(3):                                              # exact: a power of two
                v0[i], e1[i], e2[i] = v0[i] * scale[0], e1[i] * scale[0], e2[i] * scale[0]
        # c_0 = e2 × v0, c_1 = v0 × e1, c_2 = e1 × e2 (raster._cross); orthographic: only their z, and the
        # x, y of d = +z's pairing
        z20, z01, z12 = e2[0] * v0[1] - e2[1] * v0[0], v0[0] * e1[1] - v0[1] * e1[0], e1[0] * e2[1] - e1[1] * e2[0]
        if orthographic:
            c[0, 0], c[0, 1], c[0, 2] = e2[1], -e2[0], z20
            c[1, 0], c[1, 1], c[1, 2] = -e1[1], e1[0], z01
            c[2, 0], c[2, 1], c[2, 2] = 0, 0, z12
            if scale[0] != 1:                                               # raster._face_table: the origins' part
                for k in range(3):
                    c[k, 0], c[k, 1] = c[k, 0] * scale[0], c[k, 1] * scale[0]
        else:
            c[0, 0], c[0, 1], c[0, 2] = e2[1] * v0[2] - e2[2] * v0[1], e2[2] * v0[0] - e2[0] * v0[2], z20
            c[1, 0], c[1, 1], c[1, 2] = v0[1] * e1[2] - v0[2] * e1[1], v0[2] * e1[0] - v0[0] * e1[2], z01
            c[2, 0], c[2, 1], c[2, 2] = e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], z12
        for k in range(3):                                                  # rows = c_k K⁻¹, const
            r0 = _mat3_row(Minv, 0, c[k, 0], c[k, 1], c[k, 2])
            r1 = _mat3_row(Minv, 1, c[k, 0], c[k, 1], c[k, 2])
            r2 = _mat3_row(Minv, 2, c[k, 0], c[k, 1], c[k, 2])
            coef[u, k], coef[u, 3 + k], coef[u, 6 + k] = r0, r1, r2 * omk[0] + c[k, 2]


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


@numba.njit(cache=True, error_model="numpy", inline="always")
def _surface(f, qx, qy, p, row_of_face, coef, z, one, tiny, bary, depth):
    """Write bary[p] and depth[p] of face f (-1: none) at the point whose offset to the principal point is
    (qx, qy): ``raster._surface_at``'s arithmetic, operation by operation, in the arrays' dtype."""
    if f < 0:
        bary[p, 0], bary[p, 1], bary[p, 2], depth[p] = 0, 0, 0, np.inf
        return
    r = row_of_face[f]
    w1 = coef[r, 0] * qx + coef[r, 3] * qy + coef[r, 6]                     # (A x' + B y') + C, as in torch
    w2 = coef[r, 1] * qx + coef[r, 4] * qy + coef[r, 7]
    ws = coef[r, 2] * qx + coef[r, 5] * qy + coef[r, 8]
    s = tiny if abs(ws) < tiny else ws                                       # edge-on faces: finite
    b1, b2 = w1 / s, w2 / s
    bary[p, 0], bary[p, 1], bary[p, 2] = one - b1 - b2, b1, b2
    depth[p] = z[r, 0] + b1 * z[r, 1] + b2 * z[r, 2]


@numba.njit(cache=True, error_model="numpy")
def pixel_surface(face_map, row_of_face, coef, z, xs, ys, consts, bary, depth):
    """face_map (H*W,) int64 (-1: no face); row_of_face (F,) the row of each face in coef (U, 9) and
    z (U, 3); xs (W,), ys (H,): the pixel centres' offsets x - cx, y - cy; consts (2,): 1 and the guard
    ``tiny`` for edge-on faces; all floats in one dtype. Writes bary (H*W, 3) and depth (H*W,): 0 and +inf
    where no face is visible."""
    W, H = xs.shape[0], ys.shape[0]
    one, tiny = consts[0], consts[1]
    for i in range(H):                                                      # rows and columns: no division
        for j in range(W):
            p = i * W + j
            _surface(face_map[p], xs[j], ys[i], p, row_of_face, coef, z, one, tiny, bary, depth)


@numba.njit(cache=True, error_model="numpy")
def sample_surface(face_map, row_of_face, coef, z, pixels, offsets, per_pixel, width, centre, consts, tmp, bary,
                   depth):
    """``pixel_surface`` at sub-pixel samples (``raster._sample_fragments``): face_map (P * S,) the sample
    z-buffer; pixels (P,); offsets (1, S, 2), or (P, S, 2) with ``per_pixel``; centre (2,) the principal
    point (cx, cy), consts (2,) 1 and ``tiny``, tmp (2,) scratch, all three in the output dtype: a sample's
    float64 position is rounded to that dtype by storing it in tmp, as torch's ``x.to(dtype)`` rounds it."""
    S = offsets.shape[1]
    one, tiny = consts[0], consts[1]
    for k in range(pixels.shape[0]):
        col, row = pixels[k] % width, pixels[k] // width
        for s in range(S):
            p = k * S + s
            o = k if per_pixel else 0
            tmp[0], tmp[1] = col + offsets[o, s, 0], row + offsets[o, s, 1]   # float64, rounded on store
            _surface(face_map[p], tmp[0] - centre[0], tmp[1] - centre[1], p, row_of_face, coef, z, one, tiny,
                     bary, depth)


def warm_up():
    """Compile the surface kernels for float32 and float64 (or load them from the cache)."""
    faces_seen(np.zeros(1, np.int64), 1)
    for dt in (np.float32, np.float64):
        for per_pixel in (False, True):
            sample_surface(np.zeros(2, np.int64), np.zeros(1, np.int64), np.ones((1, 9), dt), np.ones((1, 3), dt),
                           np.array([0]), np.full((1, 2, 2), 0.5), per_pixel, 4, np.zeros(2, dt), np.ones(2, dt),
                           np.zeros(2, dt), np.zeros((2, 3), dt), np.zeros(2, dt))
    for dt in (np.float32, np.float64):
        eye = np.eye(3)
        for ortho in (False, True):
            face_table(np.zeros(1, np.int64), np.eye(3, dtype=dt), np.array([[0, 1, 2]]), eye, np.ones(3),
                       eye.astype(dt), eye.astype(dt), np.zeros(1, dt), np.ones(1, dt), ortho, np.empty((1, 9), dt),
                       np.empty((1, 3), dt))
    for dt in (np.float32, np.float64):
        pixel_surface(np.zeros(1, np.int64), np.zeros(1, np.int64), np.ones((1, 9), dt), np.ones((1, 3), dt),
                      np.ones(1, dt), np.ones(1, dt), np.ones(2, dt), np.zeros((1, 3), dt), np.zeros(1, dt))
