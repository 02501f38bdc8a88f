"""Ray–triangle and ray–box tests (lecture 07): the two questions a ray tracer asks most.

**Ray–triangle.** ``intersect_triangles`` is the watertight test of Woop, Benthin and Wald (2013). Each ray
is turned into the +z axis by a permutation of the axes (z = the largest component of the direction) and a
shear; the triangle, translated to the ray origin, is projected along z, and the ray hits when the origin
(0, 0) lies inside the projected triangle. Inside-ness is three 2-D edge functions U, V, W. An edge shared
by two triangles gives bit-identical values of opposite sign in both (the same products of the same sheared
vertex coordinates), so a ray can not slip through the crack between them; an edge function that rounds to
exactly 0 in float32 is recomputed in float64, where the product difference is exact. The textbook
Möller–Trumbore test (``moller_trumbore``) computes each triangle's barycentrics with its own rounding
and does leak: rays aimed at a shared edge can miss both triangles (``tests/test_raytrace.py`` finds some).

**Ray–box.** ``ray_box`` is the slab test (Kay and Kajiya 1986): a ray meets an axis-aligned box when the
intervals of t in which it lies between each pair of parallel planes overlap. The BVH's traversal
(``course.bvh``) runs the same test on many (ray, node) pairs at once (``_slab``).
"""
from __future__ import annotations

import math

import torch

from .tensors import _check_finite, as_tensor

__all__ = ["intersect_triangles", "moller_trumbore", "ray_box"]


# ---------------------------------------------------------------------------------------- input checks

def _rays_and_tris(origins, directions, tris):
    o = as_tensor(origins, name="origins")
    dtype = torch.promote_types(o.dtype, as_tensor(directions, name="directions").dtype)
    tris = as_tensor(tris, name="tris")
    dtype = torch.promote_types(dtype, tris.dtype)
    o = o.to(dtype)
    d = as_tensor(directions, dtype=dtype, device=o.device, name="directions")
    tris = tris.to(dtype=dtype, device=o.device)
    if o.dim() != 2 or o.shape[1] != 3 or d.shape != o.shape:
        raise ValueError(f"origins and directions must both have shape (N, 3), got {tuple(o.shape)} and "
                         f"{tuple(d.shape)}")
    if tris.shape != (o.shape[0], 3, 3):
        raise ValueError(f"tris must have shape (N, 3, 3) with N = {o.shape[0]}, got {tuple(tris.shape)}")
    for x, name in ((o, "origins"), (d, "directions"), (tris, "tris")):
        _check_finite(x, name)
    return o, d, tris


# ------------------------------------------------------------------------------------ ray–triangle tests

def _watertight(o, d, v0, v1, v2):
    """The watertight test on (N,) pairs: o, d, v0, v1, v2 (N, 3). Returns t (N,), bary (N, 3), hit (N,)."""
    dtype = o.dtype
    kz = d.abs().argmax(1)                                                  # the dominant axis becomes z
    kx, ky = (kz + 1) % 3, (kz + 2) % 3
    flip = d.gather(1, kz[:, None])[:, 0] < 0                               # keep the winding: swap x and y
    kx, ky = torch.where(flip, ky, kx), torch.where(flip, kx, ky)
    perm = torch.stack([kx, ky, kz], 1)                                     # (N, 3)
    dp = d.gather(1, perm)
    dz = torch.where(dp[:, 2] == 0, torch.ones_like(dp[:, 2]), dp[:, 2])    # d = 0: no ray, a miss below
    sx, sy, sz = dp[:, 0] / dz, dp[:, 1] / dz, 1 / dz                       # the shear
    A, B, C = ((v - o).gather(1, perm) for v in (v0, v1, v2))               # vertices relative to the origin
    ax, ay = A[:, 0] - sx * A[:, 2], A[:, 1] - sy * A[:, 2]                 # sheared, projected along z
    bx, by = B[:, 0] - sx * B[:, 2], B[:, 1] - sy * B[:, 2]
    cx, cy = C[:, 0] - sx * C[:, 2], C[:, 1] - sy * C[:, 2]
    U, V, W = cx * by - cy * bx, ax * cy - ay * cx, bx * ay - by * ax       # edge functions: weights of v0, v1, v2
    if dtype != torch.float64:
        # an edge function that rounded to exactly 0 decides nothing: redo all three in float64, where the
        # difference of two products of float32 numbers is exact (Woop et al., section 3.4)
        U, V, W = U.double(), V.double(), W.double()
        zero = ((U == 0) | (V == 0) | (W == 0)).nonzero().squeeze(1)
        if zero.numel():
            g = [q.index_select(0, zero).double() for q in (ax, ay, bx, by, cx, cy)]
            U[zero] = g[4] * g[3] - g[5] * g[2]
            V[zero] = g[0] * g[5] - g[1] * g[4]
            W[zero] = g[2] * g[1] - g[3] * g[0]
    neg = (U < 0) | (V < 0) | (W < 0)
    pos = (U > 0) | (V > 0) | (W > 0)
    det = U + V + W
    hit = ~(neg & pos) & (det != 0) & (dp[:, 2] != 0)                       # all >= 0 or all <= 0
    az, bz, cz = sz * A[:, 2], sz * B[:, 2], sz * C[:, 2]
    T = U * az.to(U.dtype) + V * bz.to(U.dtype) + W * cz.to(U.dtype)
    safe = torch.where(det == 0, torch.ones_like(det), det)
    t = torch.where(hit, T / safe, torch.full_like(T, math.inf))
    bary = torch.where(hit[:, None], torch.stack([U, V, W], 1) / safe[:, None], torch.zeros_like(safe)[:, None])
    hit &= torch.isfinite(t)
    return t.to(dtype), bary.to(dtype), hit


def intersect_triangles(origins, directions, tris):
    """The watertight ray–triangle test (Woop, Benthin and Wald 2013), one triangle per ray.

    origins, directions: (N, 3) (directions need not be unit; t is in their units); tris: (N, 3, 3) the
    triangle tested against each ray. Returns ``t`` (N,) ray parameter of the hit (``o + t d``, +inf on a
    miss; negative t is a hit behind the origin, filter it yourself), ``bary`` (N, 3) weights of the hit
    point on (v0, v1, v2) (0 on a miss) and ``hit`` (N,) bool. Both windings hit (no culling). A ray
    through a shared edge or vertex of a closed mesh hits at least one of the triangles there; a ray in
    the plane of a triangle misses it.
    """
    o, d, tris = _rays_and_tris(origins, directions, tris)
    return _watertight(o, d, tris[:, 0], tris[:, 1], tris[:, 2])


def moller_trumbore(origins, directions, tris):
    """The textbook Möller–Trumbore test (1997), same arguments and results as ``intersect_triangles``.

    Barycentrics by Cramer's rule: ``u = (T · (d × e2)) / det``, ``v = (d · (T × e1)) / det`` with
    ``T = o - v0``, ``e1 = v1 - v0``, ``e2 = v2 - v0``, ``det = e1 · (d × e2)``. Each triangle rounds its
    own u and v, so along an edge shared by two triangles both can reject the ray: it is not watertight.
    """
    o, d, tris = _rays_and_tris(origins, directions, tris)
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    p = torch.linalg.cross(d, e2)
    det = (e1 * p).sum(1)
    safe = torch.where(det == 0, torch.ones_like(det), det)
    T = o - v0
    u = (T * p).sum(1) / safe
    q = torch.linalg.cross(T, e1)
    v = (d * q).sum(1) / safe
    t = (e2 * q).sum(1) / safe
    hit = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1)
    t = torch.where(hit, t, torch.full_like(t, math.inf))
    bary = torch.where(hit[:, None], torch.stack([1 - u - v, u, v], 1), torch.zeros_like(t)[:, None])
    return t, bary, hit


# ---------------------------------------------------------------------------------------------- ray–box

def ray_box(origins, directions, lo, hi):
    """The slab test (Kay and Kajiya 1986): where N rays meet N axis-aligned boxes.

    origins, directions, lo, hi: (N, 3); box k is the closed box [lo_k, hi_k]. Along axis a the ray lies
    between the box's two planes for t between (lo_a - o_a) / d_a and (hi_a - o_a) / d_a (the smaller is the
    entry); with d_a = 0 it lies between them for every t when lo_a <= o_a <= hi_a and never otherwise.
    Returns ``hit`` (N,) bool, ``t_near`` and ``t_far`` (N,): the largest entry and the smallest exit, and
    ``hit = t_near <= t_far and t_far >= 0`` (t_near < 0: the origin is inside the box). The BVH's traversal
    uses the same test on many (ray, node) pairs at once (``_slab``), clipped to each ray's [t_min, t_max].
    """
    o = as_tensor(origins, name="origins")
    d, lo, hi = (as_tensor(x, dtype=o.dtype, device=o.device, name=n)
                 for x, n in ((directions, "directions"), (lo, "lo"), (hi, "hi")))
    if not (o.shape == d.shape == lo.shape == hi.shape) or o.dim() != 2 or o.shape[1] != 3:
        raise ValueError(f"origins, directions, lo and hi must all have shape (N, 3), got {tuple(o.shape)}, "
                         f"{tuple(d.shape)}, {tuple(lo.shape)} and {tuple(hi.shape)}")
    _check_finite(o, "origins"), _check_finite(d, "directions")
    _check_finite(lo, "lo", allow_inf=True), _check_finite(hi, "hi", allow_inf=True)
    if bool((lo > hi).any()):
        raise ValueError("lo must not exceed hi: box k is [lo_k, hi_k], its min and max corners")
    a, b = (lo - o) / d, (hi - o) / d                                       # ±inf or NaN where d = 0
    near, far = torch.minimum(a, b), torch.maximum(a, b)
    parallel, between = d == 0, (o >= lo) & (o <= hi)
    inf = torch.full_like(near, math.inf)
    near = torch.where(parallel, torch.where(between, -inf, inf), near)
    far = torch.where(parallel, torch.where(between, inf, -inf), far)
    t_near, t_far = near.amax(-1), far.amin(-1)
    return (t_near <= t_far) & (t_far >= 0), t_near, t_far


def _slab(o, inv, box, t_lo, t_hi):
    """Does the segment o + t d, t in [t_lo, t_hi], meet the box? o, inv = 1/d (..., 3); box (..., 2, 3)
    min and max corners; t_lo, t_hi (...). Returns (...) bool.

    A direction component of 0 has inv = ±inf: the slab gives ±inf entry and exit, except when the origin
    lies exactly on the slab's plane, where 0 · inf = NaN; that case counts as inside the slab (the ray runs
    in the plane, on the box's face). The exit distance is widened by a few ulps (Ize 2013, "Robust BVH ray
    traversal") so rounding never culls a box the ray grazes.
    """
    a = (box[..., 0, :] - o).mul_(inv)
    b = (box[..., 1, :] - o).mul_(inv)
    near = torch.minimum(a, b).nan_to_num_(nan=-math.inf, posinf=math.inf, neginf=-math.inf)
    far = torch.maximum(a, b).nan_to_num_(nan=math.inf, posinf=math.inf, neginf=-math.inf)
    far = far.amin(-1)
    entry = torch.maximum(near.amax(-1), t_lo)
    exit_ = torch.minimum(far + far.abs() * (4 * torch.finfo(o.dtype).eps), t_hi)
    return entry <= exit_
