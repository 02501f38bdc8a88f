"""The sub-pixel sample z-buffer as a compiled loop (twin of ``scan._sample_zbuffer``, lectures 05 and 06).

Supersampling asks for the nearest face at S points inside each listed pixel. Here the screen triangles are
first sorted into the listed pixels their (slightly widened) bounding boxes reach, then::

    for each listed pixel, for each of its samples:
        for each triangle in the pixel's bucket:
            covers the sample (edge functions, top-left rule)?  in front of the far plane (float32 depth)?
            keep the nearest by q (1/z, or z for an orthographic camera), noting near-ties

As in ``zbuffer``, pairs whose keys come within ``NOTE_RTOL`` of each other are noted and decided by
``scan._NearTies.resolve``, the rule the torch path applies to its float32-key near-ties, so both give the
same face at every sample.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from .points import _buckets, _covers
from .zbuffer import _plane

__all__ = ["sample_faces", "warm_up"]

NOTE_RTOL = 1e-7                # keys this close (relative) are noted for the exact tie rule


@numba.njit(cache=True, error_model="numpy")
def sample_faces(xy, q, face, pixels, offsets, per_pixel, width, height, orthographic, far, out, notes):
    """xy (T, 3, 2) float64 screen triangles (positive area), q (T, 3) their screen-affine q, face (T,) ids;
    pixels (P,) flat pixel indices; offsets (S, 2), or (P, S, 2) with ``per_pixel``, from each pixel's
    top-left corner. Writes out (P * S,) the nearest face at every sample (-1: none) and (slot, face) pairs
    of near-ties into notes (K, 2); returns the number of notes (more than K: call again with more room)."""
    n_pix = width * height
    slot_of = np.full(n_pix, -1, np.int64)
    for k in range(pixels.shape[0]):
        slot_of[pixels[k]] = k
    S = offsets.shape[-2]
    start, bucket = _buckets(xy, slot_of, pixels.shape[0], width, height)   # the listed pixels' triangles
    far32 = np.float32(far)
    n_notes, cap = 0, notes.shape[0]
    for k in range(pixels.shape[0]):
        col, row = pixels[k] % width, pixels[k] // width
        for s in range(S):
            slot = k * S + s
            if per_pixel:
                px, py = col + offsets[k, s, 0], row + offsets[k, s, 1]
            else:
                px, py = col + offsets[0, s, 0], row + offsets[0, s, 1]
            best, best_face = math.inf, -1
            for b in range(start[k], start[k + 1]):
                t = bucket[b]
                if not _covers(xy, t, px, py):
                    continue
                qa, xa, ya, qx, qy = _plane(xy, q, t)                       # scan._plane_at, operation by operation
                qp = qa + qx * (px - xa) + qy * (py - ya)
                q32 = np.float32(qp)                                        # the far plane on float32 depth
                d32 = q32 if orthographic else np.float32(1.0) / q32
                if not d32 <= far32:
                    continue
                key = qp if orthographic else -qp                           # smaller: nearer
                f = face[t]
                if best != math.inf and abs(key - best) <= NOTE_RTOL * abs(best):
                    if n_notes + 2 <= cap:                                  # a near-tie: both faces noted
                        notes[n_notes, 0], notes[n_notes, 1] = slot, f
                        notes[n_notes + 1, 0], notes[n_notes + 1, 1] = slot, best_face
                    n_notes += 2
                if key < best or (key == best and f < best_face):
                    best, best_face = key, f
            out[slot] = best_face
    return n_notes


def warm_up():
    """Compile ``sample_faces`` (or load it from the cache)."""
    xy = np.array([[[0.0, 0.0], [4.0, 0.0], [0.0, 4.0]]])
    for per_pixel in (False, True):
        off = np.full((1, 2, 2), 0.5)
        sample_faces(xy, np.ones((1, 3)), np.zeros(1, np.int64), np.array([0, 5]), off if not per_pixel else
                     np.full((2, 2, 2), 0.5), per_pixel, 4, 4, False, 10.0, np.empty(4, np.int64),
                     np.empty((8, 2), np.int64))
