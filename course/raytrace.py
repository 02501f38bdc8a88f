"""Ray tracing: ray–triangle tests, a BVH, ``raycast`` → Fragments, shadow rays and area lights (lecture 07).

Rasterization asks "which pixels does this triangle cover?"; ray tracing asks the transposed question,
"which triangle does this ray hit first?". Both answer with the same ``Fragments``, so every shader works on
both, and ``raycast`` takes its barycentrics and depth from the very function ``rasterize`` uses
(``raster._surface_at``): the two visibility stages hand identical, differentiable inputs to shading.

**Ray–triangle.** ``intersect_triangles`` is the watertight test of Woop, Benthin and Wald (2013). Each ray
is turned into the +z axis by a permutation of the axes (z = the largest component of the direction) and a
shear; the triangle, translated to the ray origin, is projected along z, and the ray hits when the origin
(0, 0) lies inside the projected triangle. Inside-ness is three 2-D edge functions U, V, W. An edge shared
by two triangles gives bit-identical values of opposite sign in both (the same products of the same sheared
vertex coordinates), so a ray can not slip through the crack between them; an edge function that rounds to
exactly 0 in float32 is recomputed in float64, where the product difference is exact. The textbook
Möller–Trumbore test (``moller_trumbore``) computes each triangle's barycentrics with its own rounding
and does leak: rays aimed at a shared edge can miss both triangles (``tests/test_raytrace.py`` finds some).

**The BVH** (bounding volume hierarchy) is a binary tree of axis-aligned boxes; a ray skips every subtree
whose box it misses. ``BVH(mesh)`` builds a *linear* BVH (LBVH, Lauterbach et al. 2009, Karras 2012)
without a Python loop per node:

1. every triangle's centroid gets a 63-bit Morton code (21 bits per axis, interleaved): sorting by it
   lays the triangles out along a Z-order space-filling curve, so nearby triangles sit nearby in memory;
2. the root owns the whole sorted range; level by level, every range of more than ``leaf_size``
   triangles is split where its highest differing Morton bit flips (one ``searchsorted`` for the whole
   level) — that is a spatial median split on an octree plane; ranges of identical codes split in half;
3. boxes are reduced bottom-up: leaves by one ``scatter_reduce`` (amin / amax) over their triangles,
   then each level's internal nodes from their two children.

Nodes are numbered breadth-first and the two children of a node are consecutive (``left``, ``left + 1``).
The flat tensors: ``boxes`` (M, 2, 3) min and max corners, ``left`` (M,) first child (-1 for a leaf),
``first`` / ``count`` (M,) the leaf's range in ``order`` (count 0 for internal nodes), ``order`` (F,) the
face id of each sorted slot, ``tris`` (F, 3, 3) the sorted triangles.

**Traversal of many rays at once** (``BVH.intersect``), in three vectorised stages with no Python loop per
ray or per node visit:

1. *Packets down the tree.* Consecutive rays go down together in packets of 16 (``raycast`` orders its
   pixels in 4 x 4 tiles), each packet bounded by the box of its origins and the interval of its inverse
   directions. A frontier of (packet, node) pairs is processed level by level: a node is kept when some ray
   of the packet may meet its box (``_beam_box``, a slab test on intervals that never drops a box a ray
   meets), and the leaves reached are collected. One box test then serves 16 rays. Rays that are not
   coherent (random directions) are split into packets of one ray, the plain per-ray frontier.
2. *Rays into leaves.* Each (packet, leaf) pair becomes one (ray, leaf) pair per ray of the packet, kept
   when that ray's segment [t_min, t_max] meets the leaf's box, with the distance at which it enters it.
3. *Nearest leaf first.* In rounds, every ray tests the triangles of its nearest remaining leaf with the
   watertight test and keeps its closest hit (a ``scatter_reduce`` amin on t; ties go to the lower face
   id). A leaf whose box the ray enters beyond its closest hit so far cannot hold a closer hit and is
   dropped, so most rays finish in a round or two; with ``any_hit`` a ray stops at its first hit (enough
   for shadows). Rays are processed in chunks so memory stays bounded.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from .raster import Fragments, _check_inputs, _surface_at
from .tensors import as_tensor

__all__ = ["intersect_triangles", "moller_trumbore", "ray_box", "morton_codes", "BVH", "Hits", "raycast", "visible",
           "rectangle_light_samples", "disk_light_samples"]

PACKET = 16             # rays per packet in BVH.intersect (a 4 x 4 pixel tile of primary rays)
PACKET_SPREAD = 0.05    # a packet stays together while its unit directions differ by at most this per component


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


# ----------------------------------------------------------------------------------------------- the BVH

def _spread_bits(x):
    """Spread the low 21 bits of x (int64) to every third bit: b20..b0 → b20 0 0 b19 0 0 ... b0."""
    x = x & 0x1FFFFF
    x = (x | (x << 32)) & 0x1F00000000FFFF
    x = (x | (x << 16)) & 0x1F0000FF0000FF
    x = (x | (x << 8)) & 0x100F00F00F00F00F
    x = (x | (x << 4)) & 0x10C30C30C30C30C3
    x = (x | (x << 2)) & 0x1249249249249249
    return x


def morton_codes(points):
    """63-bit Morton codes (int64) of points (N, 3), quantised to 2^21 cells per axis of their bounding box."""
    p = points.double()
    lo, hi = p.min(0).values, p.max(0).values
    scale = torch.where(hi > lo, (2**21 - 1) / (hi - lo), torch.zeros_like(hi))
    q = ((p - lo) * scale).long().clamp(0, 2**21 - 1)                     # (N, 3)
    return (_spread_bits(q[:, 0]) << 2) | (_spread_bits(q[:, 1]) << 1) | _spread_bits(q[:, 2])


def _highest_bit(x):
    """Index of the highest set bit of positive int64 x (binary search with shifts, exact for every value)."""
    bit = torch.zeros_like(x)
    for s in (32, 16, 8, 4, 2, 1):
        up = (x >> (bit + s)) != 0
        bit = bit + s * up.long()
    return bit


@dataclass
class Hits:
    """Result of ``BVH.intersect`` for N rays.

    face_id: (N,) int64, the face hit (the closest one; any one with ``any_hit``), -1 on a miss.
    t:       (N,) ray parameter of the hit point ``o + t d``, +inf on a miss.
    bary:    (N, 3) barycentric weights of the hit point on the face's (v0, v1, v2), 0 on a miss.
    """
    face_id: torch.Tensor
    t: torch.Tensor
    bary: torch.Tensor

    @property
    def hit(self) -> torch.Tensor:
        """(N,) bool, True where the ray hit a face."""
        return self.face_id >= 0


class BVH:
    """A linear BVH over a triangle mesh (see the module docstring), built vectorised in torch.

    mesh: anything with ``verts`` (V, 3) and ``faces`` (F, 3) (detached: the BVH answers which face, not
    how the hit moves). leaf_size: most triangles per leaf. Attributes: ``boxes`` (M, 2, 3) min / max
    corner of each node, ``left`` (M,) int64 first child (the second is ``left + 1``; -1 for a leaf),
    ``first`` and ``count`` (M,) int64 the leaf's slots in ``order`` (count 0 for internal nodes),
    ``order`` (F,) int64 face id of each slot, ``tris`` (F, 3, 3) the triangles in slot order, ``depth``
    the number of levels, ``bounds`` (2, 3) the scene's box (the root's).
    """

    def __init__(self, mesh, *, leaf_size: int = 4):
        verts, faces = getattr(mesh, "verts", None), getattr(mesh, "faces", None)
        if not isinstance(verts, torch.Tensor) or verts.dim() != 2 or verts.shape[1] != 3:
            raise ValueError(f"mesh.verts must be a (V, 3) tensor, got {getattr(verts, 'shape', type(verts))}")
        if not isinstance(faces, torch.Tensor) or faces.dim() != 2 or faces.shape[1] != 3:
            raise ValueError(f"mesh.faces must be an (F, 3) tensor, got {getattr(faces, 'shape', type(faces))}")
        if int(leaf_size) < 1:
            raise ValueError(f"leaf_size must be >= 1, got {leaf_size}")
        verts = verts.detach()
        if not verts.is_floating_point():
            verts = verts.to(torch.get_default_dtype())
        if not torch.isfinite(verts).all():
            raise ValueError("mesh.verts contains NaN or inf")
        faces = faces.long()
        if faces.numel() and (int(faces.min()) < 0 or int(faces.max()) >= verts.shape[0]):
            raise ValueError("mesh.faces index vertices out of range")
        self.leaf_size = int(leaf_size)
        self.dtype, self.device = verts.dtype, verts.device
        F = faces.shape[0]
        tris = verts[faces]                                                 # (F, 3, 3)
        if F == 0:
            z = torch.zeros(0, dtype=torch.int64, device=self.device)
            self.boxes, self.left, self.first, self.count = verts.new_zeros((0, 2, 3)), z, z, z
            self.order, self.tris, self.depth, self._slot = z, tris, 0, z
            self.bounds = verts.new_zeros((2, 3))
            self._centre, self._half, self._diag = self.bounds[:0].double(), self.bounds[:0].double(), 0.0
            return
        codes = morton_codes(tris.mean(1))
        codes, order = torch.sort(codes, stable=True)
        self.order, self.tris = order, tris[order]
        self._build(codes)

    def _build(self, codes):
        """The topology, level by level, then the boxes bottom-up."""
        F, dev = codes.shape[0], codes.device
        lo, hi = torch.zeros(1, dtype=torch.int64, device=dev), torch.full((1,), F, dtype=torch.int64, device=dev)
        node_lo, node_hi, left, level_start = [lo], [hi], [], [0]
        n_nodes = 1
        while True:
            split_me = (hi - lo) > self.leaf_size                           # (L,) internal nodes of this level
            child = torch.full_like(lo, -1)
            k = split_me.nonzero().squeeze(1)
            if k.numel():
                child[k] = n_nodes + 2 * torch.arange(k.numel(), device=dev)
            left.append(child)
            if not k.numel():
                break
            a, b = lo[k], hi[k]
            ca, cb = codes[a], codes[b - 1]
            diff = ca ^ cb
            bit = _highest_bit(diff.clamp_min(1))
            first_set = ((ca >> bit) | 1) << bit                            # common prefix, then the bit set
            split = torch.searchsorted(codes, first_set)
            split = torch.where(diff == 0, (a + b) // 2, split)             # identical codes: halve the range
            lo = torch.stack([a, split], 1).reshape(-1)                     # children, left then right
            hi = torch.stack([split, b], 1).reshape(-1)
            level_start.append(n_nodes)
            n_nodes += lo.numel()
            node_lo.append(lo), node_hi.append(hi)
        lo, hi, self.left = torch.cat(node_lo), torch.cat(node_hi), torch.cat(left)
        leaf = self.left < 0
        self.first = torch.where(leaf, lo, torch.zeros_like(lo))
        self.count = torch.where(leaf, hi - lo, torch.zeros_like(lo))
        self.depth = len(level_start)
        # boxes: leaves from their triangles (one scatter), then internal nodes level by level, deepest first
        leaves = leaf.nonzero().squeeze(1)
        counts = self.count[leaves]
        slots = torch.repeat_interleave(lo[leaves], counts) + _ranks(counts)   # every slot, leaf by leaf
        slot_leaf = torch.empty(F, dtype=torch.int64, device=dev)           # the leaf owning each slot
        slot_leaf[slots] = torch.repeat_interleave(leaves, counts)
        M = lo.numel()
        boxes_min = torch.full((M, 3), math.inf, dtype=self.dtype, device=dev)
        boxes_max = torch.full((M, 3), -math.inf, dtype=self.dtype, device=dev)
        idx = slot_leaf[:, None].expand(-1, 3)
        boxes_min.scatter_reduce_(0, idx, self.tris.amin(1), reduce="amin")
        boxes_max.scatter_reduce_(0, idx, self.tris.amax(1), reduce="amax")
        for s, e in reversed(list(zip(level_start, level_start[1:] + [M]))):
            nodes = torch.arange(s, e, device=dev)
            nodes = nodes[self.left[nodes] >= 0]
            if nodes.numel():
                c = self.left[nodes]
                boxes_min[nodes] = torch.minimum(boxes_min[c], boxes_min[c + 1])
                boxes_max[nodes] = torch.maximum(boxes_max[c], boxes_max[c + 1])
        self.boxes = torch.stack([boxes_min, boxes_max], 1)                 # (M, 2, 3)
        self.bounds = self.boxes[0]
        lo, hi = boxes_min.double(), boxes_max.double()                     # (M, 3) each, for traversal:
        self._centre, self._half = (lo + hi) / 2, (hi - lo) / 2             # centre ± half is exact
        self._diag = float((self.bounds[1] - self.bounds[0]).norm())
        self._slot = torch.empty_like(self.order)
        self._slot[self.order] = torch.arange(F, device=dev)                # slot of each face id

    @property
    def num_nodes(self) -> int:
        return self.boxes.shape[0]

    # ------------------------------------------------------------------------------------- traversal

    def intersect(self, origins, directions, *, t_min=0.0, t_max=math.inf, any_hit: bool = False,
                  packet: int = PACKET, chunk: int = 1 << 16) -> Hits:
        """The closest hit of every ray (or any hit, ``any_hit=True``) with t in [t_min, t_max].

        origins, directions: (N, 3) world space (directions need not be unit: t is in their units);
        t_min, t_max: floats or (N,) tensors. Computed in the promoted dtype of the rays and the mesh.
        Ties in t go to the lower face id. Returns ``Hits`` (face_id (N,), t (N,), bary (N, 3)).
        packet: rays per packet (consecutive rays go down the tree together when they are coherent, see
        ``_traverse``); order coherent rays next to each other (``raycast`` orders pixels in 4 x 4 tiles).
        1 traces every ray alone. The hits do not depend on it.
        """
        if int(packet) < 1:
            raise ValueError(f"packet must be >= 1, got {packet}")
        o = as_tensor(origins, name="origins")
        d = as_tensor(directions, name="directions")
        dtype = torch.promote_types(torch.promote_types(o.dtype, d.dtype), self.dtype)
        o, d = o.to(dtype=dtype, device=self.device), d.to(dtype=dtype, device=self.device)
        if o.dim() != 2 or o.shape[1] != 3 or d.shape != o.shape:
            raise ValueError(f"origins and directions must both have shape (N, 3), got {tuple(o.shape)} and "
                             f"{tuple(d.shape)}")
        if not (torch.isfinite(o).all() and torch.isfinite(d).all()):
            raise ValueError("origins and directions must be finite")
        N = o.shape[0]
        t_lo = _per_ray(t_min, N, o, "t_min")
        t_hi = _per_ray(t_max, N, o, "t_max")
        face = torch.full((N,), -1, dtype=torch.int64, device=self.device)
        t = torch.full((N,), math.inf, dtype=dtype, device=self.device)
        bary = torch.zeros((N, 3), dtype=dtype, device=self.device)
        if self.num_nodes == 0 or N == 0:
            return Hits(face, t, bary)
        tris = self.tris.to(dtype)
        verts = [tris[:, i].contiguous() for i in range(3)]                 # (F, 3) each: quick row gathers
        for s in range(0, N, chunk):
            sl = slice(s, min(s + chunk, N))
            f = self._traverse(o[sl], d[sl], t_lo[sl], t_hi[sl], verts, any_hit, int(packet))   # face hit
            ok = (f >= 0).nonzero().squeeze(1)
            if ok.numel():                                                 # the winners' t and bary, once more
                r = ok + s
                tw, bw, _ = _watertight(o[r], d[r], *tris[self._slot[f[ok]]].unbind(1))
                face[r], t[r], bary[r] = f[ok], tw, bw
        return Hits(face, t, bary)

    def _one_by_one(self, o, d, t_lo, t_hi, boxes, tris, any_hit):
        """Incoherent rays, one by one: a frontier of (ray, node) pairs whose box the ray's segment meets,
        [t_min, closest hit so far]. Each step tests the leaves among them and replaces each internal node by
        those of its two children that the ray still meets, so a hit found high in the tree prunes the rest.
        Returns the face hit per ray (-1 on a miss)."""
        n, dev = o.shape[0], o.device
        inv = 1 / d                                                         # ±inf where a component is 0
        best = t_hi.clone()                                                 # the closest hit so far
        none = torch.iinfo(torch.int64).max
        best_face = torch.full((n,), none, dtype=torch.int64, device=dev)   # its face id (none: no hit yet)
        siblings = boxes[1:].view(-1, 2, 2, 3)                              # children 2k+1, 2k+2 side by side
        ray = torch.arange(n, device=dev)
        keep = _slab(o, inv, boxes[:1].expand(n, 2, 3), t_lo, best)         # the root
        ray = ray[keep]
        node = torch.zeros_like(ray)
        L, k = self.leaf_size, torch.arange(self.leaf_size, device=dev)
        while ray.numel():
            cnt = self.count[node]
            is_leaf = cnt > 0
            # leaves: every (ray, triangle) candidate through the watertight test
            lr, ln = ray[is_leaf], node[is_leaf]
            if lr.numel():
                valid = k < cnt[is_leaf][:, None]                           # (P, L)
                cr = lr[:, None].expand(-1, L)[valid]                       # (Q,) rays
                cs = (self.first[ln][:, None] + k)[valid]                   # (Q,) slots
                tri = tris[cs]
                tc, _, hit = _watertight(o[cr], d[cr], tri[:, 0], tri[:, 1], tri[:, 2])
                hit &= (tc >= t_lo[cr]) & (tc <= best[cr])
                cr, cf, tc = cr[hit], self.order[cs[hit]], tc[hit]
                if cr.numel():
                    new = best.scatter_reduce(0, cr, tc, reduce="amin")     # per-ray closest t
                    win = tc == new[cr]
                    # ties go to the lower face id; a ray whose t improved forgets its old face
                    face = torch.where(new < best, torch.full_like(best_face, none), best_face)
                    best_face = face.scatter_reduce_(0, cr[win], cf[win], reduce="amin")
                    best = new
            # internal nodes: both children at once, kept when the ray's segment meets their box
            ir, inode = ray[~is_leaf], node[~is_leaf]
            if any_hit:                                                     # finished rays drop their pairs
                alive = best_face[ir] == none
                ir, inode = ir[alive], inode[alive]
            c = self.left[inode]                                            # (P,) odd: 2k + 1
            keep = _slab(o[ir, None], inv[ir, None], siblings[(c - 1) // 2], t_lo[ir, None], best[ir, None])
            ray = ir[:, None].expand(-1, 2)[keep]                           # (P, 2) → kept pairs
            node = (c[:, None] + torch.arange(2, device=dev))[keep]
        return torch.where(best_face == none, torch.full_like(best_face, -1), best_face)


    def _traverse(self, o, d, t_lo, t_hi, tris, any_hit, packet):
        """Trace one chunk of rays. Returns the face hit per ray (-1 on a miss).

        1. Beams: consecutive rays go down the tree together in packets of ``packet`` (``_packets``); the
           frontier of (packet, node) pairs keeps a node when the packet's beam may meet its box
           (``_beam_box``), and collects the leaves it reaches.
        2. Each (packet, leaf) pair becomes a (ray, leaf) pair per ray of the packet, kept when that ray's
           segment meets the leaf's box; the box's entry distance is kept too.
        3. Rounds, nearest leaf first: every ray tests the triangles of its nearest remaining leaf (the
           watertight test) and keeps its closest hit; a leaf whose box starts beyond the closest hit so far
           can hold no closer hit and is dropped. Most rays finish after a round or two.
        """
        n, dev = o.shape[0], o.device
        # box tests in float64 whatever the rays' dtype: the boxes' planes centre ± half are then exact
        ob, db = o.double(), d.double()
        inv = 1 / db                                                        # ±inf where a component is 0
        start, size, beam, width = _packets(ob, db, inv, t_lo.double(), t_hi.double(), packet, self._diag)
        alone = start[size == 1]                                            # incoherent rays: one by one
        coherent = (size > 1).nonzero().squeeze(1)
        start, size = start.index_select(0, coherent), size.index_select(0, coherent)
        beam = [b.index_select(0, coherent) for b in beam]
        width = [w.index_select(0, coherent) for w in width]
        G = start.numel()
        # every ray is also a packet of its own, G + r: a packet splits into them at a node smaller than its beam
        rays = _beam(ob, ob, inv, inv, t_lo.double(), t_hi.double())
        beam = [torch.cat([b, r]) for b, r in zip(beam, rays)]
        start = torch.cat([start, torch.arange(n, device=dev)])
        size = torch.cat([size, torch.ones(n, dtype=size.dtype, device=dev)])
        spread_o = torch.cat([width[0], torch.zeros(n, dtype=width[0].dtype, device=dev)])
        spread_d = torch.cat([width[1], torch.zeros(n, dtype=width[1].dtype, device=dev)])
        centre, half = self._centre, self._half
        # 1. the (packet, node) frontier, down to the leaves
        pk = torch.arange(G, device=dev)
        node = torch.zeros_like(pk)
        leaf_pk, leaf_node = [pk[:0]], [node[:0]]
        while pk.numel():
            hit, entry = _beam_box([b.index_select(0, pk) for b in beam], centre.index_select(0, node),
                                   half.index_select(0, node))
            keep = hit.nonzero().squeeze(1)
            pk, node, entry = pk.index_select(0, keep), node.index_select(0, keep), entry.index_select(0, keep)
            # a node narrower than the packet's beam where the beam reaches it: its rays go on one by one
            beam_width = spread_o.index_select(0, pk) + entry.clamp_min(0) * spread_d.index_select(0, pk)
            split = (pk < G) & (2 * half.index_select(0, node).amax(1) < beam_width)
            if split.any():
                sp, sn = pk[split], node[split]
                k = size.index_select(0, sp)
                ray_pk = G + torch.repeat_interleave(start.index_select(0, sp), k) + _ranks(k)
                pk, node = pk[~split], node[~split]
            is_leaf = self.count.index_select(0, node) > 0
            leaf_pk.append(pk[is_leaf]), leaf_node.append(node[is_leaf])
            pk, c = pk[~is_leaf], self.left.index_select(0, node[~is_leaf])
            pk = pk.repeat_interleave(2)                                    # both children of each internal node
            node = torch.stack([c, c + 1], 1).reshape(-1)
            if split.any():                                                 # each ray tests the node itself next
                pk, node = torch.cat([pk, ray_pk]), torch.cat([node, torch.repeat_interleave(sn, k)])
        pk, node = torch.cat(leaf_pk), torch.cat(leaf_node)
        # 2. (ray, leaf) pairs, with the entry distance into the leaf's box
        k = size.index_select(0, pk)
        ray = torch.repeat_interleave(start.index_select(0, pk), k) + _ranks(k)
        leaf = torch.repeat_interleave(node, k)
        hit, entry = _beam_box([b.index_select(0, ray) for b in rays], centre.index_select(0, leaf),
                               half.index_select(0, leaf), True)
        keep = hit.nonzero().squeeze(1)
        ray, leaf, entry = ray.index_select(0, keep), leaf.index_select(0, keep), entry.index_select(0, keep)
        # 3. rounds, nearest leaf first
        best = t_hi.clone()                                                 # the closest hit so far
        none = torch.iinfo(torch.int64).max
        best_face = torch.full((n,), none, dtype=torch.int64, device=dev)   # its face id (none: no hit yet)
        while ray.numel():
            nearest = torch.full((n,), math.inf, dtype=entry.dtype, device=dev).scatter_reduce_(0, ray, entry, "amin")
            pick = entry <= nearest.index_select(0, ray)                    # (ties: all of them)
            r, lf = ray[pick], leaf[pick]
            k = self.count.index_select(0, lf)
            cr = torch.repeat_interleave(r, k)                              # (Q,) rays
            cs = torch.repeat_interleave(self.first.index_select(0, lf), k) + _ranks(k)   # (Q,) slots
            tc, _, ok = _watertight(o.index_select(0, cr), d.index_select(0, cr), tris[0].index_select(0, cs),
                                    tris[1].index_select(0, cs), tris[2].index_select(0, cs))
            ok &= (tc >= t_lo.index_select(0, cr)) & (tc <= best.index_select(0, cr))
            cr, cf, tc = cr[ok], self.order.index_select(0, cs[ok]), tc[ok]
            if cr.numel():
                new = best.scatter_reduce(0, cr, tc, reduce="amin")         # per-ray closest t
                win = tc == new.index_select(0, cr)
                # ties go to the lower face id; a ray whose t improved forgets its old face
                face = torch.where(new < best, torch.full_like(best_face, none), best_face)
                best_face = face.scatter_reduce_(0, cr[win], cf[win], reduce="amin")
                best = new
            rest = ~pick
            ray, leaf, entry = ray[rest], leaf[rest], entry[rest]
            alive = entry <= best.index_select(0, ray)                      # a box beyond the hit: nothing closer
            if any_hit:
                alive &= best_face.index_select(0, ray) == none             # finished rays drop their leaves
            ray, leaf, entry = ray[alive], leaf[alive], entry[alive]
        face = torch.where(best_face == none, torch.full_like(best_face, -1), best_face)
        if alone.numel():
            face[alone] = self._one_by_one(o[alone], d[alone], t_lo[alone], t_hi[alone],
                                           self.boxes.to(o.dtype), torch.stack(tris, 1), any_hit)
        return face


def _beam(omin, omax, ilo, ihi, t_lo, t_hi):
    """The per-packet data ``_beam_box`` needs, (G, 3) each unless said: origin box omin, omax; inverse
    direction interval ilo, ihi (set to 0 on axes that bound nothing); the sign s of the inverses (0 there);
    caps for the entry and exit (+inf / -inf on bounding axes, -inf / +inf on the others); t_lo, t_hi (G,).
    An axis bounds nothing unless all inverses have one strict sign and are finite (rays of both signs, or
    a zero direction component)."""
    bounded = (ilo * ihi > 0) & torch.isfinite(ilo) & torch.isfinite(ihi)
    zero = torch.zeros_like(ilo)
    inf = torch.full_like(ilo, math.inf)
    ilo, ihi = torch.where(bounded, ilo, zero), torch.where(bounded, ihi, zero)
    return [omin, omax, ilo, ihi, torch.sign(ilo), torch.where(bounded, inf, -inf),
            torch.where(bounded, -inf, inf), t_lo, t_hi]


def _packets(o, d, inv, t_lo, t_hi, size, diag):
    """Group N rays into packets of up to ``size`` consecutive rays; a group whose rays are not coherent (unit
    directions more than ``PACKET_SPREAD`` apart in some component, or origins more than ``PACKET_SPREAD``
    times the scene's diagonal apart) is split into packets of one ray.

    Returns start (G,), size (G,) (the packet's rays are start, ..., start + size - 1), the beams
    (``_beam``: the packet's origin box, its interval of inverse directions and its widest segment) and the
    beam's width (G,) at t = 0 and its growth per unit t (G,): the largest spread of the origins and of the
    directions over the three axes.
    """
    n, dev = o.shape[0], o.device
    g = torch.arange(n, device=dev) // size                                # group of each ray
    G = (n + size - 1) // size

    def reduce(x, how):
        fill = math.inf if how == "amin" else -math.inf
        out = torch.full((G,) + x.shape[1:], fill, dtype=x.dtype, device=dev)
        idx = g.view(-1, *([1] * (x.dim() - 1))).expand_as(x)
        return out.scatter_reduce_(0, idx, x, reduce=how)

    u = d / d.norm(dim=1, keepdim=True).clamp_min(torch.finfo(d.dtype).tiny)
    omin, omax = reduce(o, "amin"), reduce(o, "amax")
    coherent = (((reduce(u, "amax") - reduce(u, "amin")).amax(1) <= PACKET_SPREAD)
                & ((omax - omin).amax(1) <= PACKET_SPREAD * diag))
    start = torch.arange(G, device=dev) * size
    count = (n - start).clamp(max=size)
    single = (~coherent).index_select(0, g).nonzero().squeeze(1)            # rays of incoherent groups
    keep = coherent.nonzero().squeeze(1)
    start = torch.cat([start.index_select(0, keep), single])
    count = torch.cat([count.index_select(0, keep), torch.ones_like(single)])
    # the beams of the final packets
    g = torch.repeat_interleave(torch.arange(start.numel(), device=dev), count)   # packet of each ray
    G = start.numel()
    rays = torch.repeat_interleave(start, count) + _ranks(count)
    o, inv, t_lo, t_hi = o[rays], inv[rays], t_lo[rays], t_hi[rays]
    omin, omax = reduce(o, "amin"), reduce(o, "amax")
    width = ((omax - omin).amax(1), (reduce(d[rays], "amax") - reduce(d[rays], "amin")).amax(1))
    return start, count, _beam(omin, omax, reduce(inv, "amin"), reduce(inv, "amax"), reduce(t_lo, "amin"),
                               reduce(t_hi, "amax")), width


def _beam_box(beam, centre, half, single: bool = False):
    """Can some ray of a packet meet a box? beam: the packets' ``_beam`` data, one row per pair; centre, half
    (P, 3): the boxes' centres and half extents. single: every packet is one ray (omin = omax, ilo = ihi).
    Returns hit (P,) bool and the entry distance (P,).

    Along an axis where every ray's inverse direction lies in [ilo, ihi] (one sign s), a ray enters the slab
    at (near - o) / d and leaves at (far - o) / d, near = centre - s half and far = centre + s half the planes
    in the order the rays cross them. Over origins in [omin, omax] and inverses in [ilo, ihi] both are
    bilinear, so the smallest entry and the largest exit lie at corners of the two intervals: the packet
    misses the box when the largest of the smallest entries exceeds the smallest of the largest exits (or its
    segment [t_lo, t_hi]). That never drops a box one of the rays meets; for one ray it is the slab test.
    An axis that bounds nothing gives entry -inf and exit +inf (the caps). The exit is widened by a few ulps,
    as in ``_slab``.
    """
    omin, omax, ilo, ihi, s, cap_e, cap_x, t_lo, t_hi = beam
    sh = s * half
    near, far = centre - sh, centre + sh
    if single:
        e, x = (near - omin) * ilo, (far - omin) * ilo
    else:
        a, b = near - omax, near - omin
        e = torch.minimum(torch.minimum(a * ilo, a * ihi), torch.minimum(b * ilo, b * ihi))
        a, b = far - omax, far - omin
        x = torch.maximum(torch.maximum(a * ilo, a * ihi), torch.maximum(b * ilo, b * ihi))
    e, x = torch.minimum(e, cap_e).amax(1), torch.maximum(x, cap_x).amin(1)
    entry = torch.maximum(e, t_lo)
    exit_ = torch.minimum(x + x.abs() * (4 * torch.finfo(x.dtype).eps), t_hi)
    return entry <= exit_, entry


def _ranks(counts):
    """0, 1, ..., c-1 for every count c, concatenated: (sum counts,) int64."""
    starts = torch.cumsum(counts, 0) - counts
    total = int(counts.sum())
    return torch.arange(total, device=counts.device) - torch.repeat_interleave(starts, counts)


def _per_ray(value, N, like, name):
    v = torch.as_tensor(value, dtype=like.dtype, device=like.device)
    if v.dim() == 0:
        v = v.expand(N)
    if v.shape != (N,):
        raise ValueError(f"{name} must be a number or an (N,) tensor with N = {N}, got {tuple(v.shape)}")
    if torch.isnan(v).any():
        raise ValueError(f"{name} contains NaN")
    return v


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


# --------------------------------------------------------------------------------- raycast → Fragments

def _camera_rays(camera):
    """One world-space ray per pixel centre, float64: origins (H*W, 3), directions (H*W, 3) and the
    directions' camera-space z (H*W,), so that ``t = depth / d_z`` (row-major pixels)."""
    H, W = camera.height, camera.width
    K, R, t = (camera.K.detach().double(), camera.R.detach().double(), camera.t.detach().double())
    dev = K.device
    y, x = torch.meshgrid(torch.arange(H, dtype=torch.float64, device=dev) + 0.5,
                          torch.arange(W, dtype=torch.float64, device=dev) + 0.5, indexing="ij")
    q = torch.stack([x.reshape(-1) - K[0, 2], y.reshape(-1) - K[1, 2],
                     torch.full((H * W,), 1.0, dtype=torch.float64, device=dev) - K[2, 2]], 1)
    e3 = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64, device=dev)
    cam = q @ torch.linalg.inv(K).T + e3                                    # K⁻¹ p, the offset formed first
    eye = -(R.T @ t)
    if camera.orthographic:                                                 # parallel rays along camera +z
        o_cam = torch.cat([cam[:, :2], torch.zeros_like(cam[:, :1])], 1)
        d_cam = e3.expand(H * W, 3)
        return o_cam @ R + eye, d_cam @ R, d_cam[:, 2]
    return eye.expand(H * W, 3), cam @ R, cam[:, 2]


def _tile_order(H, W, device, tile: int = 4):
    """Row-major pixel indices (H*W,) reordered tile by tile (``tile`` x ``tile`` tiles, row-major inside):
    16 consecutive rays then form one tile, a coherent packet for ``BVH.intersect``."""
    p = torch.arange(H * W, device=device)
    i, j = p // W, p % W
    key = ((i // tile) * ((W + tile - 1) // tile) + j // tile) * tile * tile + (i % tile) * tile + j % tile
    return torch.argsort(key)


def raycast(mesh, camera, *, bvh: BVH | None = None) -> Fragments:
    """Ray-cast a triangle mesh: the same ``Fragments`` as ``rasterize``, found by tracing rays.

    mesh: anything with ``verts`` (V, 3) and ``faces`` (F, 3); camera: a ``Camera`` (perspective or
    orthographic). bvh: a ``BVH`` of this mesh to reuse (built when None). One ray per pixel centre
    (j + 0.5, i + 0.5), traced in float64 (as ``rasterize`` decides coverage in float64), between the near
    and far planes: a ray whose direction has camera-space z component d_z runs over t in
    [near / d_z, far / d_z], so exactly the points with depth in [near, far] count. The BVH picks the visible
    face (ties to the lower face id); the barycentrics and depth come from ``raster._surface_at``, exactly as
    in ``rasterize``, so they are differentiable w.r.t. ``mesh.verts`` and K, R, t. Returns Fragments (H, W).
    """
    verts, faces = _check_inputs(mesh, camera)
    H, W = camera.height, camera.width
    if bvh is None:
        bvh = BVH(mesh)
    elif not isinstance(bvh, BVH) or bvh.order.numel() != faces.shape[0]:
        raise ValueError("bvh must be a BVH built from this mesh")
    o, d, dz = _camera_rays(camera)
    tiles = _tile_order(H, W, o.device)                                     # 4 x 4 tiles: coherent packets
    o, d, dz = o.index_select(0, tiles), d.index_select(0, tiles), dz.index_select(0, tiles)
    with torch.no_grad():                                                   # which face: not differentiable
        hit = bvh.intersect(o.to(bvh.device), d.to(bvh.device), t_min=(camera.near / dz).to(bvh.device),
                            t_max=(camera.far / dz).to(bvh.device)).face_id.to(verts.device)
    face = torch.empty_like(hit).index_put_((tiles.to(verts.device),), hit)  # back to row-major pixels
    dtype = torch.promote_types(verts.dtype, camera.dtype)
    pix = (face >= 0).nonzero().squeeze(1)
    x, y = (pix % W).double() + 0.5, (pix // W).double() + 0.5
    bary, depth = _surface_at(face.index_select(0, pix), x, y, verts, faces, camera)
    bary_img = torch.zeros(H * W, 3, dtype=dtype, device=verts.device).index_put((pix,), bary)
    depth_img = torch.full((H * W,), math.inf, dtype=dtype, device=verts.device).index_put((pix,), depth)
    return Fragments(face.view(H, W), bary_img.view(H, W, 3), depth_img.view(H, W))


# ------------------------------------------------------------------------------- shadow rays, area lights

def visible(points, light, bvh: BVH, *, directional: bool = False, offset: float | None = None,
            normals=None) -> torch.Tensor:
    """Shadow rays: can each point see the light?

    points: (N, 3) world space. light: a point light's position (3,) or (N, 3) (``PointLight.position``);
    with ``directional=True`` the direction the light *travels* (3,) or (N, 3) (``DirectionalLight.direction``;
    the shadow ray goes the other way, to infinity); or (N, S, 3) sample positions on an area light (see
    ``rectangle_light_samples``, ``disk_light_samples``). bvh: the BVH of the occluding mesh.
    Returns (N,) bool, True where nothing blocks the segment to the light, or for (N, S, 3) samples the
    fraction (N,) of samples visible, in [0, 1] (a soft shadow).

    Self-intersection: a point on a surface, rounded, lies a little above or below it, and its shadow ray could
    hit its own triangle. ``offset`` (world units; default 1e-4 times the diagonal of the BVH's bounds, far
    above float32 rounding of the scene's coordinates and far below its features) guards against it:

    * without ``normals``, each ray starts at the point and ignores hits closer than ``offset`` along the ray
      (and closer than ``offset`` to the light): t_min = offset. Needs nothing but the points; a surface
      point with the light behind its own surface is *not* shadowed by that surface (shade it with n · l).
    * with ``normals`` (N, 3), the geometric normals of the points' faces (the side they are seen from),
      each ray starts ``offset`` above the surface along its normal: a light behind the surface is then
      shadowed by it, as it should be; at grazing light the offset origin still clears the own triangle.
    """
    if not isinstance(bvh, BVH):
        raise TypeError(f"bvh must be a BVH, got {type(bvh).__name__}")
    p = as_tensor(points, name="points")
    dtype = torch.promote_types(p.dtype, bvh.dtype)
    p = p.to(dtype=dtype, device=bvh.device)
    if p.dim() != 2 or p.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {tuple(p.shape)}")
    N = p.shape[0]
    L = as_tensor(light, dtype=dtype, device=bvh.device, name="light")
    area = L.dim() == 3
    if L.shape == (3,):
        L = L.expand(N, 3)
    if not (L.shape == (N, 3) or (area and L.shape[0] == N and L.shape[2] == 3 and not directional)):
        raise ValueError(f"light must have shape (3,), (N, 3) or, for area-light samples, (N, S, 3) with "
                         f"N = {N}, got {tuple(L.shape)}")
    if not torch.isfinite(L).all():
        raise ValueError("light contains NaN or inf")
    if offset is None:
        diag = float((bvh.bounds[1] - bvh.bounds[0]).norm()) if bvh.num_nodes else 0.0
        offset = 1e-4 * diag if diag > 0 else 1e-4
    offset = float(offset)
    if not offset >= 0:
        raise ValueError(f"offset must be >= 0, got {offset}")
    S = L.shape[1] if area else 1
    L = L.reshape(N * S, 3)
    o = p.repeat_interleave(S, 0)
    if normals is not None:
        n = as_tensor(normals, dtype=dtype, device=bvh.device, name="normals")
        if n.shape != (N, 3):
            raise ValueError(f"normals must have shape (N, 3), got {tuple(n.shape)}")
        n = n / n.norm(dim=1, keepdim=True).clamp_min(torch.finfo(dtype).tiny)
        o = o + offset * n.repeat_interleave(S, 0)
    if directional:
        d = -L / L.norm(dim=1, keepdim=True).clamp_min(torch.finfo(dtype).tiny)
        t_lo, t_hi = torch.full((N * S,), offset, dtype=dtype, device=o.device), math.inf
    else:
        d = L - o                                                           # t = 1 at the light
        dist = d.norm(dim=1)
        safe = dist.clamp_min(torch.finfo(dtype).tiny)
        t_lo, t_hi = offset / safe, 1 - offset / safe
    if normals is not None:
        t_lo = torch.zeros_like(t_lo)
    blocked = bvh.intersect(o, d, t_min=t_lo, t_max=t_hi, any_hit=True).hit
    free = ~blocked
    if area:
        return free.view(N, S).to(dtype).mean(1)
    return free


def _generator(seed, generator, device):
    if generator is not None:
        return generator
    return torch.Generator(device=device).manual_seed(int(seed))


def _stratified(n_points, grid, dtype, device, seed, generator):
    """(N, grid², 2) jittered samples in [0, 1)²: one uniform sample in each of grid × grid cells, per point."""
    if int(grid) < 1 or int(n_points) < 0:
        raise ValueError(f"need grid >= 1 and n_points >= 0, got grid={grid}, n_points={n_points}")
    g = _generator(seed, generator, device)
    cells = torch.arange(grid, dtype=dtype, device=device)
    i, j = torch.meshgrid(cells, cells, indexing="ij")
    base = torch.stack([i.reshape(-1), j.reshape(-1)], 1)                  # (S, 2) cell corners
    jitter = torch.rand((n_points, grid * grid, 2), generator=g, dtype=dtype, device=device)
    return (base + jitter) / grid


def rectangle_light_samples(corner, edge1, edge2, n_points: int, grid: int = 4, *, seed: int = 0,
                            generator: torch.Generator | None = None) -> torch.Tensor:
    """Stratified points on a rectangular area light, a fresh jittered set for each shaded point.

    corner, edge1, edge2: (3,) the rectangle ``corner + u edge1 + v edge2``, u, v in [0, 1]. n_points: N.
    grid: samples per side (S = grid² strata, one jittered sample each). seed / generator: the randomness
    (a ``torch.Generator`` wins over ``seed``). Returns (N, S, 3), for ``visible(points, samples, bvh)``.
    """
    c = as_tensor(corner, name="corner")
    e1 = as_tensor(edge1, dtype=c.dtype, device=c.device, name="edge1")
    e2 = as_tensor(edge2, dtype=c.dtype, device=c.device, name="edge2")
    for v, name in ((c, "corner"), (e1, "edge1"), (e2, "edge2")):
        if v.shape != (3,):
            raise ValueError(f"{name} must have shape (3,), got {tuple(v.shape)}")
    uv = _stratified(n_points, grid, c.dtype, c.device, seed, generator)
    return c + uv[..., :1] * e1 + uv[..., 1:] * e2


def disk_light_samples(centre, normal, radius: float, n_points: int, grid: int = 4, *, seed: int = 0,
                       generator: torch.Generator | None = None) -> torch.Tensor:
    """Stratified points on a disk light (centre (3,), normal (3,), radius), N sets of S = grid² samples.

    The strata of the unit square are carried to the disk by Shirley and Chiu's concentric map, which keeps
    them of equal area and compact (a polar map would make slivers). Returns (N, S, 3).
    """
    c = as_tensor(centre, name="centre")
    n = as_tensor(normal, dtype=c.dtype, device=c.device, name="normal")
    if c.shape != (3,) or n.shape != (3,) or float(n.norm()) == 0:
        raise ValueError(f"centre and normal must have shape (3,), normal non-zero; got {tuple(c.shape)}, "
                         f"{tuple(n.shape)}")
    if not float(radius) > 0:
        raise ValueError(f"radius must be > 0, got {radius}")
    n = n / n.norm()
    helper = torch.zeros_like(n)
    helper[int(n.abs().argmin())] = 1.0                                     # an axis far from the normal
    a = torch.linalg.cross(n, helper)
    a = a / a.norm()
    b = torch.linalg.cross(n, a)
    uv = 2 * _stratified(n_points, grid, c.dtype, c.device, seed, generator) - 1   # (N, S, 2) in [-1, 1)²
    x, y = uv[..., 0], uv[..., 1]
    wide = x.abs() > y.abs()
    r = torch.where(wide, x, y)
    safe = torch.where(r == 0, torch.ones_like(r), r)
    phi = torch.where(wide, (math.pi / 4) * y / safe, math.pi / 2 - (math.pi / 4) * x / safe)
    r = r * float(radius)
    return c + (r * torch.cos(phi))[..., None] * a + (r * torch.sin(phi))[..., None] * b
