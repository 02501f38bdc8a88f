"""Shadow maps (lecture 06): render the scene's depth from the light, then ask each point "is something nearer?".

The two-pass algorithm::

    pass 1   mesh + light camera ──rasterize──▶ depth image (the shadow map; +inf where empty)
    pass 2   point p ──project into the light camera──▶ texel (i, j), light-space depth z(p)
             p is shadowed  ⇔  z(p) - bias > depth[i, j]

Light cameras (``light_camera``): a :class:`~course.shading.DirectionalLight` gets an *orthographic* camera
looking along the way the light travels, fitted to the scene's bounding sphere; a :class:`SpotLight` a
*perspective* camera whose field of view is the cone; a :class:`~course.shading.PointLight` shines everywhere,
so it gets a *cube map*: six 90° perspective cameras, one per axis, in the order ``+x, -x, +y, -y, +z, -z``
(OpenGL's order). A point uses the face of the largest ``|component|`` of the light-to-point direction.

Bias, in two parts, both subtracted from the point's light-space depth before the comparison:

* ``bias``: constant, in **world units** along the light camera's viewing axis (its +z).
* ``slope_bias``: in **texels**: ``slope_bias * texel * tan θ``, where ``texel`` is the world-space width of
  one shadow-map texel at the point (``1 / fx`` for an orthographic map, ``z / fx`` for a perspective one)
  and θ the angle between the normal and the direction to the light (``tan θ`` clamped to ``max_slope``).
  A surface tilted by θ changes depth by ``texel * tan θ`` across one texel, which is the error of reading
  the depth at a texel's centre instead of at the point: too little bias gives *shadow acne* (a lit surface
  shadows itself), too much detaches shadows from their casters (*peter-panning*). With PCF of size k the
  comparisons reach ``(k - 1) / 2`` texels further, so the slope term is multiplied by ``(k + 1) / 2``.

Percentage-closer filtering (``pcf=k``, k odd): average the k×k comparisons at the texels around the
point's texel; it softens the outline over about k texels (it filters comparisons, never depths).

Policy: a point outside a map's frustum (outside the image, nearer than ``near`` or beyond ``far``) counts
as **lit** (factor 1): the map cannot see it, and for a spot light the cone's edge is a shading matter.
A PCF neighbour outside the image is lit too, except in a cube map, where it is clamped to the face's edge.
The comparisons are hard (0 or 1 each), so ``shadow_factor`` is not differentiable and runs without autograd.

Area lights by rasterization (``area_light_samples``, ``area_shadow_factor``): N stratified points over the
light, one shadow map each, and the average of the N factors; as N grows it converges to the fraction of the
light each point sees, the ray-traced soft shadow.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from types import SimpleNamespace

import torch

from ..camera import Camera, project_points
from ..raster import rasterize
from ..shading import DirectionalLight, PointLight
from ..tensors import _check_count, _check_finite, _check_flag, _check_real, _check_shape, _is_zero, as_tensor, unit

__all__ = ["SpotLight", "ShadowMap", "CUBE_FACES", "light_camera", "shadow_map", "light_space", "biased_depth",
           "biased_lit", "pcf", "shadow_factor", "area_light_samples", "area_shadow_factor"]

#: Cube-map face order: the axis each face's camera looks along (OpenGL's order).
CUBE_FACES = ("+x", "-x", "+y", "-y", "+z", "-z")


@dataclass
class SpotLight:
    """A point light at ``position`` (3,) shining into a cone around ``direction`` (3,), the way the light
    travels (as for :class:`~course.shading.DirectionalLight`). ``angle``: the cone's full opening angle in
    degrees, in (0, 180); its shadow map is a perspective camera with that field of view.
    ``color``, ``intensity``, ``falloff`` as for :class:`~course.shading.PointLight`."""
    position: tuple = (0.0, 2.0, 0.0)
    direction: tuple = (0.0, -1.0, 0.0)
    angle: float = 60.0
    color: tuple = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    falloff: bool = True


@dataclass
class ShadowMap:
    """What pass 1 leaves for pass 2.

    kind: ``"directional"`` (one orthographic camera), ``"spot"`` (one perspective camera) or ``"point"``
    (six perspective cameras, in ``CUBE_FACES`` order).
    cameras: tuple of C ``Camera`` (C = 1 or 6), all ``resolution`` × ``resolution``.
    depth: (C, H, W) camera-space z of the nearest surface seen by each texel, +inf where empty; detached.
    light: the light it was made for. radius: the bounding sphere's radius it was fitted to (world units).
    """
    kind: str
    cameras: tuple
    depth: torch.Tensor
    light: object
    radius: float

    @property
    def camera(self) -> Camera:
        """The single camera of a directional or spot map."""
        if len(self.cameras) != 1:
            raise ValueError("a point light's cube map has six cameras: use .cameras")
        return self.cameras[0]

    @property
    def resolution(self) -> int:
        return int(self.depth.shape[-1])


# ------------------------------------------------------------------------------------------------ helpers

def _light_kind(light) -> str:
    if isinstance(light, SpotLight):
        return "spot"
    if isinstance(light, DirectionalLight):
        return "directional"
    if isinstance(light, PointLight):
        return "point"
    raise TypeError(f"light must be a DirectionalLight, SpotLight or PointLight, got {type(light).__name__}")


def _check_resolution(resolution) -> int:
    return _check_count(resolution, "resolution", hint=" (texels per side)")


def _check_pcf(k, name: str) -> int:
    """An odd positive integer (the size of a k×k filter); a ValueError naming ``name`` otherwise."""
    try:
        ok = _check_count(k, name) % 2 == 1
    except ValueError:
        ok = False
    if not ok:
        raise ValueError(f"{name} must be an odd integer >= 1 (the k of a k×k filter), got {k!r}")
    return int(k)


def _check_angle(angle, name: str) -> float:
    """An angle in (0, 180) degrees (a cone's or a field of view's); a ValueError naming ``name`` otherwise."""
    try:
        return _check_real(angle, name, low=0, high=180, low_open=True, high_open=True)
    except ValueError:
        raise ValueError(f"{name} must be in (0, 180) degrees, got {angle!r}") from None


def _as_meshes(meshes) -> tuple:
    if not hasattr(meshes, "verts") and not isinstance(meshes, (list, tuple)):
        raise TypeError(f"expected a Mesh or a non-empty sequence of Meshes (objects with verts and faces), got "
                        f"{type(meshes).__name__}")
    meshes = (meshes,) if hasattr(meshes, "verts") else tuple(meshes)
    if not meshes or not all(hasattr(m, "verts") and hasattr(m, "faces") for m in meshes):
        raise TypeError("expected a Mesh or a non-empty sequence of Meshes (objects with verts and faces)")
    return meshes


def _bounds(meshes_or_bounds):
    """(center (3,) tensor, radius float, dtype, device) of a Mesh, Meshes, or a (center, radius) pair."""
    mb = meshes_or_bounds
    if (isinstance(mb, tuple) and len(mb) == 2 and not hasattr(mb[0], "verts")
            and isinstance(mb[1], numbers.Real)):
        center = as_tensor(mb[0], name="center")
        _check_shape(center, (3,), "center")
        return center, _check_real(mb[1], "the bounding radius", low=0, low_open=True)
    verts = torch.cat([m.verts.detach().reshape(-1, 3) for m in _as_meshes(mb)])
    if verts.shape[0] == 0:
        raise ValueError("the meshes have no vertices to fit a light camera to")
    center = (verts.min(0).values + verts.max(0).values) / 2
    radius = float((verts - center).norm(dim=-1).max())
    return center, max(radius, 1e-6 * max(1.0, float(center.abs().max())))


def _unit(v, name: str, like: torch.Tensor) -> torch.Tensor:
    v = as_tensor(v, dtype=like.dtype, device=like.device, name=name)
    _check_shape(v, (3,), name)
    if _is_zero(v):
        raise ValueError(f"{name} must be a non-zero vector")
    return unit(v)


def _up_for(forward: torch.Tensor) -> tuple:
    """A world up vector not parallel to ``forward``."""
    return (0.0, 1.0, 0.0) if abs(float(forward[1])) < 0.99 else (0.0, 0.0, -1.0)


# ------------------------------------------------------------------------------------------ light cameras

def light_camera(light, meshes_or_bounds, *, resolution: int, margin: float = 1.05):
    """The camera(s) that see the scene from the light.

    light: ``DirectionalLight``, ``SpotLight`` or ``PointLight``.
    meshes_or_bounds: a Mesh, a sequence of Meshes, or a ``(center (3,), radius)`` bounding sphere.
    resolution: texels per side (square maps). margin: the bounding sphere is grown by this factor.

    Returns a ``Camera`` (directional: orthographic, looking along ``light.direction`` at the sphere's centre
    from 2 radii away, image and near/far hugging the grown sphere; spot: perspective at ``light.position``,
    looking along ``light.direction``, ``fov = light.angle``), or for a point light a tuple of six 90°
    perspective cameras at ``light.position`` in ``CUBE_FACES`` order (+x, -x, +y, -y, +z, -z). Perspective
    near/far hug the grown sphere (near at least 1e-3 of its radius). dtype and device follow the bounds.
    """
    kind = _light_kind(light)
    res = _check_resolution(resolution)
    margin = _check_real(margin, "margin", low=1)
    center, radius = _bounds(meshes_or_bounds)
    r = radius * margin
    look = dict(width=res, height=res)
    if kind == "directional":
        d = _unit(light.direction, "light.direction", center)
        eye = center - d * (2 * r)
        return Camera.look_at(eye, center, _up_for(d), ortho_height=2 * r, near=r, far=3 * r, **look)
    pos = as_tensor(light.position, dtype=center.dtype, device=center.device, name="light.position")
    _check_shape(pos, (3,), "light.position")
    dist = float((center - pos).norm())
    near, far = max(dist - r, 1e-3 * r), dist + r
    if kind == "spot":
        _check_angle(light.angle, "SpotLight.angle")
        d = _unit(light.direction, "light.direction", center)
        return Camera.look_at(pos, pos + d, _up_for(d), fov_y=float(light.angle), near=near, far=far, **look)
    cams = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            d = torch.zeros(3, dtype=center.dtype, device=center.device)
            d[axis] = sign
            up = (0.0, 0.0, 1.0) if axis == 1 else (0.0, 1.0, 0.0)
            cams.append(Camera.look_at(pos, pos + d, up, fov_y=90.0, near=near, far=far, **look))
    return tuple(cams)


def shadow_map(mesh, light, resolution: int = 1024, *, bounds=None, margin: float = 1.05,
               cull_backfaces: bool = False) -> ShadowMap:
    """Pass 1: rasterize ``mesh`` from the light and keep the depth image(s).

    mesh: a Mesh (or a sequence of Meshes, joined), every shadow caster. light: Directional, Spot or Point.
    resolution: texels per side. bounds: what to fit the light camera to (default: the mesh itself; give
    the receivers too if they are not part of ``mesh``), as in ``light_camera``.
    cull_backfaces: pass to ``rasterize``: store only the faces turned toward the light. (The classic
    alternative to a large bias is the opposite, storing only the faces turned away from it.)
    Returns a ``ShadowMap`` whose depth (C, H, W) has the mesh's dtype and device, detached.
    """
    meshes = _as_meshes(mesh)
    cull_backfaces = _check_flag(cull_backfaces, "cull_backfaces")
    if len(meshes) == 1:
        geo = meshes[0]
    else:
        offsets, n = [], 0
        for m in meshes:
            offsets.append(n)
            n += m.verts.shape[0]
        geo = SimpleNamespace(verts=torch.cat([m.verts for m in meshes]),
                              faces=torch.cat([m.faces + o for m, o in zip(meshes, offsets)]))
    cams = light_camera(light, meshes if bounds is None else bounds, resolution=resolution, margin=margin)
    cams = cams if isinstance(cams, tuple) else (cams,)
    cams = tuple(c.to(device=geo.verts.device, dtype=geo.verts.dtype) for c in cams)
    with torch.no_grad():
        depth = torch.stack([rasterize(geo, c, cull_backfaces=cull_backfaces).depth for c in cams])
    radius = _bounds(meshes if bounds is None else bounds)[1]
    return ShadowMap(_light_kind(light), cams, depth.detach(), light, radius)


# ------------------------------------------------------------------------------- pass 2, building blocks

def light_space(points, K, R=None, t=None, orthographic: bool = False) -> torch.Tensor:
    """World points in a light camera: image coordinates (x, y) and camera-space depth, as (N, 3).

    points: (N, 3) world space. Either ``light_space(points, camera)`` with a ``Camera`` (a shadow map's
    ``.camera`` or one of its ``.cameras``), or ``light_space(points, K, R, t, orthographic)`` with K: (3, 3),
    R: (3, 3), t: (3,). Returns (N, 3), the columns (x, y, depth): x the column and y the row in the light's
    image (texel (i, j) covers [j, j + 1) × [i, i + 1)), depth the camera-space z (along the light's axis, not
    the distance to the light). Perspective divides by depth, orthographic does not: this is
    ``course.camera.project_points`` with its two results side by side, the lookup of pass 2.
    """
    if isinstance(K, Camera):
        if R is not None or t is not None:
            raise TypeError("light_space(points, camera) takes no R or t: the camera has its own")
        K, R, t, orthographic = K.K, K.R, K.t, K.orthographic
    elif R is None or t is None:
        raise TypeError("light_space needs a Camera, or K, R and t: light_space(points, K, R, t, orthographic)")
    pts = as_tensor(points, name="points")
    _check_shape(pts, (None, 3), "points")
    xy, depth = project_points(pts, K, R, t, orthographic=_check_flag(orthographic, "orthographic"))
    return torch.cat([xy, depth[:, None]], 1)


def _not_behind(depth: torch.Tensor, stored: torch.Tensor) -> torch.Tensor:
    """The shadow test itself, lit where ``not (depth > stored)``: a point exactly at the stored depth is lit,
    and so is one over an empty texel (stored +inf)."""
    return ~(depth > stored)


def biased_depth(z, texel, tan_theta, bias: float, slope_bias: float) -> torch.Tensor:
    """The light-space depth moved toward the light by the two-part bias: ``z - (bias + slope_bias * texel *
    tan_theta)``.

    z: (N,) light-space depth; texel: (N,) (or a scalar) the world width of one texel at the point (``1 / fx``
    orthographic, ``z / fx`` perspective); tan_theta: (N,) (or a scalar) tan θ, θ between the normal and the
    direction to the light, already clamped; bias: world units; slope_bias: texels. Returns (N,) in z's dtype.
    """
    z = as_tensor(z, name="z")
    _check_finite(z, "z")
    terms = {}
    for name, v in (("texel", texel), ("tan_theta", tan_theta)):
        t = as_tensor(v, dtype=z.dtype, device=z.device, name=name)
        if t.dim() > 1 or (t.dim() == 1 and t.shape != z.shape):
            raise ValueError(f"{name} must be a scalar or have z's shape {tuple(z.shape)}, got {tuple(t.shape)}")
        _check_finite(t, name)
        terms[name] = t
    bias = _check_real(bias, "bias")
    slope_bias = _check_real(slope_bias, "slope_bias")
    return z - (bias + slope_bias * terms["texel"] * terms["tan_theta"])


def biased_lit(z, stored, texel, tan_theta, bias: float, slope_bias: float) -> torch.Tensor:
    """The biased comparison of pass 2: True where a point is lit, ``not (z - total > stored)`` with
    ``total = bias + slope_bias * texel * tan_theta`` (``biased_depth``).

    z: (N,) each point's light-space depth; stored: (N,) the depth stored in its texel (+inf for an empty
    texel: lit); texel, tan_theta: (N,) as in ``biased_depth``; bias, slope_bias: floats. Returns (N,) bool.
    A point exactly at the stored depth after the bias is lit. ``shadow_factor`` with ``pcf=1`` is this test
    at the texel holding each point.
    """
    z, stored = as_tensor(z, name="z"), as_tensor(stored, name="stored")
    if z.dim() != 1:
        raise ValueError(f"z must have shape (N,), one depth per point, got {tuple(z.shape)}")
    if stored.shape != z.shape:
        raise ValueError(f"stored must have one depth per point, shape {tuple(z.shape)}, got {tuple(stored.shape)}")
    _check_finite(z, "z"), _check_finite(stored, "stored", allow_inf=True)     # +inf: an empty texel
    return _not_behind(biased_depth(z, texel, tan_theta, bias, slope_bias), stored)


def pcf(depth_map, coords, depths, k: int = 1, *, outside: str = "lit") -> torch.Tensor:
    """Percentage-closer filtering: the fraction of the k×k texels around each point's texel whose stored
    depth is not nearer than the point's (Reeves, Salesin and Cook 1987).

    depth_map: (H, W) one shadow map (+inf where empty); coords: (N, 2) each point's image coordinates (x, y)
    in the light camera, inside the map (0 <= x <= W, 0 <= y <= H; the texel is row ⌊y⌋, column ⌊x⌋, clamped
    into the map so that x = W reads the last column); depths: (N,) the points' light-space depths, already
    biased (``biased_depth``); k: odd filter size, the window is offsets -(k - 1)/2 … (k - 1)/2.
    outside: what a neighbour outside the map says: ``"lit"`` (the map cannot see there; it still counts in the
    k×k) or ``"clamp"`` (read the nearest edge texel: a cube map's faces meet there).
    Returns (N,) in depth_map's dtype (depths are compared in that dtype), each value a multiple of 1 / k².
    It filters the 0/1 comparisons, never the depths.
    """
    k = _check_pcf(k, "k")
    if outside not in ("lit", "clamp"):
        raise ValueError(f"outside must be 'lit' or 'clamp', got {outside!r}")
    depth_map = as_tensor(depth_map, name="depth_map")
    if depth_map.dim() != 2 or depth_map.shape[0] == 0 or depth_map.shape[1] == 0:
        raise ValueError(f"depth_map must be one (H, W) map, not empty, got shape {tuple(depth_map.shape)}")
    _check_finite(depth_map, "depth_map", allow_inf=True)                    # +inf: an empty texel
    coords = as_tensor(coords, name="coords")
    _check_shape(coords, (None, 2), "coords")
    depths = as_tensor(depths, dtype=depth_map.dtype, device=depth_map.device, name="depths")
    if depths.shape != coords.shape[:1]:
        raise ValueError(f"depths must have one value per point, shape ({coords.shape[0]},), got "
                         f"{tuple(depths.shape)}")
    _check_finite(depths, "depths")
    H, W = depth_map.shape
    col = coords[:, 0].floor().long().clamp(0, W - 1)
    row = coords[:, 1].floor().long().clamp(0, H - 1)
    flat = depth_map.reshape(-1)
    r = (k - 1) // 2
    lit = torch.zeros(depths.shape, dtype=depth_map.dtype, device=depth_map.device)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            rr, cc = row + dy, col + dx
            seen = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
            if outside == "clamp":
                seen = torch.ones_like(seen)
            stored = flat.index_select(0, rr.clamp(0, H - 1) * W + cc.clamp(0, W - 1))
            lit += (~seen | _not_behind(depths, stored)).to(depth_map.dtype)
    return lit / (k * k)


def _tan_theta(normals, to_light, max_slope: float):
    """tan of the angle between (M, 3) normals and (M, 3) directions to the light, clamped to max_slope."""
    cos = ((normals * to_light).sum(-1).abs()
           / (normals.norm(dim=-1) * to_light.norm(dim=-1)).clamp_min(1e-30)).clamp(0, 1)
    sin = (1 - cos * cos).clamp_min(0).sqrt()
    return torch.where(sin <= max_slope * cos, sin / cos.clamp_min(1e-30), torch.full_like(cos, max_slope))


# ----------------------------------------------------------------------------------------------- pass 2

def shadow_factor(points_world, normals, shadow_map: ShadowMap, *, bias: float | None = None,
                  slope_bias: float = 1.5, max_slope: float = 10.0, pcf: int = 1) -> torch.Tensor:
    """Pass 2: how lit each point is, from 0 (shadowed) to 1 (lit).

    points_world: (N, 3) world space. normals: (N, 3) surface normals (need not be unit length), or None
    for no slope-scaled bias. shadow_map: from ``shadow_map``.
    bias: constant depth bias in world units along the light camera's axis; None means
    ``1e-3 * shadow_map.radius`` (enough for rounding). slope_bias: in texels, times ``tan θ`` (clamped to
    ``max_slope``) and the world width of a texel at the point (module docstring). pcf: k, odd >= 1: the mean
    of the k×k comparisons around the point's texel (1 = one nearest-texel comparison).
    Returns (N,) in the points' dtype (promoted with the map's): each value a multiple of 1 / k².
    Points outside the map's frustum are lit (1). Not differentiable (hard comparisons).

    It is the three building blocks in a row: ``light_space`` (texel and depth of each point), ``biased_depth``
    (the bias, its slope term widened by (k + 1) / 2 for the PCF window) and ``pcf`` (``outside="clamp"`` for
    a cube map); with ``pcf=1`` that is ``biased_lit`` at each point's texel.
    """
    if not isinstance(shadow_map, ShadowMap):
        raise TypeError(f"shadow_map must be a ShadowMap, got {type(shadow_map).__name__}")
    pcf = _check_pcf(pcf, "pcf")
    pts = as_tensor(points_world, name="points_world")
    _check_shape(pts, (None, 3), "points_world")
    dtype = torch.promote_types(pts.dtype, shadow_map.depth.dtype)
    device = shadow_map.depth.device
    pts = pts.detach().to(dtype=dtype, device=device)
    if normals is not None:
        nrm = as_tensor(normals, name="normals")
        _check_shape(nrm, (None, 3), "normals")
        if nrm.shape[0] != pts.shape[0]:
            raise ValueError(f"normals must have one row per point: {nrm.shape[0]} normals, {pts.shape[0]} points")
        nrm = nrm.detach().to(dtype=dtype, device=device)
    bias = 1e-3 * shadow_map.radius if bias is None else _check_real(bias, "bias")
    slope_bias = _check_real(slope_bias, "slope_bias", low=0)
    max_slope = _check_real(max_slope, "max_slope", low=0)
    with torch.no_grad():
        return _factor(pts, None if normals is None else nrm, shadow_map, bias, float(slope_bias),
                       float(max_slope), int(pcf))


def _factor(pts, nrm, sm: ShadowMap, bias, slope_bias, max_slope, k):
    N, dtype = pts.shape[0], pts.dtype
    C, H, W = sm.depth.shape
    out = torch.ones(N, dtype=dtype, device=pts.device)
    if N == 0:
        return out
    # which camera sees each point: the only one, or the cube face of the largest |component|
    if sm.kind == "point":
        pos = torch.as_tensor(sm.cameras[0].eye, dtype=dtype, device=pts.device)
        v = pts - pos
        axis = v.abs().argmax(1)
        face = 2 * axis + (v.gather(1, axis[:, None])[:, 0] < 0).long()
    else:
        face = torch.zeros(N, dtype=torch.long, device=pts.device)
    # direction to the light, for the slope term
    if sm.kind == "directional":
        to_light = -torch.as_tensor(sm.cameras[0].R[2], dtype=dtype, device=pts.device).expand_as(pts)
    else:
        to_light = torch.as_tensor(sm.cameras[0].eye, dtype=dtype, device=pts.device) - pts
    sloped = nrm is not None and slope_bias > 0
    slope = slope_bias * (k + 1) / 2 if sloped else 0.0                      # PCF reaches (k - 1) / 2 further
    depth = sm.depth.to(dtype)                                               # (C, H, W)
    for c, cam in enumerate(sm.cameras):
        sel = (face == c).nonzero().squeeze(1)
        if sel.numel() == 0:
            continue
        p = pts.index_select(0, sel)
        cam = cam.to(dtype=dtype)
        x, y, z = light_space(p, cam).unbind(1)                              # (M,) each
        fx = cam.K[0, 0]
        texel = (1 / fx).expand_as(z) if cam.orthographic else z / fx        # world width of a texel
        tan = (_tan_theta(nrm.index_select(0, sel), to_light.index_select(0, sel), max_slope) if sloped
               else torch.zeros_like(z))
        inside = (z >= cam.near) & (z <= cam.far) & (x >= 0) & (x <= W) & (y >= 0) & (y <= H)
        inside &= torch.isfinite(x) & torch.isfinite(y)
        seen = inside.nonzero().squeeze(1)
        z_test = biased_depth(z.index_select(0, seen), texel.abs().index_select(0, seen),
                              tan.index_select(0, seen), bias, slope)
        xy = torch.stack([x, y], 1).index_select(0, seen)
        lit = torch.ones_like(z)
        lit[seen] = pcf(depth[c], xy, z_test, k, outside="clamp" if sm.kind == "point" else "lit")
        out[sel] = lit
    return out


# ------------------------------------------------------------------------------------------- area lights

def _generator(seed) -> torch.Generator:
    if isinstance(seed, torch.Generator):
        return seed
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise TypeError(f"seed must be an int or a torch.Generator, got {type(seed).__name__}")
    return torch.Generator(device="cpu").manual_seed(seed)


def _grid(n: int) -> tuple[int, int]:
    """rows × cols = n with rows the largest divisor <= sqrt(n): the most square grid of n strata."""
    rows = max(d for d in range(1, math.isqrt(n) + 1) if n % d == 0)
    return rows, n // rows


def area_light_samples(kind: str, center, normal, size, n: int, *, u_axis=None, seed=0,
                       dtype=None, device=None) -> torch.Tensor:
    """n stratified points over a planar area light.

    kind: ``"rectangle"`` (size = side, or (width, height) along ``u_axis`` and ``normal × u_axis``) or
    ``"disk"`` (size = radius). center: (3,). normal: (3,), the light's facing direction (its plane's
    normal). u_axis: (3,) an in-plane direction for the rectangle's width (default: any axis ⟂ normal).
    seed: int or ``torch.Generator``. Stratified: the unit square is cut into a rows × cols grid of n cells
    (the most square one) with one uniform point in each; the disk uses the concentric (Shirley–Chiu) map of
    that square, which keeps the strata equal in area. Returns (n, 3) in ``dtype`` (default: center's).
    """
    if kind not in ("rectangle", "disk"):
        raise ValueError(f"kind must be 'rectangle' or 'disk', got {kind!r}")
    n = _check_count(n, "n")
    c = as_tensor(center, dtype=dtype, device=device, name="center")
    _check_shape(c, (3,), "center")
    nz = _unit(normal, "normal", c)
    if u_axis is None:
        helper = torch.tensor((1.0, 0.0, 0.0) if abs(float(nz[0])) < 0.9 else (0.0, 1.0, 0.0),
                              dtype=c.dtype, device=c.device)
        u = helper - (helper @ nz) * nz
    else:
        u = as_tensor(u_axis, dtype=c.dtype, device=c.device, name="u_axis")
        _check_shape(u, (3,), "u_axis")
        u = u - (u @ nz) * nz
    if float(u.norm()) <= 1e-9:
        raise ValueError("u_axis must not be parallel to normal")
    u = u / u.norm()
    v = torch.linalg.cross(nz, u)
    pair = isinstance(size, (tuple, list)) or (isinstance(size, torch.Tensor) and size.dim() == 1)
    sizes = list(size) if pair else [size, size]
    try:
        if len(sizes) != 2 or (kind == "disk" and pair):
            raise ValueError
        sizes = [_check_real(s, "size", low=0, low_open=True) for s in sizes]
    except ValueError:
        raise ValueError(f"size must be positive (a side, (width, height), or a disk's radius), finite, got "
                         f"{size!r}") from None
    rows, cols = _grid(n)
    gen = _generator(seed)
    jitter = torch.rand(n, 2, generator=gen, dtype=torch.float64)
    idx = torch.arange(n, dtype=torch.float64)
    s = (torch.remainder(idx, cols) + jitter[:, 0]) / cols                   # [0, 1)
    t = (torch.div(idx, cols, rounding_mode="floor") + jitter[:, 1]) / rows
    if kind == "rectangle":
        a, b = (s - 0.5) * sizes[0], (t - 0.5) * sizes[1]
    else:                                                                    # concentric square → disk
        sx, sy = 2 * s - 1, 2 * t - 1
        first = sx.abs() > sy.abs()
        rad = torch.where(first, sx, sy)                                      # signed radius
        den = torch.where(rad == 0, torch.ones_like(rad), rad)
        phi = torch.where(first, (math.pi / 4) * sy / den, math.pi / 2 - (math.pi / 4) * sx / den)
        a, b = sizes[0] * rad * torch.cos(phi), sizes[0] * rad * torch.sin(phi)
    a, b = a.to(c.dtype).to(c.device), b.to(c.dtype).to(c.device)
    return c + a[:, None] * u + b[:, None] * v


def area_shadow_factor(points_world, normals, mesh, samples, *, resolution: int = 512, light_normal=None,
                       fov: float = 120.0, bounds=None, bias: float | None = None, slope_bias: float = 1.5,
                       pcf: int = 1) -> torch.Tensor:
    """Soft shadow of an area light by rasterization: the mean of one shadow map's factor per light sample.

    points_world: (N, 3); normals: (N, 3) or None; mesh: the casters (Mesh or sequence); samples: (S, 3)
    points on the light (``area_light_samples``). Each sample is a point light: with ``light_normal`` (3,)
    given (a one-sided light facing that way, e.g. a ceiling panel facing down) its map is one perspective
    (spot) map along ``light_normal`` with field of view ``fov`` degrees, which must cover the receivers
    (points outside count as lit); without it, a six-face cube map (6× the rasterization).
    resolution, bounds, bias, slope_bias, pcf: as in ``shadow_map`` / ``shadow_factor``.
    Returns (N,) in [0, 1]: an estimate of the fraction of the light each point sees (unweighted by the
    cosine terms), converging as S grows to the ray-traced visibility.
    """
    smp = as_tensor(samples, name="samples")
    _check_shape(smp, (None, 3), "samples")
    if smp.shape[0] == 0:
        raise ValueError("samples must hold at least one point on the light")
    pts = as_tensor(points_world, name="points_world")
    _check_shape(pts, (None, 3), "points_world")
    _check_resolution(resolution), _check_pcf(pcf, "pcf"), _check_angle(fov, "fov")
    if light_normal is not None:
        light_normal = as_tensor(light_normal, name="light_normal")
        _check_shape(light_normal, (3,), "light_normal")
        if float(light_normal.norm()) == 0:
            raise ValueError("light_normal must be a non-zero vector")
    total = None
    for p in smp.unbind(0):
        pos = tuple(float(v) for v in p)
        light = (PointLight(position=pos) if light_normal is None else
                 SpotLight(position=pos, direction=tuple(float(v) for v in as_tensor(light_normal)), angle=fov))
        sm = shadow_map(mesh, light, resolution, bounds=bounds)
        f = shadow_factor(pts, normals, sm, bias=bias, slope_bias=slope_bias, pcf=pcf)
        total = f if total is None else total + f
    return total / smp.shape[0]
