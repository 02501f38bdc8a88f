"""Hard shadows in closed form, and their gradients (lecture 12: differentiable shadows).

The image model. Flat-coloured faces and one light: directional (``light`` (3,), the way the light *travels*,
as ``DirectionalLight.direction``), or with ``point=True`` a point light at ``light`` (3,), outside the
mesh's bounding box (the shadows are then central projections from it). A point of face f shows ``c_f``
where it sees the light and ``a · c_f`` where it does not (``ambient`` a in [0, 1]). A point sees the light
when the light arrives on the front side of its face (the side from which the face's vertices run
counter-clockwise: ``n_f · l > 0``, with l the unit vector toward the light) and no other face blocks the ray
toward the light. So faces turned away from the
light are fully shadowed (self-shadowing), and a face at a grazing angle, ``n̂_f · l <= GRAZING``, counts as
turned away: its lit/shadowed state flips there, a jump of the whole face that no gradient sees (the one
discrete decision of the model; every method here, finite differences included, sees it as a step).

The exact answer. Each face f that faces the light is split, in its own plane, by the shadow outline: every
other face g, clipped to the half-space on the light's side of f's plane (``h = n̂_f · (x - v_f) >= 0``), is
projected along the light onto that plane (``x' = x - h / (n̂_f · l) · l``), a convex polygon D_g; the lit
part of f is f minus the union of the D_g, the shadowed part the rest. A convex piece minus a convex D is the
disjoint union ``(piece ∩ ¬H1) ∪ (piece ∩ H1 ∩ ¬H2) ∪ ...`` of convex pieces (H_i D's edge half-planes, as
in ``coverage``), and what is left inside every H_i is shadowed. The pieces are polygon clippings of the
vertices and the light, so the split vertices are differentiable functions of both (``split_by_shadows``).
The pieces are cropped to the camera's view (plus ``VIEW_MARGIN`` pixels: the image is the same, and edge
sampling spends no samples off screen), fan-triangulated around their centroid into a *split mesh* whose
faces carry ``c_f`` or ``a · c_f``, and ``coverage.exact_coverage`` draws it: the box-filtered shadowed image
in closed form (``shadowed_coverage``). A point light works the same way, the occluders projected from it
(``_shadow_polygon``).

The split mesh is conforming: every vertex of a piece that lies on another piece's edge (the end of a shadow
edge on a face's edge, a cut of the decomposition ending on a neighbour's edge) is inserted into that edge,
and positions that agree to ``MERGE_TOL`` of the scene's size are one vertex. The boundary term of
``course.boundary`` counts an edge shared by two faces half from each side; a T-junction would make both
sides count it in full. Conforming, the internal lit/shadow edges of a face are ordinary shared edges with a
colour jump ``(1 - a) c_f``, and the cuts of the decomposition and the fan's spokes join pieces of one colour
(a jump of 0).

Gradients (``shadow_image_gradient``), of ``L = Σ weights ⊙ image``:

* ``"exact"``: autograd through the split and ``exact_coverage``.
* ``"finite_differences"``: central differences of the closed-form image, one parameter entry at a time.
* ``"reynolds"`` / ``"edge_sampling"``: ``visibility.image_gradient`` of the split mesh w.r.t. its vertices
  (the boundary term on every edge where the colour jumps: primary silhouettes and shadow edges alike), then
  chained to the scene's vertices and the light by one vector-Jacobian product through the split: the shadow
  edge's normal velocity on screen is the chain rule through both projections (light → receiver plane →
  camera). The camera's parameters come straight from ``image_gradient``: the split does not depend on them.

Where the image has a kink there is no derivative, only two one-sided ones that differ: central differences
average them, and exact and reynolds return values that need not equal either side, nor each other (the height
of a base corner of ``shadow_scene("crossing")``: one-sided 0.16 and -2.7; lecture 12 leaves such coordinates
out of its comparisons). Two coplanar faces that share an edge (a quad's two triangles): moving a
vertex creases them, and a crease shadows one side only, concave or convex. An occluder touching its receiver
(the cube standing on the floor): the floor's height under it. A vertex of a shadow outline exactly on an edge
of its receiver (within ``SIDE_TOL``): the split snaps it onto the edge, and the derivative is the snapped
arrangement's, not either side's (a symmetric scene can do this by accident; the test scenes avoid it). And
a camera looking along the light: an occluder's silhouette and its own shadow edge then lie on the same
screen line (exactly aligned: the shadow hides behind its occluder) or a sliver apart. The boundary methods
ask the z-buffer which face shows a hair beside each edge (``boundary._side_offset``, ~1e-11 px): a sliver
wider than that is resolved (an orthographic camera 1e-9 rad off a directional light, a perspective one 1e-9
units from a point light 4 units from the scene: Reynolds equals exact to 1e-8 of central differences), a
narrower one is stepped over and both edges claim the same jump. So ``"reynolds"`` and ``"edge_sampling"``
refuse a camera within ``ALIGNED`` rad of the light's line of sight (an orthographic camera looking along a
directional light, or a perspective camera at a point light); ``"exact"`` is right there too.

Cost: the split loops over (receiver, occluder) pairs in Python, so it is for small scenes (tens to a few
hundred faces); a pair is skipped when the occluder lies below the receiver's plane or a line separates them.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from ..camera import Camera
from ..coverage import exact_coverage
from ..mesh import Mesh
from ..tensors import _is_zero, as_tensor, unit
from ..visibility import image_gradient

__all__ = ["SCENES", "shadow_scene", "SplitMesh", "project_onto_plane", "split_by_shadows", "shadowed_coverage",
           "shadow_image_gradient", "shadow_raytrace", "SHADOW_METHODS", "GRAZING"]

SHADOW_METHODS = ("exact", "finite_differences", "reynolds", "edge_sampling")
GRAZING = 1e-9           # n̂_f · l at or below this: the face is turned away from the light (fully shadowed)
SIDE_TOL = 1e-10         # of the scene's size: a vertex this close to a clipping line lies on it
MERGE_TOL = 1e-8         # of the scene's size: split vertices this close are one vertex
ALIGNED = 1e-10          # rad: a camera this close to the light's line of sight is refused by the boundary methods


@dataclass(frozen=True)
class SplitMesh:
    """The scene's faces cut into lit and shadowed triangles.

    verts: (V', 3) world space, differentiable in the scene's vertices and the light (float64).
    faces: (T, 3) int64, each triangle wound as the face it came from.
    source: (T,) int64 the original face of each triangle.
    lit: (T,) bool, True where the triangle sees the light.
    """
    verts: torch.Tensor
    faces: torch.Tensor
    source: torch.Tensor
    lit: torch.Tensor

    def colors(self, face_colors, ambient) -> torch.Tensor:
        """(T, 3) each triangle's colour: its face's (F, 3) colour, times ``ambient`` where shadowed."""
        c = face_colors[self.source]
        return torch.where(self.lit[:, None], c, ambient * c)


# ------------------------------------------------------------------------------------- the test scenes

SCENES = ("floater", "box", "crossing", "grazing", "fold", "floor_view")


def shadow_scene(name: str, size: int = 16, *, orthographic: bool = False, dtype=torch.float64):
    """(mesh, camera, face_colors (F, 3), light (3,)): small scenes on a floor at y = 0 (one big triangle, so
    that moving a floor vertex tilts the floor rather than creasing it: a crease is a kink, see the tests).

    * ``"floater"``: a tilted triangle floating above the floor, its shadow on the floor.
    * ``"box"``: a cube (side 1, without its bottom, which would lie on the floor: coplanar overlapping faces)
      standing on the floor: its faces turned from the light are shadowed, and it casts a shadow on the floor
      (self-shadowing; the cube touches its receiver).
    * ``"crossing"``: the cube, with a triangle above it whose shadow falls across the cube's top and down
      onto the floor: a shadow edge crossing a primary silhouette.
    * ``"grazing"``: the floater, lower, lit 13° above the horizon: a long thin shadow beside it.
    * ``"fold"``: no floor; a bent strip (a flat part and a wall rising from its edge, one mesh): the wall,
      turned away from the light, is all shadow, and it casts a shadow on the flat part (self-shadowing).
    * ``"floor_view"``: a triangle high above the floor, out of the camera's view (orthographic, straight
      down): the image is the floor and the shadow alone, so every gradient w.r.t. the occluder or the light
      is the shadow's (``bench shadow-gradients``, and shadow art).
    """
    if name not in SCENES:
        raise ValueError(f"name must be one of {', '.join(SCENES)}, got {name!r}")
    floor = [[-2.5, 0, -2.5], [-2.5, 0, 7], [7, 0, -2.5]]                  # one triangle: no crease in it
    faces = [[0, 1, 2]]                                                     # normal up (+y)
    verts = list(floor)
    if name == "floor_view":
        verts += [[-1.9, 2.9, -0.5], [-0.6, 3.1, 0.3], [-1.6, 3.0, 0.8]]
        faces += [[3, 5, 4]]
    if name == "fold":
        verts = [[-1.5, 0, -1], [-1.5, 0, 1], [0, 0, 1], [0, 0, -1], [0.6, 1.2, 1], [0.6, 1.2, -1]]
        faces = [[0, 1, 2], [0, 2, 3], [3, 2, 4], [3, 4, 5]]                # flat part up, wall toward -x
    if name in ("box", "crossing"):
        from ..models import cube
        box = cube(1.0, dtype=torch.float64)
        verts += (box.verts + torch.tensor([0.0, 0.5, 0.0], dtype=torch.float64)).tolist()
        walls = box.faces[(box.verts[box.faces][:, :, 1] > -0.5).any(1)]    # no bottom: it would lie on the floor
        faces += (walls + 3).tolist()
    if name in ("floater", "grazing", "crossing"):
        k = len(verts)
        lift = {"crossing": 1.6, "grazing": -0.45}.get(name, 0.0)
        verts += [[-0.5, 0.8 + lift, -0.3], [0.6, 0.9 + lift, 0.1], [-0.2, 0.7 + lift, 0.6]]
        faces += [[k, k + 2, k + 1]]                                        # normal up
    light = {"floater": (0.3, -1.0, 0.2), "box": (0.6, -1.0, 0.35), "crossing": (0.5, -1.0, 0.25),
             "grazing": (0.95, -0.22, 0.2), "fold": (-0.8, -0.5, 0.13), "floor_view": (1.0, -1.0, 0.1)}[name]
    gen = torch.Generator().manual_seed(len(faces))
    colors = 0.3 + 0.6 * torch.rand(len(faces), 3, generator=gen, dtype=torch.float64)
    eye = (0.9, 3.2, 3.6)
    if name == "floor_view":                                                # straight down on the shadow
        cam = Camera.look_at((1.8, 2.0, 0.25), (1.8, 0.0, 0.25), up=(0.0, 0.0, -1.0), ortho_height=3.0,
                             width=size, height=size, dtype=dtype)
    elif orthographic:
        cam = Camera.look_at(eye, (0.0, 0.3, 0.0), ortho_height=4.5, width=size, height=size, dtype=dtype)
    else:
        cam = Camera.look_at(eye, (0.0, 0.3, 0.0), fov_y=50.0, width=size, height=size, dtype=dtype)
    mesh = Mesh(torch.tensor(verts, dtype=dtype), torch.tensor(faces, dtype=torch.int64))
    return mesh, cam, colors.to(dtype), torch.tensor(light, dtype=dtype)


# ----------------------------------------------------------------------------------------- input checks

def _check_scene(mesh, light, point: bool = False):
    """verts (V, 3), faces (F, 3) and light (3,) (a direction, or with ``point`` a position outside the
    mesh's bounding box), with clear errors."""
    verts = as_tensor(mesh.verts, name="mesh.verts")
    faces = torch.as_tensor(mesh.faces, device=verts.device)
    if verts.dim() != 2 or verts.shape[1] != 3:
        raise ValueError(f"mesh.verts must have shape (V, 3), got {tuple(verts.shape)}")
    if faces.dim() != 2 or faces.shape[1] != 3 or faces.dtype != torch.int64:
        raise ValueError(f"mesh.faces must be int64 of shape (F, 3), got {faces.dtype} {tuple(faces.shape)}")
    if faces.numel() and (faces.min() < 0 or faces.max() >= verts.shape[0]):
        raise ValueError(f"faces index vertex {int(faces.max())} but the mesh has {verts.shape[0]} vertices")
    if not torch.isfinite(verts).all():
        raise ValueError("mesh.verts contains NaN or inf")
    d = as_tensor(light, dtype=verts.dtype, device=verts.device, name="light")
    if d.shape != (3,):
        raise ValueError(f"light must be a direction of shape (3,) (the way the light travels), got "
                         f"{tuple(d.shape)}")
    if not torch.isfinite(d).all():
        raise ValueError("light contains NaN or inf")
    if not isinstance(point, bool):
        raise ValueError(f"point must be True or False, got {point!r}")
    if point:
        lo, hi = verts.detach().amin(0), verts.detach().amax(0)
        if verts.numel() and bool(((d.detach() >= lo) & (d.detach() <= hi)).all()):
            raise ValueError(f"a point light must lie outside the scene's bounding box {lo.tolist()} - "
                             f"{hi.tolist()}, got {d.detach().tolist()} (a light inside the scene)")
    elif _is_zero(d):
        raise ValueError("light must be a non-zero direction (the way the light travels), got a zero vector")
    return verts, faces, d


def _check_ambient(ambient):
    if isinstance(ambient, torch.Tensor):
        if ambient.numel() != 1 or not torch.isfinite(ambient).all() or not 0 <= float(ambient) <= 1:
            raise ValueError(f"ambient must be one number in [0, 1], got {ambient}")
        return ambient.reshape(())
    if isinstance(ambient, bool) or not isinstance(ambient, (int, float)) or not 0 <= ambient <= 1:
        raise ValueError(f"ambient must be a number in [0, 1] (the shadowed fraction of a colour), got {ambient!r}")
    return float(ambient)


# ------------------------------------------------------------------------------------ polygon clipping

def _clip(poly, s, tol):
    """The part of the convex polygon ``poly`` (K, 3) where ``s >= 0`` (Sutherland–Hodgman), s (K,) the
    signed distances of its vertices to the clipping line. Vertices with |s| <= tol lie on the line: kept,
    never cut, so a line along an edge makes no sliver. Returns (K', 3), K' possibly < 3 (empty)."""
    side = [1 if v > tol else (-1 if v < -tol else 0) for v in s.detach().tolist()]
    K = len(side)
    out = []
    for i in range(K):
        j = (i + 1) % K
        if side[i] >= 0:
            out.append(poly[i])
        if side[i] * side[j] < 0:                                           # strictly across: cut the edge
            t = s[i] / (s[i] - s[j])
            out.append(poly[i] + t * (poly[j] - poly[i]))
    return torch.stack(out) if len(out) >= 3 else poly[:0]


def _area_vector(poly):
    """(3,) half the sum of cross products: the polygon's area times its unit normal."""
    return 0.5 * torch.linalg.cross(poly, poly.roll(-1, 0), dim=1).sum(0)


@dataclass(frozen=True)
class _Light:
    """The light in float64: ``position`` (3,) of a point light, or ``to_light`` (3,), the unit vector toward a
    directional one (the other None)."""
    to_light: torch.Tensor | None
    position: torch.Tensor | None


def _shadow_polygon(g_poly, v0, n_hat, light: _Light, cos, tol):
    """The shadow D (K, 3) that the triangle g (3, 3) casts on the plane through v0 with unit normal n_hat,
    counter-clockwise about n_hat, or None. g is clipped to the light's side of the plane (h >= 0, h the
    height above it) and, for a point light at height h_p, below the light (h <= h_p: nothing beyond the light
    blocks it), then moved onto the plane: along l by ``h / cos`` (directional, cos = n̂ · l), or along the
    ray from the light, ``x' = x + (x - p) h / (h_p - h)`` (point, cos = h_p; the same point as
    ``p + (x - p) h_p / (h_p - h)``, without the cancellation of p against -p when the light is far: that form
    lost the shadow of a light 1e17 away). None when nothing of g is
    between the plane and the light, or D has no area (g edge-on to the light)."""
    h = (g_poly - v0) @ n_hat                                               # (3,) heights above the plane
    if float(h.detach().max()) <= tol:
        return None
    above = _clip(g_poly, h, tol)
    if light.position is not None and above.shape[0] >= 3:
        above = _clip(above, cos * (1 - 1e-9) - (above - v0) @ n_hat, tol)  # below the light
    if above.shape[0] < 3:
        return None
    h = (above - v0) @ n_hat
    if light.position is None:
        D = above - (h / cos)[:, None] * light.to_light                     # (K, 3) on the plane
    else:
        D = above + (above - light.position) * (h / (cos - h))[:, None]
    orient = float(_area_vector(D.detach()) @ n_hat.detach())
    if abs(orient) <= tol * tol:
        return None                                                         # edge-on to the light
    return D if orient > 0 else D.flip(0)


def project_onto_plane(points, plane_point, plane_normal, light) -> torch.Tensor:
    """Where the shadows of ``points`` (N, 3) fall on a plane, under a directional light: (N, 3).

    The plane passes through ``plane_point`` (3,) with normal ``plane_normal`` (3,), any length; ``light`` (3,)
    is the way the light travels. A point at height ``h = n̂ · (x - p)`` above the plane slides along the light
    until its height is 0: ``x' = x - h / (n̂ · l) · l`` (the split's formula, for one point at a time; the
    sign of l cancels). Differentiable in all four; a light parallel to the plane (n̂ · l = 0) casts no
    shadow on it and is refused."""
    x = as_tensor(points, name="points")
    if x.dim() != 2 or x.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {tuple(x.shape)}")
    p, n, l = (as_tensor(v, dtype=x.dtype, device=x.device, name=name)
               for v, name in ((plane_point, "plane_point"), (plane_normal, "plane_normal"), (light, "light")))
    for v, name in ((p, "plane_point"), (n, "plane_normal"), (l, "light")):
        if v.shape != (3,):
            raise ValueError(f"{name} must have shape (3,), got {tuple(v.shape)}")
    if not all(bool(torch.isfinite(v).all()) for v in (x, p, n, l)):
        raise ValueError("points, plane_point, plane_normal and light must be finite (no NaN or inf)")
    if _is_zero(n) or _is_zero(l):
        raise ValueError("plane_normal and light must be non-zero vectors")
    n_hat = unit(n)
    cos = n_hat @ l
    if abs(float((n_hat @ unit(l)).detach())) <= GRAZING:
        raise ValueError("the light is parallel to the plane (n · l = 0): it casts no shadow on it")
    h = (x - p) @ n_hat                                                     # (N,) heights above the plane
    return x - (h / cos)[:, None] * l


def _subtract(piece, D, n_hat, tol):
    """piece (K, 3) minus the convex D (M, 3), both convex and in one plane of unit normal n_hat:
    (outside pieces, the inside piece or None). The outside pieces are disjoint convex polygons."""
    outside = []
    rest = piece
    for i in range(D.shape[0]):
        edge = D[(i + 1) % D.shape[0]] - D[i]
        m = torch.linalg.cross(n_hat, edge, dim=0)
        m = m / m.norm()                                                    # unit, pointing into D
        s = (rest - D[i]) @ m                                               # (K,) signed distances
        sd = s.detach()
        if bool((sd >= -tol).all()):
            continue                                                        # all inside this half-plane
        if bool((sd <= tol).all()):
            return outside + [rest], None                                   # a line separates them
        part = _clip(rest, -s, tol)
        if part.shape[0] >= 3:
            outside.append(part)
        rest = _clip(rest, s, tol)
        if rest.shape[0] < 3:
            return outside, None
    return outside, rest


def _face_pieces(v, f, light: _Light, tol):
    """The lit and shadowed convex pieces of face f: (list of (K, 3), list of (K, 3)). v: (F, 3, 3)."""
    tri = v[f]
    n = torch.linalg.cross(tri[1] - tri[0], tri[2] - tri[0], dim=0)
    size = n.norm()
    if float(size.detach()) == 0:
        return [], []                                                       # a degenerate face shows nothing
    n_hat = n / size
    if light.position is None:
        cos = n_hat @ light.to_light                                        # n̂ · l
        facing = float(cos.detach()) > GRAZING
    else:
        cos = n_hat @ (light.position - tri[0])                             # the light's height above the plane
        facing = float(cos.detach()) > GRAZING * float((light.position - tri[0]).detach().norm())
    if not facing:
        return [], [tri]                                                    # turned away: all in shadow
    lit, shadow = [tri], []
    for g in range(v.shape[0]):
        if g == f or not lit:
            continue
        D = _shadow_polygon(v[g], tri[0], n_hat, light, cos, tol)
        if D is None:
            continue
        still_lit = []
        for piece in lit:
            out, inside = _subtract(piece, D, n_hat, tol)
            still_lit += out
            if inside is not None:
                shadow.append(inside)
        lit = still_lit
    return lit, shadow


# ------------------------------------------------------------------------------- the conforming split mesh

def _merge(points, tol):
    """(N,) ids of one representative per group of points closer than tol (max norm), and the group count.
    Compares all pairs: N² bytes, fine for the few thousand corners of a small scene."""
    p = points.detach()
    close = (p[:, None, :] - p[None, :, :]).abs().amax(-1) <= tol          # (N, N)
    first = close.to(torch.int8).argmax(1)                                  # the first point close to each
    first = first[first]                                                    # follow one step: chains of two
    ids, inverse = torch.unique(first, return_inverse=True)
    return inverse, ids.shape[0]


def _insert_on_edges(polys, U, tol):
    """Each polygon (a list of vertex ids into U (N, 3)) with every vertex of U that lies strictly inside one
    of its edges inserted there, in order along the edge: no T-junctions."""
    P = U.detach()
    out = []
    for ids in polys:
        new = []
        for k in range(len(ids)):
            a, b = ids[k], ids[(k + 1) % len(ids)]
            new.append(a)
            e = P[b] - P[a]
            length2 = float(e @ e)
            if length2 == 0:
                continue
            t = (P - P[a]) @ e / length2                                    # (N,) along the edge
            dist = (P - P[a] - t[:, None] * e).abs().amax(1)               # (N,) off the edge's line
            inner = tol / length2 ** 0.5
            hit = ((dist <= tol) & (t > inner) & (t < 1 - inner)).nonzero().squeeze(1)
            hit = [int(i) for i in hit[torch.argsort(t[hit])] if int(i) not in (a, b)]
            new += hit
        out.append(new)
    return out


VIEW_MARGIN = 2.0        # pixels: ``split_by_shadows(..., view=camera)`` keeps the pieces up to this far outside


def _view_lines(camera, margin):
    """The view's four sides pushed ``margin`` pixels out, as linear functions of world points: each of the
    (4,) values ``s(P) = a · P + b`` is >= 0 inside. For a perspective camera ``x_pixel >= -m`` is
    ``fx X + (cx + m) Z >= 0`` in camera space (Z > 0); orthographic, ``fx X + cx + m >= 0``. (a (4, 3), b (4,),
    detached: the crop is a discrete choice, the image is the same whatever the camera's motion.)"""
    K, R, t = (x.detach().double() for x in (camera.K, camera.R, camera.t))
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    W, H, m = camera.width, camera.height, margin
    if camera.orthographic:                                                 # rows over (X, Y, 1) in camera space
        rows = torch.stack([torch.stack([fx, 0 * fx, cx + m]), torch.stack([-fx, 0 * fx, W + m - cx]),
                            torch.stack([0 * fy, fy, cy + m]), torch.stack([0 * fy, -fy, H + m - cy])])
        a = rows[:, :2] @ R[:2]
        b = rows[:, :2] @ t[:2] + rows[:, 2]
    else:                                                                   # rows over (X, Y, Z)
        rows = torch.stack([torch.stack([fx, 0 * fx, cx + m]), torch.stack([-fx, 0 * fx, W + m - cx]),
                            torch.stack([0 * fy, fy, cy + m]), torch.stack([0 * fy, -fy, H + m - cy])])
        a = rows @ R
        b = rows @ t
    return a, b


def _crop(poly, camera, lines, tol):
    """The part of the piece (K, 3) within the view plus its margin, or None; a piece not wholly in front of
    a perspective camera's centre is kept whole (the lines only hold for Z > 0)."""
    a, b = lines
    if not camera.orthographic:
        z = poly.detach() @ camera.R.detach().double()[2] + float(camera.t.detach()[2])
        if bool((z <= 0).any()):
            return poly
    for k in range(4):
        poly = _clip(poly, poly @ a[k] + b[k], tol)
        if poly.shape[0] < 3:
            return None
    return poly


def _diameter(poly) -> float:
    """The largest distance between two corners of a piece (K, 3). Pieces below 1e-6 of the scene's size are
    dropped (an area below 1e-12 of it): their fan apex could lie within ``boundary``'s welding tolerance of
    their corners, and a welded pair would be counted as one point twice."""
    p = poly.detach()
    return float((p[:, None] - p[None]).norm(dim=-1).max())


def split_by_shadows(mesh, light, *, point: bool = False, view=None) -> SplitMesh:
    """Cut every face into lit and shadowed triangles (module docstring: the exact answer).

    mesh: ``verts`` (V, 3) world space, ``faces`` (F, 3); light: (3,) the direction the light travels, or
    with ``point=True`` a point light's position (outside the mesh's bounding box). view: a ``Camera`` or
    None: keep only the parts of the pieces that this camera sees, up to ``VIEW_MARGIN`` pixels outside its
    image (the image and its derivatives are the same; edge sampling then spends no samples off screen).
    Works in float64 whatever the input dtype; differentiable w.r.t. ``mesh.verts`` and ``light``.
    Returns a ``SplitMesh``.
    """
    verts, faces, d = _check_scene(mesh, light, point)
    v64 = verts.double()
    lamp = _Light(None, d.double()) if point else _Light(-unit(d.double()), None)
    v = v64[faces]                                                          # (F, 3, 3)
    extent = float((v64.detach().amax(0) - v64.detach().amin(0)).amax()) if v64.numel() else 1.0
    extent = extent if extent > 0 else 1.0
    polys, source, lit = [], [], []
    lines = None if view is None else _view_lines(view, VIEW_MARGIN)
    for f in range(faces.shape[0]):
        lit_pieces, shadow_pieces = _face_pieces(v, f, lamp, SIDE_TOL * extent)
        for pieces, flag in ((lit_pieces, True), (shadow_pieces, False)):
            for p in pieces:
                if view is not None:
                    p = _crop(p, view, lines, SIDE_TOL * extent)
                if (p is not None and _diameter(p) > 100 * MERGE_TOL * extent    # a speck, or a sliver of no
                        and float(_area_vector(p.detach()).norm()) > (SIDE_TOL * extent) ** 2):   # area: dropped
                    polys.append(p), source.append(f), lit.append(flag)
    dev = verts.device
    if not polys:
        empty = torch.zeros(0, 3, dtype=torch.float64, device=dev)
        none = torch.zeros(0, dtype=torch.int64, device=dev)
        return SplitMesh(empty, torch.zeros(0, 3, dtype=torch.int64, device=dev), none, none.bool())
    points = torch.cat(polys)                                               # (N, 3) every corner of every piece
    group, G = _merge(points, MERGE_TOL * extent)
    count = torch.bincount(group, minlength=G).to(torch.float64)          # (G,) copies per vertex
    U = torch.zeros(G, 3, dtype=torch.float64, device=dev).index_add(0, group, points) / count[:, None]
    sizes = [p.shape[0] for p in polys]
    starts = [sum(sizes[:k]) for k in range(len(sizes))]
    ids = [group[s:s + n].tolist() for s, n in zip(starts, sizes)]
    ids = [[a for k, a in enumerate(poly) if a != poly[k - 1]] for poly in ids]   # merged neighbours: one
    ids = _insert_on_edges(ids, U, 10 * MERGE_TOL * extent)
    centres = torch.stack([points[s:s + n].mean(0) for s, n in zip(starts, sizes)])  # (P, 3) fan apexes
    tris, tri_source, tri_lit = [], [], []
    for k, poly in enumerate(ids):
        c = G + k
        for i in range(len(poly)):
            tris.append([c, poly[i], poly[(i + 1) % len(poly)]])            # keeps the face's winding
            tri_source.append(source[k]), tri_lit.append(lit[k])
    return SplitMesh(torch.cat([U, centres]), torch.tensor(tris, dtype=torch.int64, device=dev),
                     torch.tensor(tri_source, dtype=torch.int64, device=dev),
                     torch.tensor(tri_lit, dtype=torch.bool, device=dev))


# ------------------------------------------------------------------------------------------ the image

def _check_colors(face_colors, F, like):
    c = as_tensor(face_colors, device=like.device, name="face_colors")
    if c.shape != (F, 3):
        raise ValueError(f"face_colors must have shape (F, 3) = ({F}, 3), got {tuple(c.shape)}")
    if not torch.isfinite(c).all():
        raise ValueError("face_colors contains NaN or inf")
    return c


def shadowed_coverage(mesh, camera, face_colors, light, ambient=0.3, background=(0.0, 0.0, 0.0), *,
                      point: bool = False) -> torch.Tensor:
    """The exact box-filtered image of flat-coloured faces with the hard shadows of one light.

    mesh: ``verts`` (V, 3), ``faces`` (F, 3); camera: a ``Camera``; face_colors: (F, 3); light: (3,) the way
    the light travels (or with ``point=True`` a point light's position); ambient: the fraction of its colour a
    shadowed point keeps, in [0, 1]; background: (3,).
    Returns (H, W, 3) in ``promote(verts, camera, face_colors)``: ``exact_coverage`` of the split mesh
    (``split_by_shadows``). Differentiable w.r.t. verts, light, face_colors, ambient (a tensor) and the camera.
    """
    split = split_by_shadows(mesh, light, point=point, view=camera)
    colors = _check_colors(face_colors, torch.as_tensor(mesh.faces).shape[0], split.verts)
    ambient = _check_ambient(ambient)
    dtype = torch.promote_types(torch.promote_types(as_tensor(mesh.verts).dtype, camera.dtype), colors.dtype)
    return exact_coverage(Mesh(split.verts.to(dtype), split.faces), camera,
                          split.colors(colors.to(dtype), ambient), background)


def _camera_with(camera, R, t, K):
    return Camera(K, R, t, camera.width, camera.height, camera.near, camera.far, camera.orthographic)


def shadow_image_gradient(mesh, camera, face_colors, light, weights, *, method, ambient=0.3,
                          background=(0.0, 0.0, 0.0), point: bool = False, wrt=("verts",), **options):
    """The gradient of ``L = Σ weights ⊙ shadowed_coverage(...)`` by one of ``SHADOW_METHODS``.

    mesh, camera, face_colors, light, ambient, background, point: as ``shadowed_coverage``; weights: (H, W, 3).
    wrt: names among "verts" ((V, 3)), "light" ((3,): the direction, or the point light's position),
    "R" ((3, 3)), "t" ((3,)); a tuple comes back in that order (the split does not depend on the camera: R and
    t come straight from ``image_gradient`` of the split mesh; finite differences do not take R).
    options: finite_differences: ``step`` (1e-6, world units), ``vertices`` (rows to compute, the others NaN);
    reynolds: ``order``; edge_sampling: ``samples``, ``seed`` (0 by default). Returns gradients in the
    scene's dtype. The method's cost: exact and reynolds about one image each (the split included),
    finite differences two images per entry.
    """
    if method not in SHADOW_METHODS:
        raise ValueError(f"method must be one of {', '.join(SHADOW_METHODS)}, got {method!r}")
    names = tuple(wrt)
    if not names or any(n not in ("verts", "light", "R", "t") for n in names) or len(set(names)) != len(names):
        raise ValueError(f"wrt must name some of verts, light, R, t, each once, got {wrt!r}")
    verts, faces, d = _check_scene(mesh, light, point)
    colors = _check_colors(face_colors, faces.shape[0], verts)
    w = as_tensor(weights, name="weights")
    if w.shape != (camera.height, camera.width, 3):
        raise ValueError(f"weights must have shape (H, W, 3) = ({camera.height}, {camera.width}, 3), "
                         f"got {tuple(w.shape)}")
    ambient = _check_ambient(ambient)
    params = {"verts": verts.detach().clone(), "light": d.detach().clone(),
              "R": camera.R.detach().clone(), "t": camera.t.detach().clone()}

    def loss(p):
        cam = _camera_with(camera, p["R"], p["t"], camera.K)
        image = shadowed_coverage(Mesh(p["verts"], faces), cam, colors, p["light"], ambient, background,
                                  point=point)
        return (image * w.to(image.dtype)).sum()

    if method == "exact" and options:
        raise TypeError(f"method='exact' takes no options, got {', '.join(options)}")
    if method == "exact":
        leaves = {k: v.requires_grad_(k in names) for k, v in params.items()}
        grads = torch.autograd.grad(loss(leaves), [leaves[n] for n in names], allow_unused=True)
        return tuple(torch.zeros_like(leaves[n]) if g is None else g for n, g in zip(names, grads))
    if method == "finite_differences":
        return _fd_gradient(loss, params, names, options.pop("step", 1e-6), options.pop("vertices", None))
    # reynolds / edge_sampling: the boundary term of the split mesh, chained back through the split
    _check_not_aligned(camera, d, point, verts)
    v_leaf = params["verts"].requires_grad_("verts" in names)
    l_leaf = params["light"].requires_grad_("light" in names)
    split = split_by_shadows(Mesh(v_leaf, faces), l_leaf, point=point, view=camera)
    dtype = torch.promote_types(verts.dtype, camera.dtype)
    split_mesh = Mesh(split.verts.detach().to(dtype), split.faces)
    cam_names = tuple(n for n in names if n in ("R", "t"))
    opts = dict(options)
    if method == "edge_sampling" and "seed" not in opts:
        opts["seed"] = 0
    g = image_gradient(split_mesh, camera, split.colors(colors.detach().to(dtype), ambient), w.to(dtype),
                       method=method, background=background, wrt=("verts",) + cam_names, **opts)
    g_split, g_cam = g[0], dict(zip(cam_names, g[1:]))
    wanted = [n for n in ("verts", "light") if n in names]
    chained = {}
    if wanted and split.verts.requires_grad:
        leaves = [params[n] for n in wanted]
        back = torch.autograd.grad(split.verts, leaves, grad_outputs=g_split.to(torch.float64), allow_unused=True)
        chained = {n: (torch.zeros_like(params[n]) if b is None else b.to(params[n].dtype))
                   for n, b in zip(wanted, back)}
    result = []
    for n in names:
        result.append(g_cam[n] if n in g_cam else chained.get(n, torch.zeros_like(params[n])))
    return tuple(result)


# ------------------------------------------------------------------------------- the ray-traced reference

def _check_not_aligned(camera, d, point, verts):
    """Refuse the boundary methods where the camera looks along the light within ``ALIGNED`` rad (module
    docstring): an orthographic camera and a directional light, or a perspective camera at a point light (the
    angle: the distance between them over the nearest scene vertex's distance)."""
    if bool(camera.orthographic) == bool(point):
        return                                                              # aligned along one ray at most
    if camera.orthographic:
        forward = camera.R.detach().double()[2]
        sine = float(torch.linalg.cross(forward, unit(d.detach().double()), dim=0).norm())
    else:
        eye = camera.eye.detach().double()
        reach = float((verts.detach().double() - eye).norm(dim=1).min()) if verts.numel() else 1.0
        sine = float((eye - d.detach().double()).norm()) / max(reach, 1e-300)
    if sine < ALIGNED:
        raise ValueError(f"the camera looks along the light ({sine:.1e} rad off, below ALIGNED = {ALIGNED:g}): an "
                         f"occluder's silhouette and its own shadow's edge meet on screen, and the boundary methods "
                         f"would count that jump twice; use method='exact' (autograd through the closed form)")


def _fd_gradient(loss, params, names, step, vertices):
    """Central differences ``(L(π + h) - L(π - h)) / 2h``, one entry at a time, on the closed-form image.
    ``vertices``: the vertex rows to compute (others NaN), for large meshes; R is not offered (a step off
    the rotations); every other name is all of its entries."""
    if "R" in names:
        raise ValueError("finite_differences does not take wrt='R' (a step in one entry leaves the rotations); "
                         "use 'reynolds' or 'exact' for R")
    if not (isinstance(step, float) and 0 < step < 1):
        raise ValueError(f"step must be a float in (0, 1), got {step!r}")
    out = []
    with torch.no_grad():
        for n in names:
            g = torch.zeros_like(params[n])
            rows = range(g.shape[0]) if n != "verts" or vertices is None else [int(i) for i in vertices]
            if n == "verts" and vertices is not None:
                g.fill_(float("nan"))
            for idx in (r * 3 + k for r in rows for k in range(3)) if n == "verts" else range(g.numel()):
                plus = {k: v.clone() for k, v in params.items()}
                minus = {k: v.clone() for k, v in params.items()}
                plus[n].view(-1)[idx] += step
                minus[n].view(-1)[idx] -= step
                g.view(-1)[idx] = (loss(plus) - loss(minus)) / (2 * step)
            out.append(g)
    return tuple(out)


def shadow_raytrace(mesh, camera, face_colors, light, ambient=0.3, background=(0.0, 0.0, 0.0),
                    supersample: int = 8, *, point: bool = False) -> torch.Tensor:
    """The same image by ray tracing: ``supersample``² primary rays per pixel (a regular grid, ``raycast`` on
    a camera with ``supersample`` times the resolution), one shadow ray per hit (``raytrace.visible`` with the
    faces' front normals, so a face turned away from the light is shadowed; it starts 2^-40 of the scene's
    largest coordinate above the surface, enough to clear rounding and too little to shift a grazing shadow),
    box-averaged. (H, W, 3) float64. The reference ``shadowed_coverage`` converges to as ``supersample`` grows."""
    from ..raytrace import BVH, raycast, visible                             # the reference only
    verts, faces, d = _check_scene(mesh, light, point)
    s = int(supersample)
    if s < 1:
        raise ValueError(f"supersample must be a positive integer, got {supersample!r}")
    cam = camera.to(dtype=torch.float64)
    K = cam.K.clone()
    K[:2] *= s                                                              # pixel (j, i) → s × s sub-pixels
    big = Camera(K, cam.R, cam.t, cam.width * s, cam.height * s, cam.near, cam.far, cam.orthographic)
    m = Mesh(verts.detach().double(), faces)
    bvh = BVH(m)
    frags = raycast(m, big, bvh=bvh)
    fid = frags.face_id.reshape(-1)
    hit = fid >= 0
    tri = m.verts[faces[fid[hit]]]                                          # (N, 3, 3)
    points = (frags.bary.reshape(-1, 3)[hit][:, :, None] * tri).sum(1)      # (N, 3) world
    normals = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], dim=1)
    lamp = d.detach().double()
    to_light = (lamp - tri[:, 0]) if point else -unit(lamp)                 # (N, 3) or (3,)
    cos = ((normals / normals.norm(dim=1, keepdim=True)) * to_light).sum(1)
    facing = cos > GRAZING * (to_light.norm(dim=-1) if point else 1.0)
    # the shadow ray starts above the surface by 2^-40 of the scene's largest coordinate: ~4000 roundings of a
    # hit point's height, so it never meets its own face, and no more: an offset moves a shadow edge by
    # offset / tan(elevation) and skips occluders closer than it (``visible``'s default, 1e-4 of the diagonal,
    # left a floater 1e-5 above a floor lit 1e-4 rad above the horizon 0.25 off at any sample count)
    offset = 2.0 ** -40 * max(float(m.verts.abs().max()), float(points.abs().max()) if points.numel() else 0.0)
    sees = visible(points, lamp, bvh, directional=not point, normals=normals, offset=offset or None) & facing
    c = as_tensor(face_colors, dtype=torch.float64, name="face_colors")[fid[hit]]
    c = torch.where(sees[:, None], c, float(ambient) * c)
    image = as_tensor(background, dtype=torch.float64, name="background").expand(fid.shape[0], 3).clone()
    image[hit] = c
    H, W = camera.height, camera.width
    return image.view(H, s, W, s, 3).mean((1, 3))
