"""Exact pixel coverage of vertex colours interpolated affinely on screen: the second image model (lecture 05, 09).

The image model
---------------
Each face's colour is the **affine function on the screen** that takes vertex k's colour at vertex k's
projected position: ``c(p) = Σ_k b_k(p) c_k`` with ``b`` the *screen-space* barycentrics of the point p with
respect to the face's projected triangle. This is deliberately **not** perspective-correct interpolation
(``raster.interpolate`` weights by 1/z): under a perspective camera it is a different, but well defined,
image model; under an orthographic camera the two coincide (depth does not divide). Visibility is that of
``coverage.visible_regions`` (``rasterize`` without culling: near and far clipping, point-by-point depth).

The closed form
---------------
A pixel's box-filtered value is ``∫_square c = Σ_pieces ∫_piece c_f + background · (1 - Σ area)`` over
the visible convex pieces of ``visible_regions``. c_f is affine, so its integral over a polygon is exactly
``area · c_f(centroid)``: ``exact_affine_coverage = Σ area · c_f(centroid) + background · uncovered``. With
equal colours at a face's three vertices this is ``exact_coverage``.

* **Centroids** (``polygon_centroids``): the standard formula ``Σ (v_i + v_i+1) cross_i / (6 A)``, taken
  relative to the piece's first vertex (pixel-relative coordinates, numbers below 1). A piece whose area is
  at the level of its own rounding (a sliver) takes the mean of its vertices instead: the two differ by at
  most the piece's diameter, times an area that is ~0, and no division by ~0 can make a NaN.
* **Barycentrics** of the centroid w.r.t. the projected triangle: camera space in float64 (as ``coverage``),
  projected with the same K (x = K X / z, or K [X, Y, 1] orthographic), made relative to the pixel corner,
  then two edge functions over the doubled area (``b0 = 1 - b1 - b2``, so equal vertex colours give exactly
  that colour). Differentiable w.r.t. verts, K, R and t; the division is guarded for zero-area faces (which
  have no pieces anyway), and b is clamped to [-1, 2] as a guard against rounding in slivers (exact
  arithmetic gives [0, 1]: every piece lies inside its projected triangle).
* **The near plane**: the model is defined by the three projected vertices, meaningless for a vertex behind
  a pinhole camera (and huge and imprecise for one just in front of it). So under a **perspective** camera
  a face with a visible piece must have all three vertices at z >= near: otherwise ``ValueError`` (faces
  that cross the near plane but are hidden or off-screen are fine). Under an **orthographic** camera the
  projection does not involve depth, so the model is defined for every face, and a face crossing the near
  plane is simply clipped there (the clip line is straight on screen, the pieces stay convex: still exact).

Work and memory follow ``exact_coverage``: the pieces come chunk by chunk (``coverage._region_chunks``), each
chunk's contribution is added into the image and let go.

For the gradient code (``course.visibility``, model "affine"): ``iter_affine_pieces`` / ``affine_pieces`` give
every visible piece's pixel, face, area and centroid (differentiable), and ``affine_color_at`` evaluates a
face's colour field at given points, differentiable w.r.t. verts, K, R, t and the vertex colours. The
interior term of the derivative of ``L = Σ w ⊙ image`` is then the autograd derivative of
``Σ_pieces w[pixel] · area.detach() · affine_color_at(..., face, centroid.detach(), pixel=pixel)`` (the
colour moves with π at a fixed screen point; the boundary term does the rest).
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from . import raster
from .camera import world_to_camera
from .coverage import _region_chunks
from .tensors import as_tensor

__all__ = ["exact_affine_coverage", "affine_color_at", "affine_pieces", "iter_affine_pieces", "AffinePieces",
           "polygon_centroids"]


@dataclass(frozen=True)
class AffinePieces:
    """Visible convex pieces (N of them), reduced to what an affine integrand needs.

    pixel:    (N,) int64 flat pixel index (row = pixel // W, column = pixel % W).
    face:     (N,) int64 face id.
    area:     (N,) area in pixels. Differentiable.
    centroid: (N, 2) the piece's centroid relative to its pixel's top-left corner (x right, y down).
              Differentiable.
    ``∫_piece c = area · c(centroid)`` for every affine c.
    """
    pixel: torch.Tensor
    face: torch.Tensor
    area: torch.Tensor
    centroid: torch.Tensor

    def image_centroid(self, width: int) -> torch.Tensor:
        """(N, 2) the centroids in image coordinates."""
        corner = torch.stack([self.pixel % width, self.pixel // width], -1).to(self.centroid.dtype)
        return self.centroid + corner


def polygon_centroids(poly, count) -> torch.Tensor:
    """Centroids of padded convex polygons: poly (N, M, 2) (slots past count repeat the last vertex, as in
    ``VisibleRegions.verts``), count (N,). Returns (N, 2).

    ``Σ (w_i + w_i+1) cross(w_i, w_i+1) / (3 Σ cross(w_i, w_i+1))`` with w relative to the first vertex (the
    padded slots add nothing). Where the doubled area is within rounding of zero (below 64 eps times the sum
    of the cross products' magnitudes), the mean of the vertices: finite values and gradients, no 0/0.
    """
    poly = as_tensor(poly, name="poly")
    count = torch.as_tensor(count, device=poly.device).long()
    if poly.dim() != 3 or poly.shape[2] != 2 or count.shape != poly.shape[:1]:
        raise ValueError(f"expected poly (N, M, 2) and count (N,), got {tuple(poly.shape)} and {tuple(count.shape)}")
    if poly.shape[1] == 0:
        return poly.new_zeros(poly.shape[0], 2)
    v0 = poly[:, :1]
    w = poly - v0
    w1 = w.roll(-1, 1)
    ab, ba = w[..., 0] * w1[..., 1], w[..., 1] * w1[..., 0]
    cross = ab - ba                                                         # (N, M)
    a2 = cross.sum(1)                                                       # twice the area
    scale = (ab.abs() + ba.abs()).sum(1).detach()
    ok = a2.detach().abs() > 64 * torch.finfo(poly.dtype).eps * scale
    num = ((w + w1) * cross[..., None]).sum(1)                              # (N, 2)
    centre = num / (3 * torch.where(ok, a2, torch.ones_like(a2)))[:, None]
    real = (torch.arange(poly.shape[1], device=poly.device) < count[:, None]).to(poly.dtype)
    mean = (w * real[..., None]).sum(1) / count.clamp(min=1).to(poly.dtype)[:, None]
    return v0[:, 0] + torch.where(ok[:, None], centre, mean)


# ------------------------------------------------------------------------------------------ the colour field

def _check_colors(vertex_colors, verts):
    colors = as_tensor(vertex_colors, device=verts.device, name="vertex_colors")
    if colors.dim() != 2 or colors.shape[0] != verts.shape[0] or colors.shape[1] < 1:
        raise ValueError(f"vertex_colors must have shape (V, C) with V = {verts.shape[0]} vertices and C >= 1 "
                         f"channels, got {tuple(colors.shape)}")
    if not colors.dtype.is_floating_point:
        colors = colors.to(torch.get_default_dtype())
    if not torch.isfinite(colors).all():
        raise ValueError("vertex_colors contains NaN or inf")
    return colors


class _Field:
    """The faces' screen triangles (float64, differentiable) and the near-plane check of the model."""

    def __init__(self, verts, faces, camera):
        self.faces, self.camera = faces, camera
        cam = world_to_camera(verts.double(), camera.R.double(), camera.t.double())   # (V, 3)
        self.z = cam[:, 2].detach()
        z = cam[:, 2:]
        if camera.orthographic:
            xy1 = torch.cat([cam[:, :2], torch.ones_like(z)], -1)
        else:                                                               # z < near only on faces that raise
            xy1 = cam / torch.where(z >= camera.near, z, torch.ones_like(z))
        self.xy = (xy1 @ camera.K.double().T)[:, :2]                        # (V, 2) pixels

    def check(self, face, caller):
        """Raise when a listed face (N,) crosses the near plane of a perspective camera."""
        if self.camera.orthographic or face.numel() == 0:
            return
        z = self.z[self.faces[face]]                                        # (N, 3)
        bad = (z < self.camera.near).any(-1)
        if bool(bad.any()):
            k = int(bad.nonzero()[0, 0])
            raise ValueError(
                f"{caller}: face {int(face[k])} is visible and crosses the near plane (its vertices have camera "
                f"z = {[round(float(v), 6) for v in z[k]]}, near = {self.camera.near}). The screen-affine colour "
                f"model is defined by the three projected vertices, which need z >= near under a perspective "
                f"camera: move the camera or the mesh, clip the mesh, or use an orthographic camera")

    def bary(self, face, pixel, offset):
        """Screen barycentrics (N, 3) float64 of points offset (N, 2) (relative to pixel's corner) w.r.t. the
        projected triangles of face (N,)."""
        W = self.camera.width
        corner = torch.stack([pixel % W, pixel // W], -1).double()
        q = self.xy[self.faces[face]] - corner[:, None]                    # (N, 3, 2) pixel-relative
        g = offset.double()
        e1, e2, d = q[:, 1] - q[:, 0], q[:, 2] - q[:, 0], g - q[:, 0]
        a2 = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        ok = a2.detach().abs() > torch.finfo(a2.dtype).tiny ** 0.5
        den = torch.where(ok, a2, torch.ones_like(a2))
        b1 = torch.where(ok, (d[:, 0] * e2[:, 1] - d[:, 1] * e2[:, 0]) / den, torch.full_like(a2, 1 / 3))
        b2 = torch.where(ok, (e1[:, 0] * d[:, 1] - e1[:, 1] * d[:, 0]) / den, torch.full_like(a2, 1 / 3))
        b1, b2 = b1.clamp(-1, 2), b2.clamp(-1, 2)                           # a guard: exact values lie in [0, 1]
        return torch.stack([1 - b1 - b2, b1, b2], -1)

    def colors(self, face, pixel, offset, colors):
        """The colour (N, C) of face's field at the points, in colors' dtype."""
        b = self.bary(face, pixel, offset).to(colors.dtype)
        c = colors[self.faces[face]]                                        # (N, 3, C)
        return c[:, 0] + b[:, 1:2] * (c[:, 1] - c[:, 0]) + b[:, 2:3] * (c[:, 2] - c[:, 0])


def affine_color_at(mesh, camera, vertex_colors, face, points, *, pixel=None) -> torch.Tensor:
    """The screen-affine colour field of faces at points: ``Σ_k b_k c_k`` with b the screen-space (not
    perspective-correct) barycentrics of the point w.r.t. the face's projected triangle.

    mesh: ``verts`` (V, 3), ``faces`` (F, 3); camera: a ``Camera``; vertex_colors: (V, C); face: (N,) face ids;
    points: (N, 2) in image coordinates (x right, y down), or, when ``pixel`` (N,) flat pixel indices is
    given, relative to those pixels' top-left corners (keeps float32 points precise). Returns (N, C) in
    ``promote(verts, camera, vertex_colors)``, differentiable w.r.t. verts, K, R, t, vertex_colors and points.
    Points outside the triangle extrapolate the affine function. Raises ValueError for a face that crosses
    the near plane of a perspective camera (the model needs its three projected vertices).
    """
    verts, faces = raster._check_inputs(mesh, camera)
    colors = _check_colors(vertex_colors, verts)
    face = torch.as_tensor(face, device=verts.device)
    points = as_tensor(points, device=verts.device, name="points")
    if face.dim() != 1 or face.dtype.is_floating_point or points.shape != (face.shape[0], 2):
        raise ValueError(f"expected face (N,) integer ids and points (N, 2), got {face.dtype} "
                         f"{tuple(face.shape)} and {tuple(points.shape)}")
    face = face.long()
    if face.numel() and (int(face.min()) < 0 or int(face.max()) >= faces.shape[0]):
        raise ValueError(f"face ids must lie in [0, {faces.shape[0]}), got [{int(face.min())}, {int(face.max())}]")
    if not torch.isfinite(points).all():
        raise ValueError("points contains NaN or inf")
    if pixel is None:
        pixel = torch.zeros_like(face)
    else:
        pixel = torch.as_tensor(pixel, device=verts.device).long()
        if pixel.shape != face.shape:
            raise ValueError(f"pixel must have shape (N,) = ({face.shape[0]},), got {tuple(pixel.shape)}")
    dtype = torch.promote_types(torch.promote_types(verts.dtype, camera.dtype), colors.dtype)
    field = _Field(verts, faces, camera)
    field.check(face, "affine_color_at")
    return field.colors(face, pixel, points, colors.to(dtype))


# ------------------------------------------------------------------------------------------------ the pieces

def iter_affine_pieces(mesh, camera, *, dtype=None):
    """``AffinePieces`` chunk by chunk (bounded memory, as ``exact_coverage``): the pixels one face covers
    entirely, then chunks of about ``coverage.CHUNK`` (pixel, face) pairs. dtype: the working precision of
    the pieces, default ``promote(verts, camera)``. Everything differentiable w.r.t. verts, K, R, t."""
    verts, faces = raster._check_inputs(mesh, camera)
    dtype = dtype or torch.promote_types(verts.dtype, camera.dtype)
    for r in _region_chunks(verts, faces, camera, dtype):
        yield AffinePieces(r.pixel, r.face, r.area, polygon_centroids(r.verts, r.count))


def affine_pieces(mesh, camera, *, dtype=None) -> AffinePieces:
    """Every visible piece of the image (``iter_affine_pieces``, concatenated): its size grows with the image."""
    parts = list(iter_affine_pieces(mesh, camera, dtype=dtype))
    return AffinePieces(*(torch.cat([getattr(p, n) for p in parts]) for n in ("pixel", "face", "area", "centroid")))


def exact_affine_coverage(mesh, camera, vertex_colors, background=(0.0, 0.0, 0.0)) -> torch.Tensor:
    """The exact box-filtered image of vertex colours interpolated affinely in screen space (module docstring):
    each pixel ``Σ_pieces area · colour(centroid) + background · uncovered area``.

    mesh: ``verts`` (V, 3), ``faces`` (F, 3); camera: a ``Camera`` (perspective or orthographic);
    vertex_colors: (V, C) one colour per vertex; background: (C,) (or a scalar). Returns (H, W, C) in
    ``promote(verts, camera, vertex_colors)``. Screen-space barycentrics, not perspective-correct: exact
    for the perspective-correct image only under an orthographic camera. Same visibility as
    ``exact_coverage``; with equal colours at each face's vertices it equals ``exact_coverage``.
    Differentiable w.r.t. verts, vertex_colors, K, R and t (one-sided at kinks, always finite). Raises
    ValueError when a visible face crosses the near plane of a perspective camera.
    """
    verts, faces = raster._check_inputs(mesh, camera)
    colors = _check_colors(vertex_colors, verts)
    C = colors.shape[1]
    dtype = torch.promote_types(torch.promote_types(verts.dtype, camera.dtype), colors.dtype)
    bg = as_tensor(background, dtype=dtype, device=verts.device, name="background")
    if bg.dim() == 0 or bg.shape == (1,):
        bg = bg.reshape(1).expand(C)
    if bg.shape != (C,):
        raise ValueError(f"background must have shape (C,) = ({C},) like vertex_colors, or be a scalar, "
                         f"got {tuple(bg.shape)}")
    if not torch.isfinite(bg).all():
        raise ValueError("background contains NaN or inf")
    H, W = camera.height, camera.width
    colors = colors.to(dtype)
    field = _Field(verts, faces, camera)
    image = torch.zeros(H * W, C, dtype=dtype, device=verts.device)
    covered = torch.zeros(H * W, dtype=dtype, device=verts.device)
    for r in _region_chunks(verts, faces, camera, dtype):                  # Σ area · colour(centroid)
        if r.pixel.numel() == 0:
            continue
        field.check(torch.unique(r.face), "exact_affine_coverage")
        centroid = polygon_centroids(r.verts, r.count)
        image = image.index_add(0, r.pixel, r.area[:, None] * field.colors(r.face, r.pixel, centroid, colors))
        covered = covered.index_add(0, r.pixel, r.area)
    return (image + (1 - covered)[:, None] * bg).view(H, W, C)
