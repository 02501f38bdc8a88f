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
when its entry lies beyond the closest hit by more than a few ulps of the rays' dtype (a hit exactly on a
box's face, found first through a neighbour with the same t, must not drop the box), and the box test widens
the exit by as much, more than ``bvh._beam_box`` does. The order of the visits changes how much work is done,
never the answer. With ``any_hit`` a ray stops at its first hit (shadow rays), which, as in torch, may be
any of the faces it hits.
"""
from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["closest_hits", "warm_up"]

_EPS64 = float(np.finfo(np.float64).eps)
_EPS32 = float(np.finfo(np.float32).eps)
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
        return 0, 0, -1, d[0], d[0], d[0]
    return kx, ky, kz, d[kx] / dz, d[ky] / dz, np.float32(1.0) / dz     # 1 / dz in d's dtype


@numba.njit(cache=True, error_model="numpy", inline="always")
def _watertight(o, kx, ky, kz, sx, sy, sz, a, b, c, s, is32):
    """Woop, Benthin and Wald's watertight test of one ray against one triangle, in the rays' dtype.

    o: (3,) the ray's origin, and its frame from ``_ray_frame``; a, b, c: (F, 3) the triangles' corners and s
    the one to test, all float32 (``is32``) or all float64. Returns t (rounded to the rays' dtype, held in a
    float64; +inf on a miss), whether it hit, and the barycentric weights U, V, W (float64, before division by
    their sum). The arithmetic is ``intersect._watertight``'s, operation by operation, so t is bit-identical.
    """
    ox, oy, oz = o[kx], o[ky], o[kz]
    Ax, Ay, Az = a[s, kx] - ox, a[s, ky] - oy, a[s, kz] - oz              # vertices relative to the origin
    Bx, By, Bz = b[s, kx] - ox, b[s, ky] - oy, b[s, kz] - oz
    Cx, Cy, Cz = c[s, kx] - ox, c[s, ky] - oy, c[s, kz] - oz
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
def _entry(boxes, node, ox, oy, oz, ix, iy, iz, nx, ny, nz, cx, cy, cz, t_lo, t_hi, tol):
    """Slab test of one ray against the box of ``node``: the distance at which the segment [t_lo, t_hi]
    enters the box, or +inf when it misses it.

    boxes: (M, 2, 3) float64 min and max corners. Along axis x the ray crosses the box's planes at
    ``(plane - ox) * ix`` (ix = 1 / d_x), the near plane first: nx = 0 (the min corner) when ix > 0, 1 when
    ix < 0. An axis along which the ray does not move (d_x = 0) constrains nothing, as in ``bvh._beam``: its
    ix is set to 0 and its cap cx to -inf, so the entry there is min(0, -inf) = -inf and the exit +inf (no
    branch per box). The exit is widened by ``tol`` (relative) so that rounding never drops a box the ray
    grazes: a hit's t carries the rounding of the rays' dtype."""
    entry = max(max(max(t_lo, min((boxes[node, nx, 0] - ox) * ix, cx)), min((boxes[node, ny, 1] - oy) * iy, cy)),
                min((boxes[node, nz, 2] - oz) * iz, cz))
    exit_ = min(min(max((boxes[node, 1 - nx, 0] - ox) * ix, -cx), max((boxes[node, 1 - ny, 1] - oy) * iy, -cy)),
                max((boxes[node, 1 - nz, 2] - oz) * iz, -cz))
    exit_ = min(exit_ + abs(exit_) * tol, t_hi + abs(t_hi) * tol)
    return entry if entry <= exit_ else math.inf


@numba.njit(cache=True, error_model="numpy", inline="always")
def _axis(d):
    """Per ray and axis: 1 / d (0 where d = 0, or where 1 / d overflows), which corner is near, and the cap."""
    inv = 1.0 / np.float64(d)
    if math.isinf(inv):
        return 0.0, 0, -math.inf
    return inv, (0 if inv > 0 else 1), math.inf


@numba.njit(cache=True, error_model="numpy", parallel=True)
def closest_hits(o, d, t_lo, t_hi, boxes, left, first, count, order, v0, v1, v2, any_hit, stack_size,
                 face, t_out, bary):
    """The face each ray hits first (or any face it hits, ``any_hit``), -1 on a miss.

    o, d: (N, 3) rays; t_lo, t_hi: (N,) their segments (all in the rays' dtype). The BVH (``bvh.BVH``):
    boxes (M, 2, 3) float64 min and max corners; left (M,) first child (-1: leaf; the second child is
    left + 1); first, count (M,) a leaf's slots; order (F,) the face id of each slot; v0, v1, v2 (F, 3) the
    triangles in slot order, in the rays' dtype. stack_size: more than the tree's depth. Writes face (N,)
    int64, t (N,) and bary (N, 3) (the rays' dtype; +inf and 0 on a miss), as ``BVH.intersect`` returns them.
    """
    N = o.shape[0]
    is32 = o.itemsize == 4
    tol = 16 * (_EPS32 if is32 else _EPS64)                                  # a few ulps of a hit's t, relative
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
            ix, nx, cx = _axis(d[r, 0])
            iy, ny, cy = _axis(d[r, 1])
            iz, nz, cz = _axis(d[r, 2])
            lo_r, hi_r = np.float64(t_lo[r]), np.float64(t_hi[r])
            best = hi_r                                                      # the closest hit so far
            best_face = -1
            bu, bv, bw = 0.0, 0.0, 0.0
            if _entry(boxes, 0, ox, oy, oz, ix, iy, iz, nx, ny, nz, cx, cy, cz, lo_r, hi_r, tol) == math.inf:
                continue
            node, top = 0, 0
            while True:
                if count[node] > 0:                                          # a leaf: its triangles
                    for s in range(first[node], first[node] + count[node]):
                        t, hit, U, V, W = _watertight(orig, kx, ky, kz, sx, sy, sz, v0, v1, v2, s, is32)
                        if hit and t >= lo_r and t <= best:
                            f = order[s]
                            if t < best or best_face < 0 or f < best_face:
                                best, best_face, bu, bv, bw = t, f, U, V, W
                    if any_hit and best_face >= 0:
                        break
                    node = -1
                else:                                                        # internal: the children it meets
                    c = left[node]
                    e1 = _entry(boxes, c, ox, oy, oz, ix, iy, iz, nx, ny, nz, cx, cy, cz, lo_r, hi_r, tol)
                    e2 = _entry(boxes, c + 1, ox, oy, oz, ix, iy, iz, nx, ny, nz, cx, cy, cz, lo_r, hi_r, tol)
                    bound = best + abs(best) * tol                           # nothing closer beyond this
                    ok1, ok2 = e1 < math.inf and e1 <= bound, e2 < math.inf and e2 <= bound   # inf: missed
                    if ok1 and ok2:                                          # both: the nearer next, the other later
                        if e2 < e1:
                            stack[top], enter[top], node = c, e1, c + 1
                        else:
                            stack[top], enter[top], node = c + 1, e2, c
                        top += 1
                    elif ok1:
                        node = c
                    elif ok2:
                        node = c + 1
                    else:
                        node = -1
                if node < 0:                                                 # pop a node that may hold a closer hit
                    while top > 0:
                        top -= 1
                        if enter[top] <= best + abs(best) * tol:
                            node = stack[top]
                            break
                    if node < 0:
                        break
            if best_face >= 0:
                det = bu + bv + bw
                face[r], t_out[r] = best_face, best
                bary[r, 0], bary[r, 1], bary[r, 2] = bu / det, bv / det, bw / det


def warm_up():
    """Compile ``closest_hits`` for float32 and float64 rays (or load it from the cache)."""
    boxes = np.array([[[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]]])
    idx = np.zeros(1, np.int64)
    for dt in (np.float32, np.float64):
        tri = [np.array([[0, 0, 0]], dt), np.array([[1, 0, 0]], dt), np.array([[0, 1, 0]], dt)]
        o, d = np.array([[0.2, 0.2, -1]], dt), np.array([[0, 0, 1]], dt)
        t0, t1 = np.zeros(1, dt), np.full(1, np.inf, dt)
        closest_hits(o, d, t0, t1, boxes, np.full(1, -1, np.int64), idx, np.ones(1, np.int64), idx, *tri,
                     False, 4, np.empty(1, np.int64), np.empty(1, dt), np.empty((1, 3), dt))
