"""A bounding volume hierarchy over a triangle mesh, built and traversed for many rays at once (lecture 07).

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
   meets), and the leaves reached are collected. One box test then serves 16 rays. Where a node is
   narrower than the packet's beam, the packet splits into its rays, which go on one by one.
2. *Rays into leaves.* Each (packet, leaf) pair becomes one (ray, leaf) pair per ray of the packet, kept
   when that ray's segment [t_min, t_max] meets the leaf's box, with the distance at which it enters it.
3. *Nearest leaf first.* In rounds, every ray tests the triangles of its nearest remaining leaf with the
   watertight test and keeps its closest hit (a ``scatter_reduce`` amin on t; ties go to the lower face
   id). A leaf whose box the ray enters beyond its closest hit so far cannot hold a closer hit and is
   dropped, so most rays finish in a round or two; after ``NEAREST_ROUNDS`` rounds the leaves left are
   tested all at once. With ``any_hit`` a ray stops at its first hit (enough for shadows).

Rays that are not coherent (random directions) take the per-ray frontier instead (``_one_by_one``): (ray,
node) pairs level by level, leaves tested as soon as they are reached, so a hit found high in the tree
prunes the rest. Rays are processed in chunks so memory stays bounded.

**The compiled twin.** All of the above is the data-parallel way, the one CUDA tensors take. On CPU tensors
``BVH.intersect`` hands the same tree to ``course.kernels.traverse.closest_hits``, the textbook loop (one ray,
one stack, nearer child first), compiled by Numba: the same face, t and barycentrics for every ray, several
times faster (``python -m course bench raytrace``). ``course.kernels.using("torch")`` runs the code above.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from . import kernels
from .intersect import _slab, _watertight
from .tensors import _as_faces, _check_count, _check_flag, _check_shape, as_tensor

__all__ = ["morton_codes", "BVH", "Hits"]

PACKET = 16             # rays per packet in BVH.intersect (a 4 x 4 pixel tile of primary rays)
PACKET_SPREAD = 0.05    # a packet stays together while its unit directions differ by at most this per component
NEAREST_ROUNDS = 8      # rounds of "each ray's nearest leaf" before the leaves left are tested all at once


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
    p = as_tensor(points, dtype=torch.float64, name="points")
    _check_shape(p, (None, 3), "points")
    if p.shape[0] == 0:
        return torch.zeros(0, dtype=torch.int64, device=p.device)
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
        if verts is None or faces is None:
            raise TypeError(f"mesh must have verts (V, 3) and faces (F, 3), got {type(mesh).__name__}")
        if not isinstance(verts, torch.Tensor) or verts.dim() != 2 or verts.shape[1] != 3:
            raise ValueError(f"mesh.verts must be a (V, 3) tensor, got {getattr(verts, 'shape', type(verts))}")
        if not isinstance(faces, torch.Tensor):
            raise ValueError(f"mesh.faces must be an (F, 3) tensor, got {type(faces).__name__}")
        leaf_size = _check_count(leaf_size, "leaf_size")
        verts = as_tensor(verts.detach(), name="mesh.verts")
        if not torch.isfinite(verts).all():
            raise ValueError("mesh.verts contains NaN or inf")
        faces = _as_faces(faces, "mesh.faces", num_verts=verts.shape[0], device=verts.device)
        self.leaf_size = leaf_size
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
        packet, chunk = _check_count(packet, "packet"), _check_count(chunk, "chunk")
        any_hit = _check_flag(any_hit, "any_hit")
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
        if kernels.active(o) and self.num_nodes and N:                      # the compiled twin: one loop per ray
            face, t, bary = kernels.buffer(N, torch.int64), kernels.buffer(N, dtype), kernels.buffer((N, 3), dtype)
            self._kernel_traverse(o, d, t_lo, t_hi, self._corners(dtype), any_hit, face, t, bary)
            return Hits(face, t, bary)                                      # (every entry written)
        face = torch.full((N,), -1, dtype=torch.int64, device=self.device)
        t = torch.full((N,), math.inf, dtype=dtype, device=self.device)
        bary = torch.zeros((N, 3), dtype=dtype, device=self.device)
        if self.num_nodes == 0 or N == 0:
            return Hits(face, t, bary)
        verts = self._corners(dtype)                                        # (F, 3) each: quick row gathers
        tris = self.tris.to(dtype)
        for s in range(0, N, chunk):
            sl = slice(s, min(s + chunk, N))
            f = self._traverse(o[sl], d[sl], t_lo[sl], t_hi[sl], verts, any_hit, packet)   # face hit
            ok = (f >= 0).nonzero().squeeze(1)
            if ok.numel():                                                 # the winners' t and bary, once more
                r = ok + s
                tw, bw, _ = _watertight(o[r], d[r], *tris[self._slot[f[ok]]].unbind(1))
                face[r], t[r], bary[r] = f[ok], tw, bw
        return Hits(face, t, bary)

    def _corners(self, dtype):
        """The triangles' three corners in slot order, (F, 3) contiguous each, in ``dtype`` (kept for reuse)."""
        cache = self.__dict__.setdefault("_corner_cache", {})
        if dtype not in cache:
            tris = self.tris.to(dtype)
            cache[dtype] = [tris[:, i].contiguous() for i in range(3)]
        return cache[dtype]

    def _kernel_traverse(self, o, d, t_lo, t_hi, verts, any_hit, face, t, bary):
        """``_traverse`` and the winners' t and bary by ``kernels.traverse.closest_hits``, written into
        face, t, bary: the same values, one compiled loop per ray."""
        import numba

        from .kernels import threads
        from .kernels.traverse import closest_hits
        if getattr(self, "_flat", None) is None:                            # the tree as numpy arrays, once
            self._flat = tuple(x.contiguous().numpy() for x in (self.boxes.double(), self.left, self.first,
                                                                  self.count, self.order))
        numba.set_num_threads(threads())
        rays = [x.contiguous().numpy() for x in (o, d, t_lo, t_hi)]
        closest_hits(*rays, *self._flat, *(v.numpy() for v in verts), any_hit, self.depth + 2,
                     face.numpy(), t.numpy(), bary.numpy())

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
        start, size, beam, width, alone = _packets(ob, db, inv, t_lo.double(), t_hi.double(), packet, self._diag)
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
        rounds = 0
        while ray.numel():
            if rounds < NEAREST_ROUNDS:                                     # each ray's nearest leaf (ties: all)
                nearest = torch.full((n,), math.inf, dtype=entry.dtype, device=dev)
                pick = entry <= nearest.scatter_reduce_(0, ray, entry, "amin").index_select(0, ray)
                r, lf = ray[pick], leaf[pick]
            else:                                                           # then all that are left, at once
                pick, r, lf = None, ray, leaf
            rounds += 1
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
            if pick is None:
                break
            alive = ~pick & (entry <= best.index_select(0, ray))            # a box beyond the hit: nothing closer
            if any_hit:
                alive &= best_face.index_select(0, ray) == none             # finished rays drop their leaves
            alive = alive.nonzero().squeeze(1)
            ray, leaf, entry = ray.index_select(0, alive), leaf.index_select(0, alive), entry.index_select(0, alive)
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
    """Group N rays into packets of up to ``size`` consecutive rays. A group whose rays are not coherent (unit
    directions more than ``PACKET_SPREAD`` apart in some component, or origins more than ``PACKET_SPREAD``
    times the scene's diagonal apart), or that holds a single ray, is left to the per-ray traversal.

    Returns start (G,), size (G,) of the packets (the rays start, ..., start + size - 1), their beams
    (``_beam``: the origin box, the interval of inverse directions and the widest segment), the beam's width
    (G,) at t = 0 and its growth per unit t (G,) (the largest spread of the origins and of the directions over
    the three axes), and the rays (K,) left alone.
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
    start = torch.arange(G, device=dev) * size
    count = (n - start).clamp(max=size)
    packed = (((reduce(u, "amax") - reduce(u, "amin")).amax(1) <= PACKET_SPREAD)
              & ((omax - omin).amax(1) <= PACKET_SPREAD * diag) & (count > 1))
    alone = (~packed).index_select(0, g).nonzero().squeeze(1)
    keep = packed.nonzero().squeeze(1)
    pick = lambda x: x.index_select(0, keep)
    width = (pick((omax - omin).amax(1)), pick((reduce(d, "amax") - reduce(d, "amin")).amax(1)))
    beam = _beam(pick(omin), pick(omax), pick(reduce(inv, "amin")), pick(reduce(inv, "amax")),
                 pick(reduce(t_lo, "amin")), pick(reduce(t_hi, "amax")))
    return pick(start), pick(count), beam, width, alone


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
    if isinstance(value, (bool, str)) or not isinstance(value, (int, float, torch.Tensor)) and \
            not hasattr(value, "__array__"):
        raise ValueError(f"{name} must be a number or an (N,) tensor with N = {N}, got {value!r}")
    v = as_tensor(value, dtype=like.dtype, device=like.device, name=name)
    if v.dim() == 0:
        v = v.expand(N)
    if v.shape != (N,):
        raise ValueError(f"{name} must be a number or an (N,) tensor with N = {N}, got {tuple(v.shape)}")
    if torch.isnan(v).any():
        raise ValueError(f"{name} contains NaN")
    return v
