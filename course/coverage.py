"""Exact pixel coverage: the box-filtered image of flat-coloured faces, in closed form (lecture 05).

A pixel (row i, column j) is the unit square [j, j+1] × [i, i+1]. Its exact (box-filtered) value is the
integral of the visible colour over that square: ``Σ_f colour_f · area(visible part of f in the square)``
plus the background times the uncovered area. Supersampling estimates that integral; here it is computed
exactly, as a sum of polygon areas, and it is the ground truth every antialiasing method is compared with.

The algorithm
-------------
1. **Which faces touch which pixels** (discrete, float64, no graph): raster's stage 1 clips every face at the
   near plane and projects it (``_screen_triangles``); ``pixel_triangle_pairs`` lists every (pixel, triangle)
   pair whose closed square and triangle touch. A face clipped into two triangles is listed once per pixel.
2. **Each face on screen, differentiably**: its camera-space triangle is clipped at z = near (a triangle or
   a quad) and projected; its *nearness* ``n(x, y) = A x + B y + C`` is affine on screen: n = 1/z for a
   pinhole camera (a plane's 1/z is affine in the image coordinates), n = -z for an orthographic one. Larger
   n is nearer. Polygons are reordered so their shoelace area is positive (``polygon_area``). This step runs
   in float64 whatever the working dtype: it is one row per face (cheap), and float32 screen coordinates
   hundreds of pixels from the origin would lose the digits that steps 4-5 need.
3. **Skips**: a face that covers the whole pixel square (its edge lines hold at the 4 corners, and the far
   plane does not cut it there) and is nearer than another face g at the 4 corners (n is affine, so the
   corners decide) hides g in that pixel: g is dropped there. A pixel left with one face that covers it is
   that face's colour (area 1, no clipping); a pixel left with one face needs no subtraction. And when only
   the image matters (not each face's own colour's derivative), a pixel whose square no edge where the
   colour can jump touches (``discontinuities.discontinuity_pixels``) shows one colour all over, the one at
   its centre, however many faces of that colour tile it: the interior of a silhouette needs no clipping.
4. **Visible pieces**: per (pixel, face f) the piece ``f ∩ square ∩ {z <= far}`` (Sutherland–Hodgman
   clipping, ``clip_polygon``), minus, for every other face g of the pixel, the convex region
   ``D = g ∩ {n_g > n_f} ∩ {z_g <= far}``: g's 3 or 4 edge half-planes, one depth half-plane and maybe one
   far half-plane, H1..Hk. A convex piece minus D is the disjoint union of convex pieces
   ``(piece ∩ ¬H1) ∪ (piece ∩ H1 ∩ ¬H2) ∪ ... ∪ (piece ∩ H1 ∩ ... ∩ ¬Hk)``; empty ones are dropped. The
   depth half-plane's border is where the planes of f and g cross in 3D, so faces that pass through each
   other (the teapot's spout and body) and cyclic overlaps need no special case. When the two faces are
   coplanar over the pixel there is no depth half-plane: the lower face id is in front (as ``rasterize``).
   A piece skips g when g is farther at the 4 pixel corners, when their bounding boxes miss, or when a line
   separates them (one of D's lines, or one of the piece's own edges against g's corners); it disappears
   when it lies inside D. Faces are subtracted nearest first (at the pixel centre), which removes most of a
   hidden piece early. The cost grows with Σ K² over pixels (K faces touching a pixel): cheap at ordinary
   resolutions, slow when hundreds of faces share a pixel.
5. **Areas** by the shoelace formula. Steps 4 and 5 work in coordinates relative to the pixel's top-left
   corner (numbers below 1, where float32 keeps its digits), in the working dtype; then
   ``exact_coverage = Σ area · colour + background · (1 - Σ area)``.

Derivatives: everything in steps 2-5 is plain torch on the differentiable camera-space vertices, so autograd
gives d image / d (verts, colours, K, R, t). The image is piecewise rational in those: smooth while the
arrangement of lines is fixed, with kinks where it changes (a vertex crossing a pixel border, an edge-on
face, two faces becoming coplanar). The commonest kinks are exact ties, not accidents: a symmetric scene puts
a line of the scene exactly on a pixel border, a square on the pixel grid puts its corners on pixel corners.
There, when a gradient is wanted, every decision is taken as if the scene sat a hair (1e-9 px) toward +x, +y
against the pixel grid (``_Pieces``), so the derivative is the one-sided one for that motion, the same in
every pixel and the same that ``boundary`` (Reynolds, edge sampling) computes; the values are unchanged.
Elsewhere (two faces becoming coplanar, an edge turning edge-on) autograd returns the derivative of the
arrangement the code chose, one side's; every division is guarded, so it is finite.

Memory: the plan (steps 1 and 3) lists the whole image's (pixel, face) pairs: raster's
``pixel_triangle_pairs`` needs about 150 bytes per pair while it runs (100 MB for 700k pairs, a 20k-face
sphere at 512²), then 24 bytes per pair are kept. The pieces are then built in chunks of about ``CHUNK``
pairs (whole pixels): about 0.5 KB per pair of a chunk, ≈ 8 MB at CHUNK = 2**14 (measured: 30 MB at 2**16).
``exact_coverage`` adds each chunk into the image and lets it go, so without autograd that is its peak;
``visible_regions`` returns every piece (about 150 bytes each). With autograd the graph keeps every
chunk's tensors until backward, so memory then grows with the number of pieces in the image.

A camera batch (``exact_coverage(mesh, [camera, ...], ...)``): steps 1-3 run view by view (the plan, discrete
and cheap), the plans are joined with pixel ids ``view · H · W + pixel`` (``_joined``), and steps 4-5 run
chunk by chunk over every view's pairs at once. The chunks keep their size, so the gain is the partly empty
last chunk of every view, and the per-chunk work a call per view repeats: measured in ``bench fit --only batch``.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from itertools import accumulate

import torch

from . import raster, scan
from .camera import world_to_camera
from .discontinuities import _color_keys, discontinuity_pixels
from .tensors import as_tensor

__all__ = ["exact_coverage", "visible_regions", "VisibleRegions", "clip_polygon", "polygon_area",
           "halfplane_pixel_area", "CHUNK"]

CHUNK = 1 << 14          # (pixel, face) pairs per chunk of work; bounds the working memory (module docstring)


@dataclass(frozen=True)
class VisibleRegions:
    """The visible part of every face in every pixel, as convex pieces (N of them, at most M vertices).

    pixel: (N,) int64 flat pixel index (row-major: row = pixel // W, column = pixel % W).
    face:  (N,) int64 face id.
    verts: (N, M, 2) the piece's vertices relative to its pixel's top-left corner (column, row), positive
           shoelace orientation; slots past ``count`` repeat the last vertex (so they add no area). Differentiable.
    count: (N,) int64 number of vertices.
    area:  (N,) area of the piece in pixels (the unit square has area 1). Differentiable.
    A face may have several pieces in one pixel; pieces of one pixel never overlap.
    """
    pixel: torch.Tensor
    face: torch.Tensor
    verts: torch.Tensor
    count: torch.Tensor
    area: torch.Tensor

    def image_verts(self, width: int) -> torch.Tensor:
        """(N, M, 2) the vertices in image coordinates (x right, y down)."""
        corner = torch.stack([self.pixel % width, self.pixel // width], -1).to(self.verts.dtype)
        return self.verts + corner[:, None, :]


# ------------------------------------------------------------------------- the lecture's building blocks

def clip_polygon(poly, line) -> torch.Tensor:
    """One Sutherland–Hodgman step: the part of a convex polygon where ``a x + b y + c >= 0``.

    poly: (N, 2) vertices in order; line: (3,) the coefficients (a, b, c). Returns (M, 2), M <= N + 1, the
    clipped polygon in the same cyclic order (M = 0 when nothing is left). Walk each edge p → q: keep p when
    it is inside, and add the crossing ``p + s_p / (s_p - s_q) (q - p)`` when p and q lie on different sides
    (s = a x + b y + c; the denominator is nonzero exactly then). Differentiable.
    """
    poly = as_tensor(poly, name="poly")
    line = as_tensor(line, dtype=poly.dtype, device=poly.device, name="line")
    if poly.dim() != 2 or poly.shape[1] != 2 or line.shape != (3,):
        raise ValueError(f"expected poly (N, 2) and line (3,), got {tuple(poly.shape)} and {tuple(line.shape)}")
    s = poly[:, 0] * line[0] + poly[:, 1] * line[1] + line[2]              # (N,) signed value per vertex
    out = []
    for k in range(poly.shape[0]):
        nxt = (k + 1) % poly.shape[0]
        if s[k] >= 0:
            out.append(poly[k])
        if (s[k] >= 0) != (s[nxt] >= 0):                                   # the edge crosses the line
            out.append(poly[k] + s[k] / (s[k] - s[nxt]) * (poly[nxt] - poly[k]))
    return torch.stack(out) if out else poly.new_zeros((0, 2))


def polygon_area(poly) -> torch.Tensor:
    """Signed area of a polygon by the shoelace formula, ``½ Σ (x_k y_k+1 - x_k+1 y_k)``.

    poly: (N, 2) in image coordinates (x right, y down). Returns a scalar tensor, positive when the vertices
    run *clockwise as seen on screen* (e.g. (0,0) → (1,0) → (1,1): right, then down), negative when they
    run counter-clockwise on screen, as a front face's do. Coordinates are taken relative to the first
    vertex, so a small polygon far from the origin keeps its digits. Differentiable.
    """
    poly = as_tensor(poly, name="poly")
    if poly.dim() != 2 or poly.shape[1] != 2:
        raise ValueError(f"poly must have shape (N, 2), got {tuple(poly.shape)}")
    if poly.shape[0] < 3:
        return poly.new_zeros(())
    p = poly - poly[0]
    x, y = p[:, 0], p[:, 1]
    return 0.5 * (x * y.roll(-1) - x.roll(-1) * y).sum()


def halfplane_pixel_area(line, col, row) -> torch.Tensor:
    """Area of pixel (row, col)'s unit square [col, col+1] × [row, row+1] on the side ``a x + b y + c >= 0``.

    line: (3,) (a, b, c) in image coordinates; col, row: integers. Returns a scalar in [0, 1]: the coverage
    of that pixel by a half-plane, the building block of analytic antialiasing (one clip, one area).
    """
    line = as_tensor(line, name="line")
    if line.shape != (3,):
        raise ValueError(f"line must have shape (3,), got {tuple(line.shape)}")
    a, b, c = line.unbind(0)
    local = torch.stack([a, b, c + a * col + b * row])                     # the same line, pixel-relative
    square = torch.tensor([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], dtype=line.dtype, device=line.device)
    return polygon_area(clip_polygon(square, local))


# ---------------------------------------------------------------- the same steps, on padded batches

def _take(x, idx):
    """Rows of a batch of point lists: x (N, M, D), idx (N, K) → (N, K, D)."""
    return x.gather(1, idx[..., None].expand(-1, -1, x.shape[-1]))


def _pad(poly, width):
    """(N, M, D) → (N, width, D), width >= M, repeating the last slot (padding adds no area)."""
    extra = width - poly.shape[1]
    return poly if extra <= 0 else torch.cat([poly, poly[:, -1:].expand(-1, extra, -1)], 1)


def _clip_rows(poly, count, s, inside=None, tol=0.0, on=None, lines=None, line=None):
    """``clip_polygon`` on N padded convex polygons at once, keeping the part where s >= 0.

    poly: (N, M, D) points (D = 2 on screen, 3 in camera space), slots past count repeating the last vertex;
    count: (N,); s: (N, M) the value at each vertex of a function affine along the edges; inside: optional
    (N, M) bool decisions to use instead of ``s >= 0``; tol: an edge whose two ends have ``|s| <= tol`` lies
    on the line (on: (N, M) bool, those vertices, given instead). Returns (N, M', D) and the new counts (N,).
    lines: optional (N, M, 3), the line each edge k → k+1 lies on, and line (N, 3) the clipping line: then
    the clipped polygon's edge lines come back too, (N, M', 3) (a kept vertex keeps its edge; a crossing
    starts an edge along the clipping line where the polygon leaves the half-plane, along its own edge where
    it enters).
    Every vertex emits itself (if inside) and its edge's crossing (if the edge changes side); a cumulative sum
    gives each emitted point its output slot.

    Why tol: a vertex that lies on the line in exact arithmetic (an earlier crossing on a line through the
    same mesh vertex, a shared edge seen from both of its faces) has an s of rounding noise, ±1e-17. When
    both ends of an edge are such vertices, their signs can differ, and the crossing ``t = s_p / (s_p - s_q)``
    is noise / noise: a point anywhere on the edge whose derivative is a ratio of rounding errors, O(1) or
    worse, left in a sliver of area 0 that autograd still differentiates (it moved the teapot's gradients by
    O(1)). Such an edge is split at its start p instead, t = 0, with p's derivative; the complementary clip
    (``-s``) splits it at the same point, so the two parts still tile the polygon, derivatives included.
    An isolated vertex on the line keeps its noisy sign: its crossings (t near 0 or 1) are well conditioned
    and lie on the right lines, which is what keeps a vertex where three lines meet (a symmetric mesh)
    differentiable.
    """
    N, M, D = poly.shape
    k = torch.arange(M, device=poly.device)
    real = k < count[:, None]                                               # (N, M)
    nxt = torch.where(k + 1 < count[:, None], k + 1, 0)                     # the edge k → nxt, cyclic
    ins = s >= 0 if inside is None else inside
    keep = real & ins
    cross = real & (ins != ins.gather(1, nxt))
    on = s.detach().abs() <= tol if on is None else on
    cross_at = cross & ~(on & on.gather(1, nxt))                            # not an edge along the line (t = 0)
    denom = s - s.gather(1, nxt)
    denom = torch.where(cross_at & (denom != 0), denom, torch.ones_like(denom))   # guarded: no 0/0, even unused
    t = torch.where(cross_at, s / denom, torch.zeros_like(s))
    # kept on the edge: at a tie (a vertex on the line) rounding can put t a hair outside [0, 1], and clamp's
    # derivative would be 0 where the crossing does move; far outside, the values disagree with the decisions
    # (a float32 piece decided in float64) and t's derivative means nothing: clamped
    near = (t.detach() > -0.5) & (t.detach() < 1.5)
    t = torch.where(near, t + (t.detach().clamp(0, 1) - t.detach()), t.clamp(0, 1))
    hit = poly + t[..., None] * (_take(poly, nxt) - poly)                   # (N, M, D) crossings
    cand = torch.stack([poly, hit], 2).reshape(N, 2 * M, D)
    emit = torch.stack([keep, cross], 2).reshape(N, 2 * M)
    new_count = emit.sum(1)
    width = max(int(new_count.max()), 1) if N else 1
    slot = torch.where(emit, emit.cumsum(1) - 1, width)                     # unused candidates → a spare slot
    src = torch.zeros(N, width + 1, dtype=torch.int64, device=poly.device)
    src.scatter_(1, slot, torch.arange(2 * M, device=poly.device).expand(N, -1))
    last = torch.minimum(torch.arange(width, device=poly.device), (new_count - 1).clamp(min=0)[:, None])
    which = src.gather(1, last)
    if lines is None:
        return _take(cand, which), new_count
    enters = ins.gather(1, nxt)                                             # the edge's end is inside
    hit_line = torch.where(enters[..., None], lines, line[:, None, :].expand_as(lines))
    cand_lines = torch.stack([lines, hit_line], 2).reshape(N, 2 * M, 3)
    return _take(cand, which), new_count, _take(cand_lines, which)


def _areas(poly):
    """Shoelace areas of padded polygons (N, M, 2) → (N,)."""
    x, y = poly[..., 0], poly[..., 1]
    return 0.5 * (x * y.roll(-1, 1) - x.roll(-1, 1) * y).sum(1)


def _edge_lines(poly):
    """(N, M, 2) polygons → (N, M, 3) the line of each edge k → k+1, ``cross(q - p, x - p) >= 0`` inside
    (the interior of a positively oriented polygon)."""
    p, q = poly, poly.roll(-1, 1)
    d = q - p
    return torch.stack([-d[..., 1], d[..., 0], d[..., 1] * p[..., 0] - d[..., 0] * p[..., 1]], -1)


def _values(lines, pts):
    """Lines (N, L, 3) evaluated at points (N, M, 2) → (N, L, M)."""
    return (lines[..., 0:1] * pts[:, None, :, 0] + lines[..., 1:2] * pts[:, None, :, 1]) + lines[..., 2:3]


def _local(coef, corner):
    """An affine function A x + B y + C (N, 3) in the coordinates relative to corner (N, 2)."""
    c = coef[:, 2] + coef[:, 0] * corner[:, 0] + coef[:, 1] * corner[:, 1]
    return torch.stack([coef[:, 0], coef[:, 1], c], -1)


# ------------------------------------------------------------------------------- faces on screen

@dataclass
class _Faces:
    """The used faces on screen: xy (U, 4, 2) polygon (padded), count (U,), coef (U, 3) nearness A, B, C."""
    xy: torch.Tensor
    count: torch.Tensor
    coef: torch.Tensor

    @staticmethod
    def cat(parts) -> "_Faces":
        """The rows of several, in order (the views of a camera batch)."""
        return _Faces(*(torch.cat([getattr(p, f.name) for p in parts]) for f in fields(_Faces)))


def _safe(x):
    """x with values too close to 0 replaced by ±sqrt(tiny): a finite quotient for edge-on faces."""
    tiny = torch.finfo(x.dtype).tiny ** 0.5
    return torch.where(x.abs() < tiny, torch.where(x < 0, -tiny, tiny), x)


def _face_geometry(verts_cam, faces, camera, K, inside, flip) -> _Faces:
    """Near-clipped screen polygons and nearness planes of faces (U, 3), in verts_cam's dtype.

    inside: (U, 3) bool, which corners are in front of the near plane (decided once, in float64, so both
    precisions clip alike); flip: (U,) bool, reverse the order (so every polygon has positive area).
    """
    v = verts_cam[faces]                                                    # (U, 3, 3)
    v = torch.where(flip[:, None, None], v[:, [0, 2, 1]], v)
    inside = torch.where(flip[:, None], inside[:, [0, 2, 1]], inside)
    three = torch.full((v.shape[0],), 3, dtype=torch.int64, device=v.device)
    poly, count = _clip_rows(v, three, v[..., 2] - camera.near, inside)    # (U, <=4, 3) camera space
    poly = _pad(poly, 4)
    z = poly[..., 2:]
    if camera.orthographic:
        xy1 = torch.cat([poly[..., :2], torch.ones_like(z)], -1)
    else:
        xy1 = poly / torch.where(z > 0, z, torch.ones_like(z))              # z >= near > 0 where used
    xy = (xy1 @ K.T)[..., :2]                                               # (U, 4, 2) pixels
    # the plane N · X = d through the face; a pixel p = (x, y, 1) sees X = z K⁻¹ p (pinhole) or (K⁻¹ p)_xy + z e3
    normal = torch.linalg.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])      # (U, 3)
    d = (normal * v[:, 0]).sum(-1)
    Kinv = torch.linalg.inv(K)
    if camera.orthographic:                                                 # n = -z = (N_x X + N_y Y - d) / N_z
        e3 = torch.tensor([0.0, 0.0, 1.0], dtype=K.dtype, device=K.device)
        coef = (normal[:, :1] * Kinv[0] + normal[:, 1:2] * Kinv[1] - d[:, None] * e3) / _safe(normal[:, 2:])
    else:                                                                   # n = 1/z = (N K⁻¹ p) / d
        coef = (normal @ Kinv) / _safe(d)[:, None]
    return _Faces(xy, count, coef)


def _far_value(camera):
    """The nearness of the far plane: z <= far ⇔ n >= this."""
    return -camera.far if camera.orthographic else 1.0 / camera.far


# ------------------------------------------------------------------- step 1 and 3: the plan (float64)

@dataclass
class _Plan:
    """What the discrete, float64 part decides (no graph). U used faces, R pairs needing pieces."""
    used: torch.Tensor        # (U,) face ids
    inside: torch.Tensor      # (U, 3) corners in front of the near plane
    flip: torch.Tensor        # (U,) reverse the corner order
    geo: _Faces               # float64 geometry of the used faces (oriented)
    edge_ok: torch.Tensor     # (U, 4) the polygon edge has nonzero length
    far: torch.Tensor         # (U,) the face reaches beyond the far plane
    lo: torch.Tensor          # (U, 2) bounding box of the screen polygon
    hi: torch.Tensor          # (U, 2)
    pixel: torch.Tensor       # (R,) pairs needing pieces, by pixel, nearest face first
    face: torch.Tensor        # (R,) local face index
    size: torch.Tensor        # (R,) number of faces kept in the pair's pixel
    full_pixel: torch.Tensor  # pixels a single face covers entirely
    full_face: torch.Tensor   # (local index of) that face


def _corners(pixel, W):
    """(R,) flat pixels → (R, 4, 2) the corners of their squares in image coordinates."""
    col, row = (pixel % W).double(), (pixel // W).double()
    dx = torch.tensor([0.0, 1.0, 1.0, 0.0], dtype=torch.float64, device=pixel.device)
    dy = torch.tensor([0.0, 0.0, 1.0, 1.0], dtype=torch.float64, device=pixel.device)
    return torch.stack([col[:, None] + dx, row[:, None] + dy], -1)


def _nearness(coef, pts):
    """coef (R, 3) at points (R, K, 2) → the value (R, K) and a scale for its rounding (R, K)."""
    terms = coef[:, None, :2] * pts
    return terms.sum(-1) + coef[:, None, 2], terms.abs().sum(-1) + coef[:, None, 2].abs()


def _coplanar(n_a, s_a, n_b, s_b):
    """Two faces' nearness agrees at the 4 corners to rounding: treat them as one plane (tie → lower id)."""
    return ((n_a - n_b).abs() <= 1e-9 * (s_a + s_b)).all(-1)


def _groups(pixel):
    """For pairs sorted by pixel (R,): the first pair of each one's pixel and the pixel's pair count (R,)."""
    _, counts = torch.unique_consecutive(pixel, return_counts=True)
    start = torch.cumsum(counts, 0) - counts
    return torch.repeat_interleave(start, counts), torch.repeat_interleave(counts, counts)


def _pixel_chunks(pixel, size):
    """(lo, hi) ranges of pairs sorted by pixel (R,): about ``size`` pairs each, never splitting a pixel."""
    lo, R = 0, pixel.numel()
    while lo < R:
        hi = min(lo + size, R)
        while hi < R and pixel[hi] == pixel[hi - 1]:
            hi += 1
        yield lo, hi
        lo = hi


def _plan(verts, faces, camera, shift: bool = False, mask=None) -> _Plan:
    H, W, F = camera.height, camera.width, faces.shape[0]
    vc = raster._camera_space(verts, camera)                                # (V, 3) float64, detached
    st = raster._screen_triangles(vc, faces, camera, False, reach=0.0)
    pixel, tri = scan.pixel_triangle_pairs(st.xy, W, H, mask)             # mask: the pixels to plan (None: all)
    key = torch.unique(pixel * F + st.face.index_select(0, tri))            # one entry per (pixel, face)
    del pixel, tri
    pixel, face_id = key // F, key % F
    used, face = torch.unique(face_id, return_inverse=True)
    K = camera.K.detach().double()
    inside = vc[faces[used]][..., 2] >= camera.near
    no_flip = torch.zeros_like(used, dtype=torch.bool)
    flip = _areas(_face_geometry(vc, faces[used], camera, K, inside, no_flip).xy) < 0
    geo = _face_geometry(vc, faces[used], camera, K, inside, flip)
    d = geo.xy.roll(-1, 1) - geo.xy
    edge_ok = d.abs().amax(-1) > 1e-12 * (1 + geo.xy.abs().amax(-1))
    far = vc[faces[used]][..., 2].amax(-1) > camera.far
    kept = [_hide(pixel[lo:hi], face[lo:hi], face_id[lo:hi], geo, edge_ok, far, camera, shift)
            for lo, hi in _pixel_chunks(pixel, 4 * CHUNK)]
    pixel, face, covers = (torch.cat(x) for x in zip(*kept)) if kept else (pixel, face, face > 0)
    _, size = _groups(pixel)
    full = (size == 1) & covers
    rest = ~full
    return _Plan(used, inside, flip, geo, edge_ok, far, geo.xy.amin(1), geo.xy.amax(1), pixel[rest], face[rest],
                 size[rest], pixel[full], face[full])


def _joined(plans, pixels) -> _Plan:
    """One plan of a camera batch from its views' (``_plan``, in order): view k's pixels numbered
    k · pixels + their own, its faces' rows after the earlier views' (local face indices offset by their
    used faces), so its pairs stay sorted by pixel and the chunks run over every view at once."""
    if len(plans) == 1:
        return plans[0]
    offset = list(accumulate([p.used.numel() for p in plans[:-1]], initial=0))

    def cat(name):
        return torch.cat([getattr(p, name) for p in plans])
    return _Plan(cat("used"), cat("inside"), cat("flip"), _Faces.cat([p.geo for p in plans]), cat("edge_ok"),
                 cat("far"), cat("lo"), cat("hi"),
                 torch.cat([p.pixel + k * pixels for k, p in enumerate(plans)]),
                 torch.cat([p.face + o for p, o in zip(plans, offset)]), cat("size"),
                 torch.cat([p.full_pixel + k * pixels for k, p in enumerate(plans)]),
                 torch.cat([p.full_face + o for p, o in zip(plans, offset)]))


def _hide(pixel, face, face_id, geo, edge_ok, far, camera, shift):
    """Step 3 on pairs of whole pixels: order each pixel's faces nearest first (at its centre) and drop the
    faces that a face covering the whole square hides. Returns the kept pixel, face and covers (R',)."""
    corner = _corners(pixel, camera.width)                                  # (R, 4, 2)
    if shift:                                                               # as the decision copy sees them
        corner = corner - corner.new_tensor(TIE_SHIFT)                      # (_Pieces: ties)
    lines = _edge_lines(geo.xy).index_select(0, face)                       # (R, 4, 3)
    covers = ((_values(lines, corner) >= 0) | ~edge_ok[face][..., None]).all(-1).all(-1)
    n, scale = _nearness(geo.coef.index_select(0, face), corner)            # (R, 4)
    covers &= (geo.count[face] >= 3) & (~far[face] | (n >= _far_value(camera)).all(-1))
    n_centre = _nearness(geo.coef.index_select(0, face), corner.mean(1, keepdim=True))[0][:, 0]
    order = torch.argsort(-n_centre, stable=True)
    order = order[torch.argsort(pixel[order], stable=True)]
    pixel, face, face_id, covers, n, scale = (x[order] for x in (pixel, face, face_id, covers, n, scale))
    start, size = _groups(pixel)
    reps = size * covers                                                    # each covering a meets its pixel
    a = torch.repeat_interleave(torch.arange(pixel.numel(), device=pixel.device), reps)
    first = torch.repeat_interleave(torch.cumsum(reps, 0) - reps, reps)   # where each a's run begins
    b = start[a] + torch.arange(a.numel(), device=a.device) - first
    cop = _coplanar(n[a], scale[a], n[b], scale[b])
    hides = (a != b) & torch.where(cop, face_id[a] < face_id[b], (n[a] > n[b]).all(-1))
    kept = torch.ones_like(covers).index_put((b[hides],), torch.tensor(False, device=b.device))
    return pixel[kept], face[kept], covers[kept]


# ------------------------------------------------------------------- step 4: pieces, differentiably

TRUE = (0.0, 0.0, 1.0)   # a line that holds everywhere: a half-plane that is not there
TIE_SHIFT = (1e-9, 0.7548776662466927e-9)   # pixels: where the decisions see the scene (see _Pieces)


def _tol(dtype):
    """Distances (pixels) below this are rounding: a vertex this close to a line is on it."""
    return max(1e-12, 16 * torch.finfo(dtype).eps)


@dataclass
class _Pieces:
    """A batch of convex pieces, pixel-relative: ``poly`` (N, M, 2) the values autograd differentiates (in
    the working dtype), ``count`` (N,) and ``owner`` (N,) the (pixel, face) pair each belongs to.

    With a gradient wanted, two more: ``dec`` (N, M, 2), a float64 copy that takes every decision, and
    ``lines`` (N, M, 3), the line each edge lies on. Why. The image is continuous, but where a line of the
    scene lies exactly on a pixel border or a vertex sits exactly on a pixel corner (a symmetric scene, a
    square on the pixel grid, a line through the image centre) each pixel's value has a kink: moving the
    line left changes one pixel, moving it right the other. Autograd differentiates whichever arrangement
    the clipping chose, pixel by pixel, and rounding noise can choose one side in one pixel and the other in
    its neighbour: a derivative that belongs to no motion at all. So every decision (which side of a line a
    vertex is on, whether a piece is empty) is taken on ``dec``, the scene shifted by ``TIE_SHIFT`` (1e-9 px
    right, 0.75e-9 px down) against the pixel squares; the values follow the same decisions unshifted. A
    line on a border then belongs to the pixel on its right (or below), as the half-open pixels [j, j+1) of
    the conventions say, in every pixel at once: the derivative is the one-sided one for moving the scene
    toward +x, +y on screen. Pieces that are empty in the values but not in ``dec`` (a line on a border
    bounds a sliver of width 0 that grows as it moves) are kept, and at the end each vertex takes the
    derivative of the crossing of its two edges' lines (``_vertex_derivatives``): where several lines meet
    at one point (a vertex on a pixel corner) the values' edges between them have length 0 and an
    interpolation along them would lose how the point moves. Without a gradient the values decide."""
    poly: torch.Tensor
    count: torch.Tensor
    owner: torch.Tensor
    dec: torch.Tensor | None = None
    lines: torch.Tensor | None = None

    def take(self, idx) -> "_Pieces":
        pick = lambda x: None if x is None else x[idx]
        return _Pieces(self.poly[idx], self.count[idx], self.owner[idx], pick(self.dec), pick(self.lines))

    def decide(self):
        """The points decisions are taken on: the decision copy, or the values themselves."""
        return self.poly.detach() if self.dec is None else self.dec

    def clip(self, s, s_dec, line, tol, inside=None) -> "_Pieces":
        """The part where s >= 0 (values s (N, M), decision values s_dec or None, the line (N, 3) in the
        values' frame): both copies clipped alike, with the decision copy's sides (or ``inside``) and its
        notion of a vertex lying on the line (``_clip_rows``)."""
        d = s.detach() if s_dec is None else s_dec
        inside = d >= 0 if inside is None else inside
        on = d.abs() <= tol
        if self.dec is None:
            poly, count = _clip_rows(self.poly, self.count, s, inside, on=on)
            return _Pieces(poly, count, self.owner)
        poly, count, lines = _clip_rows(self.poly, self.count, s, inside, on=on, lines=self.lines, line=line)
        dec, _ = _clip_rows(self.dec, self.count, s_dec, inside, on=on)
        return _Pieces(poly, count, self.owner, dec, lines)

    def keep(self, tol) -> "_Pieces":
        """Drop pieces with fewer than 3 vertices or no area (as the decision copy sees it)."""
        return self.take(((self.count >= 3) & (_areas(self.decide()) > tol * tol)).nonzero().squeeze(1))

    @staticmethod
    def cat(parts) -> "_Pieces":
        width = max(p.poly.shape[1] for p in parts)
        join = lambda xs: None if xs[0] is None else torch.cat([_pad(x, width) for x in xs])
        return _Pieces(join([p.poly for p in parts]), torch.cat([p.count for p in parts]),
                       torch.cat([p.owner for p in parts]), join([p.dec for p in parts]),
                       join([p.lines for p in parts]))


def _vertex_derivatives(pieces: _Pieces):
    """The pieces' vertices (N, M, 2) with the values of ``poly`` and, where the two lines through a vertex
    cross at an angle (sin > 1e-6), the derivative of their crossing point (``_Pieces``: why)."""
    poly, lines, count = pieces.poly, pieces.lines, pieces.count
    if lines is None or poly.shape[0] == 0:
        return poly
    M = poly.shape[1]
    k = torch.arange(M, device=poly.device)
    prev = torch.where(k > 0, k - 1, count[:, None] - 1).clamp(min=0)       # the edge into vertex k
    l1, l2 = _take(lines, prev), lines                                      # (N, M, 3) each
    det = l1[..., 0] * l2[..., 1] - l2[..., 0] * l1[..., 1]
    size = l1[..., :2].norm(dim=-1) * l2[..., :2].norm(dim=-1)
    good = (det.detach().abs() > 1e-6 * size.detach()) & (k < count[:, None])
    det = torch.where(good, det, torch.ones_like(det))
    x = (l1[..., 1] * l2[..., 2] - l2[..., 1] * l1[..., 2]) / det
    y = (l2[..., 0] * l1[..., 2] - l1[..., 0] * l2[..., 2]) / det
    cross = torch.stack([x, y], -1)
    out = torch.where(good[..., None], poly.detach() + (cross - cross.detach()), poly)
    last = torch.minimum(k, (count - 1).clamp(min=0)[:, None])              # padding repeats the last vertex
    return _take(out, last)


def _distances(line, poly):
    """Signed distances (N, M) of points (N, M, 2) to lines (N, 3); ``TRUE`` rows give huge values."""
    norm = line[:, :2].norm(dim=-1).clamp(min=torch.finfo(line.dtype).tiny)
    return _values(line[:, None], poly)[:, 0] / norm[:, None]


SQUARE = ((1.0, 0.0, 0.0), (-1.0, 0.0, 1.0), (0.0, 1.0, 0.0), (0.0, -1.0, 1.0))   # u >= 0, u <= 1, v >= 0, v <= 1


def _square_piece(geo, plan, pixel, face, camera, dtype, shift):
    """Each pair's piece f ∩ square ∩ {z <= far}, pixel-relative, as ``_Pieces`` (owner: the pair's index),
    and the pixels' corners (R, 2) for the values and for the decisions (``None`` without the shifted copy)."""
    W = camera.width
    corner = torch.stack([pixel % W, pixel // W], -1).to(geo.xy.dtype)      # (R, 2)
    poly, count = (geo.xy[face] - corner[:, None]).to(dtype), geo.count[face]   # pixel-relative, then dtype
    owner = torch.arange(pixel.numel(), device=pixel.device)
    corner_dec = corner - corner.new_tensor(TIE_SHIFT) if shift else None
    if shift:
        pieces = _Pieces(poly, count, owner, geo.xy[face].detach() - corner_dec[:, None], _edge_lines(poly))
    else:
        pieces = _Pieces(poly, count, owner)
    tol = _tol(torch.float64 if shift else dtype)
    for line in SQUARE:
        line = poly.new_tensor(line).expand(poly.shape[0], 3)
        s = _values(line[:, None], pieces.poly)[:, 0]
        s_dec = None if not shift else _values(line[:, None].double(), pieces.dec)[:, 0]
        pieces = pieces.clip(s, s_dec, line, tol)
    far = plan.far[face]
    if bool(far.any()):
        def far_line(c):
            line = _local(geo.coef[face], c) - c.new_tensor([0.0, 0.0, _far_value(camera)])
            return torch.where(far[:, None], line, line.new_tensor(TRUE))
        line = far_line(corner).to(dtype)
        s_dec = None if not shift else _distances(far_line(corner_dec).detach(), pieces.dec)
        pieces = pieces.clip(_distances(line, pieces.poly), s_dec, line, tol)
    return pieces, corner, corner_dec


def _occluder_lines(geo, plan, f, g, corner, camera, cop, dtype):
    """D = g ∩ {n_g > n_f} ∩ {z_g <= far} as 6 half-planes (rows, 6, 3), pixel-relative, in dtype; ``TRUE``
    rows for the half-planes a face does not have (a triangle's 4th edge, the depth line when coplanar...)."""
    true = torch.tensor(TRUE, dtype=geo.xy.dtype, device=geo.xy.device)
    edges = _edge_lines(geo.xy[g] - corner[:, None])                        # (rows, 4, 3)
    edges = torch.where(plan.edge_ok[g][..., None], edges, true)
    depth = _local(geo.coef[g] - geo.coef[f], corner)                       # n_g - n_f > 0: g is nearer
    depth = torch.where(cop[:, None], true, depth)
    far = _local(geo.coef[g], corner) - true.new_tensor([0.0, 0.0, _far_value(camera)])
    far = torch.where(plan.far[g][:, None], far, true)
    return torch.cat([edges, depth[:, None], far[:, None]], 1).to(dtype)


def _classify(poly, lines, g_poly, tol):
    """Per row: does a line separate the piece from D (skip g), or does the piece lie inside D (drop it)?"""
    norm = lines[..., :2].norm(dim=-1).clamp(min=torch.finfo(lines.dtype).tiny)   # TRUE: huge values
    val = _values(lines, poly) / norm[..., None]                            # (rows, 6, M) distances
    separated = (val.amax(-1) <= tol).any(-1)                               # one of D's lines
    inside = (val.amin(-1) >= -tol).all(-1)
    edges = _edge_lines(poly)                                               # or one of the piece's edges
    length = edges[..., :2].norm(dim=-1)
    gval = _values(edges, g_poly) / length.clamp(min=torch.finfo(lines.dtype).tiny)[..., None]
    separated |= ((length > tol) & (gval.amax(-1) <= tol)).any(-1)
    return separated, inside & ~separated


def _subtract(pieces: _Pieces, lines, lines_dec, tol):
    """Convex pieces minus the convex regions given by lines (rows, 6, 3) (lines_dec: the same for the
    decision copy, or None): the disjoint pieces piece ∩ ¬H1, piece ∩ H1 ∩ ¬H2, ... Returns a list of
    ``_Pieces`` whose ``owner`` is the row each came from.

    The values are distances, so tol (pixels) tells an edge that lies on Hh's line (a shared edge of two
    occluders, a crossing through a mesh vertex) from one that crosses it (``_clip_rows``)."""
    rows = torch.arange(pieces.poly.shape[0], device=pieces.poly.device)
    pieces = _Pieces(pieces.poly, pieces.count, rows, pieces.dec, pieces.lines)
    out = []
    for h in range(lines.shape[1]):
        s = _distances(lines[:, h], pieces.poly)                            # (rows, M) signed distances
        s_dec = None if lines_dec is None else _distances(lines_dec[:, h], pieces.dec)
        d = s.detach() if s_dec is None else s_dec
        real = torch.arange(pieces.poly.shape[1], device=s.device) < pieces.count[:, None]
        cut = ((d < 0) & real).any(1)
        if not bool(cut.any()):
            continue                                                        # nothing outside Hh: no piece
        i = cut.nonzero().squeeze(1)
        inside = d[i] >= 0
        part = pieces.take(i)
        neg = None if s_dec is None else -s_dec[i]
        out.append(part.clip(-s[i], neg, -lines[i, h], tol, ~inside))      # piece ∩ ¬Hh
        rest = part.clip(s[i], None if s_dec is None else s_dec[i], lines[i, h], tol, inside)   # go on in Hh
        width = max(rest.poly.shape[1], pieces.poly.shape[1])
        put = lambda x, y: None if x is None else _pad(x, width).index_copy(0, i, _pad(y, width))
        pieces = _Pieces(put(pieces.poly, rest.poly), pieces.count.index_copy(0, i, rest.count), pieces.owner,
                         put(pieces.dec, rest.dec), put(pieces.lines, rest.lines))
    return out


def _chunk_pieces(geo, plan, lo, hi, camera, dtype, shift):
    """The visible pieces of the pairs lo:hi of the plan (whole pixels). Returns poly, count, pair index.
    shift: take the decisions on a shifted float64 copy (``_Pieces``), for a gradient. The plan may be a
    camera batch's (``_joined``): a pixel id is then view · H · W + the pixel's own, and its square's corners
    are those of the pixel's own id; camera: any of the batch's (its size, far plane and projection)."""
    pixel, face, size = plan.pixel[lo:hi], plan.face[lo:hi], plan.size[lo:hi]
    start = _groups(pixel)[0]
    own = pixel % (camera.width * camera.height)                            # the pixel in its view's image
    pieces, corner, corner_dec = _square_piece(geo, plan, own, face, camera, dtype, shift)
    tol = _tol(torch.float64 if shift else dtype)
    pieces = pieces.keep(tol)
    corner64 = _corners(own, camera.width)
    n, scale = _nearness(plan.geo.coef[face], corner64)                     # (R, 4) at the pixel's corners
    g_lo, g_hi = plan.lo[face] - corner64[:, 0], plan.hi[face] - corner64[:, 0]   # (R, 2) relative bbox
    done = []                                                               # pieces whose pixel has no more faces
    for j in range(int(size.max()) if size.numel() else 0):                # the j-th face of every pixel
        live = j < size[pieces.owner]
        if not bool(live.all()):
            done.append(pieces.take(~live))
            pieces = pieces.take(live)
        owner = pieces.owner
        pos = start[owner] + j                                              # the pair (pixel, g)
        i = (pos != owner).nonzero().squeeze(1)
        a, b = owner[i], pos[i]
        box = pieces.decide()[i]                                            # g misses the piece's bbox
        skip = ((g_hi[b] < box.amin(1) - 1e-4) | (g_lo[b] > box.amax(1) + 1e-4)).any(-1)   # (a loose test)
        cop = _coplanar(n[a], scale[a], n[b], scale[b])                     # or g is behind f everywhere
        skip |= torch.where(cop, plan.used[face[b]] > plan.used[face[a]], (n[b] < n[a]).all(-1))
        i, cop = i[~skip], cop[~skip]                                       # (coplanar: lower id in front)
        if i.numel() == 0:
            continue
        f, g = face[owner], face[pos]
        lines = _occluder_lines(geo, plan, f[i], g[i], corner[owner[i]], camera, cop, dtype)
        with torch.no_grad():                                               # the decisions
            if shift:
                c = corner_dec[owner[i]]
                lines_dec = _occluder_lines(geo, plan, f[i], g[i], c, camera, cop, torch.float64)
                g_poly = geo.xy[g[i]] - c[:, None]
            else:
                lines_dec = None
                g_poly = (geo.xy[g[i]] - corner[owner[i]][:, None]).to(dtype)
            separated, inside = _classify(pieces.decide()[i], lines.detach() if lines_dec is None else lines_dec,
                                          g_poly, tol)
        same = torch.ones_like(owner, dtype=torch.bool)
        same[i[~separated]] = False
        parts = [pieces.take(same)]                                         # untouched by g
        sel = ~separated & ~inside                                          # (pieces inside D are gone)
        split = i[sel]
        for part in _subtract(pieces.take(split), lines[sel], None if lines_dec is None else lines_dec[sel], tol):
            part.owner = owner[split][part.owner]
            parts.append(part.keep(tol))
        pieces = _Pieces.cat(parts)
    pieces = _Pieces.cat(done + [pieces])
    return _vertex_derivatives(pieces), pieces.count, pieces.owner


# ------------------------------------------------------------------------------------------ public API

def _region_chunks(verts, faces, camera, dtype, keys=None):
    """The visible pieces chunk by chunk: one ``VisibleRegions`` for the pixels a single face covers, then
    one per chunk of at most about ``CHUNK`` (pixel, face) pairs.

    camera: a ``Camera``, or a list of N cameras of one size sharing far and the projection (a camera batch:
    pixel ids are then view · H · W + the pixel's own). A batch is planned view by view (``_plan``, discrete,
    float64) and the plans joined (``_joined``), so that the chunks, the expensive clipping, run over every
    view's pairs at once: fewer, fuller chunks than a call per view (each view's last chunk is partly empty).

    keys: None, or (F,) integers 0..K-1, equal for faces of one colour (``_color_keys``), when only the image
    matters (flat colours, no derivative w.r.t. a face's own colour): a pixel whose square no edge where the
    colour can jump touches (``discontinuities.discontinuity_pixels``: silhouettes, colour changes, crossings,
    near/far cuts) shows one colour all over, the colour at its centre, whatever faces tile it; it comes back
    as one unit square of the face the centre sees, unclipped. The interior of a one-colour silhouette is then
    skipped: no piece of its thousands of interior edges is clipped. Its derivative w.r.t. the vertices is 0,
    as it should be (moving an edge between two faces of one colour changes nothing); w.r.t. each face's
    colour it would not be (the area of each face is not computed), hence keys only without that derivative."""
    cameras = camera if isinstance(camera, list) else [camera]
    pixels = cameras[0].width * cameras[0].height                           # of one view
    shift = torch.is_grad_enabled() and any(x.requires_grad for c in cameras for x in (verts, c.K, c.R, c.t))
    square = torch.tensor([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], dtype=dtype, device=verts.device)
    masks = [None] * len(cameras)
    if keys is not None and keys.numel() and int(keys.max()) + 1 < keys.numel():   # faces share a colour
        mesh = _Mesh(verts, faces)
        for k, cam in enumerate(cameras):
            with torch.no_grad():
                masks[k] = discontinuity_pixels(mesh, cam, keys).reshape(-1)    # where the colour may jump
                seen = raster.rasterize(mesh, cam).face_id.reshape(-1)      # the centre's face elsewhere
                quiet = (~masks[k] & (seen >= 0)).nonzero().squeeze(1)
            yield VisibleRegions(quiet + k * pixels, seen[quiet], square.expand(quiet.numel(), 4, 2),
                                 torch.full_like(quiet, 4), square.new_ones(quiet.numel()))
    with torch.no_grad():                                                   # (shift: _Pieces, ties)
        plans = [_plan(verts, faces, cam, shift, mask) for cam, mask in zip(cameras, masks)]
    # per-face geometry in float64 (one row per face: cheap), the pieces in dtype once pixel-relative
    geo = []
    for cam, p in zip(cameras, plans):
        verts_cam = world_to_camera(verts.double(), cam.R.double(), cam.t.double())   # (V, 3)
        geo.append(_face_geometry(verts_cam, faces[p.used], cam, cam.K.double(), p.inside, p.flip))
    plan, geo = _joined(plans, pixels), _Faces.cat(geo)
    n_full = plan.full_pixel.numel()                                        # the unit square, area 1
    yield VisibleRegions(plan.full_pixel, plan.used[plan.full_face], square.expand(n_full, 4, 2),
                         torch.full_like(plan.full_pixel, 4), square.new_ones(n_full))
    for lo, hi in _pixel_chunks(plan.pixel, CHUNK):                         # chunks of whole pixels
        poly, count, owner = _chunk_pieces(geo, plan, lo, hi, cameras[0], dtype, shift)
        yield VisibleRegions(plan.pixel[lo:hi][owner], plan.used[plan.face[lo:hi][owner]], poly, count,
                             _areas(poly))


@dataclass
class _Mesh:
    verts: torch.Tensor
    faces: torch.Tensor


def visible_regions(mesh, camera, *, dtype=None) -> VisibleRegions:
    """The visible part of every face in every pixel, as convex polygons: the building block of
    ``exact_coverage`` (module docstring: the algorithm).

    mesh: ``verts`` (V, 3) world space, ``faces`` (F, 3); camera: a ``Camera`` (perspective or orthographic).
    Semantics of ``rasterize`` without culling: back faces count, faces are clipped at the near plane and
    the far plane, coplanar faces resolve to the lower face id, and depth is compared point by point (faces
    may intersect or overlap cyclically). dtype: the working precision of the pieces (per-face geometry is
    float64), default ``promote(verts, camera)``; float64 is the reference. Differentiable w.r.t. verts, K, R and t
    (one-sided at kinks, where the arrangement of the pieces changes). Returns ``VisibleRegions``, whose
    size grows with the image (``exact_coverage`` works chunk by chunk instead).
    """
    verts, faces = raster._check_inputs(mesh, camera)
    dtype = dtype or torch.promote_types(verts.dtype, camera.dtype)
    parts = list(_region_chunks(verts, faces, camera, dtype))
    width = max(r.verts.shape[1] for r in parts)
    return VisibleRegions(*(torch.cat([getattr(r, name) for r in parts]) for name in ("pixel", "face")),
                          torch.cat([_pad(r.verts, width) for r in parts]),
                          *(torch.cat([getattr(r, name) for r in parts]) for name in ("count", "area")))


def exact_coverage(mesh, camera, face_colors, background=(0.0, 0.0, 0.0)) -> torch.Tensor:
    """The exact box-filtered image of flat-coloured faces: each pixel the integral of the visible colour
    over its unit square, background where nothing is visible.

    mesh: ``verts`` (V, 3), ``faces`` (F, 3); camera: a ``Camera``, or a list of N cameras of one image size
    sharing far and the projection (a camera batch: returns (N, H, W, 3), each image its own call's; the
    views are planned one by one and clipped together, ``_region_chunks``); face_colors: (F, 3) one colour
    per face; background: (3,). Returns (H, W, 3) in ``promote(verts, camera, face_colors)``. Same visibility as
    ``rasterize`` without culling (``visible_regions``): the nearest face in float64, except that two faces
    whose nearness (1/z, or -z for an orthographic camera) agrees at a pixel's four corners to 1e-9 of its
    size count as coplanar there, the lower face id in front (``_coplanar``; surfaces about 2e-9 apart in
    relative depth tie, 5e-9 is resolved). ``rasterize`` ties only below 1e-12 and ``raycast`` compares
    float64 depths exactly, so the three agree from about 5e-9 up (``tests/test_raster.py`` checks 3.3e-8).
    Differentiable w.r.t. verts, face_colors, K, R and t: the image is piecewise rational in them; where the
    arrangement changes (a vertex crossing a pixel border, an edge-on face) autograd returns a one-sided
    derivative, always finite (module docstring: at a tie with the pixel grid, the one toward +x, +y).
    """
    verts, faces, cameras, batched = raster._check_views(mesh, camera, ("far", "orthographic"))
    colors = as_tensor(face_colors, device=verts.device, name="face_colors")
    if colors.shape != (faces.shape[0], 3):
        raise ValueError(f"face_colors must have shape (F, 3) = ({faces.shape[0]}, 3), got {tuple(colors.shape)}")
    if not torch.isfinite(colors).all():
        raise ValueError("face_colors contains NaN or inf")
    dtype = colors.dtype
    for x in [verts] + cameras:
        dtype = torch.promote_types(dtype, x.dtype)
    bg = as_tensor(background, dtype=dtype, device=verts.device, name="background")
    if bg.shape != (3,):
        raise ValueError(f"background must have shape (3,), got {tuple(bg.shape)}")
    if not torch.isfinite(bg).all():
        raise ValueError("background contains NaN or inf")
    N, H, W = len(cameras), cameras[0].height, cameras[0].width
    # pixels of one colour all over need no clipping, unless each face's own colour wants its derivative
    keys = None if (colors.requires_grad and torch.is_grad_enabled()) else _color_keys(colors)
    colors = colors.to(dtype)
    image = torch.zeros(N * H * W, 3, dtype=dtype, device=verts.device)
    covered = torch.zeros(N * H * W, dtype=dtype, device=verts.device)
    for regions in _region_chunks(verts, faces, cameras, dtype, keys):     # Σ area · colour, chunk by chunk
        image = image.index_add(0, regions.pixel, regions.area[:, None] * colors[regions.face])
        covered = covered.index_add(0, regions.pixel, regions.area)
    return (image + (1 - covered)[:, None] * bg).view(*((N,) if batched else ()), H, W, 3)
