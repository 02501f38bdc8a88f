"""Where an image of flat-coloured faces can jump (lectures 05 and 09): the pixels adaptive supersampling
refines, the pixels ``exact_coverage`` must clip, the crossing lines the boundary term integrates along.

Only along (a) silhouette edges (folds, where a front face meets a back face, and boundary edges), (b) edges
between faces of different colour, (c) lines where two faces intersect, and (d) lines where the near or far
plane cuts a face. ``discontinuity_pixels`` marks every pixel whose *square* (not just its centre) one of
them touches, so a sliver that covers no pixel centre is still found. Everything else is covered by faces
of one colour: one sample there is exact, and so is its colour for the box filter.
"""
from __future__ import annotations

import torch

from .camera import Camera
from .raster import _camera_space, _check_inputs, _project, _screen_triangles
from .scan import edge_function, pixel_triangle_pairs
from .tensors import as_tensor

__all__ = ["discontinuity_pixels", "segment_pixels"]


def _weld(verts) -> torch.Tensor:
    """(V,) one id per distinct vertex position: equal coordinates, equal id. Meshes often split vertices
    for uvs or normals; two faces meeting along such a seam still share the edge geometrically."""
    order = torch.arange(verts.shape[0], device=verts.device)
    for c in (2, 1, 0):                                                      # lexicographic: stable sorts
        order = order[torch.sort(verts[order, c], stable=True).indices]
    v = verts[order]
    new = torch.ones(v.shape[0], dtype=torch.bool, device=verts.device)
    new[1:] = (v[1:] != v[:-1]).any(1)
    weld = torch.empty_like(order)
    weld[order] = torch.cumsum(new, 0) - 1
    return weld


def _pairs_within_groups(group: torch.Tensor):
    """All pairs (i, j), i < j, of positions whose sorted ``group`` labels are equal. group: (N,) sorted."""
    N = group.numel()
    first = torch.ones(N, dtype=torch.bool, device=group.device)
    first[1:] = group[1:] != group[:-1]
    gid = torch.cumsum(first, 0) - 1
    start = first.nonzero().squeeze(1)[gid]                                  # start of each one's group
    size = torch.bincount(gid)[gid]
    later = size - (torch.arange(N, device=group.device) - start) - 1        # partners after each element
    i = torch.repeat_interleave(torch.arange(N, device=group.device), later)
    step = torch.arange(i.numel(), device=group.device) - torch.repeat_interleave(torch.cumsum(later, 0) - later, later)
    return i, i + 1 + step


def _welded_edges(weld, faces):
    """Edges of the welded mesh: for each face corner k (the edge k → k+1) an edge id, (F, 3)."""
    w = weld[faces]                                                          # (F, 3)
    a, b = w, w.roll(-1, 1)
    n = int(weld.max()) + 1 if weld.numel() else 1
    key = (torch.minimum(a, b) * n + torch.maximum(a, b)).reshape(-1)        # (3F,) one key per edge
    return _dense_ids(key).view(-1, 3)


def _dense_ids(key: torch.Tensor) -> torch.Tensor:
    """Integer keys (N,) → ids 0..U-1, equal keys equal ids (``unique(return_inverse=True)``, by one sort)."""
    sorted_key, order = torch.sort(key)
    new = torch.ones_like(sorted_key, dtype=torch.bool)
    new[1:] = sorted_key[1:] != sorted_key[:-1]
    ids = torch.empty_like(order)
    ids[order] = torch.cumsum(new, 0) - 1
    return ids


def _seam_edges(weld, faces) -> torch.Tensor:
    """(F, 3) bool: face edges whose welded edge is also used, by another face, with other vertex indices."""
    edge_of = _welded_edges(weld, faces).reshape(-1)                         # (3F,)
    a, b = faces, faces.roll(-1, 1)
    n = int(faces.max()) + 1                                                 # vertex count bound
    raw = (torch.minimum(a, b) * n + torch.maximum(a, b)).reshape(-1)
    E = int(edge_of.max()) + 1
    big = torch.iinfo(torch.int64).max
    lo = torch.full((E,), big, dtype=torch.int64, device=faces.device).scatter_reduce(0, edge_of, raw, "amin")
    hi = torch.full((E,), -big, dtype=torch.int64, device=faces.device).scatter_reduce(0, edge_of, raw, "amax")
    return (lo != hi)[edge_of].view(-1, 3)


MAX_CELLS = 512          # a face whose box spans more grid cells skips the grid (_intersecting_faces)


def _intersecting_faces(verts, faces, weld, shared_vertex: bool = False):
    """Pairs of faces that may cross each other and share no vertex (in 3D, conservative): f, g (N,) each.
    shared_vertex: also pairs that share exactly one (welded) vertex and pass through each other from it (a
    fold of a mesh through itself); two faces sharing an edge cannot cross (their planes meet along it).

    Broad phase: a uniform grid of cells about one face wide; faces whose bounding boxes share a cell are
    candidates. Narrow phase: the boxes overlap, and each face has corners strictly on both sides of the
    other's plane (faces that only touch, or lie in one plane, draw no line across each other). Faces of a
    closed, non-self-intersecting mesh fail it; the teapot's spout and body pass.
    """
    F = faces.shape[0]
    none = torch.zeros(0, dtype=torch.int64, device=faces.device)
    if F < 2:
        return none, none
    v = verts[faces]                                                         # (F, 3, 3)
    lo, hi = v.amin(1), v.amax(1)
    size = (hi - lo).amax(1).median().clamp_min(1e-12)                       # cell: a typical face
    c_lo, c_hi = torch.floor(lo / size).long(), torch.floor(hi / size).long()
    span = c_hi - c_lo + 1                                                   # (F, 3) cells per axis
    count = span.prod(1)
    huge = count > MAX_CELLS                                                 # a few faces far larger than most:
    count = torch.where(huge, torch.zeros_like(count), count)                # paired with every box they meet
    face = torch.repeat_interleave(torch.arange(F, device=faces.device), count)
    k = torch.arange(face.numel(), device=faces.device) - torch.repeat_interleave(torch.cumsum(count, 0) - count, count)
    sx, sy = span[face, 0], span[face, 1]
    cell = c_lo[face] + torch.stack([k % sx, (k // sx) % sy, k // (sx * sy)], 1)
    cell = cell - cell.amin(0)
    dims = cell.amax(0) + 1
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    order = torch.argsort(key)
    i, j = _pairs_within_groups(key[order])
    f, g = face[order][i], face[order][j]
    for h in huge.nonzero().squeeze(1).tolist():
        meets = ((lo[h] <= hi) & (lo <= hi[h])).all(1).nonzero().squeeze(1)
        f, g = torch.cat([f, torch.full_like(meets, h)]), torch.cat([g, meets])
    pair = torch.sort(torch.minimum(f, g) * F + torch.maximum(f, g)).values
    pair = pair[torch.cat([pair.new_ones(min(1, pair.numel()), dtype=torch.bool), pair[1:] != pair[:-1]])]
    f, g = pair // F, pair % F
    shared = (weld[faces[f]][:, :, None] == weld[faces[g]][:, None, :]).flatten(1).sum(1)
    overlap = ((lo[f] <= hi[g]) & (lo[g] <= hi[f])).all(1)
    allowed = shared <= (1 if shared_vertex else 0)
    f, g = f[overlap & allowed & (f != g)], g[overlap & allowed & (f != g)]
    def straddles(a, b):                                                     # b's corners strictly on both sides
        n = torch.linalg.cross(v[a, 1] - v[a, 0], v[a, 2] - v[a, 0])
        d = ((v[b] - v[a, 0][:, None]) * n[:, None]).sum(-1)                 # (N, 3)
        tol = 1e-9 * n.norm(dim=1) * (hi[b] - lo[b]).abs().amax(1)
        return (d.amax(1) > tol) & (d.amin(1) < -tol)
    both = straddles(f, g) & straddles(g, f)
    return f[both], g[both]


def _crossing_segments(verts, faces, f, g):
    """Where face f meets the plane of face g: for each pair, the (up to 3) segments (N, 3, 2, 3) between
    the points where f's edges reach g's plane, and which of them exist (N, 3). The line where two faces
    intersect lies on this segment, so marking its pixels marks the intersection (a superset of it)."""
    v = verts[faces[f]]                                                     # (N, 3, 3) f's corners
    w = verts[faces[g]]
    n = torch.linalg.cross(w[:, 1] - w[:, 0], w[:, 2] - w[:, 0])            # g's plane
    d = ((v - w[:, :1]) * n[:, None]).sum(-1)                               # (N, 3) signed distances
    d1 = d.roll(-1, 1)
    reach = ((d <= 0) & (d1 >= 0)) | ((d >= 0) & (d1 <= 0))                 # edge k → k+1 meets the plane
    s = torch.where(d == d1, torch.zeros_like(d), d / torch.where(d == d1, torch.ones_like(d), d - d1))
    p = v + s[..., None] * (v.roll(-1, 1) - v)                              # (N, 3, 3) the meeting points
    a, b = p, p.roll(-1, 1)                                                 # segments between them
    ok = reach & reach.roll(-1, 1)
    return torch.stack([a, b], 2), ok


def _discontinuous_edges(verts_cam, faces, weld, camera, keys, in_view, cull_backfaces):
    """(F, 3) bool: the face edges along which the image may jump.

    An edge between two faces is continuous only if exactly two faces share it, both are in view, they
    have the same key (colour) and they lie on opposite sides of it on screen (no fold: both front-facing or
    both back-facing). Anything else — a boundary, a fold (the silhouette), a colour change, a face that is
    culled, edge-on or out of view, a non-manifold edge — is a possible discontinuity.
    """
    F = faces.shape[0]
    edge_of = _welded_edges(weld, faces)
    v = verts_cam[faces]                                                     # (F, 3, 3)
    n = torch.linalg.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    facing = torch.sign(n[:, 2]) if camera.orthographic else -torch.sign((n * v[:, 0]).sum(-1))   # +1 front
    present = in_view & (facing != 0)
    if cull_backfaces:
        present &= facing > 0
    E = int(edge_of.max()) + 1
    flat_edge = edge_of.reshape(-1)                                          # (3F,)
    face_of = torch.arange(F, device=faces.device).repeat_interleave(3)
    live = present.repeat_interleave(3)
    count = torch.zeros(E, dtype=torch.int64, device=faces.device).index_add_(0, flat_edge, live.long())
    # with exactly two live faces per edge, min == max of key and facing means they agree
    big = torch.iinfo(torch.int64).max
    key_f, face_sign = keys[face_of], facing[face_of].long()
    kmin = torch.full((E,), big, dtype=torch.int64, device=faces.device).scatter_reduce(
        0, flat_edge[live], key_f[live], "amin")
    kmax = torch.full((E,), -big, dtype=torch.int64, device=faces.device).scatter_reduce(
        0, flat_edge[live], key_f[live], "amax")
    smin = torch.full((E,), 2, dtype=torch.int64, device=faces.device).scatter_reduce(
        0, flat_edge[live], face_sign[live], "amin")
    smax = torch.full((E,), -2, dtype=torch.int64, device=faces.device).scatter_reduce(
        0, flat_edge[live], face_sign[live], "amax")
    smooth = (count == 2) & (kmin == kmax) & (smin == smax)
    return ~smooth[edge_of]                                                  # (F, 3)


def discontinuity_pixels(mesh, camera: Camera, face_keys=None, *, cull_backfaces: bool = False,
                         seams: bool = False) -> torch.Tensor:
    """(H, W) bool: the pixels whose square a discontinuity of a flat-coloured image may cross.

    face_keys: (F,) integers, faces with equal keys have equal colours (None: all equal, a silhouette;
    use one key per distinct colour for flat colours). A pixel is marked when its square touches
    (a) an edge where the image may jump (``_discontinuous_edges``: silhouettes and folds, boundaries, colour
    changes), (b) any edge of a face cut by the near or the far plane (the cut itself is an edge), or (c) the
    segment where a face crosses the plane of another face it may intersect (``_intersecting_faces``), which
    holds the intersection line. The test is conservative: it may mark a pixel
    where the jump turns out to be hidden, never miss one; so on an unmarked pixel all samples see one colour.
    seams: also mark edges where the two faces meet at the same positions but different vertices (split for
    uvs or normals): attributes interpolated from those vertices may jump there (shaded and textured images).
    """
    verts, faces = _check_inputs(mesh, camera)
    H, W = camera.height, camera.width
    F = faces.shape[0]
    keys = torch.zeros(F, dtype=torch.int64, device=faces.device) if face_keys is None else \
        torch.as_tensor(face_keys, device=faces.device).long().reshape(-1)
    if keys.numel() != F:
        raise ValueError(f"face_keys must have one entry per face ({F}), got {keys.numel()}")
    marked = torch.zeros(H * W, dtype=torch.bool, device=faces.device)
    with torch.no_grad():
        verts_cam = _camera_space(verts, camera)
        st = _screen_triangles(verts_cam, faces, camera, cull_backfaces, reach=0.0)
        if st.face.numel() == 0:
            return marked.view(H, W)
        in_view = torch.zeros(F, dtype=torch.bool, device=faces.device)
        in_view[st.face] = True
        z = verts_cam[faces][..., 2]                                         # (F, 3)
        cut = (z.amin(1) < camera.near) | (z.amax(1) > camera.far)           # (F,) faces a plane cuts
        weld = _weld(verts.detach())
        jump = _discontinuous_edges(verts_cam, faces, weld, camera, keys, in_view, cull_backfaces)   # (F, 3)
        if seams:
            jump |= _seam_edges(weld, faces)
        # the screen triangles' edges, each mapped to the face edge it lies on (st reorders corners)
        xy = st.xy                                                           # (T, 3, 2)
        whole = ~cut[st.face]
        edge_jumps = torch.ones(st.face.numel(), 3, dtype=torch.bool, device=faces.device)
        if whole.any():                                                      # clipped faces keep all edges
            # an unclipped screen triangle is the face's corners in the order (0, 1, 2), or (0, 2, 1) where
            # the face's screen area is negative; then its edges 0→2, 2→1, 1→0 are face edges 2, 1, 0
            fw = st.face[whole]
            v = _project_faces(verts_cam, faces[fw], camera)                 # (n, 3, 2) in face order
            flipped = edge_function(v[:, 0], v[:, 1], v[:, 2]) < 0           # as _screen_triangles decides
            j = jump[fw]
            edge_jumps[whole] = torch.where(flipped[:, None], j[:, [2, 1, 0]], j)
        segs_a = xy[edge_jumps.nonzero(as_tuple=True)]                       # (E, 2)
        segs_b = xy.roll(-1, 1)[edge_jumps.nonzero(as_tuple=True)]
        if segs_a.numel():
            seg_tris = torch.stack([segs_a, segs_b, segs_b], 1)              # degenerate: the segment
            pix, _ = pixel_triangle_pairs(seg_tris, W, H)
            marked[pix] = True
        f, g = _intersecting_faces(verts.detach().double(), faces, weld, shared_vertex=True)   # folds too
        if f.numel():                                                        # the lines where faces cross
            seg, ok = _crossing_segments(verts_cam, faces, torch.cat([f, g]), torch.cat([g, f]))
            seg = seg[ok]                                                    # (M, 2, 3) camera space
            z = seg[..., 2]
            front = (z >= camera.near).all(1)
            if not front.all():                                              # cut at the near plane
                keep = (z >= camera.near).any(1)
                lo, hi = seg[:, 0], seg[:, 1]
                t = ((camera.near - lo[:, 2]) / torch.where(hi[:, 2] == lo[:, 2], torch.ones_like(z[:, 0]),
                                                            hi[:, 2] - lo[:, 2])).clamp(0, 1)[:, None]
                cut = lo + t * (hi - lo)
                lo = torch.where((lo[:, 2] < camera.near)[:, None], cut, lo)
                hi = torch.where((hi[:, 2] < camera.near)[:, None], cut, hi)
                seg = torch.stack([lo, hi], 1)[keep]
            ends, _ = _project(seg.reshape(-1, 3), camera, camera.K.detach().to(torch.float64))
            ends = ends.view(-1, 2, 2)
            if ends.numel():
                pix, _ = pixel_triangle_pairs(torch.stack([ends[:, 0], ends[:, 1], ends[:, 1]], 1), W, H)
                marked[pix] = True
    return marked.view(H, W)


def segment_pixels(a, b, width: int, height: int) -> torch.Tensor:
    """(H, W) bool: the pixels whose closed square the segment a→b touches (its "supercover").

    a, b: (2,) or (N, 2) endpoints in image coordinates (N segments, all marked in one mask). This is how
    ``discontinuity_pixels`` marks an edge: every pixel the edge passes through, not only those whose
    centre it passes near, so an edge that slips between two rows of pixel centres is still found.
    """
    a = as_tensor(a, dtype=torch.float64, name="a").reshape(-1, 2)
    b = as_tensor(b, dtype=torch.float64, device=a.device, name="b").reshape(-1, 2)
    if a.shape != b.shape:
        raise ValueError(f"a and b must have the same shape (2,) or (N, 2), got {tuple(a.shape)} and {tuple(b.shape)}")
    if not (torch.isfinite(a).all() and torch.isfinite(b).all()):
        raise ValueError("segment endpoints must be finite")
    if width < 1 or height < 1:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    mask = torch.zeros(height * width, dtype=torch.bool, device=a.device)
    pix, _ = pixel_triangle_pairs(torch.stack([a, b, b], 1), width, height)   # a degenerate triangle
    mask[pix] = True
    return mask.view(height, width)


def _project_faces(verts_cam, face_verts, camera):
    """Screen positions (n, 3, 2) of the faces' vertices, as ``_screen_triangles`` computes them."""
    xy, _ = _project(verts_cam, camera, camera.K.detach().to(torch.float64))
    return xy[face_verts]


def _color_keys(colors: torch.Tensor) -> torch.Tensor:
    """(F,) integers, equal keys only for equal colours (rows of colors (F, C)); equal colours get equal keys
    unless a different colour happens to sort between them (a generic projection makes that all but
    impossible, and it would only cost a skip, never a wrong image). One sort of the rows projected on a
    generic direction: ``torch.unique(dim=0)`` is ten times slower, and exact_coverage asks for every image."""
    c = colors.detach().reshape(colors.shape[0], -1 if colors.numel() else 1).double()
    weights = torch.tensor([1.0, 0.7548776662466927, 0.5698402909980532, 0.4301597090019468],
                           dtype=torch.float64, device=c.device)[: c.shape[1]]
    order = torch.sort(c @ weights if c.shape[1] <= 4 else c.sum(1), stable=True).indices
    rows = c[order]
    new = torch.ones(c.shape[0], dtype=torch.bool, device=c.device)
    new[1:] = (rows[1:] != rows[:-1]).any(1)
    keys = torch.empty_like(order)
    keys[order] = torch.cumsum(new, 0) - 1
    return keys
