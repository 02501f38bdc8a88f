"""Shading: lights, materials, Lambert and Blinn-Phong, texture lookup, flat / Gouraud / Phong shading.

Two layers, kept apart:

* **Pure lighting math** on points (``...`` leading dimensions: ``N`` points or an ``H, W`` image):
  :func:`lambert`, :func:`blinn_phong`, :func:`phong`, :func:`light_terms` and :func:`shade`. No meshes, no
  cameras, no Fragments; every one is differentiable and NaN-free at zero vectors and grazing angles
  (vectors are normalised with a clamped length).
* **Fragments plumbing**: :func:`flat_shading`, :func:`gouraud_shading`, :func:`phong_shading` and
  :func:`wireframe_overlay` take a mesh, the camera and the rasterizer's ``Fragments`` and call the pure layer.

Texture lookups (nearest, bilinear, and mipmapped trilinear with the uv footprint that picks the level)
live in ``course.textures``; ``sample_texture``, ``mip_level``, ``mip_pyramid``, ``uv_derivatives`` and
``sample_texture_mip`` are also importable from here.

Directions follow one rule: every direction argument points *away from the surface* — ``light_dir``
toward the light, ``view_dir`` toward the viewer — and ``normal`` out of the front face. The one exception
is :class:`DirectionalLight`'s ``direction``, which is the direction the light *travels* (sunlight going
down is ``(0, -1, 0)``), as in glTF and most scene formats.

The shading model (lecture 04), for a point with base colour ``c`` and material ``m``::

    colour = c * (m.ambient * Σ ambient_i  +  m.diffuse * Σ L_j max(0, n·l_j))  +  m.specular * Σ L_j s_j

where ``L_j`` is light j's colour × intensity (÷ d² for a point light) and ``s_j`` the Blinn-Phong
(or Phong) highlight. Colours are linear RGB; nothing is clamped here.

**Linear and sRGB.** All shading happens on *linear* RGB, proportional to light power, because only there
do adding lights and averaging samples mean what they mean physically. Images are encoded to sRGB
(IEC 61966-2-1) only on their way to a screen or a PNG, and 8-bit image textures, stored sRGB-encoded by
convention, are decoded on load: :func:`linear_to_srgb` and :func:`srgb_to_linear`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence, Union

import torch

from course.tensors import _check_finite, _check_real, _is_zero, as_tensor, unit_scale
from course.textures import mip_level, mip_pyramid, sample_texture, sample_texture_mip, uv_derivatives

__all__ = [
    "AmbientLight", "DirectionalLight", "PointLight", "Material",
    "normalize", "lambert", "blinn_phong", "phong", "sample_texture", "light_terms", "shade",
    "view_directions", "flat_shading", "gouraud_shading", "phong_shading", "edge_distance",
    "wireframe_overlay", "linear_to_srgb", "srgb_to_linear", "mip_level", "mip_pyramid", "uv_derivatives",
    "sample_texture_mip",
]

EPS = 1e-12            # lengths below sqrt(EPS) count as zero in normalize()

Color = Union[float, Sequence[float], torch.Tensor]


# ------------------------------------------------------------------------------------------------ lights

@dataclass
class AmbientLight:
    """Light arriving equally from every direction: adds ``color * intensity`` times the base colour."""
    color: Color = (1.0, 1.0, 1.0)
    intensity: float = 0.2


@dataclass
class DirectionalLight:
    """A light infinitely far away (the sun). ``direction`` (3,), world space, is the way the light
    *travels*: ``(0, -1, 0)`` shines straight down. The vector toward the light is ``-direction``."""
    direction: Color = (0.0, -1.0, 0.0)
    color: Color = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    cast_shadows: bool = True        # used when render() draws shadows (RenderSettings.shadows)

    def incident(self, points_world: torch.Tensor):
        """points_world: (..., 3). Returns unit ``light_dir`` (..., 3) toward the light and radiance (..., 3)."""
        d = _light_vector(self.direction, "DirectionalLight.direction", points_world)
        if _is_zero(d):
            raise ValueError("DirectionalLight.direction must be a non-zero vector (the way the light travels)")
        light_dir = normalize(-unit_scale(d)).expand_as(points_world)      # any magnitude (1e-200, 1e200)
        return light_dir, _radiance(self.color, self.intensity, points_world).expand_as(points_world)


@dataclass
class PointLight:
    """A light at ``position`` (3,), world space, shining in every direction.

    With ``falloff=True`` (default) the arriving radiance is ``color * intensity / d²`` (inverse square law,
    d = distance to the light), so ``intensity`` is the brightness at distance 1; ``falloff=False`` drops it.
    """
    position: Color = (0.0, 2.0, 2.0)
    color: Color = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    falloff: bool = True
    cast_shadows: bool = True        # used when render() draws shadows (RenderSettings.shadows)

    def incident(self, points_world: torch.Tensor):
        """points_world: (..., 3). Returns unit ``light_dir`` (..., 3) toward the light and radiance (..., 3)."""
        p = _light_vector(self.position, "PointLight.position", points_world)
        to_light = p - points_world                                          # (..., 3)
        radiance = _radiance(self.color, self.intensity, points_world)
        if self.falloff:
            dist2 = (to_light * to_light).sum(-1, keepdim=True).clamp_min(1e-8)
            radiance = radiance / dist2                                      # inverse square law
        return normalize(to_light), radiance.expand_as(points_world)


def _light_vector(v, name: str, like: torch.Tensor) -> torch.Tensor:
    """A light's direction or position: (3,) finite, in ``like``'s dtype and device."""
    v = as_tensor(v, dtype=like.dtype, device=like.device, name=name)
    if v.shape != (3,):
        raise ValueError(f"{name} must have shape (3,), got {tuple(v.shape)}")
    _check_finite(v, name)
    return v


def _radiance(color, intensity, like: torch.Tensor) -> torch.Tensor:
    """color × intensity as an RGB tensor (3,) of ``like``'s dtype and device."""
    c = as_tensor(color, dtype=like.dtype, device=like.device, name="light color")
    k = as_tensor(intensity, dtype=like.dtype, device=like.device, name="light intensity")
    if c.shape not in ((), (1,), (3,)):
        raise ValueError(f"light color must be one number or RGB (3,), got shape {tuple(c.shape)}")
    if k.numel() != 1:
        raise ValueError(f"light intensity must be one number, got shape {tuple(k.shape)}")
    _check_finite(c, "light color"), _check_finite(k, "light intensity")
    return c.expand(3) * k.reshape(())


# ---------------------------------------------------------------------------------------------- material

@dataclass
class Material:
    """How a surface answers light. ``ambient``, ``diffuse``, ``specular`` are scalars or RGB (3,) factors;
    ``shininess`` is the Blinn-Phong exponent (higher: smaller, sharper highlight).

    ``base_color`` (RGB) colours the surface where the mesh has neither a texture nor vertex colours.
    ``specular_model`` picks ``"blinn_phong"`` (half vector, the default) or ``"phong"`` (mirror vector).
    Fields may be tensors that require grad.
    """
    ambient: Color = 1.0
    diffuse: Color = 1.0
    specular: Color = 0.3
    shininess: Union[float, torch.Tensor] = 32.0
    base_color: Color = (0.7, 0.7, 0.7)
    specular_model: str = "blinn_phong"

    def __post_init__(self):
        if self.specular_model not in ("blinn_phong", "phong"):
            raise ValueError(f"specular_model must be 'blinn_phong' or 'phong', got {self.specular_model!r}")


# ---------------------------------------------------------------------------------------- pure lighting

def normalize(v, eps: float = EPS) -> torch.Tensor:
    """v: (..., 3) → unit vectors (..., 3). A zero vector stays zero (no NaN, in value or gradient):
    the length is ``sqrt(max(|v|², eps))``."""
    v = as_tensor(v, name="vector")
    _check_finite(v, "vector")
    return v / (v * v).sum(-1, keepdim=True).clamp_min(eps).sqrt()


def _dot(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Dot product over the last axis: (..., 3), (..., 3) → (...)."""
    return (a * b).sum(-1)


def _vectors(x, name: str, like: torch.Tensor | None = None) -> torch.Tensor:
    """(..., 3) direction vectors, finite; with ``like``, in its dtype and device and broadcastable to it."""
    x = as_tensor(x, name=name) if like is None else as_tensor(x, dtype=like.dtype, device=like.device, name=name)
    if x.shape[-1:] != (3,):
        raise ValueError(f"{name} must have shape (..., 3), got {tuple(x.shape)}")
    if like is not None:
        _check_broadcast(x, like, name)
    _check_finite(x, name)
    return x


def _check_broadcast(x: torch.Tensor, like: torch.Tensor, name: str) -> None:
    """x must broadcast to like's shape (never enlarge it)."""
    try:
        ok = torch.broadcast_shapes(x.shape, like.shape) == like.shape
    except RuntimeError:
        ok = False
    if not ok:
        raise ValueError(f"{name} must have shape {tuple(like.shape)} or broadcast to it, got {tuple(x.shape)}")


def _unit_pair(normal, light_dir):
    """Tensors of one dtype/device (the normal's), both normalised."""
    n = _vectors(normal, "normal")
    l = _vectors(light_dir, "light_dir", n)
    return normalize(n), normalize(l)


def lambert(normal, light_dir, albedo) -> torch.Tensor:
    """Lambert's cosine law: ``albedo * max(0, n·l)``.

    normal: (N, 3) (any leading shape ``...``); light_dir: (N, 3) or (3,), pointing toward the light;
    albedo: (N, 3) or (3,). Both directions are normalised first. Returns (N, 3).
    d/dn is ``albedo ⊗ l`` where n·l > 0 and 0 elsewhere (clamp's subgradient).
    """
    n, l = _unit_pair(normal, light_dir)
    albedo = _vectors(albedo, "albedo", n)
    cos = _dot(n, l).clamp_min(0.0)                                          # (N,)
    return albedo * cos[..., None]


def _highlight(cos: torch.Tensor, lit: torch.Tensor, shininess) -> torch.Tensor:
    """max(0, cos)^shininess where ``lit``, else 0 — with a finite gradient for every exponent.

    ``torch.where`` alone leaks NaN from the unused branch (0^(s-1) · 0 with s < 1), so the cosine is
    first replaced by 1 where the highlight is off: the classic "safe where".
    """
    cos, lit = torch.broadcast_tensors(cos, lit)
    on = lit & (cos > 0)
    safe = torch.where(on, cos, torch.ones_like(cos))
    s = as_tensor(shininess, dtype=cos.dtype, device=cos.device, name="shininess")
    _check_broadcast(s, cos, "shininess")
    _check_finite(s, "shininess")
    if bool((s.detach() < 0).any()):
        raise ValueError(f"shininess must be >= 0 (the highlight's exponent), got {float(s.detach().min()):g}")
    return torch.where(on, safe ** s, torch.zeros_like(cos))


def blinn_phong(normal, light_dir, view_dir, shininess) -> torch.Tensor:
    """Blinn-Phong highlight: ``max(0, n·h)^shininess`` with the half vector ``h = normalize(l + v)``.

    normal: (N, 3); light_dir: (N, 3) or (3,), toward the light; view_dir: (N, 3) or (3,), toward the viewer;
    shininess: scalar or (N,). Returns (N,). Zero where n·l <= 0 (a light behind the surface makes no
    highlight). The peak, 1, is where h = n: the surface would mirror the light into the eye.
    """
    n, l = _unit_pair(normal, light_dir)
    v = normalize(_vectors(view_dir, "view_dir", n))
    h = normalize(l + v)                                                     # half vector (zero if l = -v)
    lit = _dot(n, l) > 0
    return _highlight(_dot(n, h), lit, shininess)


def phong(normal, light_dir, view_dir, shininess) -> torch.Tensor:
    """Phong highlight: ``max(0, r·v)^shininess`` with the mirror direction ``r = 2 (n·l) n - l``.

    Same arguments and shapes as :func:`blinn_phong`; returns (N,), zero where n·l <= 0. For the same
    exponent Phong's highlight is tighter (r·v falls off about twice as fast as n·h).
    """
    n, l = _unit_pair(normal, light_dir)
    v = normalize(_vectors(view_dir, "view_dir", n))
    n_dot_l = _dot(n, l)
    r = 2 * n_dot_l[..., None] * n - l                                       # mirror of l about n, unit
    return _highlight(_dot(r, v), n_dot_l > 0, shininess)


def _factor(x, like: torch.Tensor, name: str) -> torch.Tensor:
    """A material factor (scalar, (3,) or (..., 3)) as a tensor broadcastable to ``like`` (..., 3)."""
    t = as_tensor(x, dtype=like.dtype, device=like.device, name=name)
    given = tuple(t.shape)
    t = t[..., None] if t.dim() >= 1 and t.shape[-1] != 3 else t            # (N,) per-point scalars → (N, 1)
    try:
        ok = torch.broadcast_shapes(t.shape, like.shape) == like.shape
    except RuntimeError:
        ok = False
    if not ok:
        raise ValueError(f"{name} must be one number, RGB (3,), or one of those per point, got shape "
                         f"{given} for points of shape {tuple(like.shape)}")
    _check_finite(t, name)
    return t


def light_terms(points_world, normals, view_dirs, lights, material: Material | None = None):
    """The two halves of the shading model, before the base colour is applied.

    points_world: (..., 3); normals: (..., 3) (need not be unit); view_dirs: (..., 3) toward the viewer;
    lights: a sequence of AmbientLight / DirectionalLight / PointLight. Returns ``diffuse`` (..., 3), the
    factor the base colour is multiplied by (ambient + Lambert terms), and ``specular`` (..., 3), added on
    top. Gouraud shading interpolates these two across a face; Phong shading evaluates them per pixel.
    """
    material = material or Material()
    if not isinstance(material, Material):
        raise TypeError(f"material must be a Material, got {type(material).__name__}")
    if isinstance(lights, (AmbientLight, DirectionalLight, PointLight)) or not hasattr(lights, "__iter__"):
        raise TypeError(f"lights must be a sequence of lights, got {type(lights).__name__} (wrap one light in a "
                        "list: [light])")
    p = _vectors(points_world, "points_world")
    n = normalize(_vectors(normals, "normals", p))
    v = _vectors(view_dirs, "view_dirs", p)
    kd = _factor(material.diffuse, p, "material.diffuse")
    ks = _factor(material.specular, p, "material.specular")
    highlight = blinn_phong if material.specular_model == "blinn_phong" else phong
    diffuse = torch.zeros_like(p)
    specular = torch.zeros_like(p)
    for light in lights:
        if isinstance(light, AmbientLight):
            ka = _factor(material.ambient, p, "material.ambient")
            diffuse = diffuse + ka * _radiance(light.color, light.intensity, p)
        elif isinstance(light, (DirectionalLight, PointLight)):
            l, radiance = light.incident(p)                                  # (..., 3), (..., 3)
            diffuse = diffuse + lambert(n, l, kd * radiance)
            s = highlight(n, l, v, material.shininess)                       # (...,)
            specular = specular + ks * radiance * s[..., None]
        else:
            raise TypeError(f"unknown light {type(light).__name__}; use AmbientLight, DirectionalLight "
                            "or PointLight")
    return diffuse, specular


def shade(points_world, normals, view_dirs, base_color, lights, material: Material | None = None) -> torch.Tensor:
    """Colour of surface points: ``base_color * diffuse + specular`` (see :func:`light_terms`).

    points_world, normals, view_dirs: (..., 3) world space; base_color: (..., 3) or (3,); lights: sequence of
    lights; material: a :class:`Material` (default ``Material()``). Returns (..., 3), linear RGB, unclamped.
    """
    diffuse, specular = light_terms(points_world, normals, view_dirs, lights, material)
    return _combine(base_color, diffuse, specular)


# ------------------------------------------------------------------------------------ Fragments plumbing

def view_directions(points_world: torch.Tensor, camera) -> torch.Tensor:
    """points_world: (..., 3) → unit directions (..., 3) toward the camera: to the eye for a perspective
    camera, the constant ``-forward`` (minus the third row of R) for an orthographic one."""
    _check_camera(camera)
    if camera.orthographic:
        return (-camera.R[2]).to(points_world.dtype).expand_as(points_world)
    return normalize(camera.eye.to(points_world.dtype) - points_world)


def _check_camera(camera) -> None:
    from course.raster import _is_camera
    if not _is_camera(camera):
        raise TypeError(f"camera must be a course.camera.Camera, got {type(camera).__name__}")


def _check_fragments(fragments, mesh=None) -> None:
    """Fragments from rasterize / raycast (face_id (H, W), bary (H, W, 3)), their faces inside ``mesh``."""
    if not (hasattr(fragments, "face_id") and hasattr(fragments, "bary")):
        raise TypeError(f"fragments must be Fragments (from rasterize or raycast), got {type(fragments).__name__}")
    if mesh is not None and fragments.face_id.numel() and int(fragments.face_id.max()) >= mesh.faces.shape[0]:
        raise ValueError(f"fragments reference face {int(fragments.face_id.max())} but the mesh has "
                         f"{mesh.faces.shape[0]} faces: were they rasterized from this mesh?")


def _face_material(material, index, like):
    """``material`` as it applies to each element of ``index`` (face or vertex ids).

    material: one Material, or a pair (materials, material_id) with material_id (F,) or (V,) int64 picking
    one of ``materials`` per element; ``index``: (...) int64 into that table. Returns a Material whose
    factors are (..., 3) tensors (a single Material is returned unchanged: nothing to gather).
    """
    if isinstance(material, Material) or material is None:
        return material
    materials, material_id = material
    mid = material_id[index.clamp_min(0)]                                    # (...) material per element
    def table(field):
        rows = [as_tensor(getattr(m, field), dtype=like.dtype, device=like.device).expand(3) for m in materials]
        return torch.stack(rows)[mid]                                        # (..., 3)
    shininess = torch.stack([as_tensor(m.shininess, dtype=like.dtype, device=like.device).reshape(())
                             for m in materials])[mid]                       # (...)
    model = {m.specular_model for m in materials}
    if len(model) > 1:
        raise ValueError("all materials of one scene must use the same specular_model")
    return Material(table("ambient"), table("diffuse"), table("specular"), shininess,
                    specular_model=model.pop())


def flat_shading(mesh, fragments, camera, lights, material, base_color) -> torch.Tensor:
    """Flat shading: one lighting evaluation per face, at its centroid with its face normal.

    fragments: the rasterizer's Fragments (H × W); base_color: (H, W, 3) or (3,), applied per pixel (so a
    texture still varies across a face). material: a Material, or ``(materials, face_material (F,))``.
    Returns (H, W, 3); empty pixels get face 0's lighting (finite) and are meant to be composited away.
    """
    _check_fragments(fragments, mesh), _check_camera(camera)
    centroids = mesh.verts[mesh.faces].mean(1)                               # (F, 3) world
    mat = _face_material(material, torch.arange(mesh.num_faces, device=mesh.faces.device), centroids)
    diffuse_f, specular_f = light_terms(centroids, mesh.face_normals(), view_directions(centroids, camera),
                                        lights, mat)                         # (F, 3) each
    face = fragments.face_id.clamp_min(0)                                    # (H, W); empty → face 0
    return _combine(base_color, diffuse_f[face], specular_f[face])


def gouraud_shading(mesh, fragments, camera, lights, material, base_color, vert_normals=None) -> torch.Tensor:
    """Gouraud shading: light every vertex (with its vertex normal), then interpolate the two lighting terms
    across each face with the perspective-correct barycentrics. Highlights smaller than a face get lost.

    material: a Material, or ``(materials, vert_material (V,))``. vert_normals: (V, 3), default
    ``mesh.vertex_normals()``. Returns (H, W, 3).
    """
    from course.raster import interpolate
    _check_fragments(fragments, mesh), _check_camera(camera)
    verts = mesh.verts                                                       # (V, 3) world
    normals = mesh.vertex_normals() if vert_normals is None else _vert_normals(vert_normals, verts)
    mat = _face_material(material, torch.arange(mesh.num_verts, device=mesh.faces.device), verts)
    diffuse_v, specular_v = light_terms(verts, normals, view_directions(verts, camera), lights, mat)
    diffuse = interpolate(diffuse_v, fragments, mesh.faces)                  # (H, W, 3)
    specular = interpolate(specular_v, fragments, mesh.faces)                # (H, W, 3)
    return _combine(base_color, diffuse, specular)


def phong_shading(mesh, fragments, camera, lights, material, base_color, vert_normals=None):
    """Phong shading: interpolate vertex normals (and positions) to every pixel, renormalise, light per pixel.

    material: a Material, or ``(materials, face_material (F,))``. Returns the colour (H, W, 3) and the
    unit per-pixel normals (H, W, 3) (zero where nothing is hit).
    """
    from course.raster import interpolate
    _check_fragments(fragments, mesh), _check_camera(camera)
    normals_v = mesh.vertex_normals() if vert_normals is None else _vert_normals(vert_normals, mesh.verts)
    points = interpolate(mesh.verts, fragments, mesh.faces)                  # (H, W, 3) world
    normals = normalize(interpolate(normals_v, fragments, mesh.faces))       # (H, W, 3) unit (0 if empty)
    mat = _face_material(material, fragments.face_id, points)
    diffuse, specular = light_terms(points, normals, view_directions(points, camera), lights, mat)
    return _combine(base_color, diffuse, specular), normals


def _vert_normals(vert_normals, verts) -> torch.Tensor:
    n = as_tensor(vert_normals, dtype=verts.dtype, device=verts.device, name="vert_normals")
    if n.shape != verts.shape:
        raise ValueError(f"vert_normals must have shape (V, 3) = {tuple(verts.shape)}, got {tuple(n.shape)}")
    _check_finite(n, "vert_normals")
    return n


def _combine(base_color, diffuse, specular):
    base = _vectors(base_color, "base_color", diffuse)
    return base * diffuse + specular


def edge_distance(mesh, fragments, camera) -> torch.Tensor:
    """Screen-space distance, in pixels, from each pixel centre to the nearest edge of the face it sees.

    Returns (H, W), +inf where nothing is hit. For a pixel centre p inside triangle (a, b, c) the nearest
    boundary point lies on one of the three edge lines, at distance ``|edge_function(a, b, p)| / |b - a|``
    (twice the area of (a, b, p) over the base length). Vertices behind a perspective camera project to
    meaningless pixels, so edges of near-clipped faces may be misplaced.
    """
    _check_fragments(fragments, mesh), _check_camera(camera)
    H, W = fragments.face_id.shape
    mask = fragments.face_id >= 0
    verts_screen, _ = camera.project(mesh.verts)                             # (V, 2) pixel coordinates
    tri = verts_screen[mesh.faces[fragments.face_id[mask]]]                 # (N, 3, 2) visible triangles
    rows, cols = mask.nonzero(as_tuple=True)
    p = torch.stack([cols, rows], -1).to(tri.dtype) + 0.5                    # (N, 2) pixel centres
    a, b = tri, tri.roll(-1, dims=1)                                         # edges a→b: 0→1, 1→2, 2→0
    e = b - a                                                                # (N, 3, 2)
    cross = e[..., 0] * (p[:, None, 1] - a[..., 1]) - e[..., 1] * (p[:, None, 0] - a[..., 0])
    dist = cross.abs() / (e * e).sum(-1).clamp_min(EPS).sqrt()               # (N, 3) to each edge line
    out = torch.full((H, W), float("inf"), dtype=tri.dtype, device=tri.device)
    out[mask] = dist.min(-1).values
    return out


def wireframe_overlay(image, mesh, fragments, camera, width: float = 1.0, color=(0.0, 0.0, 0.0)) -> torch.Tensor:
    """Draw the visible triangle edges over ``image`` (H, W, 3): lines ``width`` pixels wide in ``color``.

    A pixel's line coverage is ``clamp(width/2 + 0.5 - d, 0, 1)``, d = :func:`edge_distance`: full inside
    the line, fading linearly over one pixel at its border (a cheap antialiased line). Only edges of the
    faces that win the z-test are drawn, so hidden lines are removed for free.
    """
    width = _check_real(width, "width", low=0, low_open=True)
    d = edge_distance(mesh, fragments, camera)                               # (H, W) pixels
    image = as_tensor(image, dtype=d.dtype if not torch.is_tensor(image) else None, device=d.device, name="image")
    if image.shape != (*d.shape, 3):
        raise ValueError(f"image must have the fragments' shape (H, W, 3) = {(*d.shape, 3)}, got "
                         f"{tuple(image.shape)}")
    coverage = (width / 2 + 0.5 - d).clamp(0, 1)[..., None].to(image.dtype)  # (H, W, 1); 0 where empty
    line = as_tensor(color, dtype=image.dtype, device=image.device, name="wireframe color")
    if line.shape not in ((), (3,)):
        raise ValueError(f"color must be RGB (3,), got shape {tuple(line.shape)}")
    return image * (1 - coverage) + line * coverage


# ------------------------------------------------------------------------------------------------- sRGB

SRGB_LINEAR_MAX = 0.0031308     # linear values up to here use the straight segment of the sRGB curve
SRGB_ENCODED_MAX = 0.04045      # ... which ends at this encoded value (12.92 × 0.0031308)


def linear_to_srgb(linear) -> torch.Tensor:
    """Encode linear RGB for display (IEC 61966-2-1): ``12.92 x`` for x <= 0.0031308, else
    ``1.055 x^(1/2.4) - 0.055``.

    linear: (...) any shape (colour channels only: do not pass alpha), dtype and device kept. Values are
    not clamped: below 0 the straight segment continues, above 1 the power curve. Differentiable
    everywhere; the power branch only ever sees x >= 0.0031308, so its gradient stays finite (a "safe where").
    """
    x = as_tensor(linear, name="linear colour")
    _check_finite(x, "linear colour", allow_inf=True)
    curve = x > SRGB_LINEAR_MAX
    safe = torch.where(curve, x, torch.ones_like(x))                        # keeps x^(1/2.4)'s gradient finite
    return torch.where(curve, 1.055 * safe ** (1 / 2.4) - 0.055, 12.92 * x)


def srgb_to_linear(encoded) -> torch.Tensor:
    """Decode sRGB values (in [0, 1], e.g. 8-bit texels / 255) to linear RGB (IEC 61966-2-1): ``c / 12.92``
    for c <= 0.04045, else ``((c + 0.055) / 1.055)^2.4``. The exact inverse of :func:`linear_to_srgb`.

    encoded: (...) any shape, float dtype and device kept. The range is not guessed: divide 8-bit values by
    255 first (integers are only converted to torch's default dtype). Differentiable everywhere.
    """
    c = as_tensor(encoded, name="sRGB colour")
    _check_finite(c, "sRGB colour", allow_inf=True)
    curve = c > SRGB_ENCODED_MAX
    safe = torch.where(curve, c, torch.ones_like(c))
    return torch.where(curve, ((safe + 0.055) / 1.055) ** 2.4, c / 12.92)
