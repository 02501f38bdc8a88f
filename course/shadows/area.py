"""Soft shadows of polygonal area lights in closed form: the form factor of a partly hidden light (lecture 14).

A receiving point x with unit normal n sees a planar convex light polygon L that emits uniformly from the side
its vertices wind counter-clockwise around (the right-hand rule gives its normal n_L). The fraction of the
light's power per unit area that reaches x, for a light of unit radiosity, is the **form factor**

    F(x) = (1/π) ∫ over the part of L visible from x of cos θ_x cos θ_L / r² dA,      in [0, 1],

θ_x the angle at x between n and the direction to the light point, θ_L the angle at the light point between
n_L and the direction back to x. Three steps give it exactly, for every point, with no sampling:

1. **What x could see.** x behind the light's plane (on the side n_L does not point to) gets 0. The light is
   clipped against x's tangent plane: only the part in front of the receiver counts (θ_x < 90°).
2. **What hides it.** Each occluder triangle is clipped to the slab between x and the light's plane (a point
   beyond the plane or behind x blocks no ray from x to the light) and to the pyramid from x over the light (a part
   outside it hides nothing, and a part near x's level would project to infinity), and projected from x onto the
   light's plane:
   ``q = x + (v - x) · d(x) / (d(x) - d(v))`` with d the signed distance to the plane. The projections are
   subtracted from the visible light by convex polygon clipping (``_subtract_batch``), one occluder after
   another, so where occluders overlap each part of the light is removed once.
3. **Lambert's formula.** For a polygon with vertices q_i, r_i = q_i - x,

       F = -(1 / 2π) Σ_i γ_i  n · (r_i × r_{i+1}) / |r_i × r_{i+1}|,    γ_i = ∠(r_i, r_{i+1}),

   the contour integral that Stokes' theorem makes of the area integral (Lambert 1760; the irradiance vector of
   Arvo, SIGGRAPH 1994), summed over the visible pieces. The minus: a piece wound counter-clockwise about n_L,
   which faces x, turns the sum negative.

Every step is a differentiable formula of the inputs between combinatorial decisions (which side of a
clipping line a vertex lies on, which occluder edges cut the light), so autograd gives the gradient with respect
to the points, normals, the light's vertices and the occluders' vertices: the "irradiance Jacobian" of Arvo, the
moving edges of the clipped polygon included. It is the exact derivative wherever those decisions do not
change under a small move: not where a receiver lies exactly on the umbra's or the penumbra's boundary (there
the clipped polygon gains or loses a vertex; the form factor is still continuous, C¹ in general).

Everything is computed in float64 whatever the input dtype, and returned in the input's dtype.
"""
from __future__ import annotations

import math

import torch

from ..mesh import Mesh
from ..tensors import _check_finite, as_tensor
from .gradients import _area_vector

__all__ = ["light_form_factor", "light_pieces", "polygon_form_factor", "check_light", "area_light_image", "DUNAVANT5"]

SIDE_TOL = 1e-12         # of the scene's size: a vertex this close to a clipping plane lies on it
WIDEN = 1e-3             # the pyramid that clips the occluders is over the light widened by this fraction: an
                         # occluder's projection clipped exactly at a light edge would run along it, and a move
                         # of that edge out of the plane would open a sliver on one side only (a kink)


def check_light(light, like: torch.Tensor | None = None) -> torch.Tensor:
    """``light`` (K, 3), K >= 3, as a float tensor: finite, with an area, planar (every vertex within 1e-4 of the
    polygon's size from the plane through its first vertex normal to its area vector: loose enough that a light
    moved by a finite-difference step is still one, where Lambert's formula integrates its contour and the
    occluders are projected onto that plane) and convex, wound counter-clockwise about that normal. Raises
    ValueError naming what is wrong."""
    L = as_tensor(light, name="light") if like is None else as_tensor(light, dtype=like.dtype, device=like.device,
                                                                      name="light")
    if L.dim() != 2 or L.shape[1] != 3 or L.shape[0] < 3:
        raise ValueError(f"light must be a polygon of shape (K, 3) with K >= 3 vertices, got {tuple(L.shape)}")
    _check_finite(L, "light")
    P = L.detach().double()
    area = _area_vector(P)
    size = float((P - P.mean(0)).norm(dim=1).max())
    if float(area.norm()) <= 1e-12 * max(size, 1e-300) ** 2:
        raise ValueError("light has no area (its vertices are collinear or coincide)")
    n = area / area.norm()
    off = ((P - P[0]) @ n).abs().max()
    if float(off) > 1e-4 * size:
        raise ValueError(f"light must be planar: a vertex lies {float(off):.3g} off the polygon's plane")
    turn = torch.linalg.cross(P.roll(-1, 0) - P, P.roll(-2, 0) - P.roll(-1, 0), dim=1) @ n
    if bool((turn < -1e-12 * size ** 2).any()):
        raise ValueError("light must be a convex polygon (its vertices in counter-clockwise order about the side "
                         "it emits from)")
    return L


def polygon_form_factor(x, n, poly) -> torch.Tensor:
    """Lambert's contour formula (module docstring, step 3): the form factor from point x (3,) with unit normal n
    (3,) to the polygon ``poly`` (K, 3) wound counter-clockwise about its normal, that normal facing x, and the
    polygon in front of x's tangent plane. A scalar tensor, differentiable."""
    r = poly - x                                                            # (K, 3)
    r_next = r.roll(-1, 0)
    c = torch.linalg.cross(r, r_next, dim=1)                                # (K, 3)
    length = c.norm(dim=1)
    gamma = torch.atan2(length, (r * r_next).sum(1))                        # the angle at x of each edge
    safe = torch.where(length > 0, length, torch.ones_like(length))         # an edge in line with x: no angle
    return -(gamma * (c @ n) / safe).sum() / (2 * math.pi)


def _occluder_triangles(occluders):
    if occluders is None:
        return None
    if not hasattr(occluders, "verts") or not hasattr(occluders, "faces"):
        raise ValueError(f"occluders must be a Mesh or None, got {type(occluders).__name__}")
    verts = as_tensor(occluders.verts, name="occluders.verts")
    faces = torch.as_tensor(occluders.faces)
    if verts.dim() != 2 or verts.shape[1] != 3:
        raise ValueError(f"occluders.verts must have shape (V, 3), got {tuple(verts.shape)}")
    if faces.dim() != 2 or faces.shape[1] != 3 or faces.dtype != torch.int64:
        raise ValueError(f"occluders.faces must be int64 of shape (F, 3), got {faces.dtype} {tuple(faces.shape)}")
    if faces.numel() and (int(faces.min()) < 0 or int(faces.max()) >= verts.shape[0]):
        raise ValueError(f"occluders.faces index vertex {int(faces.max())} but the mesh has {verts.shape[0]} vertices")
    _check_finite(verts, "occluders.verts")
    return verts.double()[faces]                                            # (F, 3, 3)


# ---------------------------------------------------------------- every receiving point at once
#
# Each point's light is clipped by its own planes, so the polygons differ in size from point to point. They are
# kept in padded batches: ``P`` (B, M, 3), the vertices of B polygons in order, ``n`` (B,) how many of the M
# slots each uses (the rest are ignored; fewer than 3 means empty). The clip below is Sutherland–Hodgman on all
# B at once: every vertex on the kept side, then every crossing, written into 2M slots and packed to the front.

def _clip_batch(P, n, s, tol):
    """The part of each convex polygon of the batch (P (B, M, 3), counts n (B,)) where ``s >= 0``, s (B, M) the
    signed distances of its vertices to the clipping plane. A vertex with |s| <= tol lies on the plane: kept,
    never cut (a plane along an edge makes no sliver). Returns (P', n'), n' = 0 where fewer than 3 remain."""
    B, M = s.shape
    slot = torch.arange(M, device=P.device).expand(B, M)
    used = slot < n[:, None]
    nxt = torch.where(slot + 1 < n[:, None], slot + 1, torch.zeros_like(slot))   # the next vertex, cyclically
    sd = s.detach()
    side = torch.where(sd > tol, 1, torch.where(sd < -tol, -1, 0))
    side_next = side.gather(1, nxt)
    keep = used & (side >= 0)
    cut = used & (side * side_next < 0)                                    # strictly across: cut the edge
    s_next = s.gather(1, nxt)
    t = s / torch.where(cut, s - s_next, torch.ones_like(s))
    P_next = P.gather(1, nxt[..., None].expand(B, M, 3))
    crossing = P + t[..., None] * (P_next - P)
    candidates = torch.stack([P, crossing], 2).reshape(B, 2 * M, 3)         # vertex i, then edge i's crossing
    mask = torch.stack([keep, cut], 2).reshape(B, 2 * M)
    order = torch.sort((~mask).to(torch.int8), dim=1, stable=True).indices # the kept slots first, in order
    count = mask.sum(1)
    width = max(int(count.max()) if B else 0, 1)
    order = order[:, :width]
    packed = candidates.gather(1, order[..., None].expand(B, width, 3))
    return packed, torch.where(count >= 3, count, torch.zeros_like(count))


def _area_batch(P, n):
    """(B, 3) the area vectors of the batch's polygons (half the sum of the cross products of their edges)."""
    B, M, _ = P.shape
    slot = torch.arange(M, device=P.device).expand(B, M)
    nxt = torch.where(slot + 1 < n[:, None], slot + 1, torch.zeros_like(slot))
    c = torch.linalg.cross(P, P.gather(1, nxt[..., None].expand(B, M, 3)), dim=2)
    return 0.5 * torch.where((slot < n[:, None])[..., None], c, torch.zeros_like(c)).sum(1)


def _reverse_batch(P, n, flip):
    """The polygons with ``flip`` (B,) True in the opposite order (their first ``n`` slots reversed)."""
    B, M, _ = P.shape
    slot = torch.arange(M, device=P.device).expand(B, M)
    back = torch.where(slot < n[:, None], n[:, None] - 1 - slot, slot)
    index = torch.where(flip[:, None], back, slot)
    return P.gather(1, index[..., None].expand(B, M, 3))


def _lambert_batch(P, n, x, normal):
    """(B,) Lambert's formula (``polygon_form_factor``) for each polygon of the batch seen from x (B, 3) with
    unit normal (B, 3); 0 for an empty one."""
    B, M, _ = P.shape
    slot = torch.arange(M, device=P.device).expand(B, M)
    nxt = torch.where(slot + 1 < n[:, None], slot + 1, torch.zeros_like(slot))
    r = P - x[:, None, :]
    r_next = r.gather(1, nxt[..., None].expand(B, M, 3))
    c = torch.linalg.cross(r, r_next, dim=2)
    length = c.norm(dim=2)
    gamma = torch.atan2(length, (r * r_next).sum(2))
    counted = (slot < n[:, None]) & (length > 0)                            # an edge in line with x: no angle
    safe = torch.where(counted, length, torch.ones_like(length))
    term = torch.where(counted, gamma * (c * normal[:, None, :]).sum(2) / safe, torch.zeros_like(length))
    return -term.sum(1) / (2 * math.pi)


def _subtract_batch(P, n, D, m, n_hat, tol):
    """Each convex polygon of the batch (P, n) minus the convex polygon D (B, Md, 3) with counts m (B,) in the
    same plane of unit normal ``n_hat``, D wound counter-clockwise about it: the parts outside D, as up to
    Md disjoint convex pieces per polygon (``gradients._subtract``, for a batch): walking D's edges, the part
    beyond each edge is cut off as a piece and the rest goes on. Rows with m < 3 are returned whole.
    Returns (pieces (B', M', 3), counts (B',), row (B',) the input row each piece came from)."""
    B, Md, _ = D.shape
    rows = torch.arange(B, device=P.device)
    active = m >= 3
    out_P, out_n, out_row = [], [], []
    rest, rest_n = P, torch.where(active, n, torch.zeros_like(n))
    out_P.append(P), out_n.append(torch.where(active, torch.zeros_like(n), n)), out_row.append(rows)   # untouched
    for k in range(Md):
        k_next = torch.where(k + 1 < m, k + 1, torch.zeros_like(m))
        a = D[:, k]
        b = D.gather(1, k_next[:, None, None].expand(B, 1, 3))[:, 0]
        inward = torch.linalg.cross(n_hat.expand(B, 3), b - a, dim=1)
        length = inward.norm(dim=1, keepdim=True)
        edge = (k < m) & (length[:, 0] > 0)
        inward = inward / length.clamp_min(1e-300)
        s = ((rest - a[:, None, :]) * inward[:, None, :]).sum(2)            # (B, M) into D is positive
        used = torch.arange(rest.shape[1], device=P.device)[None] < rest_n[:, None]
        sd = s.detach()
        inside_all = ((sd >= -tol) | ~used).all(1)
        outside_all = ((sd <= tol) | ~used).all(1)
        part, part_n = _clip_batch(rest, rest_n, -s, tol)
        part_n = torch.where(edge & ~inside_all, part_n, torch.zeros_like(part_n))
        out_P.append(part), out_n.append(part_n), out_row.append(rows)
        cut, cut_n = _clip_batch(rest, rest_n, s, tol)
        keep_rest = ~edge | inside_all
        width = max(cut.shape[1], rest.shape[1])
        rest = torch.where(keep_rest[:, None, None], _pad(rest, width), _pad(cut, width))
        rest_n = torch.where(keep_rest, rest_n, torch.where(outside_all, torch.zeros_like(cut_n), cut_n))
    width = max(p.shape[1] for p in out_P)
    pieces, counts, row = torch.cat([_pad(p, width) for p in out_P]), torch.cat(out_n), torch.cat(out_row)
    keep = (counts >= 3).nonzero().squeeze(1)
    return pieces[keep], counts[keep], row[keep]


def _pad(P, width):
    """The batch P (B, M, 3) with M padded (by copies of its last slot) or cut to ``width`` slots."""
    if P.shape[1] >= width:
        return P[:, :width]
    return torch.cat([P, P[:, -1:].expand(P.shape[0], width - P.shape[1], 3)], 1)


def _visible_batch(X, Nrm, L, n_L, tris, tol, own=None):
    """The convex pieces of the light L (K, 3) that each point X (N, 3) with unit normal Nrm (N, 3) sees (module
    docstring, steps 1-2), skipping triangle own[i] (its own face) for point i when given: (pieces (B, M, 3),
    counts (B,), owner (B,) the point each piece belongs to), every piece wound counter-clockwise about n_L."""
    N, K = X.shape[0], L.shape[0]
    d_x = (X - L[0]) @ n_L                                                  # the points' heights above the light
    start = L.expand(N, K, 3)
    count = torch.full((N,), K, dtype=torch.long, device=X.device)
    count = torch.where(d_x.detach() > tol, count, torch.zeros_like(count)) # behind the light: nothing
    P, count = _clip_batch(start, count, ((start - X[:, None]) * Nrm[:, None]).sum(2), tol)   # in front of x
    owner = torch.arange(N, device=X.device)
    keep = (count >= 3).nonzero().squeeze(1)
    P, count, owner = P[keep], count[keep], owner[keep]
    if tris is None or P.shape[0] == 0:
        return P, count, owner
    centre = L.detach().mean(0)
    wide = centre + (L - centre) * (1 + WIDEN)                              # the light a little wider: an
    walls = torch.linalg.cross(wide[None] - X[:, None], wide.roll(-1, 0)[None] - X[:, None], dim=2)   # occluder's
    inward = ((walls.detach() * (centre - X.detach())[:, None]).sum(2) > 0)  # projection then reaches past the
    walls = torch.where(inward[..., None], walls, -walls)                   # light's edges rather than along them
    for index in range(tris.shape[0]):
        if P.shape[0] == 0:
            break
        tri = tris[index].expand(N, 3, 3)
        d = (tri - L[0]) @ n_L                                              # the corners' heights above the light
        D, m = _clip_batch(tri, torch.full((N,), 3, device=X.device), d, tol)   # not beyond the light's plane
        h = (D - L[0]) @ n_L
        D, m = _clip_batch(D, m, d_x[:, None] - h, tol)                      # nor behind x's level
        for w in range(K):                                                  # inside the pyramid from x over
            D, m = _clip_batch(D, m, ((D - X[:, None]) * walls[:, w][:, None]).sum(2), tol)   # the light
        if own is not None:
            m = torch.where(own == index, torch.zeros_like(m), m)           # the receiver's own face
        if not bool((m >= 3).any()):
            continue
        h = (D - L[0]) @ n_L
        used = torch.arange(D.shape[1], device=X.device)[None] < m[:, None]   # (unused slots: anything finite)
        scale = d_x[:, None] / torch.where(used, d_x[:, None] - h, torch.ones_like(h))
        Q = X[:, None] + (D - X[:, None]) * scale[..., None]                # projected from x onto the plane
        orient = (_area_batch(Q.detach(), m) * n_L.detach()).sum(1)
        m = torch.where(orient.abs() > tol * tol, m, torch.zeros_like(m))   # seen edge-on: hides no area
        Q = _reverse_batch(Q, m, orient < 0)                                # counter-clockwise about n_L
        pieces, counts, row = _subtract_batch(P, count, Q[owner], m[owner], n_L, tol)
        P, count, owner = pieces, counts, owner[row]
    return P, count, owner


def light_pieces(point, normal, light, occluders=None) -> list:
    """The convex pieces of ``light`` that ``point`` (3,) with ``normal`` (3,) sees past ``occluders`` (module
    docstring, steps 1-2): a list of (M, 3) polygons in the light's plane, wound as the light. What
    ``light_form_factor`` integrates; lecture 14 draws them."""
    X = as_tensor(point, name="point").reshape(1, 3).double()
    Nrm = as_tensor(normal, name="normal").reshape(1, 3).double()
    _check_finite(X, "point")
    _check_finite(Nrm, "normal")
    L = check_light(light).double()
    tris = _occluder_triangles(occluders)
    area = _area_vector(L)
    n_L = area / area.norm()
    tol = SIDE_TOL * _scale(X, L, tris)
    P, n, _ = _visible_batch(X, Nrm / Nrm.norm(), L, n_L, tris, tol)
    return [P[i, :int(n[i])] for i in range(P.shape[0])]


def light_form_factor(points, normals, light, occluders=None) -> torch.Tensor:
    """The exact form factor from each receiving point to a partly hidden polygonal light (module docstring).

    points, normals: (N, 3) receiving points and their normals (any length, not zero); light: (K, 3) a planar
    convex polygon, emitting uniformly from the side its vertices wind counter-clockwise around; occluders: a
    ``Mesh`` (its triangles hide the light, either side) or None. Returns (N,) in [0, 1], in the promoted dtype
    of the inputs: 0 where the point is behind the light or the light behind the point's tangent plane.
    Differentiable by autograd w.r.t. points, normals, the light's vertices and the occluders' vertices; computed
    in float64.
    """
    X = as_tensor(points, name="points")
    if X.dim() != 2 or X.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {tuple(X.shape)}")
    Nrm = as_tensor(normals, dtype=X.dtype, device=X.device, name="normals")
    if Nrm.shape != X.shape:
        raise ValueError(f"normals must have the shape of points {tuple(X.shape)}, got {tuple(Nrm.shape)}")
    _check_finite(X, "points")
    _check_finite(Nrm, "normals")
    if X.shape[0] and bool((Nrm.detach() == 0).all(1).any()):
        raise ValueError("normals contains a zero vector")
    L = check_light(light, X)
    tris = _occluder_triangles(occluders)
    out_dtype = torch.promote_types(X.dtype, L.dtype)
    if tris is not None:
        out_dtype = torch.promote_types(out_dtype, as_tensor(occluders.verts).dtype)
    X64, N64, L64 = X.double(), Nrm.double(), L.double()
    N64 = N64 / N64.norm(dim=1, keepdim=True)
    return _form_factors(X64, N64, L64, tris, None).clamp(0.0, 1.0).to(out_dtype)


def _scale(X64, L64, tris):
    return float(torch.cat([X64.detach(), L64.detach()] + ([] if tris is None else [tris.detach().reshape(-1, 3)]))
                 .abs().max().clamp_min(1e-300))


def _form_factors(X64, N64, L64, tris, own, chunk: int = 4096):
    """(N,) float64 form factors of unit-normal receivers X64, N64 (N, 3) to the light L64 (K, 3) past the
    triangles ``tris`` (T, 3, 3) or None, point i ignoring triangle ``own[i]`` (its own face) when given; in
    chunks of ``chunk`` points (the batches' memory)."""
    area = _area_vector(L64)
    n_L = area / area.norm()
    tol = SIDE_TOL * _scale(X64, L64, tris)
    out = []
    for lo in range(0, X64.shape[0], chunk):
        X, Nrm = X64[lo:lo + chunk], N64[lo:lo + chunk]
        P, n, owner = _visible_batch(X, Nrm, L64, n_L, tris, tol, None if own is None else own[lo:lo + chunk])
        F = _lambert_batch(P, n, X[owner], Nrm[owner])
        out.append(X.new_zeros(X.shape[0]).index_add(0, owner, F))
    return torch.cat(out) if out else X64.new_zeros(0)


# ------------------------------------------------------------------------------------ the image it lights

# Dunavant's degree-5 rule on a triangle: 7 points (barycentric coordinates) and weights summing to 1
_A1, _B1, _W1 = 0.059715871789770, 0.470142064105115, 0.132394152788506
_A2, _B2, _W2 = 0.797426985353087, 0.101286507323456, 0.125939180544827
DUNAVANT5 = (torch.tensor([[1 / 3, 1 / 3, 1 / 3], [_A1, _B1, _B1], [_B1, _A1, _B1], [_B1, _B1, _A1],
                           [_A2, _B2, _B2], [_B2, _A2, _B2], [_B2, _B2, _A2]], dtype=torch.float64),
             torch.tensor([0.225, _W1, _W1, _W1, _W2, _W2, _W2], dtype=torch.float64))


def _on_faces(xy, face, verts, faces, camera):
    """World points (P, 3) of faces ``face`` (P,) seen at image points xy (P, 2): the pixel's ray met with the
    face's plane (differentiable in verts, K, R, t), and the faces' unit normals turned toward the camera."""
    K, R, t = camera.K.double(), camera.R.double(), camera.t.double()
    q = torch.cat([xy, torch.ones_like(xy[:, :1])], 1) @ torch.linalg.inv(K).T   # (P, 3) K⁻¹ [x, y, 1]
    eye = -R.T @ t
    if camera.orthographic:
        origin = torch.cat([q[:, :2], torch.zeros_like(q[:, :1])], 1) @ R + eye
        direction = R[2].expand_as(origin)
    else:
        origin, direction = eye.expand_as(q), q @ R
    tri = verts[faces[face]]                                                # (P, 3, 3)
    n = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], dim=1)
    s = ((tri[:, 0] - origin) * n).sum(1) / (direction * n).sum(1)
    x = origin + s[:, None] * direction
    n = n / n.norm(dim=1, keepdim=True)
    n = torch.where(((direction * n).sum(1) > 0)[:, None], -n, n)           # the side the camera sees
    return x, n


def area_light_image(mesh, camera, face_colors, light, ambient=0.1, intensity=1.0, background=(0.0, 0.0, 0.0),
                     *, subdivide: int = 1) -> torch.Tensor:
    """The box-filtered image of flat-coloured Lambertian faces lit by a polygonal area light, which the faces
    themselves shadow: each pixel ``Σ_pieces ∫ c_f (ambient + intensity · F(x)) ds + background · (uncovered
    area)``, the pieces the exact visible parts of the faces in the pixel (``coverage.visible_regions``) and F the
    exact form factor at the surface point x seen at screen point s (``light_form_factor``, every face but the
    point's own an occluder, the normal turned toward the camera).

    The integral over each piece is a quadrature: the piece split into triangles (a fan, each cut into
    ``subdivide``² smaller ones), Dunavant's 7-point degree-5 rule on each. F is smooth inside the penumbra and
    the umbra but only C¹ across their boundaries, so the quadrature's error falls like a power of the
    subdivision there (``tests/test_area_light.py`` measures it). Differentiable by autograd w.r.t. the vertices,
    the light, the face colours and the camera: the primary visibility's boundary term through the pieces'
    moving vertices, the penumbra's through F. mesh: ``verts`` (V, 3), ``faces`` (F, 3); face_colors (F, 3); light
    (K, 3) as ``light_form_factor``; returns (H, W, 3) float64.
    """
    from ..coverage import visible_regions
    verts = as_tensor(mesh.verts, name="mesh.verts")
    faces = torch.as_tensor(mesh.faces)
    colors = as_tensor(face_colors, dtype=torch.float64, name="face_colors")
    if colors.shape != (faces.shape[0], 3):
        raise ValueError(f"face_colors must have shape (F, 3) = ({faces.shape[0]}, 3), got {tuple(colors.shape)}")
    _check_finite(colors, "face_colors")
    L = check_light(light).double()
    k = int(subdivide)
    if k < 1:
        raise ValueError(f"subdivide must be a positive integer, got {subdivide!r}")
    V = verts.double()
    regions = visible_regions(Mesh(V, faces), camera.to(dtype=torch.float64), dtype=torch.float64)
    W, H = camera.width, camera.height
    corner = torch.stack([regions.pixel % W, regions.pixel // W], 1).double()
    pv = regions.verts + corner[:, None, :]                                 # (N, M, 2) image coordinates
    # the fan's triangles, each cut into k² (barycentric grid), and the rule's points in each
    bary, weight = DUNAVANT5
    sub = []
    for i in range(k):
        for j in range(k - i):
            sub.append(((i, j), (i + 1, j), (i, j + 1)))                    # upward
            if i + j < k - 1:
                sub.append(((i + 1, j), (i + 1, j + 1), (i, j + 1)))       # downward
    points, weights, piece_of = [], [], []
    M = pv.shape[1]
    for m in range(1, M - 1):
        a, b, c = pv[:, 0], pv[:, m], pv[:, m + 1]                          # (N, 2) each
        for tri in sub:
            corners = [a + (b - a) * (u / k) + (c - a) * (v / k) for u, v in tri]
            area = 0.5 * ((corners[1][:, 0] - corners[0][:, 0]) * (corners[2][:, 1] - corners[0][:, 1])
                          - (corners[1][:, 1] - corners[0][:, 1]) * (corners[2][:, 0] - corners[0][:, 0]))
            for g in range(bary.shape[0]):
                points.append(bary[g, 0] * corners[0] + bary[g, 1] * corners[1] + bary[g, 2] * corners[2])
                weights.append(weight[g] * area)
                piece_of.append(torch.arange(pv.shape[0]))
    xy, w, piece = torch.cat(points), torch.cat(weights), torch.cat(piece_of)
    keep = (w.detach().abs() > 0).nonzero().squeeze(1)                       # padded slots: zero area
    xy, w, piece = xy[keep], w[keep], piece[keep]
    face = regions.face[piece]
    x, n = _on_faces(xy, face, V, faces, camera)
    F = _form_factors(x, n, L, V[faces], face).clamp(0.0, 1.0)
    shade = colors[face] * (ambient + intensity * F)[:, None]              # (P, 3)
    image = torch.zeros(H * W, 3, dtype=torch.float64).index_add(0, regions.pixel[piece], shade * w[:, None])
    covered = torch.zeros(H * W, dtype=torch.float64).index_add(0, regions.pixel, regions.area)
    bg = as_tensor(background, dtype=torch.float64, name="background")
    image = image + (1 - covered)[:, None] * bg
    return image.view(H, W, 3)
