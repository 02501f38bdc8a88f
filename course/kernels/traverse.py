"""The BVH walk as a compiled loop: one ray, one stack (twin of ``bvh.BVH._traverse``, lecture 07).

The pseudocode of every ray tracer::

    push the root
    while the stack is not empty:
        pop a node; skip it if the ray's segment misses its box, or enters it beyond the closest hit so far
        leaf:     test its triangles (the watertight test), keep the closest hit
        internal: push both children, the farther one first, so the nearer one is visited next

``closest_hits`` runs it for every ray, rays in parallel. It must give the face ids of ``BVH._traverse``:
the hit with the least t in [t_min, t_max], exact ties in t to the lower face id. It does, because both
compute every candidate's t with the same operations in the same order (``_watertight`` below is
``intersect._watertight`` line for line, float32 rays in float32 with the float64 fallback for edge
functions that round to zero), and both visit every leaf a ray's segment may meet: a box is skipped only
when its entry lies beyond the closest hit, compared with ``<=`` so ties are kept, and the box test widens
the exit by a few ulps as ``bvh._beam_box`` does. The order of the visits changes how much work is done,
never the answer. With ``any_hit`` a ray stops at its first hit (shadow rays), which, as in torch, may be
any of the faces it hits.
"""
from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["closest_hits", "warm_up"]

_EPS64 = float(np.finfo(np.float64).eps)
BLOCK = 64                                                                  # rays per parallel task


@numba.njit(cache=True, error_model="numpy", inline="always")
def _ray_frame(d):
    """The watertight test's per-ray constants (``intersect._watertight``): the axes kx, ky, kz (z = the
    dominant component of d, first on ties; x and y swapped when it is negative, to keep the winding) and
    the shear sx, sy, sz, in d's dtype. kz = -1 when d = 0 (no ray: it hits nothing)."""
    kz = 0
    if abs(d[1]) > abs(d[kz]):
        kz = 1
    if abs(d[2]) > abs(d[kz]):
        kz = 2
    kx, ky = (kz + 1) % 3, (kz + 2) % 3
    if d[kz] < 0:
        kx, ky = ky, kx
    dz = d[kz]
    if dz == 0:
        return -1, 0, 0, d[0], d[0], d[0]
    return kx, ky, kz, d[kx] / dz, d[ky] / dz, np.float32(1.0) / dz     # 1 / dz in d's dtype


@numba.njit(cache=True, error_model="numpy", inline="always")
def _watertight(o, kx, ky, kz, sx, sy, sz, a, b, c, is32):
    """Woop, Benthin and Wald's watertight test of one ray against one triangle, in the rays' dtype.

    o: (3,) the ray's origin, and its frame from ``_ray_frame``; a, b, c: (3,) the triangle's vertices, all
    float32 (``is32``) or all float64. Returns t (rounded to the rays' dtype, held in a float64; +inf on a
    miss), whether it hit, and the barycentric weights U, V, W (float64, before division by their sum). The
    arithmetic is ``intersect._watertight``'s, operation by operation, so t is bit-identical to it.
    """
    Ax, Ay, Az = a[kx] - o[kx], a[ky] - o[ky], a[kz] - o[kz]              # vertices relative to the origin
    Bx, By, Bz = b[kx] - o[kx], b[ky] - o[ky], b[kz] - o[kz]
    Cx, Cy, Cz = c[kx] - o[kx], c[ky] - o[ky], c[kz] - o[kz]
    ax, ay = Ax - sx * Az, Ay - sy * Az                                     # sheared, projected along z
    bx, by = Bx - sx * Bz, By - sy * Bz
    cx, cy = Cx - sx * Cz, Cy - sy * Cz
    U = np.float64(cx * by - cy * bx)                                       # edge functions, in the rays' dtype
    V = np.float64(ax * cy - ay * cx)
    W = np.float64(bx * ay - by * ax)
    if (U == 0 or V == 0 or W == 0) and is32:                               # float32: redo exactly in float64
        U = np.float64(cx) * np.float64(by) - np.float64(cy) * np.float64(bx)
        V = np.float64(ax) * np.float64(cy) - np.float64(ay) * np.float64(cx)
        W = np.float64(bx) * np.float64(ay) - np.float64(by) * np.float64(ax)
    if (U < 0 or V < 0 or W < 0) and (U > 0 or V > 0 or W > 0):
        return math.inf, False, U, V, W
    det = U + V + W
    if det == 0:
        return math.inf, False, U, V, W
    T = U * np.float64(sz * Az) + V * np.float64(sz * Bz) + W * np.float64(sz * Cz)
    t = T / det
    if not math.isfinite(t):
        return math.inf, False, U, V, W
    if is32:
        return np.float64(np.float32(t)), True, U, V, W                     # rounded as torch's .to(float32)
    return t, True, U, V, W


@numba.njit(cache=True, error_model="numpy", inline="always")
def _slab(lo, hi, o, inv, entry, exit_):
    """One axis of the slab test: the interval [entry, exit_] narrowed to where the ray lies between the
    planes lo and hi (o, inv = 1 / d, float64). An axis along which the ray does not move (inv infinite)
    constrains nothing, as in ``bvh._beam``."""
    if inv > 0 and inv != math.inf:
        return max(entry, (lo - o) * inv), min(exit_, (hi - o) * inv)
    if inv < 0 and inv != -math.inf:
        return max(entry, (hi - o) * inv), min(exit_, (lo - o) * inv)
    return entry, exit_


@numba.njit(cache=True, error_model="numpy", inline="always")
def _entry(lo, hi, node, ox, oy, oz, ix, iy, iz, t_lo, t_hi):
    """Slab test of one ray against the box of ``node`` (lo, hi (M, 3) float64): the distance at which the
    segment [t_lo, t_hi] enters the box, or +inf when it misses it. The exit is widened by 4 ulps, as in
    ``bvh._beam_box``, so rounding never drops a box the ray grazes."""
    entry, exit_ = _slab(lo[node, 0], hi[node, 0], ox, ix, t_lo, math.inf)
    entry, exit_ = _slab(lo[node, 1], hi[node, 1], oy, iy, entry, exit_)
    entry, exit_ = _slab(lo[node, 2], hi[node, 2], oz, iz, entry, exit_)
    exit_ = min(exit_ + abs(exit_) * (4 * _EPS64), t_hi)
    return entry if entry <= exit_ else math.inf


@numba.njit(cache=True, error_model="numpy", parallel=True)
def closest_hits(o, d, t_lo, t_hi, lo, hi, left, first, count, order, v0, v1, v2, any_hit, stack_size,
                 face, t_out, bary):
    """The face each ray hits first (or any face it hits, ``any_hit``), -1 on a miss.

    o, d: (N, 3) rays; t_lo, t_hi: (N,) their segments (all in the rays' dtype). The BVH (``bvh.BVH``):
    lo, hi (M, 3) float64 box corners; left (M,) first child (-1: leaf); first, count (M,) a leaf's slots;
    order (F,) the face id of each slot; v0, v1, v2 (F, 3) the triangles in slot order, in the rays' dtype.
    stack_size: more than the tree's depth. Writes face (N,) int64, t (N,) and bary (N, 3) (the rays'
    dtype; +inf and 0 on a miss), as ``BVH.intersect`` returns them.
    """
    N = o.shape[0]
    is32 = o.itemsize == 4
    n_blocks = (N + BLOCK - 1) // BLOCK
    for blk in numba.prange(n_blocks):
        stack = np.empty(stack_size, np.int64)                               # nodes still to visit
        enter = np.empty(stack_size, np.float64)                             # and where the ray enters them
        for r in range(blk * BLOCK, min(N, (blk + 1) * BLOCK)):
            face[r], t_out[r] = -1, math.inf
            bary[r, 0], bary[r, 1], bary[r, 2] = 0, 0, 0
            kx, ky, kz, sx, sy, sz = _ray_frame(d[r])
            if kz < 0:
                continue
            orig = o[r]
            ox, oy, oz = np.float64(orig[0]), np.float64(orig[1]), np.float64(orig[2])
            ix, iy, iz = 1.0 / np.float64(d[r, 0]), 1.0 / np.float64(d[r, 1]), 1.0 / np.float64(d[r, 2])
            lo_r, hi_r = np.float64(t_lo[r]), np.float64(t_hi[r])
            best = hi_r                                                      # the closest hit so far
            best_face = -1
            bu, bv, bw = 0.0, 0.0, 0.0
            e = _entry(lo, hi, 0, ox, oy, oz, ix, iy, iz, lo_r, hi_r)
            if e == math.inf:
                continue
            stack[0], enter[0] = 0, e
            top = 1
            while top > 0:
                top -= 1
                node = stack[top]
                if enter[top] > best:                                        # nothing closer in there
                    continue
                if count[node] > 0:                                          # a leaf: its triangles
                    for s in range(first[node], first[node] + count[node]):
                        t, hit, U, V, W = _watertight(orig, kx, ky, kz, sx, sy, sz, v0[s], v1[s], v2[s], is32)
                        if hit and t >= lo_r and t <= best:
                            f = order[s]
                            if t < best or best_face < 0 or f < best_face:
                                best, best_face, bu, bv, bw = t, f, U, V, W
                    if any_hit and best_face >= 0:
                        break
                else:                                                        # internal: both children
                    c = left[node]
                    e1 = _entry(lo, hi, c, ox, oy, oz, ix, iy, iz, lo_r, hi_r)
                    e2 = _entry(lo, hi, c + 1, ox, oy, oz, ix, iy, iz, lo_r, hi_r)
                    near, far, e_near, e_far = c, c + 1, e1, e2
                    if e2 < e1:
                        near, far, e_near, e_far = c + 1, c, e2, e1
                    if e_far <= best:
                        stack[top], enter[top] = far, e_far
                        top += 1
                    if e_near <= best:
                        stack[top], enter[top] = near, e_near
                        top += 1
            if best_face >= 0:
                det = bu + bv + bw
                face[r], t_out[r] = best_face, best
                bary[r, 0], bary[r, 1], bary[r, 2] = bu / det, bv / det, bw / det


def warm_up():
    """Compile ``closest_hits`` for float32 and float64 rays (or load it from the cache)."""
    lo = np.array([[0.0, 0.0, 0.0]])
    hi = np.array([[1.0, 1.0, 0.0]])
    idx = np.zeros(1, np.int64)
    for dt in (np.float32, np.float64):
        tri = [np.array([[0, 0, 0]], dt), np.array([[1, 0, 0]], dt), np.array([[0, 1, 0]], dt)]
        o, d = np.array([[0.2, 0.2, -1]], dt), np.array([[0, 0, 1]], dt)
        t0, t1 = np.zeros(1, dt), np.full(1, np.inf, dt)
        closest_hits(o, d, t0, t1, lo, hi, np.full(1, -1, np.int64), idx, np.ones(1, np.int64), idx, *tri,
                     False, 4, np.empty(1, np.int64), np.empty(1, dt), np.empty((1, 3), dt))
