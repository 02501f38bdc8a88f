"""Rasterization: from triangles to the visible face, barycentrics and depth of every pixel (lecture 03).

The pipeline of ``rasterize`` in four named stages::

    verts_world ─▶ camera space ─▶ clip, cull, project ─▶ scan-line coverage + z-buffer ─▶ Fragments
                                  (_screen_triangles)     (course.scan: _scan_convert,   (_visible_surface)
                                                           _zbuffer; _sample_zbuffer)

Stage 2, coverage and the z-buffer, lives in ``course.scan`` (the edge functions, scan conversion, and the
sub-pixel samples of lecture 05); this module holds the other stages, the public ``rasterize`` and the
lecture's building blocks.

* **Coverage** is decided in screen space with edge functions (``edge_function``) and the top-left fill
  rule, so a pixel centre on an edge shared by two triangles is covered exactly once (watertight).
  The fast path walks each triangle row by row (scan conversion): per covered row it solves the three edge
  inequalities for the span of covered pixel centres and enumerates only those pixels. The crossing of a
  shared edge is computed bit-identically by both of its triangles, so no centre is lost or counted twice.
  ``rasterize_naive`` runs the per-pixel edge test over whole bounding boxes; the two agree except for
  centres within rounding error (about 1e-12 pixel) of an edge, and the tests hold them to each other.
* **Visibility** is one bulk z-buffer: every covered pixel writes a packed 64-bit key
  ``(float32 depth bits << 32) | face id`` and a single scatter-min keeps the nearest. float32 keys alone would
  confuse surfaces closer than a few float32 steps (relative depth ~1e-7), so pixels where two keys come
  within 4 float32 steps are decided again by float64 depth (``scan._NearTies``): the visible face is the
  nearest in float64, as ``raycast`` and ``coverage.exact_coverage`` find it. Depths equal to float64
  rounding (1e-12 relative: coplanar faces) are a tie and go to the lower face id, deterministically.
* **Perspective-correct barycentrics and depth** are computed last, only for the visible face of each pixel,
  by intersecting the pixel's ray with that face in camera space (Cramer's rule on the face's edges, written
  so that float32 stays accurate on sub-pixel triangles and far from the origin). This stage is written in plain
  differentiable torch, so gradients flow to the vertex positions and to the camera (K, R, t).

Triangles crossing the near plane are clipped in camera space (not dropped), triangles behind the camera
never appear, and the far plane clips per pixel. Work is chunked so memory stays bounded.

**Compiled twins.** On CPU tensors stages 1 and 2 run as compiled loops (``course.kernels``: ``screen``,
``zbuffer``), and so does stage 3 where no gradient is recorded (``surface``); each gives the numbers of the
torch code here, bit for bit, which CUDA tensors and ``course.kernels.using("torch")`` run. Wherever a
gradient is recorded, stage 3 is the torch code, so autograd sees every step.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from . import kernels
from .camera import Camera, world_to_camera
from .scan import (EMPTY_KEY, _ScreenTriangles, _depth_keys, _faces_of, _is_top_left, _max3, _min3, _nearest,
                   _sample_zbuffer, _zbuffer, edge_function, pixel_triangle_pairs)
from .tensors import _as_faces, _as_index, _check_count, _check_finite, _check_flag, _check_real, as_tensor

__all__ = [
    "Fragments", "rasterize", "rasterize_naive", "interpolate", "edge_function", "inside_triangle",
    "barycentric_2d", "perspective_correct_bary", "zbuffer_resolve", "clip_polygon_near", "pixel_triangle_pairs",
]

@dataclass(frozen=True)
class Fragments:
    """What a visibility stage (rasterizer or ray tracer) hands to shading. One entry per pixel.

    face_id: (H, W) int64, index of the visible face, -1 where nothing is hit.
    bary:    (H, W, 3) perspective-correct barycentric weights of the visible face's three vertices
             (the weights of the 3D hit point); 0 where nothing is hit. Differentiable.
    depth:   (H, W) camera-space z of the visible surface, +inf where nothing is hit. Differentiable.
    """
    face_id: torch.Tensor
    bary: torch.Tensor
    depth: torch.Tensor

    @property
    def mask(self) -> torch.Tensor:
        """(H, W) bool, True where a face is visible."""
        return self.face_id >= 0

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.face_id.shape)


# ------------------------------------------------------------------------------ the lecture's building blocks

def _oriented(tri: torch.Tensor):
    """Triangles (..., 3, 2) reordered so that their area (edge function of v2) is positive, and that area."""
    area = edge_function(tri[..., 0, :], tri[..., 1, :], tri[..., 2, :])
    flip = area < 0
    tri = torch.where(flip[..., None, None], tri[..., [0, 2, 1], :], tri)
    return tri, area.abs(), flip


def inside_triangle(tri, points) -> torch.Tensor:
    """Which points are covered by the triangle, with the top-left fill rule.

    tri: (3, 2) image coordinates, either winding; points: (N, 2). Returns (N,) bool. A point exactly on an
    edge counts only if the edge is a top or left edge; a zero-area triangle covers nothing.
    """
    tri = as_tensor(tri, name="tri")
    points = as_tensor(points, dtype=tri.dtype, device=tri.device, name="points")
    if tri.shape != (3, 2) or points.dim() != 2 or points.shape[1] != 2:
        raise ValueError(f"expected tri (3, 2) and points (N, 2), got {tuple(tri.shape)} and {tuple(points.shape)}")
    _check_finite(tri, "tri"), _check_finite(points, "points")
    tri, area, _ = _oriented(tri)
    inside = torch.ones(points.shape[0], dtype=torch.bool, device=points.device) & (area > 0)
    for k in range(3):
        a, b = tri[k], tri[(k + 1) % 3]
        e = edge_function(a, b, points)                                     # (N,)
        inside &= (e > 0) | ((e == 0) & _is_top_left(a, b))
    return inside


def barycentric_2d(tri, points) -> torch.Tensor:
    """Screen-space barycentric coordinates of points with respect to a triangle.

    tri: (3, 2); points: (N, 2). Returns (N, 3) weights ``w`` with ``Σ w_k tri[k] = p`` and ``Σ w_k = 1``:
    ``w_0 = E(v1, v2, p) / E(v0, v1, v2)`` and so on. A zero-area triangle gives 1/3 each (finite, not NaN).
    """
    tri = as_tensor(tri, name="tri")
    points = as_tensor(points, dtype=tri.dtype, device=tri.device, name="points")
    if tri.shape != (3, 2) or points.dim() != 2 or points.shape[1] != 2:
        raise ValueError(f"expected tri (3, 2) and points (N, 2), got {tuple(tri.shape)} and {tuple(points.shape)}")
    _check_finite(tri, "tri"), _check_finite(points, "points")
    v0, v1, v2 = tri
    area = edge_function(v0, v1, v2)
    w = torch.stack([edge_function(v1, v2, points), edge_function(v2, v0, points),
                     edge_function(v0, v1, points)], -1)                    # (N, 3)
    if area == 0:
        return torch.full_like(w, 1 / 3)
    return w / area


def perspective_correct_bary(bary_screen, z) -> torch.Tensor:
    """Perspective-correct barycentrics from screen-space ones: ``w_k ∝ b_k / z_k``.

    bary_screen: (N, 3) weights interpolated linearly on screen; z: (N, 3) camera depths of the three vertices
    (or (3,)). Screen-space interpolation is affine in 1/z, not in z, which is why texture checks bend without
    this correction. Returns (N, 3) summing to 1.
    """
    b = as_tensor(bary_screen, name="bary_screen")
    z = as_tensor(z, dtype=b.dtype, device=b.device, name="z")
    if b.dim() != 2 or b.shape[1] != 3:
        raise ValueError(f"bary_screen must have shape (N, 3), got {tuple(b.shape)}")
    if z.shape != (3,) and z.shape != b.shape:
        raise ValueError(f"z must have shape (N, 3) like bary_screen, or (3,), got {tuple(z.shape)}")
    _check_finite(b, "bary_screen"), _check_finite(z, "z")
    if bool((z == 0).any()):
        raise ValueError("z holds a zero depth: a vertex in the camera's plane (z = 0) has no perspective "
                         "projection; clip the triangle at the near plane first")
    w = b / z
    s = w.sum(-1, keepdim=True)
    return w / torch.where(s == 0, torch.ones_like(s), s)


def zbuffer_resolve(pixel_index, depth, face_id, num_pixels: int):
    """The z-buffer in bulk: for every pixel keep the fragment with the smallest depth.

    pixel_index: (M,) int64 flat pixel of each fragment; depth: (M,); face_id: (M,) int64 in [0, 2³¹).
    Returns ``face_map`` (P,) int64 (-1 where no fragment) and ``depth_map`` (P,) (+inf where none), with
    P = num_pixels. Ties go to the lower face id. Depths are compared as float32 (the packed key of the
    lecture); non-finite ones are ignored. (``rasterize`` packs the same keys, then re-decides near-ties, keys
    within 4 float32 steps, in float64.)
    """
    num_pixels = _check_count(num_pixels, "num_pixels", minimum=0)
    depth = as_tensor(depth, name="depth")
    pixel_index = _as_index(pixel_index, "pixel_index", device=depth.device)
    face_id = _as_index(face_id, "face_id", device=depth.device)
    if not (pixel_index.shape == depth.shape == face_id.shape) or depth.dim() != 1:
        raise ValueError("pixel_index, depth and face_id must be 1-D and the same length, got shapes "
                         f"{tuple(pixel_index.shape)}, {tuple(depth.shape)}, {tuple(face_id.shape)}")
    if pixel_index.numel() and (pixel_index.min() < 0 or pixel_index.max() >= num_pixels):
        raise ValueError(f"pixel_index must lie in [0, {num_pixels}), got values up to {int(pixel_index.max())}")
    if face_id.numel() and (face_id.min() < 0 or face_id.max() >= 2**31):
        raise ValueError("face_id must lie in [0, 2**31)")
    ok = torch.isfinite(depth)
    keys = _depth_keys(depth[ok], face_id[ok])
    zbuf = torch.full((num_pixels,), EMPTY_KEY, dtype=torch.int64, device=depth.device)
    zbuf.scatter_reduce_(0, pixel_index[ok], keys, reduce="amin")
    face_map = _faces_of(zbuf)
    winner = keys == zbuf[pixel_index[ok]]                                  # the fragment each pixel kept
    depth_map = torch.full((num_pixels,), float("inf"), dtype=depth.dtype, device=depth.device)
    depth_map[pixel_index[ok][winner]] = depth[ok][winner]
    return face_map, depth_map


def clip_polygon_near(tri_cam, near: float) -> torch.Tensor:
    """The part of one camera-space triangle in front of the near plane, as a polygon (Sutherland–Hodgman
    against the single plane z = near; ``rasterize`` clips every face this way before it projects).

    tri_cam: (3, 3) camera-space vertices (OpenCV axes: +z forward, depth positive in front); near: > 0.
    Returns (P, 3) in tri_cam's dtype, the polygon's vertices in the triangle's cyclic order (so its winding
    is kept): P = 0 when every vertex is behind (z < near), 3 when all are in front (the triangle itself) or
    one is (a smaller triangle), 4 when two are (a quad, split in two by ``rasterize``). Walk each edge
    a → b: keep a when z_a >= near, and add the edge's crossing when a and b lie on different sides. The
    crossing is interpolated in camera space, where the edge is a straight line (not on screen, where a
    point behind the camera has no image), and its z is set to exactly ``near``.
    """
    tri = as_tensor(tri_cam, name="tri_cam")
    if tri.shape != (3, 3):
        raise ValueError(f"expected one camera-space triangle tri_cam (3, 3), got {tuple(tri.shape)}")
    _check_finite(tri, "tri_cam")
    near = _check_real(near, "near", low=0, low_open=True)
    keep = (tri[:, 2] >= near).tolist()                                     # in front of (or on) the plane
    corner = lambda k: torch.tensor([k], device=tri.device)                 # noqa: E731
    polygon = []
    for a in range(3):
        b = (a + 1) % 3
        if keep[a]:
            polygon.append(tri[a])
        if keep[a] != keep[b]:                                              # the edge crosses z = near
            polygon.append(_clip_point(tri, corner(a), corner(b), near)[0])
    return torch.stack(polygon) if polygon else tri.new_zeros((0, 3))


# ------------------------------------------------------------------------------------------ input checks

def _is_camera(obj) -> bool:
    """A ``course.camera.Camera``, or a copy of that class: re-importing ``course`` (a grader, or Jupyter's
    autoreload) makes a second class of the same name, and its cameras must be accepted too."""
    fields = ("K", "R", "t", "width", "height", "near", "far", "orthographic")
    return isinstance(obj, Camera) or (type(obj).__name__ == "Camera" and all(hasattr(obj, f) for f in fields))


def _check_inputs(mesh, camera):
    if not _is_camera(camera):
        raise TypeError(f"camera must be a course.camera.Camera, got {type(camera).__name__}")
    verts, faces = getattr(mesh, "verts", None), getattr(mesh, "faces", None)
    if verts is None or faces is None:
        raise TypeError(f"mesh must have verts (V, 3) and faces (F, 3), got {type(mesh).__name__}")
    if not isinstance(verts, torch.Tensor):
        raise ValueError(f"mesh.verts must be a (V, 3) torch tensor, got {type(verts).__name__} (a "
                         "course.mesh.Mesh converts arrays for you)")
    if verts.dim() != 2 or verts.shape[1] != 3:
        raise ValueError(f"mesh.verts must have shape (V, 3), got {tuple(verts.shape)}")
    if verts.dtype == torch.bool or verts.is_complex():
        raise TypeError(f"mesh.verts must hold real numbers, got dtype {verts.dtype}")
    if not isinstance(faces, torch.Tensor):
        raise ValueError(f"mesh.faces must be an (F, 3) torch tensor, got {type(faces).__name__} (a "
                         "course.mesh.Mesh converts arrays for you)")
    faces = _as_faces(faces, "mesh.faces", num_verts=verts.shape[0])       # integers only: never rounded
    if faces.shape[0] >= 2**31:
        raise ValueError("at most 2**31 - 1 faces are supported")
    if not torch.isfinite(verts.detach()).all():
        raise ValueError("mesh.verts contains NaN or inf")
    return verts, faces


def _check_views(mesh, camera, shared=()):
    """``_check_inputs`` for a renderer that draws one camera or a batch: ``camera`` is a ``Camera`` or a list
    (or tuple) of them, all of one image size and equal in the attributes named in ``shared`` (such as
    "near", "far", "orthographic": what the renderer takes from one camera for all). Returns verts, faces,
    the cameras as a list and whether a batch was given (a batch of one is still a batch: (1, H, W) out).
    A ValueError names the camera that differs, or the empty list."""
    if not isinstance(camera, (list, tuple)):
        return (*_check_inputs(mesh, camera), [camera], False)
    cameras = list(camera)
    if not cameras:
        raise ValueError("cameras is empty: give a Camera, or a list of at least one")
    for k, c in enumerate(cameras):
        if not _is_camera(c):
            raise TypeError(f"cameras[{k}] must be a course.camera.Camera, got {type(c).__name__}")
    first = cameras[0]
    for k, c in enumerate(cameras[1:], 1):
        if (c.width, c.height) != (first.width, first.height):
            raise ValueError(f"the cameras of a batch must share one image size: cameras[0] is "
                             f"{first.width}x{first.height}, cameras[{k}] is {c.width}x{c.height} (render "
                             "each size in its own call)")
        for name in shared:
            if getattr(c, name) != getattr(first, name):
                raise ValueError(f"the cameras of a batch must share {name}: cameras[0] has "
                                 f"{name}={getattr(first, name)}, cameras[{k}] has {name}={getattr(c, name)}")
    return (*_check_inputs(mesh, first), cameras, True)


def _camera_space(verts, camera):
    """World (V, 3) → camera space in float64, detached: coverage is decided in double precision."""
    return world_to_camera(verts.detach().double(), camera.R.detach().double(), camera.t.detach().double())


# ------------------------------------------------------------------------ stage 1: clip, cull and project

def _clip_point(verts_cam, ia, ib, near):
    """Intersection of the edge (ia, ib) with the plane z = near, computed the same way from either side.

    Ordering the endpoints by vertex index makes the new point bit-identical for the two faces that share
    the edge, which keeps the clipped mesh watertight. ia, ib: (C,) vertex indices. Returns (C, 3).
    """
    lo, hi = torch.minimum(ia, ib), torch.maximum(ia, ib)
    a, b = verts_cam[lo], verts_cam[hi]                                     # (C, 3)
    s = (near - a[:, 2]) / (b[:, 2] - a[:, 2])
    p = a + s[:, None] * (b - a)
    p[:, 2] = near
    return p


def _clip_near(verts_cam, faces, face_ids, near):
    """Clip faces that cross z = near. Returns camera-space triangles (C', 3, 3) and their face ids (C',)."""
    idx = faces[face_ids]                                                   # (C, 3) vertex indices
    inside = verts_cam[idx][..., 2] >= near                                 # (C, 3)
    n_in = inside.sum(1)
    out_tris, out_ids = [], []
    for count in (1, 2):
        sel = n_in == count
        if not sel.any():
            continue
        ids, ins, vi = face_ids[sel], inside[sel], idx[sel]
        lonely = ins if count == 1 else ~ins                                # the vertex on its own side
        k = lonely.long().argmax(1)                                         # (C,) its corner
        roll = (torch.arange(3, device=k.device) + k[:, None]) % 3          # keep the cyclic order
        i0, i1, i2 = vi.gather(1, roll).unbind(1)
        v0, v1, v2 = verts_cam[i0], verts_cam[i1], verts_cam[i2]
        p01, p20 = _clip_point(verts_cam, i0, i1, near), _clip_point(verts_cam, i2, i0, near)
        if count == 1:                                                      # v0 in front: one triangle
            out_tris.append(torch.stack([v0, p01, p20], 1)), out_ids.append(ids)
        else:                                                               # v0 behind: a quad, two triangles
            out_tris += [torch.stack([p01, v1, v2], 1), torch.stack([p01, v2, p20], 1)]
            out_ids += [ids, ids]
    if not out_tris:
        return verts_cam.new_zeros((0, 3, 3)), face_ids[:0]
    return torch.cat(out_tris), torch.cat(out_ids)


def _project(p_cam, camera, K):
    """Camera space (..., 3) → screen (..., 2) and the screen-affine quantity q (...). K: (3, 3), or (N, 3, 3)
    with p_cam (N, M, 3): a batch, each row of points through its own K."""
    z = p_cam[..., 2]
    if camera.orthographic:
        xy1, q = torch.cat([p_cam[..., :2], torch.ones_like(z)[..., None]], -1), z
    else:
        xy1, q = p_cam / z[..., None], 1 / z
    return (xy1 @ K.mT)[..., :2], q


def _cross(a, b):
    """``a × b`` for (..., 3) tensors, written out: ``torch.linalg.cross`` may fuse a multiply and an add on
    one CPU and not on another, and a back-face decision must not depend on it (nor differ from the kernel's)."""
    return torch.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1], a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                        a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], -1)


def _dot(a, b):
    """``a · b`` over the last axis of (..., 3) tensors, summed left to right."""
    return (a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]) + a[..., 2] * b[..., 2]


def _screen_triangles(verts_cam, faces, camera, cull_backfaces, *, reach: float = 0.5) -> _ScreenTriangles:
    """Stage 1: drop faces outside [near, far] or facing away, clip at the near plane, project to pixels.

    reach: how far inside the image a triangle must reach to be kept. 0.5 (pixel centres, for
    ``rasterize``) drops triangles that cover no pixel centre; 0.0 keeps every triangle that touches the
    image rectangle [0, W] x [0, H] at all (sub-pixel samples, exact coverage).
    """
    near, far, W, H = camera.near, camera.far, camera.width, camera.height
    K = camera.K.detach().to(torch.float64)
    F = faces.shape[0]
    xy_v, q_v = _project(verts_cam, camera, K)                              # each vertex projected once
    if kernels.active(verts_cam):                                           # the compiled twin, face by face
        from .kernels.screen import screen_triangles
        xy, q = kernels.buffer((F, 3, 2), torch.float64), kernels.buffer((F, 3), torch.float64)
        face, face_cross = kernels.buffer(F, torch.int64), kernels.buffer(F, torch.int64)
        n, n_cross, crosses_far = screen_triangles(
            verts_cam.contiguous().numpy(), faces.contiguous().numpy(), xy_v.contiguous().numpy(),
            q_v.contiguous().numpy(), float(near), float(far), bool(cull_backfaces), bool(camera.orthographic),
            W, H, float(reach), xy.numpy(), q.numpy(), face.numpy(), face_cross.numpy())
        xy, q, face, face_cross = xy[:n], q[:n], face[:n], face_cross[:n_cross]
        if n_cross:                                                         # clipped in torch, as below
            tri_cam, ids = _clip_near(verts_cam, faces, face_cross, near)
            xy_c, q_c = _project(tri_cam, camera, K)
            xy_c, q_c, ids = _oriented_on_screen(xy_c, q_c, ids, W, H, reach)
            xy, q, face = torch.cat([xy, xy_c]), torch.cat([q, q_c]), torch.cat([face, ids])
        return _ScreenTriangles(xy, q, face, bool(crosses_far))
    flat = faces.reshape(-1)
    z = verts_cam[:, 2].contiguous().index_select(0, flat).view(F, 3)       # (F, 3)
    z_min, z_max = _min3(z), _max3(z)
    keep = (z_max >= near) & (z_min <= far)
    if cull_backfaces:
        v = verts_cam.index_select(0, flat).view(F, 3, 3)
        normal = _cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])               # (F, 3), toward a CCW viewer
        if camera.orthographic:
            keep &= normal[:, 2] < 0
        else:
            keep &= _dot(normal, v[:, 0]) < 0                               # n · (eye - v0) > 0
    whole = keep & (z_min >= near)
    sel = whole.nonzero().squeeze(1) if not bool(whole.all()) else None
    fw = faces if sel is None else faces.index_select(0, sel)
    face = torch.arange(F, device=faces.device) if sel is None else sel
    xy = xy_v.index_select(0, fw.reshape(-1)).view(-1, 3, 2)
    q = q_v.index_select(0, fw.reshape(-1)).view(-1, 3)
    face_cross = (keep & ~whole).nonzero().squeeze(1)
    if face_cross.numel():
        tri_cam, ids = _clip_near(verts_cam, faces, face_cross, near)
        xy_c, q_c = _project(tri_cam, camera, K)
        xy, q, face = torch.cat([xy, xy_c]), torch.cat([q, q_c]), torch.cat([face, ids])
    crosses_far = bool((z_max[keep] > far).any())
    return _ScreenTriangles(*_oriented_on_screen(xy, q, face, W, H, reach), crosses_far)


def _oriented_on_screen(xy, q, face, W, H, reach):
    """Screen triangles xy (T, 3, 2), q (T, 3), face (T,) with corners reordered (v0, v1, v2) → (v0, v2, v1)
    where the screen area is negative, so every area is positive (a selection, not arithmetic: the
    coordinates stay bit-identical to the neighbours' copies), and only those with area that reach
    ``reach`` into the W x H image kept."""
    area = edge_function(xy[:, 0], xy[:, 1], xy[:, 2])
    flip = (area < 0).long()
    order = torch.stack([torch.zeros_like(flip), 1 + flip, 2 - flip], 1)    # (T, 3) corner order
    xy = xy.gather(1, order[:, :, None].expand(-1, -1, 2))
    q = q.gather(1, order)
    x, y = xy[..., 0], xy[..., 1]
    good = (area != 0) & (_max3(x) >= reach) & (_min3(x) <= W - reach)      # zero area: covers nothing
    good &= (_max3(y) >= reach) & (_min3(y) <= H - reach)
    if bool(good.all()):
        return xy, q, face
    good = good.nonzero().squeeze(1)
    return xy.index_select(0, good), q.index_select(0, good), face.index_select(0, good)


# ------------------------------------------------------------- stage 3: the visible surface, differentiably

def _mat3(M, x):
    """``x @ M.T`` for x (..., 3) and M (3, 3), as three multiply-adds in a fixed order: a matrix product
    may sum in another order (or fuse) on another device, and the fragments must not depend on it."""
    return x[..., :1] * M[:, 0] + x[..., 1:2] * M[:, 1] + x[..., 2:] * M[:, 2]


def _visible_surface(face_map, verts, faces, camera, H, W):
    """Perspective-correct barycentrics and depth of the visible face at each covered pixel.

    The pixel's ray ``o + s d`` (camera space) meets the face v0, v1, v2 at the point
    ``v0 + b1 e1 + b2 e2`` with edges ``e1 = v1 - v0``, ``e2 = v2 - v0``. Cramer's rule gives the barycentrics
    as ratios of signed volumes (the Möller–Trumbore form), with ``T = o - v0``::

        b1 = d · (T × e2) / d · (e1 × e2),    b2 = d · (e1 × T) / d · (e1 × e2),    b0 = 1 - b1 - b2

    and the depth as the hit point's z, ``z0 + b1 e1_z + b2 e2_z``. For a pinhole camera ``o = 0`` and
    ``d = K⁻¹ p`` with the pixel centre ``p = (x, y, 1)``; for an orthographic one ``o = (K⁻¹ p)_xy`` and
    ``d = +z``. Either way each numerator is linear in p, so every face turns into three affine functions of
    the pixel's offset to the principal point, ``A (x - cx) + B (y - cy) + C``, and each pixel costs three.

    Why this form (float32 accuracy, ``tests/test_raster_precision.py``): every cross product involves at
    least one *edge*, never two vertex positions, so nothing cancels when a triangle is small and far away
    (``v1 × v2`` of two nearly parallel vectors of length D loses ``D / |e|`` of its digits); the edges are
    differences of world positions, rotated but not translated; ``v0 = R x0 + t`` is formed in float64,
    because far from the origin ``R x0`` and ``t`` are large and nearly cancel; the pixel enters as its
    offset to the principal point; and the depth is ``z0`` plus a small correction, which stays accurate where
    the weights are not. float32 depth then lands within a few float32 epsilons of the float64 result,
    wherever the scene sits. Plain torch, differentiable w.r.t. verts, K, R and t, and no matrix products
    (``_mat3``), so CPU and GPU give the same bits.
    """
    dtype = torch.promote_types(verts.dtype, camera.dtype)
    device = verts.device
    if kernels.active(face_map, verts) and not _records_graph(verts, camera):
        return _kernel_surface(face_map, verts, faces, camera, H, W)        # no gradient: the compiled twin
    pix = (face_map >= 0).nonzero().squeeze(1)                              # (M,) covered pixels
    pix_d = pix.double()
    row = torch.floor((pix_d + 0.5) / W)                                    # exact for any image size
    bary, depth = _surface_at(face_map.index_select(0, pix), pix_d - row * W + 0.5, row + 0.5,
                              verts, faces, camera)
    bary_img = torch.zeros(H * W, 3, dtype=dtype, device=device).index_put((pix,), bary)
    depth_img = torch.full((H * W,), float("inf"), dtype=dtype, device=device).index_put((pix,), depth)
    return bary_img.view(H, W, 3), depth_img.view(H, W)


def _records_graph(verts, camera) -> bool:
    """Would autograd record the surface stage? (a gradient is enabled and verts, K, R or t need one)"""
    return torch.is_grad_enabled() and any(getattr(x, "requires_grad", False)
                                           for x in (verts, camera.K, camera.R, camera.t))


def _kernel_surface(face_map, verts, faces, camera, H, W):
    """``_visible_surface`` by ``kernels.surface.pixel_surface`` where no gradient is recorded: the per-face
    table of the faces some pixel sees (``_kernel_face_table``), then one compiled loop over the pixels. The
    same numbers, bit for bit."""
    from .kernels.surface import pixel_surface
    dtype = torch.promote_types(verts.dtype, camera.dtype)
    fm, row, coef, z = _kernel_face_table(face_map, verts, faces, camera)
    bary, depth = kernels.buffer((H * W, 3), dtype), kernels.buffer(H * W, dtype)   # every pixel written
    K = camera.K.detach().to(dtype)
    xs = torch.arange(W, dtype=torch.float64).add_(0.5).to(dtype) - K[0, 2]   # as _surface_at: x - cx
    ys = torch.arange(H, dtype=torch.float64).add_(0.5).to(dtype) - K[1, 2]
    consts = torch.tensor([1.0, torch.finfo(dtype).tiny ** 0.5], dtype=dtype)
    pixel_surface(fm, row, *(x.contiguous().numpy() for x in (coef, z, xs, ys, consts)), bary.numpy(), depth.numpy())
    return bary.view(H, W, 3), depth.view(H, W)


def _kernel_face_table(face_map, verts, faces, camera):
    """``_face_table`` of the faces some entry of ``face_map`` (any shape, -1: none) shows, by
    ``kernels.surface.face_table``: the same numbers, one compiled loop over the faces (K⁻¹ and 1 - K22 are
    formed here, in torch, as there). Returns the flat face map as numpy, each face's row in the table (F,)
    (-1: unseen), coef (U, 9) and z (U, 3)."""
    from .kernels.surface import face_table, faces_seen
    dtype = torch.promote_types(verts.dtype, camera.dtype)
    fm = face_map.reshape(-1).contiguous().numpy()
    row, n = faces_seen(fm, faces.shape[0])
    used = torch.from_numpy(row >= 0).nonzero().squeeze(1)
    K = camera.K.detach().to(dtype)
    R = camera.R.detach().to(dtype)
    coef = torch.empty(n, 9, dtype=dtype)
    z = torch.empty(n, 3, dtype=dtype)
    scale = torch.tensor([0.0], dtype=dtype)                                # the kernel fills it: _face_table's
    arrays = (used, verts.detach().to(dtype), faces, camera.R.detach().double(), camera.t.detach().double(), R,
              torch.linalg.inv(K).T, (1 - K[2, 2]).reshape(1), scale)
    face_table(*(x.contiguous().numpy() for x in arrays), bool(camera.orthographic), coef.numpy(), z.numpy())
    return fm, row, coef, z


def _surface_at(face, x, y, verts, faces, camera):
    """``_visible_surface`` at arbitrary screen points: face (M,) int64 (all >= 0) and the points' float64
    image coordinates x, y (M,). Returns bary (M, 3) and depth (M,), differentiable."""
    dtype = torch.promote_types(verts.dtype, camera.dtype)
    K = camera.K.to(dtype)
    if faces.shape[0] <= face.numel():                                       # few faces: a table row for each
        used, row_of_face = None, face
    else:                                                                   # many: only faces some pixel sees
        seen = torch.bincount(face, minlength=faces.shape[0]) > 0
        used = seen.nonzero().squeeze(1)                                    # (U,)
        row_of_face = (torch.cumsum(seen, 0) - 1).index_select(0, face)
    coef, z = _face_table(used, verts, faces, camera)
    coef, z = coef.index_select(0, row_of_face), z.index_select(0, row_of_face)   # (M, 9), (M, 3)
    qx = x.to(dtype)[:, None] - K[0, 2]                                     # (M, 1) point x - cx
    qy = y.to(dtype)[:, None] - K[1, 2]                                     # (M, 1) y - cy
    w = coef[:, 0:3] * qx                                                   # (M, 3): w1, w2, Σw
    w += coef[:, 3:6] * qy                                                  # in place: one (M, 3) buffer
    w += coef[:, 6:9]
    del coef, qx, qy                                                        # freed before the next buffers
    tiny = torch.finfo(dtype).tiny ** 0.5
    s = torch.where(w[:, 2].abs() < tiny, torch.full_like(w[:, 2], tiny), w[:, 2])   # edge-on faces: finite
    b1, b2 = w[:, 0] / s, w[:, 1] / s                                       # (M,) each
    bary = torch.stack([1 - b1 - b2, b1, b2], 1)                            # (M, 3)
    depth = z[:, 0] + b1 * z[:, 1] + b2 * z[:, 2]                           # z0 + b1 e1_z + b2 e2_z
    return bary, depth


def _scale_for(m: float) -> float:
    """The power of two that brings a magnitude m (the largest |coordinate| of a computation) near unit size,
    or 1.0 when m already lies within 2^±32 (or is 0 or not finite). A power of two scales every product, sum
    and quotient exactly, so a computation on scaled numbers gives the same bits wherever the unscaled one
    neither overflows nor underflows: float32 scenes at 1e20 (products ~1e40 > 3.4e38: NaN barycentrics) and
    float64 ones beyond 1e154 then do neither."""
    if not 0 < m < math.inf or 2.0 ** -32 <= m <= 2.0 ** 32:
        return 1.0
    return 2.0 ** -math.frexp(m)[1]


def _surface_scale(used, verts, faces, camera) -> float:
    """``_scale_for`` of the camera-space corners of the faces ``used`` (None: all): ``raytrace`` traces a scene
    scaled by it. (``_face_table`` takes its own from the corner and edges it forms anyway.)"""
    if faces.shape[0] == 0:
        return 1.0
    with torch.no_grad():
        corners = verts.detach().double()[faces if used is None else faces.index_select(0, used)].reshape(-1, 3)
        if corners.numel() == 0:
            return 1.0
        m = float((_mat3(camera.R.detach().double(), corners) + camera.t.detach().double()).abs().max())
    return _scale_for(m)


def _face_table(used, verts, faces, camera):
    """Per face (``used`` (U,) ids, or None: every face), the coefficients of its three affine functions of
    the pixel's offset to the principal point, coef (U, 9) = (A1 A2 AΣ, B1 B2 BΣ, C1 C2 CΣ) with
    w_k = A_k (x - cx) + B_k (y - cy) + C_k, and z (U, 3) = (z0, e1_z, e2_z). See ``_visible_surface``."""
    dtype = torch.promote_types(verts.dtype, camera.dtype)
    K, R, t = camera.K.to(dtype), camera.R.to(dtype), camera.t.to(dtype)
    v_world = verts.to(dtype)[faces if used is None else faces.index_select(0, used)]   # (U, 3, 3)
    # camera-space v0 in float64: R x + t cancels digits when the scene sits far from the origin
    v0 = (_mat3(R.double(), v_world[:, 0].double()) + t.double()).to(dtype)   # (U, 3)
    e1 = _mat3(R, v_world[:, 1] - v_world[:, 0])                            # (U, 3) edges, rotated only
    e2 = _mat3(R, v_world[:, 2] - v_world[:, 0])
    # far from unit size (float32 at 1e20, float64 beyond 1e154) the cross products below overflow or underflow:
    # the corner and edges are scaled by a power of two first (``_scale_for``), exactly; (an orthographic
    # camera's rays start at pixel positions in world units: their pairing with the edges is scaled once more)
    with torch.no_grad():
        m = float(torch.stack([v0.abs().amax(), e1.abs().amax(), e2.abs().amax()]).amax()) if v0.numel() else 0.0
    s = _scale_for(m)
    zs = torch.stack([v0[:, 2], e1[:, 2], e2[:, 2]], 1)                     # (U, 3) z0, e1_z, e2_z, unscaled
    if s != 1.0:
        v0, e1, e2 = v0 * s, e1 * s, e2 * s                                 # exact: a power of two
    if camera.orthographic:                                                 # d = +z: only z of each cross
        zero = torch.zeros_like(e1[:, 0])
        c = torch.stack([torch.stack([e2[:, 1], -e2[:, 0], _cross(e2, v0)[:, 2]], -1),
                         torch.stack([-e1[:, 1], e1[:, 0], _cross(v0, e1)[:, 2]], -1),
                         torch.stack([zero, zero, _cross(e1, e2)[:, 2]], -1)], 1)
        if s != 1.0:                                                        # the ray origins' part: scaled too
            c = c * torch.tensor([s, s, 1.0], dtype=c.dtype, device=c.device)
    else:                                                                   # T = -v0
        c = torch.stack([_cross(e2, v0), _cross(v0, e1), _cross(e1, e2)], 1)
    # w_k = c_k · d with d = K⁻¹ p = K⁻¹ q + e3, q = p - K e3 = (x - cx, y - cy, 1 - K22): the offset to the
    # principal point is formed exactly first, so no large terms cancel; per face, w_k = A x' + B y' + C
    rows = _mat3(torch.linalg.inv(K).T, c)                                  # (U, 3, 3): c_k K⁻¹
    const = rows[..., 2] * (1 - K[2, 2]) + c[..., 2]                        # (U, 3)
    coef = torch.cat([rows[..., 0], rows[..., 1], const], 1)                # (U, 9)
    return coef, zs


# --------------------------------------------------------------------------------------------- public API

def rasterize(mesh, camera: Camera, *, cull_backfaces: bool = False, samples=None, pixels=None) -> Fragments:
    """Rasterize a triangle mesh: the visible face, perspective-correct barycentrics and depth per pixel.

    mesh: anything with ``verts`` (V, 3) world space and ``faces`` (F, 3) int64 (a ``course.mesh.Mesh``).
    camera: a ``Camera`` (perspective or orthographic; near and far planes clip).
    cull_backfaces: skip faces whose vertices appear clockwise to the viewer (front faces are CCW).
    Returns ``Fragments`` of shape (H, W). Coverage follows the top-left fill rule. Visibility: the face
    nearest in float64 at the pixel centre (or sample). The z-buffer's keys hold float32 depths; where two of
    a pixel's keys are within 4 float32 steps (relative depth ~5e-7) the float64 depths (each face's 1/z,
    affine on screen, at the point) decide instead, so two surfaces 3.3e-8 apart in relative depth resolve as
    ``raycast`` and ``coverage.exact_coverage`` resolve them. Depths within 1e-12 of each other (relative:
    float64 rounding, coplanar faces) are a tie, which goes to the lower face id; ``raycast`` compares its
    float64 t exactly there and ``exact_coverage`` counts faces within ~2e-9 as coplanar, so below those
    separations the three may differ (``scan.TIE_RTOL``).
    ``bary`` and ``depth`` are differentiable w.r.t. ``mesh.verts`` and the camera's K, R, t;
    the choice of visible face is not (lecture 08: why visibility is not differentiable).

    Sub-pixel samples (lecture 05, supersampling): ``samples`` (S, 2) offsets from each pixel's top-left
    corner, in [0, 1) (the same for every pixel), or (P, S, 2) one set per listed pixel; ``pixels`` None
    (every pixel), an (H, W) bool mask or (P,) flat pixel indices (row-major). With either given, the
    fragments have shape (P, S): row p is the p-th listed pixel (a mask lists its pixels in row-major
    order), column s its sample s (``samples=None`` then means the pixel centre, S = 1). Coverage and
    visibility of a sample depend on its position alone, so asking for a subset of pixels gives
    bit-identical face ids to asking for all of them. (This path tests every sample against the triangles
    touching its pixel; at the pixel centre it agrees with the scan-line path except within rounding of an
    edge.)
    """
    verts, faces = _check_inputs(mesh, camera)
    cull_backfaces = _check_flag(cull_backfaces, "cull_backfaces")
    H, W = camera.height, camera.width
    if samples is not None or pixels is not None:
        pixels, offsets = _check_samples(samples, pixels, H, W, verts.device)
        with torch.no_grad():
            st = _screen_triangles(_camera_space(verts, camera), faces, camera, cull_backfaces, reach=0.0)
            face_map = _sample_zbuffer(st, camera, pixels, offsets)         # (P, S)
        return _sample_fragments(face_map, pixels, offsets, verts, faces, camera)
    with torch.no_grad():                                                   # discrete decisions: no graph
        st = _screen_triangles(_camera_space(verts, camera), faces, camera, cull_backfaces)
        face_map = _zbuffer(st, camera)                                     # (H*W,)
    bary, depth = _visible_surface(face_map, verts, faces, camera, H, W)
    return Fragments(face_map.view(H, W), bary, depth)


def _check_samples(samples, pixels, H, W, device):
    """Validate ``rasterize``'s sample arguments: (P,) int64 pixels and float64 offsets (S, 2) or (P, S, 2)."""
    if pixels is None:
        pixels = torch.arange(H * W, device=device)
    else:
        pixels = torch.as_tensor(pixels, device=device)
        if pixels.dtype == torch.bool:
            if tuple(pixels.shape) != (H, W):
                raise ValueError(f"a pixel mask must have shape (H, W) = ({H}, {W}), got {tuple(pixels.shape)}")
            pixels = pixels.reshape(-1).nonzero().squeeze(1)
        elif pixels.dim() != 1 or pixels.dtype.is_floating_point:
            raise ValueError(f"pixels must be an (H, W) bool mask or (P,) integer indices, got "
                             f"{pixels.dtype} {tuple(pixels.shape)}")
        pixels = pixels.long()
        if pixels.numel() and (int(pixels.min()) < 0 or int(pixels.max()) >= H * W):
            raise ValueError(f"pixel indices must lie in [0, {H * W}), got values in "
                             f"[{int(pixels.min())}, {int(pixels.max())}]")
        if pixels.numel() != torch.unique(pixels).numel():
            raise ValueError("pixels lists a pixel more than once")
    if samples is None:
        offsets = torch.full((1, 2), 0.5, dtype=torch.float64, device=device)
    else:
        offsets = as_tensor(samples, dtype=torch.float64, device=device, name="samples")
        shape_ok = (offsets.dim() == 2 or (offsets.dim() == 3 and offsets.shape[0] == pixels.numel()))
        if not shape_ok or offsets.shape[-1] != 2 or offsets.shape[-2] == 0:
            raise ValueError(f"samples must have shape (S, 2) or (P, S, 2) with P = {pixels.numel()} listed "
                             f"pixels, got {tuple(offsets.shape)}")
        if offsets.numel() and (not torch.isfinite(offsets).all() or offsets.min() < 0 or offsets.max() > 1):
            raise ValueError("sample offsets must be finite and lie in [0, 1] (from the pixel's top-left corner)")
    return pixels, offsets


def _sample_fragments(face_map, pixels, offsets, verts, faces, camera) -> Fragments:
    """Fragments (P, S) of the sample z-buffer: barycentrics and depth at every covered sample."""
    P, S = face_map.shape
    W = camera.width
    dtype = torch.promote_types(verts.dtype, camera.dtype)
    flat = face_map.reshape(-1)
    if kernels.active(flat, verts) and not _records_graph(verts, camera):  # no gradient: the compiled twin
        from .kernels.surface import sample_surface
        fm, row, coef, z = _kernel_face_table(flat, verts, faces, camera)
        bary, depth = kernels.buffer((P * S, 3), dtype), kernels.buffer(P * S, dtype)
        K = camera.K.detach().to(dtype)
        per_pixel = offsets.dim() == 3
        off = (offsets if per_pixel else offsets[None]).contiguous()
        small = [x.contiguous().numpy() for x in (K[:2, 2], torch.tensor([1.0, torch.finfo(dtype).tiny ** 0.5],
                                                                          dtype=dtype), torch.zeros(2, dtype=dtype))]
        sample_surface(fm, row, coef.numpy(), z.numpy(), pixels.contiguous().numpy(), off.numpy(), per_pixel, W,
                       *small, bary.numpy(), depth.numpy())
        return Fragments(face_map, bary.view(P, S, 3), depth.view(P, S))
    hit = (flat >= 0).nonzero().squeeze(1)                                  # (M,) covered samples
    p, s = hit // S, hit % S
    pix = pixels.index_select(0, p)
    off = offsets[s] if offsets.dim() == 2 else offsets[p, s]               # (M, 2)
    x = (pix % W).double() + off[:, 0]
    y = (pix // W).double() + off[:, 1]
    bary, depth = _surface_at(flat.index_select(0, hit), x, y, verts, faces, camera)
    bary_img = torch.zeros(P * S, 3, dtype=dtype, device=verts.device).index_put((hit,), bary)
    depth_img = torch.full((P * S,), float("inf"), dtype=dtype, device=verts.device).index_put((hit,), depth)
    return Fragments(face_map, bary_img.view(P, S, 3), depth_img.view(P, S))


def rasterize_naive(mesh, camera: Camera, *, cull_backfaces: bool = False) -> Fragments:
    """The same result the slow, obvious way: for each triangle test every pixel of its bounding box.

    A Python loop over triangles calling ``inside_triangle`` — the lecture's first rasterizer and the
    reference the fast path is tested against. Visibility compares the fragments' float64 depths (within
    1e-12 relative a tie, to the lower face id), which is what ``rasterize``'s refined z-buffer computes.
    Use small images.
    """
    verts, faces = _check_inputs(mesh, camera)
    cull_backfaces = _check_flag(cull_backfaces, "cull_backfaces")
    H, W = camera.height, camera.width
    with torch.no_grad():
        st = _screen_triangles(_camera_space(verts, camera), faces, camera, cull_backfaces)
        pixels, depths, ids = [], [], []
        for tri, q, face in zip(st.xy, st.q, st.face):
            x0, x1 = int(tri[:, 0].min().floor().clamp(0, W - 1)), int(tri[:, 0].max().ceil().clamp(0, W - 1))
            y0, y1 = int(tri[:, 1].min().floor().clamp(0, H - 1)), int(tri[:, 1].max().ceil().clamp(0, H - 1))
            rows, cols = torch.meshgrid(torch.arange(y0, y1 + 1), torch.arange(x0, x1 + 1), indexing="ij")
            centres = torch.stack([cols.flatten() + 0.5, rows.flatten() + 0.5], 1).double()
            hit = inside_triangle(tri, centres)
            if not hit.any():
                continue
            b = barycentric_2d(tri, centres[hit])                           # q is affine on screen
            qp = b @ q
            depth = qp if camera.orthographic else 1 / qp
            keep = depth <= camera.far
            pixels.append((rows.flatten() * W + cols.flatten())[hit][keep])
            depths.append(depth[keep]), ids.append(face.expand(int(keep.sum())))
        if pixels:                                                          # float64 depths: as rasterize decides
            face_map = _nearest(torch.cat(pixels), torch.cat(depths), torch.cat(ids), H * W)
        else:
            face_map = torch.full((H * W,), -1, dtype=torch.int64)
    bary, depth = _visible_surface(face_map.to(verts.device), verts, faces, camera, H, W)
    return Fragments(face_map.view(H, W).to(verts.device), bary, depth)


def interpolate(attr, fragments: Fragments, faces) -> torch.Tensor:
    """Interpolate per-vertex attributes over the image with the fragments' barycentrics.

    attr: (V, C) one value per vertex (colours, normals, uvs, world positions...); faces: (F, 3) int64.
    Returns (H, W, C), zero where no face is visible. Differentiable w.r.t. ``attr`` and, through the
    barycentrics, the vertex positions.
    """
    attr = as_tensor(attr, name="attr")
    if attr.dim() != 2:
        raise ValueError(f"attr must have shape (V, C), got {tuple(attr.shape)}")
    _check_finite(attr, "attr")
    faces = _as_faces(faces, "faces", num_verts=attr.shape[0], device=attr.device, holder="attr has {} rows")
    if not (hasattr(fragments, "face_id") and hasattr(fragments, "bary")):
        raise TypeError(f"fragments must be Fragments (from rasterize or raycast), got {type(fragments).__name__}")
    if fragments.face_id.dim() != 2 or fragments.bary.shape != (*fragments.face_id.shape, 3):
        raise ValueError(f"fragments must have face_id (H, W) and bary (H, W, 3), got "
                         f"{tuple(fragments.face_id.shape)} and {tuple(fragments.bary.shape)}")
    H, W = fragments.face_id.shape
    face_id = fragments.face_id.reshape(-1)
    if face_id.numel() and int(face_id.max()) >= faces.shape[0]:
        raise ValueError(f"fragments reference face {int(face_id.max())} but faces has {faces.shape[0]} rows")
    pix = (face_id >= 0).nonzero().squeeze(1)                               # (M,)
    dtype = torch.promote_types(attr.dtype, fragments.bary.dtype)
    corner = attr.to(dtype)[faces[face_id[pix]]]                            # (M, 3, C)
    bary = fragments.bary.reshape(-1, 3)[pix].to(dtype)                     # (M, 3)
    values = (bary[:, :, None] * corner).sum(1)                             # (M, C)
    out = torch.zeros(H * W, attr.shape[1], dtype=dtype, device=attr.device).index_put((pix,), values)
    return out.view(H, W, attr.shape[1])
