"""Coverage: which pixel centres or sub-pixel samples each screen triangle covers, and the z-buffer.

Stage 2 of ``rasterize`` (lecture 03; sub-pixel samples for lecture 05), on triangles that stage 1
(``raster._screen_triangles``) has clipped, culled and projected, in float64:

* ``edge_function`` and the top-left fill rule decide coverage, so a point on an edge shared by two
  triangles is covered exactly once (watertight).
* **Pixel centres, by scan conversion** (``_scan_convert``): each triangle is walked row by row; per row the
  three edge inequalities give the span of covered centres, and only those pixels are enumerated. The
  crossing of a shared edge is computed bit-identically by both triangles, so no centre is lost or doubled.
* **Sub-pixel samples** (``_sample_zbuffer``): ``pixel_triangle_pairs`` lists every pixel *square* a
  triangle touches (conservative rasterization), and each sample of those pixels is tested with the same
  edge functions. A sample's answer depends on its position alone.
* **The z-buffer** in bulk: every covered pixel (or sample) writes a packed 64-bit key
  ``(float32 depth bits << 32) | face id`` and one scatter-min keeps the nearest. Slots where two keys come
  within ``TIE_STEPS`` (4) float32 steps of each other are noted on the way (``_NearTies``) and decided again
  by float64 depth, so the result is the face nearest in float64: the answer of ``raycast`` and
  ``coverage.exact_coverage`` for surfaces closer than float32 can tell apart. Depths equal to 1e-12
  (relative, ``TIE_RTOL``: float64 rounding, coplanar faces) are a tie, which goes to the lower face id.

Work is chunked so memory stays bounded (``CHUNK``).

On CPU tensors ``_zbuffer`` hands the triangles to its compiled twin, ``course.kernels.zbuffer.nearest_faces``
(one triangle, its rows, its pixels; the same spans and the same faces, bit for bit); the code here is the
data-parallel version, the one CUDA tensors take and ``course.kernels.using("torch")`` selects.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from . import kernels
from .tensors import _check_count, _check_finite, as_tensor

__all__ = ["edge_function", "pixel_triangle_pairs"]

# Work per chunk: (row segments, fragments). Bounds memory and keeps the working arrays small enough to stay
# in cache (measured with `python -m course bench raster`).
CHUNK = (1 << 16, 1 << 19)

def edge_function(a, b, p) -> torch.Tensor:
    """Twice the signed area of the triangle (a, b, p): ``(b - a) × (p - a)``.

    a, b, p: (..., 2) image coordinates (x right, y down). Returns (...). Positive when p lies to the right of
    a→b as seen on screen. Written as ``(a - p) × (b - p)`` so that swapping a and b negates the result
    *exactly* in floating point: two triangles sharing an edge always disagree on its sign, never both win.
    """
    a, b, p = (as_tensor(v, name=n) for v, n in ((a, "a"), (b, "b"), (p, "p")))
    for v, n in ((a, "a"), (b, "b"), (p, "p")):
        if v.shape[-1:] != (2,):
            raise ValueError(f"{n} must have shape (..., 2), image coordinates (x, y), got {tuple(v.shape)}")
    try:
        a, b, p = torch.broadcast_tensors(a, b, p)
    except RuntimeError:
        raise ValueError(f"a, b and p must broadcast together, got shapes {tuple(a.shape)}, {tuple(b.shape)} "
                         f"and {tuple(p.shape)}") from None
    return (a[..., 0] - p[..., 0]) * (b[..., 1] - p[..., 1]) - (a[..., 1] - p[..., 1]) * (b[..., 0] - p[..., 0])


def _is_top_left(a, b) -> torch.Tensor:
    """Top-left rule for the edge a→b of a triangle with positive edge functions inside (y down).

    A *top* edge is horizontal with the triangle below it (direction +x); a *left* edge has the triangle to
    its right (direction -y). Reversing an edge flips the answer, so a shared edge belongs to one side only.
    """
    d = b - a
    return (d[..., 1] < 0) | ((d[..., 1] == 0) & (d[..., 0] > 0))




EMPTY_KEY = torch.iinfo(torch.int64).max    # z-buffer start value; its low 32 bits are all set


def _depth_keys(depth: torch.Tensor, face_id: torch.Tensor, positive: bool = False) -> torch.Tensor:
    """Pack (depth, face id) into int64 keys whose integer order is (depth, face) order.

    The float32 bit pattern of a float orders like an int32 for positive values; negative ones (and -0.0)
    are mirrored, a step skipped when the caller knows every depth is > 0 (``positive``, the perspective
    fast path). The face id fills the low 32 bits, so equal depths resolve to the lower face id.
    """
    bits = depth.to(torch.float32).view(torch.int32).to(torch.int64)        # sign-extended int32
    if not positive:
        bits = torch.where(bits < 0, bits ^ 0x7FFFFFFF, bits)              # mirror negative floats
    return (bits << 32) | face_id


def _faces_of(zbuf: torch.Tensor) -> torch.Tensor:
    """Face ids from resolved keys: the low 32 bits, and -1 where a pixel still holds ``EMPTY_KEY``
    (adding 1 carries its all-ones low bits to zero)."""
    return ((zbuf + 1) & 0xFFFFFFFF) - 1


# ------------------------------------------------------------------- near-ties: float64 after the float32 keys

# Near-ties. The packed key rounds each fragment's depth to float32 (relative steps of 2^-24 ≈ 6e-8, and the
# depth passes through two float32 roundings, 1/q of a rounded q), so two surfaces closer than a few float32
# steps would tie (the lower face id winning) or even swap, where ``raycast`` and ``coverage.exact_coverage``
# compare in float64. So that they agree, the z-buffer notes every pixel where two fragments' keys come within
# ``TIE_STEPS`` float32 steps of each other while it fills (``_NearTies``: two gathers per fragment, its
# pixel's key before and after the scatter-min, one on the first chunk, and a few integer operations: 0-10 %
# of ``rasterize``'s time on the ``bench raster`` scenes, ``REFINE_TIES = False`` to compare), and afterwards
# decides those pixels among the faces noted there by float64 depth, each face's screen-affine q evaluated at
# the pixel centre or sample (``_nearest``). Depths within ``TIE_RTOL`` (1e-12, relative) of the nearest count
# as a tie and go to the lower face id: that is float64 rounding, not geometry, so coplanar faces (z-fighting)
# keep the deterministic lower-id rule instead of rounding noise. Every face that could win in float64 is among those
# noted: two float32 roundings move a key by at most 2 steps from its exact place, so a fragment nearer in
# float64 than the float32 winner has a key at most 3 steps above the winner's, and the notes catch every
# pair within 4 steps (a fragment is compared with the key its pixel held before its chunk, and with the
# winner after its chunk).
TIE_STEPS = 4
TIE_RTOL = 1e-12
_GAP_SHIFT = 35             # 2^35 = 8 << 32: the key gaps noted cover TIE_STEPS float32 steps and a few more
REFINE_TIES = True          # False: the float32 keys alone (benchmarks show what the refinement costs)


class _NearTies:
    """Notes (slot, face) pairs whose keys came within TIE_STEPS float32 steps of each other in one slot.

    zbuf: the z-buffer being filled (its entries only decrease). ``check`` after each scatter-min; ``resolve``
    at the end with a function giving the float64 depth of (slots, faces)."""

    def __init__(self, zbuf: torch.Tensor):
        self.zbuf = zbuf
        self.slots, self.faces = [], []

    def check(self, slot, keys, before=None):
        """slot, keys (M,): the fragments just scattered; before (M,): their slots' keys before the scatter
        (None: the z-buffer was empty, the first chunk).

        A fragment is noted with the key its slot held before when it lies at most TIE_STEPS float32 steps
        below it (it displaced that one, or a sibling of its chunk displaced both), and with its slot's key after
        the scatter when it lies above that by at most TIE_STEPS (it lost to a fragment of an earlier chunk or of
        this one). Key differences ``(Δbits << 32) + Δface`` below ``8 << 32`` stand in for gaps of at most
        TIE_STEPS steps (they admit up to 7: harmless extra notes; an empty slot's key, whose difference can wrap
        around, is never noted), which keeps this to a few integer operations per fragment."""
        after = self.zbuf.index_select(0, slot)
        # x >> SHIFT == 0 exactly when 0 <= x < 2^SHIFT = 8 << 32: key gaps of at most 7 float32 steps
        above = torch.sub(keys, after).sub_(1).bitwise_right_shift_(_GAP_SHIFT)   # 0: lost to a near key
        if before is None:
            idx = (above == 0).nonzero().squeeze(1)
        else:
            below = torch.sub(before, keys).bitwise_right_shift_(_GAP_SHIFT)     # 0: displaced a near key
            idx = (torch.mul(below, above) == 0).nonzero().squeeze(1)       # (both are small after the shift)
        if idx.numel() == 0:
            return
        s = slot.index_select(0, idx)
        self.slots.append(s)
        self.faces.append(keys.index_select(0, idx) & 0xFFFFFFFF)
        pairs = ((above, after),) if before is None else ((below, before), (above, after))
        for gap, other in pairs:
            other = other.index_select(0, idx)
            i = ((gap.index_select(0, idx) == 0) & (other != EMPTY_KEY)).nonzero().squeeze(1)
            self.slots.append(s.index_select(0, i))
            self.faces.append(other.index_select(0, i) & 0xFFFFFFFF)

    def resolve(self, faces: torch.Tensor, depth_of) -> torch.Tensor:
        """``faces`` (N,) (the float32 winners) with the noted slots decided by ``depth_of(slots, faces)``,
        float64 depths (``_nearest``: ties within TIE_RTOL to the lower face id)."""
        if not self.slots:
            return faces
        slots = torch.cat(self.slots)
        tied = torch.unique(slots)
        slots = torch.cat([slots, tied])
        cand = torch.cat(self.faces + [faces.index_select(0, tied)])
        best = _nearest(slots, depth_of(slots, cand), cand, faces.numel())
        return faces.index_put((tied,), best.index_select(0, tied))


def _nearest(slot, depth, face, n: int) -> torch.Tensor:
    """The z-buffer without packing: per slot (n of them) the face of least depth, where depths within
    ``TIE_RTOL`` (relative) of the least are a tie that goes to the lower face id; -1 where no fragment.
    slot, depth, face: (M,), depths in float64."""
    nearest = torch.full((n,), float("inf"), dtype=depth.dtype, device=depth.device)
    nearest.scatter_reduce_(0, slot, depth, reduce="amin")
    least = nearest.index_select(0, slot)
    win = (depth <= least + TIE_RTOL * least.abs()).nonzero().squeeze(1)
    best = torch.full((n,), torch.iinfo(torch.int64).max, dtype=torch.int64, device=depth.device)
    best.scatter_reduce_(0, slot.index_select(0, win), face.index_select(0, win), reduce="amin")
    return torch.where(best == torch.iinfo(torch.int64).max, torch.full_like(best, -1), best)


def _depth_at(st: "_ScreenTriangles", camera, faces, x, y) -> torch.Tensor:
    """Float64 camera-space depth of each face (M,) at screen points x, y (M,): its screen-affine q there."""
    tri_of_face = torch.zeros(int(st.face.max()) + 1, dtype=torch.int64, device=st.face.device)
    tri_of_face[st.face] = torch.arange(st.face.numel(), device=st.face.device)   # any piece: one plane
    q = _plane_at(_plane(st), tri_of_face.index_select(0, faces), x, y)
    return q if camera.orthographic else q.reciprocal()




def _min3(a):
    """Smallest of the three columns of a (T, 3) tensor (faster than a reduction over a length-3 axis)."""
    return torch.minimum(torch.minimum(a[:, 0], a[:, 1]), a[:, 2])


def _max3(a):
    """Largest of the three columns of a (T, 3) tensor."""
    return torch.maximum(torch.maximum(a[:, 0], a[:, 1]), a[:, 2])




@dataclass
class _ScreenTriangles:
    """Triangles ready for scan conversion (float64, T of them after clipping and culling)."""
    xy: torch.Tensor     # (T, 3, 2) screen coordinates, ordered so the area is positive
    q: torch.Tensor      # (T, 3) the quantity affine on screen: 1/z (perspective) or z (orthographic)
    face: torch.Tensor   # (T,) int64 id of the original face
    crosses_far: bool = True   # False when no triangle reaches beyond the far plane (no per-pixel test)

    def __getitem__(self, sl):
        return _ScreenTriangles(self.xy[sl], self.q[sl], self.face[sl], self.crosses_far)




# ------------------------------------------------------------------- stage 2: scan conversion + z-buffer

def _row_range(xy, height):
    """Rows whose pixel centres (y = i + 0.5) the triangles' y-extent reaches: first, last, count."""
    y = xy[..., 1]
    first = torch.ceil(_min3(y) - 0.5).clamp(min=0)
    last = torch.floor(_max3(y) - 0.5).clamp(max=height - 1)
    return first.long(), last.long(), (last - first + 1).clamp(min=0).long()


def _expand(counts: torch.Tensor):
    """Segments of the given lengths laid end to end: the owning segment of every element, and the start
    of every segment (``repeat_interleave`` of the counts alone returns exactly the owners)."""
    return torch.repeat_interleave(counts), torch.cumsum(counts, 0) - counts


def _spans(x, y, row_y, width):
    """Per (triangle, row) segment: the first and last covered pixel column, as float64 (S,) tensors.

    x, y: (3, S) the triangle's screen vertices, one row per vertex; row_y: (S,) the row's centre.
    Along the row, edge a→b (a = vertex k, b = vertex k+1) is the linear function ``E(px) = A px + r`` with
    ``A = a_y - b_y``: it bounds the span from the left when A > 0 and from the right when A < 0, at the
    crossing ``x0 = -r / A``. A pixel centre ``j + 0.5`` exactly on the crossing belongs to the triangle only
    if the edge is a top or left edge. Watertightness does not depend on rounding: the two triangles sharing
    an edge traverse it in opposite directions and compute *bit-identical* crossings (every operation below
    is exactly antisymmetric in a and b), so one's last column is always the other's first minus one.
    A horizontal edge (A = 0) keeps the whole row or none of it. The three edges are processed together as
    (3, S) tensors, with arithmetic instead of ``torch.where`` (several times faster here).
    """
    BIG = 1e18
    ax, ay, bx, by = x, y, x.roll(-1, 0), y.roll(-1, 0)                    # (3, S) edges v0→v1, v1→v2, v2→v0
    da, db = ay - row_y, by - row_y
    sign_a = torch.sign(ay - by)                                            # +1 left edge, -1 right edge
    flat = 1 - sign_a.abs()                                                 # 1.0 for a horizontal edge
    tl = (sign_a + flat * (bx > ax)).clamp_(0, 1)                           # top-left: A > 0, or flat going +x
    x0 = ((bx * da - ax * db) / (ay - by + flat)).clamp_(-2, width + 2)     # the crossing, E(x0) = 0
    f, c = torch.floor(x0 - 0.5), torch.ceil(x0 - 0.5)
    on_centre = tl * (f + 1 - c)                                            # 1: a centre exactly on a top-left edge
    first_col = f + 1 - on_centre                                           # first centre right of x0 (or on it)
    last_col = c - 1 + on_centre                                            # last centre left of x0 (or on it)
    is_left, is_right = sign_a.clamp(min=0), (-sign_a).clamp_(min=0)
    first = (first_col * is_left - BIG * (1 - is_left)).amax(0).clamp_(min=0)
    last = (last_col * is_right + BIG * (1 - is_right)).amin(0).clamp_(max=width - 1)
    if not bool(flat.any()):
        return first, last
    # a horizontal edge: the whole row is inside if the row is on the inner side, E = da (a_x - b_x) > 0
    inside_flat = (2 * torch.sign(da) * torch.sign(ax - bx) + tl).clamp_(0, 1)
    empty = (flat * (1 - inside_flat)).sum(0)
    return first, last - BIG * empty


def _scan_convert(st: _ScreenTriangles, width: int, height: int):
    """Stage 2a: enumerate covered pixels of a batch of triangles, row by row.

    Returns flat pixel indices (M,) int64, the fragments' screen-affine q (M,) float64 and face id (M,).
    """
    T = st.face.numel()
    first_row, _, n_rows = _row_range(st.xy, height)
    tri_of_seg, seg_start = _expand(n_rows)                                 # one segment per (triangle, row)
    row = torch.take(first_row.to(st.xy.dtype) - seg_start.to(st.xy.dtype), tri_of_seg) + torch.arange(
        tri_of_seg.numel(), dtype=st.xy.dtype, device=st.xy.device)        # (S,) row index
    row_y = row + 0.5                                                       # (S,) pixel-centre y of the row
    corner = tri_of_seg + T * torch.arange(3, device=tri_of_seg.device)[:, None]   # (3, S) into (3, T)
    xs = torch.take(st.xy[..., 0].T.contiguous(), corner)                   # (3, S)
    ys = torch.take(st.xy[..., 1].T.contiguous(), corner)
    first, last = _spans(xs, ys, row_y, width)
    length = last - first + 1
    seg = (length > 0).nonzero().squeeze(1)                                 # drop empty rows
    tri_of_seg = tri_of_seg.index_select(0, seg)
    row_y, first, length = row_y.index_select(0, seg), first.index_select(0, seg), length.index_select(0, seg)
    # q = 1/z (or z) is affine on screen (``_plane``). Per span it is evaluated once, at the end where it is
    # least (the first centre when qx >= 0, the last otherwise), and stepped from there by |qx| per pixel: two
    # terms of one sign, so q stays accurate to a few roundings of its own size even where it runs to 0 at a
    # vanishing line. (Stepping from the span's other end, or from the start of the chunk's element array,
    # cancels there: the torch path once put a face 1e-4 behind a wall in front of it that way.)
    qa, xa, ya, qx, qy = (torch.take(t, tri_of_seg) for t in _plane(st))
    seg_of_px, px_start = _expand(length.long())                            # one element per covered pixel
    base = ((row_y - 0.5) * width + first).long() - px_start                # pixel = base + element index
    rising = qx >= 0
    col_a = torch.where(rising, first, first + length - 1)                  # (S,) the anchor column
    q_a = qa + qx * (col_a + 0.5 - xa) + qy * (row_y - ya)
    elem_a = px_start + torch.where(rising, 0, length.long() - 1)           # (S,) its element index
    index = torch.arange(seg_of_px.numel(), device=first.device)
    pixel = torch.take(base, seg_of_px) + index
    q_px = torch.take(q_a, seg_of_px) + torch.take(qx, seg_of_px) * (index - torch.take(elem_a, seg_of_px)).to(qx.dtype)
    face = torch.take(st.face.index_select(0, tri_of_seg), seg_of_px)
    return pixel, q_px, face


def _plane(st: _ScreenTriangles):
    """The affine function q(px, py) through the triangles' vertex values, anchored at the corner of least |q|:
    ``q(px, py) = qa + qx (px - xa) + qy (py - ya)``. Returns (qa, xa, ya, qx, qy), (T,) each (``_plane_at``).

    Why anchored: near a vanishing line q = 1/z runs to 0 while the plane's terms stay large, so the textbook
    form ``q0 + qx px + qy py`` (q0 the value at the screen's origin) cancels: a wall seen to depth 1e15 has
    q ≈ 1e-11 at a pixel centre 1e-8 px from its vanishing line, and q0 + qx px carries an absolute error of
    ~1e-16 · qx · 4096 there, a relative 4 % (the z-buffer then puts a face 1e-4 behind it in front). Measured
    from the corner of least q, the nearest to the vanishing line, the terms are as small as q itself allows.
    """
    xy, q = st.xy, st.q
    # the slope from the two shorter edges, out of the corner opposite the longest: for a sliver (two far
    # corners a pixel apart, the third 1e15 px away) the edges from another corner are nearly parallel and
    # their cross product cancels to nothing (a 6 % error in qx, measured); these two cross without cancelling
    side = xy.roll(-2, 1) - xy.roll(-1, 1)                                  # (T, 3, 2): the edge opposite corner k
    o = (side * side).sum(2).argmax(1, keepdim=True)                        # (T, 1) (the first if tied)
    k1, k2 = (o + 1) % 3, (o + 2) % 3                                       # cyclic: the orientation is kept
    take = lambda v, k: v.gather(1, k).squeeze(1)                           # noqa: E731
    x0, y0, q0 = take(xy[..., 0], o), take(xy[..., 1], o), take(q, o)
    e1x, e1y, d1 = take(xy[..., 0], k1) - x0, take(xy[..., 1], k1) - y0, take(q, k1) - q0
    e2x, e2y, d2 = take(xy[..., 0], k2) - x0, take(xy[..., 1], k2) - y0, take(q, k2) - q0
    det = e1x * e2y - e1y * e2x                                             # twice the area, > 0
    qx, qy = (d1 * e2y - d2 * e1y) / det, (d2 * e1x - d1 * e2x) / det
    a = q.abs().argmin(1, keepdim=True)                                     # (T, 1) the anchor corner (first if tied)
    qa = q.gather(1, a).squeeze(1)
    xa, ya = xy[..., 0].gather(1, a).squeeze(1), xy[..., 1].gather(1, a).squeeze(1)
    return qa, xa, ya, qx, qy


def _plane_at(plane, t, x, y) -> torch.Tensor:
    """q of triangles t (M,) at screen points x, y (M,): ``qa + qx (x - xa) + qy (y - ya)`` (``_plane``)."""
    qa, xa, ya, qx, qy = (c.index_select(0, t) for c in plane)
    return qa + qx * (x - xa) + qy * (y - ya)


def _chunks(st: _ScreenTriangles, width, height, budget):
    """Split triangles into consecutive batches of about ``budget[0]`` row segments and at most about
    ``budget[1]`` fragments (estimated from bounding boxes): small enough that the working arrays stay in
    cache and are reused, large enough that the fixed cost of each torch call is shared by many elements."""
    seg_budget, frag_budget = budget
    _, _, n_rows = _row_range(st.xy, height)
    x = st.xy[..., 0]
    n_cols = (_max3(x).clamp(max=width) - _min3(x).clamp(min=0)).clamp(min=0)
    cost = torch.cumsum(n_rows / seg_budget + n_rows * n_cols / (2 * frag_budget), 0)   # (T,) in batches
    if float(cost[-1]) <= 1:
        yield st
        return
    batch = cost.long()                                                     # (T,) batch of each triangle
    cuts = ((batch[1:] != batch[:-1]).nonzero().squeeze(1) + 1).tolist()
    for lo, hi in zip([0] + cuts, cuts + [len(batch)]):
        yield st[lo:hi]


def _zbuffer(st: _ScreenTriangles, camera, budget=CHUNK) -> torch.Tensor:
    """Stage 2b: the nearest face per pixel, (H*W,) int64, -1 where none. One scatter-min per chunk."""
    H, W = camera.height, camera.width
    if st.face.numel() == 0:
        return torch.full((H * W,), -1, dtype=torch.int64, device=st.xy.device)
    if kernels.active(st.xy):                                               # the compiled twin
        return _kernel_zbuffer(st, camera)
    zbuf = torch.full((H * W,), EMPTY_KEY, dtype=torch.int64, device=st.xy.device)
    ties = _NearTies(zbuf) if REFINE_TIES else None
    filled = False
    for chunk in _chunks(st, W, H, budget):
        pixel, q, face = _scan_convert(chunk, W, H)
        depth = q.float() if camera.orthographic else q.float().reciprocal_()
        if chunk.crosses_far:                                               # the far plane clips per pixel
            ok = (depth <= camera.far).nonzero().squeeze(1)
            pixel, depth, face = pixel[ok], depth[ok], face[ok]
        keys = _depth_keys(depth, face, positive=not camera.orthographic)  # orthographic z may round to -0.0
        before = zbuf.index_select(0, pixel) if ties is not None and filled else None
        zbuf.scatter_reduce_(0, pixel, keys, reduce="amin")
        filled = True                                                       # before the first chunk: all empty
        if ties is not None:
            ties.check(pixel, keys, before)
    faces = _faces_of(zbuf)
    if ties is None:
        return faces
    centre = lambda slots: ((slots % W).double() + 0.5, (slots // W).double() + 0.5)   # noqa: E731
    return ties.resolve(faces, lambda slots, f: _depth_at(st, camera, f, *centre(slots)))




def _kernel_zbuffer(st: _ScreenTriangles, camera, capacity: int | None = None) -> torch.Tensor:
    """``_zbuffer`` by ``kernels.zbuffer.nearest_faces``: the same face ids, one compiled loop over the
    triangles, their rows and pixels; the near-ties it notes are decided by ``_NearTies.resolve`` as here.
    capacity: room for notes in the first call (default two per pixel; more: the call is repeated)."""
    from .kernels.zbuffer import nearest_faces
    H, W = camera.height, camera.width
    args = (st.xy.contiguous().numpy(), st.q.contiguous().numpy(), st.face.contiguous().numpy(), W, H,
            bool(camera.orthographic), float(camera.far), bool(st.crosses_far))
    capacity = max(1024, 2 * H * W) if capacity is None else capacity
    while True:
        faces = kernels.buffer(H * W, torch.int64, fill=-1)
        keys = kernels.scratch("zbuffer_keys", H * W, torch.float64).fill_(float("inf"))
        notes = kernels.scratch("zbuffer_notes", 2 * capacity, torch.int64).view(capacity, 2)
        n = nearest_faces(*args, faces.numpy(), keys.numpy(), notes.numpy())
        if n <= capacity:
            break
        capacity = n                                                        # rare: coplanar faces everywhere
    if n == 0:
        return faces
    ties = _NearTies(faces)
    ties.slots, ties.faces = [notes[:n, 0].clone()], [notes[:n, 1].clone()]   # (the scratch is reused)
    centre = lambda slots: ((slots % W).double() + 0.5, (slots // W).double() + 0.5)   # noqa: E731
    return ties.resolve(faces, lambda slots, f: _depth_at(st, camera, f, *centre(slots)))


def _kernel_sample_zbuffer(st: _ScreenTriangles, camera, pixels, offsets) -> torch.Tensor:
    """``_sample_zbuffer`` by ``kernels.samples.sample_faces``: the same face ids, one compiled loop over the
    listed pixels and their samples; the near-ties it notes are decided by ``_NearTies.resolve`` as there."""
    from .kernels.samples import sample_faces
    H, W = camera.height, camera.width
    P, S = pixels.numel(), offsets.shape[-2]
    per_pixel = offsets.dim() == 3
    off = offsets.contiguous() if per_pixel else offsets[None].contiguous()
    args = (st.xy.contiguous().numpy(), st.q.contiguous().numpy(), st.face.contiguous().numpy(),
            pixels.contiguous().numpy(), off.numpy(), per_pixel, W, H, bool(camera.orthographic), float(camera.far))
    capacity = max(1024, 2 * P * S)
    while True:
        faces = kernels.buffer(P * S, torch.int64)
        notes = kernels.scratch("sample_notes", 2 * capacity, torch.int64).view(capacity, 2)
        n = sample_faces(*args, faces.numpy(), notes.numpy())
        if n <= capacity:
            break
        capacity = n
    if n == 0:
        return faces.view(P, S)
    ties = _NearTies(faces)
    ties.slots, ties.faces = [notes[:n, 0].clone()], [notes[:n, 1].clone()]

    def sample_point(slots):
        p, s = slots // S, slots % S
        pix = pixels.index_select(0, p)
        o = offsets[s] if offsets.dim() == 2 else offsets[p, s]
        return (pix % W).double() + o[:, 0], (pix // W).double() + o[:, 1]
    return ties.resolve(faces, lambda slots, f: _depth_at(st, camera, f, *sample_point(slots))).view(P, S)


# ------------------------------------------- stage 2, sub-pixel samples: the pixels a triangle touches

def pixel_triangle_pairs(xy, width: int, height: int, mask=None):
    """Every (pixel, triangle) pair whose closed pixel square and triangle touch: conservative coverage.

    xy: (T, 3, 2) screen triangles; width, height: the image; mask: None, or an (H*W,) bool tensor of the
    pixels to consider (the others are never enumerated). Returns ``pixel`` (N,) flat pixel indices
    (row-major) and ``tri`` (N,) indices into xy, grouped by triangle.

    Where ``rasterize`` asks whether a triangle covers a pixel's *centre*, this asks whether it touches the
    pixel's *square* at all: a sliver between two centres, or a triangle smaller than a pixel, still shows
    up. Row by row, the triangle is cut to the band ``[i, i+1]`` and the x-extent of that piece gives the
    columns. The extents are widened by a few rounding errors, so a pair is never lost to rounding; a pair
    that only touches a pixel's border (zero shared area) may be listed, which callers must tolerate.
    """
    xy = as_tensor(xy, dtype=torch.float64, name="xy")
    device = xy.device
    if xy.dim() != 3 or xy.shape[1:] != (3, 2):
        raise ValueError(f"xy must have shape (T, 3, 2), got {tuple(xy.shape)}")
    _check_finite(xy, "xy")
    width, height = _check_count(width, "width", minimum=0), _check_count(height, "height", minimum=0)
    if mask is not None:
        mask = torch.as_tensor(mask, device=device)
        if mask.dtype != torch.bool:
            raise TypeError(f"mask must be a bool tensor, got dtype {mask.dtype}")
        if mask.numel() != width * height:
            raise ValueError(f"mask must have H*W = {width * height} entries, got {mask.numel()}")
    none = torch.zeros(0, dtype=torch.int64, device=device)
    if xy.shape[0] == 0 or width <= 0 or height <= 0:
        return none, none
    slack = 1e-9 * (1 + xy.abs().amax((1, 2)))                              # (T,) a few rounding errors
    y = xy[..., 1]
    first = torch.floor(_min3(y) - slack).clamp(min=0)
    last = (torch.ceil(_max3(y) + slack) - 1).clamp(max=height - 1)
    tri_of_seg, seg_start = _expand((last - first + 1).clamp(min=0).long())
    row = first.index_select(0, tri_of_seg) + (torch.arange(tri_of_seg.numel(), device=device)
                                               - seg_start.index_select(0, tri_of_seg))   # (S,) band top
    a = xy.index_select(0, tri_of_seg)                                      # (S, 3, 2) corners
    b = a.roll(-1, 1)                                                       # edges a→b
    lo, hi = row[:, None], row[:, None] + 1                                 # (S, 1) the band
    dy = b[..., 1] - a[..., 1]
    flat = dy == 0
    t0 = (lo - a[..., 1]) / torch.where(flat, torch.ones_like(dy), dy)      # where the edge meets y = lo, hi
    t1 = (hi - a[..., 1]) / torch.where(flat, torch.ones_like(dy), dy)
    t_in = torch.minimum(t0, t1).clamp(min=0)                               # the part of the edge in the band
    t_out = torch.maximum(t0, t1).clamp(max=1)
    in_band = (a[..., 1] >= lo) & (a[..., 1] <= hi)
    t_in = torch.where(flat, torch.zeros_like(t_in), t_in)
    t_out = torch.where(flat, torch.ones_like(t_out), t_out)
    ok = torch.where(flat, in_band, t_in <= t_out)                          # (S, 3)
    dx = b[..., 0] - a[..., 0]
    x_in, x_out = a[..., 0] + t_in * dx, a[..., 0] + t_out * dx
    inf = torch.full_like(x_in, float("inf"))
    x_lo = torch.where(ok, torch.minimum(x_in, x_out), inf).amin(1)         # (S,)
    x_hi = torch.where(ok, torch.maximum(x_in, x_out), -inf).amax(1)
    pad = slack.index_select(0, tri_of_seg)
    meets = torch.isfinite(x_lo)                                            # a band the slack added may be empty
    col0 = torch.where(meets, torch.floor(x_lo - pad), torch.zeros_like(x_lo)).clamp(min=0)
    col1 = torch.where(meets, torch.ceil(x_hi + pad) - 1, torch.full_like(x_hi, -1.0)).clamp(max=width - 1)
    count = (col1 - col0 + 1).clamp(min=0).long()                           # empty where off the image
    base = (row * width + col0.clamp(max=width - 1)).long()                 # (only empty segments move)
    if mask is not None:                                                    # skip segments with no wanted pixel
        mask = mask.reshape(-1)
        cum = torch.cat([torch.zeros(1, dtype=torch.int64, device=device), torch.cumsum(mask.long(), 0)])
        wanted = (cum.index_select(0, base + count) - cum.index_select(0, base)) > 0
        count = count * wanted
    seg_of_px, px_start = _expand(count)
    pixel = base.index_select(0, seg_of_px) + (torch.arange(seg_of_px.numel(), device=device)
                                                - px_start.index_select(0, seg_of_px))
    tri = tri_of_seg.index_select(0, seg_of_px)
    if mask is not None:
        keep = mask.index_select(0, pixel).nonzero().squeeze(1)
        pixel, tri = pixel.index_select(0, keep), tri.index_select(0, keep)
    return pixel, tri


def _sample_inside(xy, points):
    """Top-left coverage of points by triangles with positive area. xy: (N, 3, 2); points: (N, S, 2).

    The same edge functions and fill rule as ``inside_triangle``, so a sample on an edge shared by two
    triangles is covered exactly once."""
    inside = torch.ones(points.shape[:2], dtype=torch.bool, device=points.device)
    for k in range(3):
        a, b = xy[:, k, None, :], xy[:, (k + 1) % 3, None, :]              # (N, 1, 2)
        e = edge_function(a, b, points)                                     # (N, S)
        inside &= (e > 0) | ((e == 0) & _is_top_left(a, b))
    return inside


def _sample_zbuffer(st: _ScreenTriangles, camera, pixels, offsets, budget=CHUNK[1]) -> torch.Tensor:
    """Stage 2 for sub-pixel samples: the nearest face at every sample of the listed pixels.

    pixels: (P,) flat pixel indices; offsets: (S, 2) the same for every pixel, or (P, S, 2) one set per
    pixel, each from the pixel's top-left corner. Returns (P, S) int64 face ids, -1 where none. A sample's
    answer depends only on its own position, never on which other pixels or samples are asked for, so a
    subset of pixels gets bit-identical ids to the full image.
    """
    H, W = camera.height, camera.width
    P, S = pixels.numel(), offsets.shape[-2]
    device = st.xy.device
    zbuf = torch.full((P * S,), EMPTY_KEY, dtype=torch.int64, device=device)
    if st.face.numel() == 0 or P == 0:
        return torch.full((P, S), -1, dtype=torch.int64, device=device)
    if kernels.active(st.xy):                                               # the compiled twin
        return _kernel_sample_zbuffer(st, camera, pixels, offsets)
    slot_of = torch.full((H * W,), -1, dtype=torch.int64, device=device)
    slot_of[pixels] = torch.arange(P, device=device)
    plane = _plane(st)
    pixel, tri = pixel_triangle_pairs(st.xy, W, H, slot_of >= 0)
    ties = _NearTies(zbuf) if REFINE_TIES else None
    step = max(1, budget // S)
    for lo in range(0, pixel.numel(), step):                                # bounded memory: step * S samples
        pix, t = pixel[lo:lo + step], tri[lo:lo + step]
        slot = slot_of.index_select(0, pix)
        corner = torch.stack([pix % W, pix // W], 1).double()               # (N, 2) top-left corner
        off = offsets[None] if offsets.dim() == 2 else offsets.index_select(0, slot)
        points = corner[:, None, :] + off                                   # (N, S, 2)
        inside = _sample_inside(st.xy.index_select(0, t), points)
        n, s = inside.nonzero().unbind(1)
        tn = t.index_select(0, n)
        p = points[n, s]
        q = _plane_at(plane, tn, p[:, 0], p[:, 1])
        depth = q.float() if camera.orthographic else q.float().reciprocal_()
        ok = (depth <= camera.far).nonzero().squeeze(1)
        face, target = st.face.index_select(0, tn).index_select(0, ok), (slot.index_select(0, n) * S + s)[ok]
        keys = _depth_keys(depth.index_select(0, ok), face, positive=not camera.orthographic)
        before = zbuf.index_select(0, target) if ties is not None and lo > 0 else None   # first step: empty
        zbuf.scatter_reduce_(0, target, keys, reduce="amin")
        if ties is not None:
            ties.check(target, keys, before)
    faces = _faces_of(zbuf)
    if ties is None:
        return faces.view(P, S)

    def sample_point(slots):
        p, s = slots // S, slots % S
        pix = pixels.index_select(0, p)
        off = offsets[s] if offsets.dim() == 2 else offsets[p, s]
        return (pix % W).double() + off[:, 0], (pix // W).double() + off[:, 1]
    return ties.resolve(faces, lambda slots, f: _depth_at(st, camera, f, *sample_point(slots))).view(P, S)
