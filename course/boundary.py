"""The boundary term of visibility gradients: edges on screen, the pieces of them that bound what is visible,
and the integrand there (lecture 09; ``course.visibility`` is the front door).

Reynolds transport: the derivative of a pixel's integral gains a boundary integral, ``∫ (c_in - c_out) v_n ds``
along the curves where the visible colour jumps. ``boundary_gradient`` evaluates it by Gauss-Legendre
quadrature on every piece of edge inside a pixel (``order``, the "reynolds" method) or at random points on
the edges (``samples``, "edge_sampling"), and lets autograd carry ``v_n`` back to the parameters through the
edges' screen positions.

Boundaries counted once. A point x on the edge of face f is a boundary of f's visible region when f is what
the z-buffer shows just inside the edge; the region then grows at rate ``(c_f - c_out) v_n``. An edge two
faces share is found from both (each sees the other outside): each counts half. A silhouette fold is found
from the face in front only (the one behind is not visible inside its edge), an occluding edge from the
occluder only, and an edge whose face is hidden on both sides adds nothing. Visibility along an edge changes
only where another edge or an intersection line crosses it, so the pieces are cut there and one quadrature
point per piece decides; a piece some face hides entirely needs no cut (``_hidden_pieces``). Lines where two
faces pass through each other are boundaries too: the segment f ∩ g in 3D (``_intersection_segments``: f's
chord on g's plane overlapped with g's chord on f's plane, faces sharing one vertex included: a fold through
itself), cut at the near plane and projected; there the line n_f = n_g (the faces' nearness planes on screen)
moves at ``∂(n_f - n_g)/∂π / |∇(n_f - n_g)|``. The near plane cuts faces: an edge cut there keeps the ids of
its welded edge at its new end (``_corner_ids``), so the faces sharing it still find it once. The far plane is
not a boundary here (faces are taken whole up to it).
Vertices count as one where their positions agree to 1e-9 of the mesh's size (``_weld``): seam copies of a
point evaluated twice (the teapot's poles) differ in the last bits, and must not look like an open crack.
Everything here runs in float64, whatever the problem's dtype (``boundary_gradient``).
A piece of edge exactly on a pixel border belongs to the pixel its midpoint falls in, the one to the right or
below (the half-open pixels [j, j+1)): the same one-sided derivative ``exact`` returns there.
A camera batch (``boundary_gradient`` of a list of problems, one per view) shares what depends on the mesh
alone: the welded positions, the faces that pass through each other and their 3D segments (``_crossings``),
whether the mesh is closed (``_closed_outward``), and the leaves; each view's edges on screen, pieces, cuts and
visibility samples are its own, in a loop over the views, and one autograd pass differentiates their sum.
"""
from __future__ import annotations

import math

import numpy as np
import torch

from . import kernels
from .discontinuities import _intersecting_faces
from .coverage import _region_chunks
from .coverage_affine import _Field, polygon_centroids
from .raster import _camera_space, _project, _screen_triangles
from .scan import _plane, _plane_at, pixel_triangle_pairs
from .soft import _screen_faces

__all__ = ["boundary_points", "boundary_gradient"]

OFFSET = 2.0 ** 16       # float64 roundings of a point's coordinates: how far beside an edge the z-buffer is asked
CUT_SLACK = 1e-9         # of an edge's length: how far past its ends it still cuts the edges it meets


def _edges(prob, p) -> "_Edges":
    """Every face's edges on screen (differentiable endpoints, the normal out of the face, the ids of the
    endpoints: welded vertex ids, or one id per welded edge for a point the near-plane clip made on it), then
    the faces' intersection lines. p: the parameters in float64 (``boundary_gradient``)."""
    mesh, cam = prob.mesh(p), prob.camera(p)
    weld = prob.weld
    cull = _back_faces_hidden(prob, weld)                                   # a closed mesh seen from outside
    xy, q, face, _ = _screen_faces(mesh.verts, mesh.faces, cam, cull)       # (T, 3, 2), (T, 3), (T,)
    T = xy.shape[0]
    ids = _corner_ids(prob, mesh.verts.detach(), cam, xy.detach(), q.detach(), face)
    a, b, c = xy, xy.roll(-1, 1), xy.roll(-2, 1)                            # edge k: corner k → k+1
    va, vb = ids, ids.roll(-1, 1)
    d = (b - a).detach()
    n = torch.stack([d[..., 1], -d[..., 0]], -1)
    inward = ((c.detach() - a.detach()) * n).sum(-1) > 0
    n = torch.where(inward[..., None], -n, n)
    n = n / n.norm(dim=-1, keepdim=True).clamp_min(1e-300)
    keep = (d.norm(dim=-1) > 0).reshape(-1)
    area = (d[:, 0, 0] * (c - a).detach()[:, 0, 1] - d[:, 0, 1] * (c - a).detach()[:, 0, 0]).abs()
    keep &= (area > 0)[:, None].expand(T, 3).reshape(-1)                   # a zero-area face bounds nothing
    sel = keep.nonzero().squeeze(1)
    flat = lambda x: x.reshape(T * 3, *x.shape[2:]).index_select(0, sel)
    edges = _Edges(flat(a), flat(b), flat(n), face[:, None].expand(T, 3).reshape(-1).index_select(0, sel),
                   torch.stack([flat(va), flat(vb)], 1), None)
    edges = _with_crossings(_merge_twins(edges), prob, p, weld)
    edges.culled = cull
    return edges


def _corner_ids(prob, verts, cam, xy, q, face):
    """(T, 3) an id for each corner of the screen triangles of ``_screen_faces``: a face's own corner keeps
    its welded vertex id; a point the near-plane clip made on the face edge (i, j) gets the id of that welded
    edge, past the vertex ids, so the two faces sharing a clipped edge name its clipped end alike and the
    edge is found once (``_merge_twins``). A clipped triangle's corners are matched to the candidates (the
    face's corners in front of the near plane, the clip points of its edges) by position on screen and q."""
    faces, weld = prob.faces, prob.weld
    T = face.numel()
    V = int(weld.max()) + 1 if weld.numel() else 0
    ids = torch.empty((T, 3), dtype=torch.int64, device=face.device)
    if T == 0:
        return ids
    vc = _camera_space(verts, cam)                                          # (V, 3) float64
    z = vc[:, 2]
    tri = faces[face]                                                       # (T, 3) vertex indices
    whole = z[tri].amin(1) >= cam.near                                      # not clipped: the face's corners
    ids[whole] = weld[tri[whole]]
    cut = (~whole).nonzero().squeeze(1)
    if cut.numel() == 0:
        return ids
    K = cam.K.detach().double()
    i, j = tri[cut], tri[cut].roll(-1, 1)                                   # (C, 3) edges k → k+1
    lo, hi = torch.minimum(i, j), torch.maximum(i, j)
    za, zb = z[lo], z[hi]
    s = ((cam.near - za) / torch.where(zb == za, torch.ones_like(za), zb - za))[..., None]
    clip = vc[lo] + s * (vc[hi] - vc[lo])                                   # (C, 3, 3) as raster._clip_point
    clip[..., 2] = cam.near
    crosses = (torch.minimum(za, zb) < cam.near) & (torch.maximum(za, zb) >= cam.near)
    cand = torch.cat([vc[i], clip], 1)                                      # (C, 6, 3): corners, clip points
    valid = torch.cat([z[i] >= cam.near, crosses], 1)
    c_xy, c_q = _project(cand, cam, K)
    pos = torch.cat([xy[cut], q[cut][..., None]], -1)                       # (C, 3, 3) the triangle's corners
    c_pos = torch.cat([c_xy, c_q[..., None]], -1)                           # (C, 6, 3)
    scale = pos.abs().amax(-1, keepdim=True) + 1.0
    dist = ((pos[:, :, None] - c_pos[:, None]).abs() / scale[:, :, None]).amax(-1)   # (C, 3, 6)
    dist = torch.where(valid[:, None], dist, torch.full_like(dist, math.inf))
    best = dist.argmin(-1)                                                  # (C, 3) which candidate
    wi, wj = weld[i], weld[j]
    edge_key = torch.minimum(wi, wj) * V + torch.maximum(wi, wj)            # (C, 3) welded edge
    _, edge_id = torch.unique(edge_key, return_inverse=True)
    cand_id = torch.cat([wi, V + edge_id], 1)                               # (C, 6)
    ids[cut] = cand_id.gather(1, best)
    return ids


def _merge_twins(edges):
    """An edge two faces share appears twice; keep one copy and remember the other face (``twin``, -1 for
    none) and whether its outward normal is the same (a fold: both faces on one side) or the opposite. The
    same two visibility samples then serve both faces."""
    vid = edges.vid
    E = vid.shape[0]
    twin = torch.full((E,), -1, dtype=torch.int64, device=vid.device)
    fold = torch.zeros(E, dtype=torch.bool, device=vid.device)
    ok = (vid >= 0).all(1).nonzero().squeeze(1)
    V = int(vid.max()) + 1 if vid.numel() else 0
    key = torch.minimum(vid[ok, 0], vid[ok, 1]) * V + torch.maximum(vid[ok, 0], vid[ok, 1])
    key, order = torch.sort(key, stable=True)
    ok = ok[order]
    _, counts = torch.unique_consecutive(key, return_counts=True)
    first = torch.cumsum(counts, 0) - counts
    pairs = first[counts == 2]                                              # exactly two faces share it
    keep_e, drop_e = ok[pairs], ok[pairs + 1]
    twin[keep_e] = edges.face[drop_e]
    fold[keep_e] = (edges.n[keep_e] * edges.n[drop_e]).sum(1) > 0
    alive = torch.ones(E, dtype=torch.bool, device=vid.device)
    alive[drop_e] = False
    idx = alive.nonzero().squeeze(1)
    merged = _Edges(edges.a[idx], edges.b[idx], edges.n[idx], edges.face[idx], edges.vid[idx], None)
    merged.twin, merged.fold = twin[idx], fold[idx]
    return merged


class _Edges:
    """Curves along which the image may jump, as screen segments a → b (E, 2): the first ones are face edges
    (differentiable endpoints), then the lines where two faces pass through each other (detached endpoints;
    ``other`` (K,) the second face, the first being ``face``). n (E, 2): the unit normal pointing out of the
    region of ``face``; vid (E, 2): welded vertex ids of a face edge's endpoints (-1: none)."""

    def __init__(self, a, b, n, face, vid, other):
        self.a, self.b, self.n, self.face, self.vid, self.other = a, b, n, face, vid, other
        self.n_edges = a.shape[0] if other is None else a.shape[0] - other.shape[0]
        self.twin = torch.full_like(face, -1)                               # the face sharing the edge, if any
        self.fold = torch.zeros_like(face, dtype=torch.bool)                # ... on the same side of it


def _planes(verts_cam, faces, K, orthographic):
    """The nearness of each face on screen as a plane n(x, y) = A x + B y + C, (F, 3), differentiable: 1/z
    for a pinhole camera, -z for an orthographic one (larger = nearer; as ``coverage`` defines it)."""
    v = verts_cam[faces]
    normal = torch.linalg.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    d = (normal * v[:, 0]).sum(-1)
    Kinv = torch.linalg.inv(K)
    tiny = torch.finfo(v.dtype).tiny ** 0.5
    safe = lambda x: torch.where(x.abs() < tiny, torch.where(x < 0, -tiny, tiny), x)
    if orthographic:
        e3 = torch.tensor([0.0, 0.0, 1.0], dtype=K.dtype, device=K.device)
        return (normal[:, :1] * Kinv[0] + normal[:, 1:2] * Kinv[1] - d[:, None] * e3) / safe(normal[:, 2:])
    return (normal @ Kinv) / safe(d)[:, None]


def _with_crossings(edges, prob, p, weld):
    """Append the lines where two faces pass through each other: for each pair (f, g) of faces that can show
    and cross (``_crossings``), the segment f ∩ g, cut at the near plane and projected. The image may jump
    along it where it is visible, which the visibility samples find. Its normal points from f's nearer side
    to g's."""
    verts = prob.params["verts"].double()
    # faces that can show (in front of the camera; front faces when back ones never show): the faces of
    # the edges and their twins (a face whose every edge is shared may own none of the merged copies)
    shows = torch.zeros(prob.faces.shape[0], dtype=torch.bool, device=edges.face.device)
    shows[edges.face] = True
    shows[edges.twin[edges.twin >= 0]] = True
    f, g, seg = _crossings(prob, weld)
    ok = shows[f] & shows[g]
    f, g, seg = f[ok], g[ok], seg[ok]
    cam = prob.camera0.to(dtype=torch.float64)
    ends = cam.to_camera(seg.reshape(-1, 3)).view(-1, 2, 3)                 # camera space
    ends, front = _clip_segments_near(ends, cam.near)                       # cut at z = near
    f, g, ends = f[front], g[front], ends[front]
    if f.numel() == 0:
        return edges
    xy, _ = _project(ends.reshape(-1, 3), cam, cam.K.double())
    xy = xy.view(-1, 2, 2)
    with torch.no_grad():
        P = _planes(cam.to_camera(verts), prob.faces, cam.K.double(), cam.orthographic)
        grad = (P[f] - P[g])[:, :2]                                         # ∇(n_f - n_g): toward f nearer
        n = -grad / grad.norm(dim=1, keepdim=True).clamp_min(1e-300)        # out of f's region
    dtype = edges.a.dtype
    none = torch.full((f.numel(), 2), -1, dtype=torch.int64, device=f.device)
    out = _Edges(torch.cat([edges.a, xy[:, 0].to(dtype)]), torch.cat([edges.b, xy[:, 1].to(dtype)]),
                 torch.cat([edges.n, n.to(dtype)]), torch.cat([edges.face, f]), torch.cat([edges.vid, none]), g)
    out.twin = torch.cat([edges.twin, torch.full_like(f, -1)])
    out.fold = torch.cat([edges.fold, torch.zeros_like(f, dtype=torch.bool)])
    return out


def _crossings(prob, weld):
    """The pairs of faces f, g (K,) that pass through each other (``discontinuities._intersecting_faces``,
    pairs sharing one vertex included: a fold through itself) and the segment f ∩ g of each in world space
    (``_intersection_segments``), (K, 2, 3), over the whole mesh: they depend on the mesh alone, so the views
    of a camera batch share them (``_Problem.shared``), and each view keeps the pairs of faces it can show.
    (Its pairs are those a search among its own faces finds: the search is exact pair by pair.)"""
    if "crossings" not in prob.shared:
        verts = prob.params["verts"].double()
        f, g = _intersecting_faces(verts, prob.faces, weld, shared_vertex=True)
        seg, ok = _intersection_segments(verts, prob.faces, f, g)           # (K, 2, 3) world, (K,)
        prob.shared["crossings"] = f[ok], g[ok], seg[ok]
    return prob.shared["crossings"]


def _chord(v, d, tol):
    """Where a triangle meets a plane: its corners v (N, 3, 3) at signed distances d (N, 3) from the plane.
    Returns the two ends (N, 2, 3) of the chord and whether there is one (N,): the corners on the plane
    (|d| <= tol) and the points where an edge crosses it strictly (its ends on opposite sides), the first two
    of those (a triangle straddling the plane has exactly two; a corner on the plane is not also counted as
    the crossing of its two edges, which is what doubled a chord that ended at a corner)."""
    on = d.abs() <= tol                                                     # (N, 3)
    side = torch.where(on, torch.zeros_like(d), torch.sign(d))
    d1, v1 = d.roll(-1, 1), v.roll(-1, 1)
    across = side * side.roll(-1, 1) < 0                                    # edge k → k+1 crosses strictly
    s = d / torch.where(across, d - d1, torch.ones_like(d))
    cross = v + s[..., None] * (v1 - v)                                     # (N, 3, 3)
    pts = torch.cat([v, cross], 1)                                          # (N, 6, 3) candidates
    use = torch.cat([on, across], 1)                                        # (N, 6)
    order = torch.argsort((~use).to(torch.int8), dim=1, stable=True)[:, :2] # the first two used
    ends = pts.gather(1, order[..., None].expand(-1, -1, 3))
    return ends, use.sum(1) == 2


def _intersection_segments(verts, faces, f, g):
    """The segment where triangles f and g (N,) cross, in 3D: f's chord on g's plane and g's chord on f's
    plane lie on the same line (the planes' intersection), and their overlap is f ∩ g. Returns its ends
    (N, 2, 3) and whether it exists (N,) with a positive length. float64. A chord alone reaches beyond the
    other face when the crossing ends on that face's open boundary."""
    v, w = verts[faces[f]], verts[faces[g]]                                 # (N, 3, 3)
    nf = torch.linalg.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    ng = torch.linalg.cross(w[:, 1] - w[:, 0], w[:, 2] - w[:, 0])
    size = torch.maximum((v - v[:, :1]).abs().amax((1, 2)), (w - w[:, :1]).abs().amax((1, 2)))
    dv = ((v - w[:, :1]) * ng[:, None]).sum(-1)                             # f's corners to g's plane
    dw = ((w - v[:, :1]) * nf[:, None]).sum(-1)
    ef, okf = _chord(v, dv, 1e-9 * ng.norm(dim=1, keepdim=True) * size[:, None])
    eg, okg = _chord(w, dw, 1e-9 * nf.norm(dim=1, keepdim=True) * size[:, None])
    u = torch.linalg.cross(nf, ng)                                          # along the common line
    tf, tg = (ef * u[:, None]).sum(-1), (eg * u[:, None]).sum(-1)           # (N, 2) positions along it
    lo_f, hi_f = tf.argmin(1), tf.argmax(1)
    lo_g, hi_g = tg.argmin(1), tg.argmax(1)
    take = lambda e, k: e.gather(1, k[:, None, None].expand(-1, 1, 3))[:, 0]
    t_lo_f, t_lo_g = tf.gather(1, lo_f[:, None])[:, 0], tg.gather(1, lo_g[:, None])[:, 0]
    t_hi_f, t_hi_g = tf.gather(1, hi_f[:, None])[:, 0], tg.gather(1, hi_g[:, None])[:, 0]
    start = torch.where((t_lo_f >= t_lo_g)[:, None], take(ef, lo_f), take(eg, lo_g))   # the later start
    end = torch.where((t_hi_f <= t_hi_g)[:, None], take(ef, hi_f), take(eg, hi_g))     # the earlier end
    ok = okf & okg & (torch.minimum(t_hi_f, t_hi_g) > torch.maximum(t_lo_f, t_lo_g))
    return torch.stack([start, end], 1), ok


def _clip_segments_near(ends, near):
    """Camera-space segments (N, 2, 3) cut to z >= near: the new ends (N, 2, 3), and which segments keep a
    part of positive length in front (N,)."""
    a, b = ends[:, 0], ends[:, 1]
    dz = b[:, 2] - a[:, 2]
    t = ((near - a[:, 2]) / torch.where(dz == 0, torch.ones_like(dz), dz)).clamp(0, 1)
    cut = a + t[:, None] * (b - a)                                          # where the segment meets z = near
    cut[:, 2] = near
    a2 = torch.where((a[:, 2] < near)[:, None], cut, a)
    b2 = torch.where((b[:, 2] < near)[:, None], cut, b)
    front = (ends[..., 2] >= near).any(1) & ((b2 - a2).abs().amax(1) > 0)
    return torch.stack([a2, b2], 1), front


def _back_faces_hidden(prob, weld) -> bool:
    """Can no back face be visible? True when the mesh is closed and consistently oriented, each of its
    connected pieces enclosing a positive volume (``_closed_outward``: per mesh, shared by the views of a
    camera batch, ``_Problem.shared``), and every vertex lies beyond the near plane: the camera centre
    (z = 0) is then outside the convex hull, so outside every piece, and a ray enters a piece through a front
    face before it can reach a back one. The back faces' edges can then be skipped. A check, never an
    assumption: anything else keeps every face."""
    verts = prob.params["verts"].double()
    if "closed" not in prob.shared:
        prob.shared["closed"] = _closed_outward(verts, prob.faces, weld)
    cam = prob.camera0.to(dtype=torch.float64)
    return prob.shared["closed"] and not bool((cam.to_camera(verts)[:, 2] <= cam.near).any())


def _closed_outward(verts, faces, weld) -> bool:
    """Is the mesh closed and consistently oriented (every welded edge a → b has exactly one twin b → a), with
    each of its connected pieces enclosing a positive volume (outward normals, front faces counter-clockwise)?
    verts: (V, 3) float64; faces: (F, 3); weld: (V,) welded ids (``_weld``)."""
    welded = weld[faces]                                                    # (F, 3) welded
    if welded.numel() == 0:
        return False
    V = int(weld.max()) + 1
    a, b = welded.reshape(-1), welded.roll(-1, 1).reshape(-1)
    sorted_key, counts = torch.unique(a * V + b, return_counts=True)
    if (counts != 1).any() or (a == b).any():
        return False
    twin = b * V + a
    pos = torch.searchsorted(sorted_key, twin).clamp(max=sorted_key.numel() - 1)
    if not torch.equal(sorted_key[pos], twin):
        return False
    label = torch.arange(V, device=faces.device)                            # connected pieces: min label,
    for _ in range(V):                                                      # spread and jumped to a fixpoint
        new = label.scatter_reduce(0, a, label[b], reduce="amin").scatter_reduce(0, b, label[a], reduce="amin")
        new = new[new]
        if torch.equal(new, label):
            break
        label = new
    v = verts[faces]                                                        # signed volume of each piece
    vol = (v[:, 0] * torch.linalg.cross(v[:, 1], v[:, 2])).sum(1) / 6
    piece = torch.unique(label[welded[:, 0]], return_inverse=True)[1]
    return bool((torch.zeros(int(piece.max()) + 1, dtype=vol.dtype).index_add(0, piece, vol) > 0).all())


WELD_TOL = 1e-9          # relative to the mesh's extent: vertices this close are one position (``_weld``)


def _weld(verts, tol: float = WELD_TOL):
    """(V,) one id per vertex position: vertices at the same place, up to ``tol`` × the mesh's extent, get
    the same id.

    Exact equality is not enough: a mesh built by evaluating patches (the teapot) puts seam copies of one
    point a few ulps apart, and two faces meeting there would look like an open crack, each edge a boundary
    counted in full. Points are put in grid cells of size h = tol × extent, on 8 grids shifted by h/2 along
    each axis: two points less than h/2 apart on every axis share a cell on at least one of them. The ids are
    the connected groups of "shares a cell somewhere" (so points up to about 2h apart may merge, and chains
    of them: h is far below any edge length)."""
    v = verts.detach().double()
    V = v.shape[0]
    if V == 0:
        return torch.zeros(0, dtype=torch.int64, device=verts.device)
    lo = v.amin(0)
    h = float((v.amax(0) - lo).amax()) * tol
    if not 0 < h < math.inf:                                                # one point, or inf / NaN: exact
        return torch.unique(v, dim=0, return_inverse=True)[1]
    x = (v - lo) / h                                                        # (V, 3) in [0, 1/tol]
    groups = []
    for k in range(8):                                                      # shifts (0 or ½ per axis)
        shift = torch.tensor([k & 1, (k >> 1) & 1, (k >> 2) & 1], dtype=x.dtype, device=x.device) / 2
        groups.append(_cell_ids(torch.floor(x + shift).long()))
    label = torch.arange(V, device=verts.device)                            # the smallest index in the group,
    while True:                                                             # spread to a fixpoint
        new = label
        for g in groups:
            new = torch.full_like(label, V).scatter_reduce(0, g, new, reduce="amin")[g]
        if torch.equal(new, label):
            break
        label = new
    return torch.unique(label, return_inverse=True)[1]


def _cell_ids(cells):
    """(V, 3) integer cells → (V,) ids, equal cells equal ids: ranks along each axis, then of the pairs
    (1-D uniques; the keys stay below V², no overflow however fine the grid)."""
    V = cells.shape[0]
    key = torch.unique(cells[:, 0], return_inverse=True)[1]
    for c in (1, 2):
        key = torch.unique(key * V + torch.unique(cells[:, c], return_inverse=True)[1], return_inverse=True)[1]
    return key


def _pixel_segments(a, b, W, H):
    """Every edge a → b (E, 2 each, detached) cut at the pixel borders it crosses: the pieces' parameter
    intervals [s0, s1] (N,), their edge (N,) and pixel (N,) (row-major; pieces outside the image dropped)."""
    E = a.shape[0]
    ts = [torch.zeros(E, dtype=a.dtype, device=a.device), torch.ones(E, dtype=a.dtype, device=a.device)]
    owners = [torch.arange(E, device=a.device)] * 2
    for axis in range(2):
        lo, hi = torch.minimum(a[:, axis], b[:, axis]), torch.maximum(a[:, axis], b[:, axis])
        first = torch.floor(lo) + 1
        count = (torch.ceil(hi) - first).clamp(min=0).long()               # integers strictly inside (lo, hi)
        count = torch.where(hi > lo, count, torch.zeros_like(count))
        edge = torch.repeat_interleave(torch.arange(E, device=a.device), count)
        k = first[edge] + (torch.arange(edge.numel(), device=a.device)
                           - torch.repeat_interleave(torch.cumsum(count, 0) - count, count))
        ts.append(((k - a[edge, axis]) / (b[edge, axis] - a[edge, axis])).clamp(0, 1))
        owners.append(edge)
    s, edge = torch.cat(ts), torch.cat(owners)
    order = torch.argsort(edge.double() * 4 + s)                            # by edge, then along it
    s, edge = s[order], edge[order]
    same = edge[1:] == edge[:-1]
    s0, s1, e = s[:-1][same], s[1:][same], edge[:-1][same]
    keep = s1 > s0
    s0, s1, e = s0[keep], s1[keep], e[keep]
    mid = a[e] + ((s0 + s1) / 2)[:, None] * (b[e] - a[e])
    col, row = torch.floor(mid[:, 0]), torch.floor(mid[:, 1])
    inside = (col >= 0) & (col < W) & (row >= 0) & (row < H)
    return s0[inside], s1[inside], e[inside], (row * W + col)[inside].long()


def _split_at_crossings(a, b, s0, s1, e, pixel):
    """Cut every piece of edge (s0, s1, edge e, pixel) where another piece in the same pixel crosses it.
    Visibility along an edge can change only there (where an occluder's outline passes over it), so each
    resulting piece is visible all along or nowhere, and one quadrature point decides it."""
    order = torch.argsort(pixel, stable=True)
    s0, s1, e, pixel = s0[order], s1[order], e[order], pixel[order]
    _, counts = torch.unique_consecutive(pixel, return_counts=True)
    start = torch.repeat_interleave(torch.cumsum(counts, 0) - counts, counts)     # first piece of the pixel
    size = torch.repeat_interleave(counts, counts)
    i = torch.repeat_interleave(torch.arange(pixel.numel(), device=pixel.device), size)   # every (i, j) pair
    j = start[i] + (torch.arange(i.numel(), device=pixel.device)
                    - torch.repeat_interleave(torch.cumsum(size, 0) - size, size))
    ei, ej = e.index_select(0, i), e.index_select(0, j)
    other = (ei != ej).nonzero().squeeze(1)
    i, j, ei, ej = i[other], j[other], ei[other], ej[other]
    ax, ay = a[:, 0].contiguous(), a[:, 1].contiguous()                     # columns: quick gathers
    dx, dy = (b[:, 0] - a[:, 0]).contiguous(), (b[:, 1] - a[:, 1]).contiguous()
    dix, diy, djx, djy = dx.index_select(0, ei), dy.index_select(0, ei), dx.index_select(0, ej), dy.index_select(0, ej)
    rx = ax.index_select(0, ej) - ax.index_select(0, ei)
    ry = ay.index_select(0, ej) - ay.index_select(0, ei)
    den = dix * djy - diy * djx
    ok = den != 0
    safe = torch.where(ok, den, torch.ones_like(den))
    s = (rx * djy - ry * djx) / safe                                        # along i
    u = (rx * diy - ry * dix) / safe                                        # along j
    # j may end exactly on i (an intersection line ends on the edges of its faces, where an edge passes
    # under the other face): rounding puts u a few ulps outside j, so j is taken a little longer. A cut
    # too many only splits a piece that is visible all along anyway; one too few mixes two visibilities.
    cut = ok & (s > s0.index_select(0, i)) & (s < s1.index_select(0, i)) & \
        (u >= s0.index_select(0, j) - CUT_SLACK) & (u <= s1.index_select(0, j) + CUT_SLACK)
    piece = torch.cat([torch.arange(pixel.numel(), device=pixel.device)] * 2 + [i[cut]])
    t = torch.cat([s0, s1, s[cut]])
    order = torch.argsort(piece.double() * 4 + (t - s0[piece]) / (s1[piece] - s0[piece]).clamp_min(1e-300))
    piece, t = piece[order], t[order]
    same = piece[1:] == piece[:-1]
    lo, hi, owner = t[:-1][same], t[1:][same], piece[:-1][same]
    keep = hi > lo
    return lo[keep], hi[keep], e[owner[keep]], pixel[owner[keep]]


def _hidden_pieces(mesh, cam, culled, planes, face, a, b, s0, s1, e, pixel, front: int = 8):
    """(N,) bool: the pieces of edge (s0, s1 on edge e, in pixel) that are certainly hidden: one face
    covers the whole piece (both ends strictly inside its triangle on screen) and is nearer than the
    piece's own face at both ends (nearness is affine along the piece), by a margin. A hidden piece
    bounds nothing visible, and where it crosses a visible piece it changes nothing there either (the face
    hiding it is in front of it at the crossing), so it needs no cuts: with K faces in a pixel most of
    the K² intersection lines are hidden, and cutting every piece against every other would cost (K²)².
    planes: (F, 3) nearness planes of the faces (``_planes``); face: (E,) the face each edge lies on.
    The faces are tried nearest first (at the pixel's centre), in blocks of ranks [0, front), [front, 4 front),
    ...: the pieces a block hides are not tested against the next."""
    N = s0.numel()
    hidden = torch.zeros(N, dtype=torch.bool, device=s0.device)
    if N == 0:
        return hidden
    W, H = cam.width, cam.height
    with torch.no_grad():
        st = _screen_triangles(_camera_space(mesh.verts, cam), mesh.faces, cam, culled, reach=0.0)
        if st.face.numel() == 0:
            return hidden
        mask = torch.zeros(H * W, dtype=torch.bool, device=s0.device)
        mask[pixel] = True
        pair_pix, tri = pixel_triangle_pairs(st.xy, W, H, mask)             # the faces of each pixel
        plane = _plane(st)
        q = _plane_at(plane, tri, (pair_pix % W).double() + 0.5, (pair_pix // W).double() + 0.5)
        near = -q if cam.orthographic else q                                # larger = nearer
        by_depth = torch.argsort(-near, stable=True)
        by_depth = by_depth[torch.argsort(pair_pix[by_depth], stable=True)]     # per pixel, nearest first
        pair_pix, tri = pair_pix[by_depth], tri[by_depth]
        _, n_pairs = torch.unique_consecutive(pair_pix, return_counts=True)
        rank = torch.arange(pair_pix.numel(), device=s0.device) - torch.repeat_interleave(
            torch.cumsum(n_pairs, 0) - n_pairs, n_pairs)
        d = b - a
        ends = [a[e] + s[:, None] * d[e] for s in (s0, s1)]                 # (N, 2) each
        own = [(planes[face[e]] * torch.cat([x, torch.ones_like(x[:, :1])], 1)).sum(1) for x in ends]
        test = (st, plane, ends, own, -cam.far if cam.orthographic else 1 / cam.far, cam.orthographic)
        lo = 0
        while lo <= int(rank.max()):                                        # the nearest faces first: a piece
            hi = lo + front if lo == 0 else 4 * lo                          # hidden by them is not tested again
            rest = (~hidden).nonzero().squeeze(1)
            if rest.numel() == 0:
                break
            block = (rank >= lo) & (rank < hi)
            hidden[_covered(rest, pixel[rest], pair_pix[block], tri[block], test)] = True
            lo = hi
    return hidden


def _covered(pieces, pixel, pair_pix, tri, test, budget: int = 1 << 22):
    """The pieces (indices, (n,), in pixels (n,)) that one of the (pixel, triangle) pairs covers and is
    nearer than (``_hidden_pieces``), about ``budget`` tests at a time. Returns their indices."""
    st, plane, ends, own, far, ortho = test
    xy = st.xy
    size = (xy.amax(1) - xy.amin(1)).amax(1)                                # (T,) for the margins
    order = torch.argsort(pixel)                                            # pieces grouped by pixel
    sorted_pix = pixel[order]
    first = torch.searchsorted(sorted_pix, pair_pix)
    count = torch.searchsorted(sorted_pix, pair_pix, right=True) - first
    ends_cum = torch.cumsum(count, 0)
    out = []
    lo = 0
    while lo < pair_pix.numel():
        hi = int(torch.searchsorted(ends_cum, ends_cum[lo] - count[lo] + budget, right=True).clamp(min=lo + 1))
        c = count[lo:hi]
        pair = torch.repeat_interleave(torch.arange(lo, hi, device=pixel.device), c)
        k = pieces[order[first[pair] + (torch.arange(pair.numel(), device=pixel.device)
                                        - torch.repeat_interleave(torch.cumsum(c, 0) - c, c))]]   # the piece
        t = tri[pair]                                                       # the face that may hide it
        for x, n_own in zip(ends, own):                                     # nearer at both ends, by a margin
            px, py = x[k, 0], x[k, 1]
            q = _plane_at(plane, t, px, py)
            n = -q if ortho else q                                          # larger = nearer
            n_k = n_own[k]
            keep = ((n > n_k + 1e-9 * n_k.abs()) & (n >= far)).nonzero().squeeze(1)
            k, t = k[keep], t[keep]
        for x in ends:                                                      # strictly inside, by a margin
            px, py = x[k, 0], x[k, 1]
            inside = torch.ones_like(k, dtype=torch.bool)
            for j in range(3):                                              # st triangles: positive area
                ax, ay = xy[t, j, 0], xy[t, j, 1]
                bx, by = xy[t, (j + 1) % 3, 0], xy[t, (j + 1) % 3, 1]
                ef = (bx - ax) * (py - ay) - (by - ay) * (px - ax)
                inside &= ef > 1e-9 * size[t] * ((bx - ax).abs() + (by - ay).abs())
            k, t = k[inside], t[inside]
        out.append(k)
        lo = hi
    return torch.cat(out) if out else pieces[:0]


def _finer_cells(tests, points, cells, W, H, target=16, most=16, max_cells=1 << 24):
    """The cells per pixel side for ``_visible_at``: ``cells`` while the points meet about ``target``
    triangles each or fewer (every ordinary mesh); else more, a power of 2 (exact in floating point), by the
    factor that would get there if the triangles were spread evenly (at least 2), at most ``most`` and with
    fewer than ``max_cells`` cells in the image. Asked again at the finer grid until it settles."""
    if tests <= 3 * target * max(points, 1):
        return cells
    finer = cells * 2
    while finer < most and tests * cells * cells / (finer * finer) > target * points:
        finer *= 2
    while finer > cells and finer * finer * W * H > max_cells:
        finer //= 2
    return min(finer, most)


def _visible_at(mesh, camera, pts, cull_backfaces: bool = False, budget: int = 1 << 21):
    """The face the z-buffer shows at screen points (N, 2), -1 for background or outside the image: the
    sample z-buffer of ``rasterize(samples=...)`` (same coverage rule and far plane), asked at arbitrary
    points, with depths compared in float64 (ties to the lower face id), as ``exact_coverage`` orders faces.
    Each point is tested against the triangles touching its pixel (or a smaller cell, ``_finer_cells``, where
    hundreds of faces share a pixel). cull_backfaces: leave the back faces out, when they are known never to
    be visible (``_back_faces_hidden``)."""
    W, H = camera.width, camera.height
    col, row = torch.floor(pts[:, 0]), torch.floor(pts[:, 1])
    ok = (col >= 0) & (col < W) & (row >= 0) & (row < H)
    out = torch.full((pts.shape[0],), -1, dtype=torch.int64, device=pts.device)
    idx = ok.nonzero().squeeze(1)
    with torch.no_grad():
        st = _screen_triangles(_camera_space(mesh.verts, camera), mesh.faces, camera, cull_backfaces, reach=0.0)
        if idx.numel() == 0 or st.face.numel() == 0:
            return out
        px_all, py_all = pts[idx, 0].double().contiguous(), pts[idx, 1].double().contiguous()
        if kernels.active(px_all, st.xy):                                   # the compiled twin
            from .kernels.points import visible_at
            found = torch.empty(idx.numel(), dtype=torch.int64)
            visible_at(st.xy.contiguous().numpy(), st.q.contiguous().numpy(), st.face.contiguous().numpy(),
                       px_all.numpy(), py_all.numpy(), W, H, bool(camera.orthographic), float(camera.far),
                       found.numpy())
            out[idx] = found
            return out
        cells = 1                                                           # cells per pixel side
        while True:                                                         # the triangles of each point's cell
            cw, ch = W * cells, H * cells
            pix = (torch.floor(py_all * cells) * cw + torch.floor(px_all * cells)).long()
            order = torch.argsort(pix)
            sorted_pix = pix[order]
            mask = torch.zeros(cw * ch, dtype=torch.bool, device=pts.device)
            mask[pix] = True
            pair_pix, tri = pixel_triangle_pairs(st.xy * cells, cw, ch, mask)
            first = torch.searchsorted(sorted_pix, pair_pix)
            count = torch.searchsorted(sorted_pix, pair_pix, right=True) - first
            # dense pixels (hundreds of faces crossing in one pixel): each point would be tested against
            # all of them; cells a power of 2 smaller (exact in floating point) cut that to a few
            finer = _finer_cells(int(count.sum()), idx.numel(), cells, W, H)
            if finer == cells:
                break
            cells = finer
        plane = _plane(st)
        X = [st.xy[:, k, 0].contiguous() for k in range(3)]                 # corner columns: quick gathers
        Y = [st.xy[:, k, 1].contiguous() for k in range(3)]
        best_q = torch.full((idx.numel(),), -math.inf, dtype=torch.float64, device=pts.device)
        cand_k, cand_t, cand_q = [], [], []
        ends = torch.cumsum(count, 0)
        lo = 0
        while lo < pair_pix.numel():                                        # about ``budget`` tests at a time
            hi = int(torch.searchsorted(ends, ends[lo] - count[lo] + budget, right=True).clamp(min=lo + 1))
            c = count[lo:hi]
            pair = torch.repeat_interleave(torch.arange(lo, hi, device=pts.device), c)
            k = order[first[pair] + (torch.arange(pair.numel(), device=pts.device)
                                     - torch.repeat_interleave(torch.cumsum(c, 0) - c, c))]
            t = tri.index_select(0, pair)
            px, py = px_all.index_select(0, k), py_all.index_select(0, k)
            inside = torch.ones_like(px, dtype=torch.bool)
            for c in range(3):                                              # scan._sample_inside, by columns
                ax, ay = X[c].index_select(0, t), Y[c].index_select(0, t)
                bx, by = X[(c + 1) % 3].index_select(0, t), Y[(c + 1) % 3].index_select(0, t)
                e = (ax - px) * (by - py) - (ay - py) * (bx - px)          # scan.edge_function
                top_left = (by - ay < 0) | ((by == ay) & (bx > ax))         # scan._is_top_left
                inside &= (e > 0) | ((e == 0) & top_left)
            sel = inside.nonzero().squeeze(1)
            k, t, px, py = k[sel], t[sel], px[sel], py[sel]
            q = _plane_at(plane, t, px, py)
            depth = q if camera.orthographic else 1 / q
            keep = (depth <= camera.far).nonzero().squeeze(1)
            # nearest = smallest depth, compared in float64 (the points lie 1e-6 px from edges, where two
            # faces that share the edge differ in depth by far less than float32 resolves)
            near = -q if camera.orthographic else q                         # larger = nearer
            k, t, near = k[keep], t[keep], near[keep]
            best_q.scatter_reduce_(0, k, near, reduce="amax")
            cand_k.append(k), cand_t.append(t), cand_q.append(near)
            lo = hi
        k, t, near = torch.cat(cand_k), torch.cat(cand_t), torch.cat(cand_q)
        win = (near == best_q[k]).nonzero().squeeze(1)                      # ties: the lower face id
        face = torch.full((idx.numel(),), torch.iinfo(torch.int64).max, dtype=torch.int64, device=pts.device)
        face.scatter_reduce_(0, k[win], st.face[t[win]], reduce="amin")
        out[idx] = torch.where(face == torch.iinfo(torch.int64).max, torch.full_like(face, -1), face)
    return out


def boundary_points(prob, p, *, order=None, samples=None, generator=None):
    """Points on the edges where the integrand of the boundary term is evaluated, with their weights.

    Quadrature (``order``): Gauss-Legendre nodes on every piece of edge inside one pixel, weight = node
    weight × the piece's length. Sampling (``samples``): points on the edges with probability proportional
    to length, weight = total length / samples. Returns edge data and per point: edge (N,), s (N,),
    weight (N,), pixel (N,).
    """
    return _boundary_points(prob, p, order, samples, generator)[:5]


def _boundary_points(prob, p, order, samples, generator):
    """``boundary_points``, and per point how far (pixels) it lies from the nearer end of its piece of edge
    (N,), inf for sampled points (no pieces): how close another edge can come to it (``_side_offset``)."""
    edges = _edges(prob, p)
    a, b = edges.a, edges.b
    W, H = prob.camera0.width, prob.camera0.height
    ad, bd = a.detach(), b.detach()
    length = (bd - ad).norm(dim=1)
    if order is not None:
        s0, s1, e, pix = _pixel_segments(ad, bd, W, H)
        mesh, cam = prob.mesh(p), prob.camera(p)
        with torch.no_grad():
            planes = _planes(cam.to_camera(mesh.verts.detach()), prob.faces, cam.K.detach(), cam.orthographic)
        hidden = _hidden_pieces(mesh, cam, edges.culled, planes, edges.face, ad, bd, s0, s1, e, pix)
        s0, s1, e, pix = s0[~hidden], s1[~hidden], e[~hidden], pix[~hidden]
        s0, s1, e, pix = _split_at_crossings(ad, bd, s0, s1, e, pix)
        x, w = np.polynomial.legendre.leggauss(int(order))
        x = torch.as_tensor(x, dtype=s0.dtype, device=s0.device)
        w = torch.as_tensor(w, dtype=s0.dtype, device=s0.device)
        half = (s1 - s0) / 2
        s = ((s0 + s1) / 2)[:, None] + half[:, None] * x                   # (N, q)
        weight = (half * length[e])[:, None] * w
        q = x.numel()
        gap = (torch.minimum(s - s0[:, None], s1[:, None] - s) * length[e][:, None]).reshape(-1)
        e, pix = e[:, None].expand(-1, q).reshape(-1), pix[:, None].expand(-1, q).reshape(-1)
        s, weight = s.reshape(-1), weight.reshape(-1)
    else:
        total = length.sum()
        if samples is None or int(samples) < 1:
            raise ValueError(f"samples must be a positive int, got {samples!r}")
        if float(total) == 0:
            empty, none = torch.zeros(0, dtype=torch.int64, device=a.device), a.new_zeros(0).detach()
            return edges, empty, none, none, empty, none
        e = torch.multinomial(length / total, int(samples), replacement=True, generator=generator)
        s = torch.rand(int(samples), dtype=ad.dtype, generator=generator).to(ad.device)
        weight = torch.full_like(s, float(total) / int(samples))
        pt = ad[e] + s[:, None] * (bd[e] - ad[e])
        col, row = torch.floor(pt[:, 0]), torch.floor(pt[:, 1])
        inside = (col >= 0) & (col < W) & (row >= 0) & (row < H)
        e, s, weight = e[inside], s[inside], weight[inside]
        pix = (row * W + col)[inside].long()
        gap = torch.full_like(s, math.inf)
    return edges, e, s, weight, pix, gap


def _side_offset(gap, x):
    """How far beside an edge (pixels) to ask what is visible, for points x (N, 2) ``gap`` (N,) pixels from the
    ends of their pieces: ``OFFSET`` float64 roundings of the point's coordinates (1.5e-11 px near the origin,
    1.5e-9 px at 100 px), shrunk in proportion on pieces shorter than a pixel, down to 64 roundings.

    What it must not step over: a face between the edge and another one beside it. A piece ends where another
    edge crosses or meets it, and a face between the two can be a wedge as thin as ``gap`` × its angle there; and
    two edges can run side by side a hair apart without meeting: an occluder's silhouette and its own shadow's
    edge when the camera looks nearly along the light (1e-9 rad off: a shadow sliver ~3e-9 px wide). A probe of
    1e-6 px, once fixed here, stepped over that sliver, so both edges saw the occluder on one side and the lit
    floor on the other and the jump was counted twice (Reynolds shadow gradients 71 % off at 1e-7 rad, 100 % at
    1e-9). Near rounding it stays far enough out that the point-in-triangle and depth tests decide its side
    (an edge function ~2^16 roundings from zero)."""
    eps = torch.finfo(torch.float64).eps
    scale = x.detach().abs().amax(1).clamp(min=1.0) * eps
    return torch.maximum(OFFSET * scale * gap.clamp(max=1.0), 64 * scale)


def _jumps(prob, p, edges, e, s, weight, pix, gap):
    """(N,) the integrand of the boundary term at the points (e, s) without its speed, times their weights:
    ``weight · Σ_channels w (c_in - c_out)`` where the edge bounds what is visible there (the z-buffer asked
    ``_side_offset(gap)`` beside it, on both sides), 0 where it does not."""
    a, b, n, face, vid = edges.a, edges.b, edges.n, edges.face, edges.vid
    mesh, cam = prob.mesh(p), prob.camera(p)
    with torch.no_grad():
        x = a.detach()[e] + s[:, None] * (b.detach()[e] - a.detach()[e])  # (N, 2) on the edge
        step = _side_offset(gap, x)[:, None] * n[e]                         # beside the edge, either side
        inside, outside = _visible_at(mesh, cam, torch.cat([x - step, x + step]), edges.culled).chunk(2)
        colors = p["colors"].detach()
        background = prob.background.double()
        w = prob.weights.double().reshape(-1, 3)[pix]
        ends = vid[e]
        if prob.model == "affine":                                          # each face's colour field at x
            params = {k: v.double() for k, v in prob.params.items()}
            field = _Field(params["verts"], prob.faces, prob.camera(params))
            color_of = lambda f: field.colors(f.clamp(min=0), torch.zeros_like(f), x, colors)
        else:
            color_of = lambda f: colors[f.clamp(min=0)]

        def term(owner, partner, inner, outer):
            """(N,) w · (c_owner - c_outer), where the owner shows on its inner side, halved when the face
            beyond also has this edge (it finds the same boundary from its side): the partner the edge was
            merged with (``_merge_twins``), or a face with both end vertices (an edge of three faces)."""
            c_out = torch.where((outer >= 0)[:, None], color_of(outer), background)
            beyond = prob.weld[prob.faces[outer.clamp(min=0)]]              # (N, 3)
            shared = (outer >= 0) & ((outer == partner) | ((ends >= 0).all(1) & (beyond == ends[:, :1]).any(1)
                                                          & (beyond == ends[:, 1:]).any(1)))
            t = (w * (color_of(owner) - c_out)).sum(1) * torch.where(shared, 0.5, 1.0)
            return torch.where((owner >= 0) & (inner == owner), t, torch.zeros_like(t))

        own, twin, fold = face[e], edges.twin[e], edges.fold[e]            # the face sharing the edge: same
        value = term(own, twin, inside, outside)                            # samples, its normal along n (a
        value = value + torch.where(fold, term(twin, own, inside, outside),   # fold) or against it
                                    -term(twin, own, outside, inside))
        value = value * weight
    return value


def normal_shift(prob, p, edges, e, s, x):
    """(N,) how far the points x (N, 2) on the curves (e, s) have moved along their normals ``edges.n``,
    differentiable in the parameters p and 0 at their values: its derivative is the normal speed v_n. On a face
    edge the point at s moves with the edge's ends; on an intersection line, where n_f - n_g = 0 (the two
    faces' nearness planes, ``_planes``), a point moves along the normal by ``(n_f - n_g)(x; π) / |∇(n_f - n_g)|``."""
    a, b, n = edges.a, edges.b, edges.n
    out = x.new_zeros(e.shape[0])
    m = e < edges.n_edges                                                   # face edges
    xq = a[e[m]] + s[m, None] * (b[e[m]] - a[e[m]])                         # differentiable in π
    out = out.index_put((m.nonzero().squeeze(1),), ((xq - xq.detach()) * n[e[m]]).sum(1))
    if (~m).any():                                                          # intersection lines
        k = e[~m]
        mesh, cam = prob.mesh(p), prob.camera(p)
        planes = _planes(cam.to_camera(mesh.verts), prob.faces, cam.K, cam.orthographic)
        L = planes[edges.face[k]] - planes[edges.other[k - edges.n_edges]]  # (N, 3)
        xl = x[~m].detach()
        size = L[:, :2].detach().norm(dim=1).clamp_min(1e-300)
        shift = (L[:, 0] * xl[:, 0] + L[:, 1] * xl[:, 1] + L[:, 2]) / size
        out = out.index_put(((~m).nonzero().squeeze(1),), shift - shift.detach())
    return out


def boundary_pieces(prob, p):
    """The pieces of curve inside each pixel along which the image jumps (lecture 09's reparameterization
    follows them): edges (``_Edges``), and per piece its curve e, its ends s0 < s1 on it (fractions of a → b),
    its pixel, and ``Σ w (c_in - c_out)`` at its midpoint (never 0: pieces where nothing jumps are left out).
    p: the parameters in float64."""
    edges, e, s, weight, pix, gap = _boundary_points(prob, p, 1, None, None)
    if e.numel() == 0:
        return edges, e, s, s, pix, s
    length = (edges.b.detach() - edges.a.detach()).norm(dim=1)[e]
    half = weight / (2 * length)                                            # order 1: the midpoint, 2 × half
    value = _jumps(prob, p, edges, e, s, torch.ones_like(weight), pix, gap)
    keep = value != 0
    return edges, e[keep], (s - half)[keep], (s + half)[keep], pix[keep], value[keep]


VIEW_PARAMETERS = ("R", "t", "focal")   # a camera's own: one gradient per view of a batch (the rest are summed)


def boundary_gradient(prob, names, *, order=None, samples=None, generator=None):
    """The boundary term ``Σ w (c_in - c_out) v_n`` by quadrature (Reynolds) or sampling (edge sampling),
    differentiated by autograd through the edges' screen positions (see the module docstring).

    prob: a ``visibility._Problem``, or a list of them, the views of a camera batch (``_Problem.view``: one
    mesh seen by N cameras, each with its weights): then the gradient of the sum of their losses, one pass of
    autograd through every view's term; the views share the mesh's leaves and its per-mesh work (the welded
    positions, the faces that pass through each other, whether back faces can show); each view's edges,
    pieces and visibility samples are its own (edge sampling: ``samples`` points a view, drawn from
    ``generator`` view after view). Returns one gradient per name: for a batch, "verts" summed over the views,
    and a camera's own parameters ("R", "t", "focal") stacked, (N, ...), one per view.

    Everything is evaluated in float64 whatever the problem's dtype: the visibility samples sit 1e-6 px
    beside an edge, below float32's resolution a few pixels from the origin, so a float32 problem is cast
    up (differentiably) and its gradient cast back. A float32 scene then gets the float64 answer for its own
    (float32) numbers."""
    probs = prob if isinstance(prob, list) else [prob]
    leaves = [probs[0].leaves(names)]
    leaves += [q.leaves(names, like=leaves[0]) for q in probs[1:]]         # the mesh's leaves: one set
    terms = [_surrogate(q, {k: v.double() for k, v in p.items()}, order, samples, generator)   # float64
             for q, p in zip(probs, leaves)]
    terms = [t for t in terms if t is not None and t.requires_grad]
    targets = [[p[n] for p in leaves] if n in VIEW_PARAMETERS else probs[0].targets(leaves[0], (n,))
               for n in names]                                              # a list per name
    flat = [x for ts in targets for x in ts]
    grads = iter(torch.autograd.grad(sum(terms), flat, allow_unused=True) if terms else (None,) * len(flat))
    out = []
    for n, ts in zip(names, targets):
        g = probs[0].gradients([next(grads) for _ in ts], ts, (n,) * len(ts))
        out.append(torch.stack(g) if isinstance(prob, list) and n in VIEW_PARAMETERS else g[0])
    return tuple(out)


def _surrogate(prob, p, order, samples, generator):
    """A scalar whose gradient in the parameters p (float64) is the boundary term of one view: ``Σ value · v_n``
    over its points (``_jumps``, ``normal_shift``), plus the interior term for affine colours; None when no
    edge is on screen."""
    edges, e, s, weight, pix, gap = _boundary_points(prob, p, order, samples, generator)
    if e.numel() == 0:
        return None
    value = _jumps(prob, p, edges, e, s, weight, pix, gap)
    keep = (value != 0).nonzero().squeeze(1)
    e, s, value = e[keep], s[keep], value[keep]
    x = edges.a.detach()[e] + s[:, None] * (edges.b.detach()[e] - edges.a.detach()[e])
    surrogate = (value * normal_shift(prob, p, edges, e, s, x)).sum()       # d/dπ = Σ value · v_n
    if prob.model == "affine":                                              # the interior term: the colour field
        surrogate = surrogate + _interior(prob, p)                          # moves under fixed pieces
    return surrogate


def _interior(prob, p):
    """``Σ w · area · c(centroid; π)`` over the visible pieces, with the pieces' areas and centroids held
    fixed: its derivative is ``∫ ∂c/∂π`` over each piece, exact since ∂c/∂π is affine on screen too.
    p: the parameters in float64."""
    mesh, cam = prob.mesh(p), prob.camera(p)
    params = {k: v.double() for k, v in prob.params.items()}
    with torch.no_grad():
        pieces = list(_region_chunks(mesh.verts.detach(), mesh.faces, prob.camera(params), torch.float64))
    field = _Field(mesh.verts, mesh.faces, cam)
    w = prob.weights.double().reshape(-1, 3)
    total = 0.0
    for r in pieces:
        if r.pixel.numel():
            field.check(torch.unique(r.face), "image_gradient")
            c = field.colors(r.face, r.pixel, polygon_centroids(r.verts, r.count), p["colors"])
            total = total + (w[r.pixel] * r.area[:, None] * c).sum()
    return total
