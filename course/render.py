"""Scenes and ``render()``: plan the passes a scene needs, run them in order, skip the rest.

::

    plan ─▶ join meshes ─▶ rasterize (cull) ─▶ base colour (texture / vertex colours / material)
         ─▶ normals ─▶ shadow maps or a BVH for shadow rays (lights that cast shadows)
         ─▶ lighting (flat | Gouraud | Phong)
         ─▶ composite over the background
         ─▶ antialias: detect edge pixels, shade k × k samples there (or everywhere), box-filter ─▶ wireframe

Each stage runs only when the scene and settings need it: an unlit scene (or one without lights) computes
no normals and no lighting; a mesh without a texture makes no UV lookups; when nothing requires a gradient
the whole render runs under ``torch.no_grad()``; several meshes are joined once, with a per-face mesh index
that picks each face's material. ``RenderResult.passes`` lists the stages that ran, so a test (or a
curious student) can see a skip happen.

The degrees of realism of lecture 04 are one setting each: ``shading="wireframe"``, ``"silhouette"``
(visibility, one flat colour per mesh), ``"flat"``, ``"gouraud"`` / ``"phong"`` (smooth, Blinn-Phong
highlights), and any of these on a textured mesh. ``"unlit"`` shows base colours; ``"depth"`` and
``"normals"`` visualise the G-buffer.

Antialiasing (lecture 05) is a setting too: ``antialias="supersample"`` shades k × k samples in every pixel
and box-filters them; ``"adaptive"`` does so only in the pixels a discontinuity touches (silhouettes,
occlusion, intersections, material changes; every edge under flat shading), and skips the samples entirely
when no pixel needs them. Textures are filtered by mipmaps (``texture_filter="trilinear"``), which
supersampling alone does not replace. Shadows (lectures 06-07) come from shadow maps or shadow rays
(``shadows="map"`` / ``"rays"``), and differentiable visibility (lecture 08) from ``visibility="nmr"`` (the
same image with NMR's gradient) or ``"soft"`` (soft rasterization of per-vertex or per-face colours, and
of a texture read per pixel and face).
The scene helpers ``frame_camera`` and ``default_lights`` live in ``course.framing``; the command line in
``course.render_cli``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import torch

from course.antialias import resolve, sample_fragments
from course.discontinuities import discontinuity_pixels
from course.camera import Camera
from course.framing import default_lights, frame_camera
from course.mesh import Mesh
from course.raster import Fragments, _is_camera, interpolate, rasterize
from course.raytrace import BVH
from course.raytrace import visible as ray_visible
from course.shading import (
    AmbientLight, DirectionalLight, Material, PointLight, _face_material, flat_shading, gouraud_shading, light_terms,
    mip_pyramid, normalize, phong_shading, sample_texture, sample_texture_mip, uv_derivatives, view_directions,
    wireframe_overlay,
)
from course.shadows.maps import shadow_factor, shadow_map
from course.nmr import nmr_image
from course.soft import soft_rasterize
from course.tensors import _check_count, _check_flag, _check_real, as_tensor

__all__ = ["Scene", "RenderSettings", "RenderResult", "render", "plan_passes", "frame_camera",
           "default_lights", "SHADING_MODES"]

SHADING_MODES = ("phong", "gouraud", "flat", "unlit", "silhouette", "wireframe", "depth", "normals")
LIT_MODES = ("phong", "gouraud", "flat")
COLOR_MODES = LIT_MODES + ("unlit",)                       # modes that show textures and vertex colours
FORCEABLE = ("normals", "lighting", "texture", "autograd")
ANTIALIAS_MODES = ("none", "supersample", "adaptive")
SHADOW_MODES = ("none", "map", "rays")
TEXTURE_FILTERS = ("bilinear", "nearest", "trilinear")
VISIBILITY_MODES = ("hard", "nmr", "soft")
SOFT_SHADING = ("phong", "gouraud", "flat", "unlit", "silhouette")


# -------------------------------------------------------------------------------------- scene and settings

@dataclass
class Scene:
    """What to draw: ``meshes`` (one Mesh or a sequence), seen by ``camera``, lit by ``lights``.

    background: RGB (3,) where nothing is hit. materials: None (``Material()`` for every mesh), one
    Material for all meshes, or one per mesh. A scene without lights is drawn unlit (base colours).
    """
    meshes: object
    camera: Camera
    lights: Sequence = ()
    background: object = (1.0, 1.0, 1.0)
    materials: object = None

    def __post_init__(self):
        meshes = (self.meshes,) if isinstance(self.meshes, Mesh) else tuple(self.meshes or ())
        if not meshes:
            raise ValueError("the scene has no meshes; give Scene(meshes=mesh or [mesh, ...], ...)")
        for i, m in enumerate(meshes):
            if not isinstance(m, Mesh):
                raise TypeError(f"scene mesh {i} is a {type(m).__name__}, not a Mesh (course.mesh.Mesh)")
        if not _is_camera(self.camera):
            raise TypeError(f"camera must be a course.camera.Camera, got {type(self.camera).__name__}")
        if self.camera.width < 1 or self.camera.height < 1:
            raise ValueError(f"the camera image is empty ({self.camera.width}x{self.camera.height} pixels)")
        _check_background(self.background)
        if self.lights is None:
            self.lights = ()
        one_light = isinstance(self.lights, (AmbientLight, DirectionalLight, PointLight))
        if one_light or not hasattr(self.lights, "__iter__"):
            raise TypeError(f"lights must be a sequence of lights, got {type(self.lights).__name__} (wrap one light "
                            "in a list: [light])")
        for i, light in enumerate(self.lights):
            if not isinstance(light, (AmbientLight, DirectionalLight, PointLight)):
                raise TypeError(f"scene light {i} is a {type(light).__name__}; use AmbientLight, DirectionalLight or "
                                "PointLight")
        self.meshes, self.lights = meshes, tuple(self.lights)
        self.materials = _materials_per_mesh(self.materials, len(meshes))
        for m in meshes:
            if m.verts.dtype != self.camera.dtype:
                raise ValueError(f"meshes are {m.verts.dtype} but the camera is {self.camera.dtype}; "
                                 "convert one with .to(dtype=...)")


def _check_background(bg) -> None:
    try:
        t = as_tensor(bg)
        ok = t.numel() == 3 and bool(torch.isfinite(t.detach()).all())
    except (TypeError, ValueError, RuntimeError):
        ok = False
    if not ok:
        raise ValueError(f"background must be 3 numbers (RGB in [0, 1], finite), got {bg!r}")


def _materials_per_mesh(materials, n: int) -> tuple:
    if materials is None:
        return (Material(),) * n
    if isinstance(materials, Material):
        return (materials,) * n
    materials = tuple(materials)
    if len(materials) != n or not all(isinstance(m, Material) for m in materials):
        raise ValueError(f"materials must be one Material or one per mesh ({n}), got {len(materials)} items")
    return materials


@dataclass(frozen=True)
class RenderSettings:
    """How to draw a scene.

    shading: one of SHADING_MODES. texture_filter: ``"bilinear"``, ``"nearest"`` or ``"trilinear"`` (mipmapped,
    the level from each pixel's exact uv footprint: no moiré where the texture is minified). textures: use mesh
    textures (False: vertex or material colours instead). wireframe: draw visible edges on top
    (``wireframe_width`` pixels, ``wireframe_color``). cull_backfaces: skip faces seen from behind
    (clockwise on screen). clamp: clip the image to [0, 1] (gradients vanish where it clips).
    return_depth / return_normals / return_silhouette: fill those fields of the result.
    antialias: ``"none"`` (one sample at each pixel centre), ``"supersample"`` (``samples`` × ``samples``
    per pixel everywhere) or ``"adaptive"`` (that many only in the pixels a discontinuity of the image
    touches: silhouettes, occlusion, intersections, colour and material changes, seams; lecture 05).
    jitter: stratified jittered samples instead of a regular grid, from a hash of (``seed``, pixel, sample).
    With antialiasing the image and the silhouette are box-filtered (each sample clamped, then averaged);
    depth and normals come from the pixel centres, and the wireframe is drawn over the filtered image.
    shadows: ``"none"``, ``"map"`` (lecture 06: a shadow map per light whose ``cast_shadows`` is set,
    ``shadow_resolution`` texels a side, ``shadow_pcf`` × ``shadow_pcf`` percentage-closer filtering) or
    ``"rays"`` (lecture 07: a shadow ray per pixel and light through a BVH of the scene). A light's direct
    contribution (diffuse and highlight) is weighted per pixel by how lit the pixel is; ambient light is
    never shadowed.
    visibility (lecture 08): ``"hard"`` (the z-buffer: no gradient where visibility changes), ``"nmr"`` (the same
    image, with the Neural 3D Mesh Renderer's approximate gradient for vertex positions and the camera) or
    ``"soft"`` (soft rasterization, ``sigma`` / ``gamma`` / ``soft_threshold`` as in ``soft.soft_rasterize``: a
    blurred image, smooth in every vertex). Soft rasterization shades at the vertices (``"phong"`` and
    ``"gouraud"`` both give Gouraud shading) or per face (``"flat"``) and blends those colours; a one-mesh
    scene's texture is read per pixel and blended face (bilinearly, at the pixel's perspective-correct
    barycentrics in the face, as SoftRas does) and multiplied by that lighting. It draws ``"phong"``,
    ``"gouraud"``, ``"flat"``, ``"unlit"`` and ``"silhouette"``, without shadows, antialiasing or a wireframe
    (a clear error says so). ``soft_blend``: how the soft image meets the background, ``"softmax"`` (the
    paper: the background is one more term of the depth softmax) or ``"alpha"`` (the faces' softmax
    composited over the background by the soft silhouette: no fattening at small γ; ``soft.soft_rasterize``'s
    ``blend``). NMR needs ``antialias="none"``.
    """
    shading: str = "phong"
    texture_filter: str = "bilinear"
    textures: bool = True
    wireframe: bool = False
    wireframe_width: float = 1.0
    wireframe_color: tuple = (0.0, 0.0, 0.0)
    cull_backfaces: bool = False
    clamp: bool = True
    return_depth: bool = False
    return_normals: bool = False
    return_silhouette: bool = False
    antialias: str = "none"
    samples: int = 4
    jitter: bool = False
    seed: int = 0
    shadows: str = "none"
    shadow_resolution: int = 1024
    shadow_pcf: int = 1
    visibility: str = "hard"
    sigma: float = 1e-4
    gamma: float = 1e-4
    soft_threshold: float = 1e-4
    soft_blend: str = "softmax"

    def __post_init__(self):
        for name in ("textures", "wireframe", "cull_backfaces", "clamp", "return_depth", "return_normals",
                     "return_silhouette", "jitter"):
            _check_flag(getattr(self, name), name)
        _check_count(self.seed, "seed", minimum=0)
        _check_real(self.wireframe_width, "wireframe_width", low=0, low_open=True)
        try:
            color = as_tensor(self.wireframe_color)
            ok = color.shape == (3,) and bool(torch.isfinite(color).all())
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ValueError(f"wireframe_color must be 3 finite numbers (RGB), got {self.wireframe_color!r}")
        if self.shading not in SHADING_MODES:
            raise ValueError(f"unknown shading mode {self.shading!r}; choose one of {', '.join(SHADING_MODES)}")
        if self.texture_filter not in TEXTURE_FILTERS:
            raise ValueError(f"texture_filter must be one of {', '.join(map(repr, TEXTURE_FILTERS))}, "
                             f"got {self.texture_filter!r}")
        if not self.wireframe_width > 0:
            raise ValueError(f"wireframe_width must be positive (pixels), got {self.wireframe_width}")
        if self.antialias not in ANTIALIAS_MODES:
            raise ValueError(f"antialias must be one of {', '.join(map(repr, ANTIALIAS_MODES))}, "
                             f"got {self.antialias!r}")
        if isinstance(self.samples, bool) or not isinstance(self.samples, int) or self.samples < 1:
            raise ValueError(f"samples (per axis) must be a positive int, got {self.samples!r}")
        if self.shadows not in SHADOW_MODES:
            raise ValueError(f"shadows must be one of {', '.join(map(repr, SHADOW_MODES))}, got {self.shadows!r}")
        if isinstance(self.shadow_resolution, bool) or not isinstance(self.shadow_resolution, int) or \
                self.shadow_resolution < 1:
            raise ValueError(f"shadow_resolution must be a positive int, got {self.shadow_resolution!r}")
        if isinstance(self.shadow_pcf, bool) or not isinstance(self.shadow_pcf, int) or self.shadow_pcf < 1 or \
                self.shadow_pcf % 2 == 0:
            raise ValueError(f"shadow_pcf must be a positive odd int, got {self.shadow_pcf!r}")
        if self.visibility not in VISIBILITY_MODES:
            raise ValueError(f"visibility must be one of {', '.join(map(repr, VISIBILITY_MODES))}, "
                             f"got {self.visibility!r}")
        for name in ("sigma", "gamma", "soft_threshold"):
            _check_real(getattr(self, name), name, low=0, low_open=True)
        if self.soft_blend not in ("softmax", "alpha"):
            raise ValueError(f"soft_blend must be 'softmax' or 'alpha', got {self.soft_blend!r}")
        if self.visibility == "nmr" and self.antialias != "none":
            raise ValueError("visibility='nmr' needs antialias='none': its gradient is that of the pixel centres")
        if self.visibility == "soft":
            unsupported = {"antialias": self.antialias != "none", "shadows": self.shadows != "none",
                           "wireframe": self.wireframe, "shading": self.shading not in SOFT_SHADING}
            bad = [k for k, v in unsupported.items() if v]
            if bad:
                raise ValueError(f"visibility='soft' blends per-vertex or per-face colours and cannot draw "
                                 f"{', '.join(bad)} as set here (shading must be one of {', '.join(SOFT_SHADING)}; "
                                 "antialias 'none', shadows 'none', no wireframe)")


@dataclass(frozen=True)
class RenderResult:
    """image (H, W, 3) linear RGB. depth (H, W) camera z, +inf where empty; normals (H, W, 3) unit world
    normals, 0 where empty; silhouette (H, W) 1 where a face is hit — each only when asked for.
    fragments: the rasterizer's output. passes: names of the stages that ran, in order."""
    image: torch.Tensor
    depth: Optional[torch.Tensor] = None
    normals: Optional[torch.Tensor] = None
    silhouette: Optional[torch.Tensor] = None
    fragments: Optional[Fragments] = None
    passes: tuple = ()


# -------------------------------------------------------------------------------------------------- plan

def _has_texture(mesh) -> bool:
    return mesh.texture is not None and mesh.uvs is not None


def _tensors(obj):
    """The tensors held by a mesh, camera, light, material or colour (for the requires-grad check)."""
    if isinstance(obj, torch.Tensor):
        return [obj]
    names = ("verts", "vert_colors", "vert_normals", "uvs", "texture", "K", "R", "t", "color", "intensity",
             "direction", "position", "ambient", "diffuse", "specular", "shininess", "base_color")
    return [v for v in (getattr(obj, n, None) for n in names) if isinstance(v, torch.Tensor)]


def _needs_grad(scene: Scene) -> bool:
    objs = [*scene.meshes, scene.camera, *scene.lights, *scene.materials, scene.background]
    return torch.is_grad_enabled() and any(t.requires_grad for o in objs for t in _tensors(o))


def plan_passes(scene: Scene, settings: RenderSettings) -> tuple:
    """The stages ``render`` will run for this scene, in order (a subset of the module docstring's chain)."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a Scene, got {type(scene).__name__}")
    if not isinstance(settings, RenderSettings):
        raise TypeError(f"settings must be a RenderSettings, got {type(settings).__name__}")
    mode = settings.shading
    lit = mode in LIT_MODES and len(scene.lights) > 0                      # no lights: drawn unlit
    wanted = {
        "join": len(scene.meshes) > 1,
        "cull_backfaces": settings.cull_backfaces,
        "rasterize": settings.visibility != "soft" or settings.return_depth or settings.return_normals,
        "soft_rasterize": settings.visibility == "soft",
        "texture": mode in COLOR_MODES and settings.textures and any(map(_has_texture, scene.meshes)),
        "vertex_colors": mode in COLOR_MODES and any(m.vert_colors is not None for m in scene.meshes),
        "normals": lit or mode == "normals" or settings.return_normals,
        "shadow_maps": lit and settings.shadows == "map" and _casters(scene.lights) != [],
        "shadow_rays": lit and settings.shadows == "rays" and _casters(scene.lights) != [],
        "lighting": lit,
        "detect_edges": settings.antialias == "adaptive",                 # lecture 05: after shading the
        "supersample": settings.antialias != "none",                      # centres, refine edge pixels
        "wireframe": settings.wireframe or mode == "wireframe",
        "autograd": _needs_grad(scene),
    }
    wanted["nmr"] = settings.visibility == "nmr" and wanted["autograd"]    # the forward is the hard image
    if settings.visibility == "soft":                                       # lecture 08: no shadow passes
        wanted["shadow_maps"] = wanted["shadow_rays"] = False
    return tuple(name for name, on in wanted.items() if on)


# ----------------------------------------------------------------------------------------------- stages

@dataclass(frozen=True)
class _Geometry:
    """All meshes as one: ``mesh`` (joined), ``face_mesh`` (F,) and ``vert_mesh`` (V,) mesh index."""
    mesh: object
    face_mesh: torch.Tensor
    vert_mesh: torch.Tensor


def _join(meshes) -> _Geometry:
    dev = meshes[0].faces.device
    counts = lambda n: torch.tensor([n(m) for m in meshes], device=dev)
    face_mesh = torch.repeat_interleave(torch.arange(len(meshes), device=dev), counts(lambda m: m.faces.shape[0]))
    vert_mesh = torch.repeat_interleave(torch.arange(len(meshes), device=dev), counts(lambda m: m.verts.shape[0]))
    if len(meshes) == 1:
        return _Geometry(meshes[0], face_mesh, vert_mesh)
    # Geometry only: colours, uvs and textures stay per mesh (see _base_color), so unlike
    # course.mesh.join_meshes no texture atlas is built and bilinear lookups never bleed between tiles.
    offsets = torch.cumsum(torch.tensor([0] + [m.verts.shape[0] for m in meshes[:-1]], device=dev), 0)
    faces = torch.cat([m.faces + off for m, off in zip(meshes, offsets)])
    return _Geometry(Mesh(torch.cat([m.verts for m in meshes]), faces), face_mesh, vert_mesh)


def _per_vertex(meshes, attr: str, width: int, like: torch.Tensor) -> torch.Tensor:
    """One attribute of every mesh stacked to (V, width); zeros for meshes that lack it."""
    rows = [getattr(m, attr) if getattr(m, attr) is not None else torch.zeros(m.num_verts, width)
            for m in meshes]
    return torch.cat([as_tensor(r, dtype=like.dtype, device=like.device) for r in rows])


def _base_color(scene, geo, frags, settings, passes, spacing: float = 1.0):
    """Per-pixel colours (H, W, 3): the mesh's material colour, and the base colour (texture where the
    mesh has one, else vertex colours, else the material colour) when those passes run. spacing: the
    distance between samples in pixels (1/k for k x k supersampling), which scales a sample's uv footprint
    for the mip level: each sample should filter its own share of the pixel, not the whole pixel again."""
    like = geo.mesh.verts
    mesh_px = geo.face_mesh[frags.face_id.clamp_min(0)]                      # (H, W) mesh of each pixel
    table = torch.stack([as_tensor(m.base_color, dtype=like.dtype, device=like.device).expand(3)
                         for m in scene.materials])                          # (M, 3)
    material_color = base = table[mesh_px]                                   # (H, W, 3)
    if "vertex_colors" in passes:
        has = torch.tensor([m.vert_colors is not None for m in scene.meshes], device=like.device)
        colors = interpolate(_per_vertex(scene.meshes, "vert_colors", 3, like), frags, geo.mesh.faces)
        base = torch.where(has[mesh_px][..., None], colors, base)
    if "texture" in passes:
        uvs = _per_vertex(scene.meshes, "uvs", 2, like)                      # (V, 2)
        uv = interpolate(uvs, frags, geo.mesh.faces)                         # (H, W, 2)
        duv, pyramids = None, {}
        if settings.texture_filter == "trilinear":                           # footprints: (H, W, 2) each
            duv = [d * spacing for d in uv_derivatives(uvs, geo.mesh.faces, frags, geo.mesh.verts, scene.camera)]
        for k, m in enumerate(scene.meshes):
            if _has_texture(m):
                texture = as_tensor(m.texture, dtype=like.dtype, device=like.device)
                if duv is None:
                    texel = sample_texture(texture, uv, settings.texture_filter)   # (H, W, 3)
                else:
                    if id(m.texture) not in pyramids:                        # one pyramid per texture
                        pyramids[id(m.texture)] = mip_pyramid(texture)
                    texel = sample_texture_mip(pyramids[id(m.texture)], uv, *duv)
                base = torch.where((mesh_px == k)[..., None], texel[..., :3], base)
    return material_color, base


def _vertex_normals(meshes, like) -> torch.Tensor:
    """(V, 3) vertex normals of all meshes (each mesh's stored normals, else area-weighted)."""
    return torch.cat([as_tensor(m.vertex_normals(), dtype=like.dtype, device=like.device) for m in meshes])


def _pixel_normals(geo, frags, vert_normals, flat: bool) -> torch.Tensor:
    """(H, W, 3) unit world normals: the face normal (flat) or interpolated vertex normals; 0 where empty."""
    if flat:
        n = geo.mesh.face_normals()[frags.face_id.clamp_min(0)]
        return n * frags.mask[..., None]
    return normalize(interpolate(vert_normals, frags, geo.mesh.faces))


def _light(scene, geo, frags, mode, base, vert_normals, shadows=None, pcf: int = 1) -> torch.Tensor:
    """(H, W, 3) lit colour with the mode's interpolation (Phong when forced on for an unlit mode).

    shadows: {light index: ShadowMap or BVH} for the lights that cast shadows. Shading is linear in the
    lights, so each of those lights is shaded on its own and weighted per pixel by how lit the pixel is (its
    shadow map, or shadow rays through the BVH); the other lights are shaded together as before."""
    mats = scene.materials
    one = len(set(map(id, mats))) == 1
    per_face = mats[0] if one else (mats, geo.face_mesh)
    per_vert = mats[0] if one else (mats, geo.vert_mesh)

    def lit(lights):
        if mode == "flat":
            return flat_shading(geo.mesh, frags, scene.camera, lights, per_face, base)
        if mode == "gouraud":
            return gouraud_shading(geo.mesh, frags, scene.camera, lights, per_vert, base, vert_normals)
        return phong_shading(geo.mesh, frags, scene.camera, lights, per_face, base, vert_normals)[0]

    if not shadows:
        return lit(scene.lights)
    color = lit([l for k, l in enumerate(scene.lights) if k not in shadows])
    points = interpolate(geo.mesh.verts, frags, geo.mesh.faces).detach()   # (..., 3) world
    normals = geo.mesh.face_normals().detach()[frags.face_id.clamp_min(0)]  # geometric: for the slope bias
    for k, occluders in shadows.items():
        if isinstance(occluders, BVH):                                      # the side the camera sees
            toward = view_directions(points, scene.camera)
            n = torch.where(((normals * toward).sum(-1, keepdim=True) < 0), -normals, normals)
            light = scene.lights[k]
            directional = isinstance(light, DirectionalLight)
            target = light.direction if directional else light.position
            visible = ray_visible(points.reshape(-1, 3), target, occluders, directional=directional,
                                  normals=n.reshape(-1, 3)).to(points.dtype).view(points.shape[:-1])
        else:
            visible = shadow_factor(points.reshape(-1, 3), normals.reshape(-1, 3), occluders,
                                    pcf=pcf).view(points.shape[:-1])
        color = color + visible[..., None].to(color.dtype) * lit([scene.lights[k]])
    return color


def _casters(lights) -> list:
    """Indices of the lights that cast shadows (directional and point lights with ``cast_shadows``)."""
    return [k for k, l in enumerate(lights)
            if isinstance(l, (DirectionalLight, PointLight)) and getattr(l, "cast_shadows", False)]


def _shadow_maps(scene, geo, settings, passes) -> dict:
    """{light index: ShadowMap, or the scene's BVH for shadow rays} for the lights that cast shadows, when a
    shadow pass runs."""
    if "shadow_maps" in passes:
        return {k: shadow_map(geo.mesh, scene.lights[k], settings.shadow_resolution)
                for k in _casters(scene.lights)}
    if "shadow_rays" in passes:
        bvh = BVH(geo.mesh)                                                 # one BVH for every light
        return {k: bvh for k in _casters(scene.lights)}
    return {}


def _depth_range(frags):
    """Nearest and farthest visible depth (detached), or None where nothing is visible."""
    hit = frags.depth.detach()[frags.mask]
    return (hit.min(), hit.max()) if hit.numel() else None


def _depth_image(frags, depth_range=None) -> torch.Tensor:
    """(..., 3) grey: nearest visible depth white, farthest black (normalised over the hit pixels, or over
    ``depth_range``, the pixel-centre image's, so that samples are shaded like the pixels they refine)."""
    d = frags.depth
    if depth_range is None:
        hit = d[frags.mask]
        near, far = hit.min(), hit.max()
    else:
        near, far = depth_range
    grey = 1 - (d - near) / (far - near).clamp_min(1e-12)
    return torch.where(frags.mask, grey, torch.zeros_like(grey))[..., None].expand(*d.shape, 3)


def _composite(color, frags, background, settings) -> torch.Tensor:
    bg = as_tensor(background, dtype=color.dtype, device=color.device, name="background").reshape(3)
    image = torch.where(frags.mask[..., None], color, bg)                    # (H, W, 3)
    return image.clamp(0, 1) if settings.clamp else image


# ------------------------------------------------------------------------------------------------ render

def render(scene: Scene, settings: RenderSettings | None = None, *, _force: Sequence[str] = ()) -> RenderResult:
    """Render ``scene``; returns a :class:`RenderResult` (``.image`` is (H, W, 3) linear RGB).

    Only the passes the scene needs run (``result.passes`` names them). ``_force`` (private, for tests and
    benchmarks) turns skipped passes back on — one of ``FORCEABLE`` — to show each skip changes nothing.
    """
    settings = RenderSettings() if settings is None else settings
    if not isinstance(scene, Scene):
        raise TypeError(f"render() takes a Scene, got {type(scene).__name__}")
    if not isinstance(settings, RenderSettings):
        raise TypeError(f"settings must be a RenderSettings, got {type(settings).__name__}")
    unknown = set(_force) - set(FORCEABLE)
    if unknown:
        raise ValueError(f"cannot force {sorted(unknown)}; forceable passes: {', '.join(FORCEABLE)}")
    planned = plan_passes(scene, settings)
    passes = tuple(dict.fromkeys(planned + tuple(_force)))                  # planned, then forced extras
    grad_mode = torch.enable_grad() if "autograd" in passes else torch.no_grad()
    with grad_mode:
        return _run(scene, settings, passes)


def _run(scene: Scene, settings: RenderSettings, passes: tuple) -> RenderResult:
    geo = _join(scene.meshes)                                                # one mesh, per-face mesh index
    if "soft_rasterize" in passes:
        return _run_soft(scene, settings, passes, geo)
    frags = rasterize(geo.mesh, scene.camera, cull_backfaces=settings.cull_backfaces)
    if not frags.mask.any():                                                 # nothing visible: nothing to shade
        ran = tuple(p for p in passes if p in ("join", "cull_backfaces", "rasterize", "autograd"))
        empty = torch.zeros(*frags.shape, 3, dtype=geo.mesh.verts.dtype, device=geo.mesh.verts.device)
        return _result(_composite(empty, frags, scene.background, settings), frags, None, settings, ran)
    shadows = _shadow_maps(scene, geo, settings, passes)                    # before lighting, once per light
    color, pixel_normals = _shade(scene, geo, frags, settings, passes, shadows=shadows)
    wire = lambda img: wireframe_overlay(img, geo.mesh, frags, scene.camera, settings.wireframe_width,
                                         settings.wireframe_color)
    if "wireframe" in passes:
        color = wire(color)
    image = _composite(color, frags, scene.background, settings)            # (H, W, 3)
    silhouette = frags.mask.to(image.dtype)
    if "supersample" in passes:
        image, silhouette, ran = _supersample(scene, geo, frags, settings, passes, image, silhouette, shadows)
        passes = tuple(p for p in passes if p in ran or p not in ("detect_edges", "supersample"))
        if "wireframe" in passes and "supersample" in ran:                  # lines over the filtered image
            image = wire(image).clamp(0, 1) if settings.clamp else wire(image)
    if "nmr" in passes:                                                     # lecture 08: same image, NMR's gradient
        nmr = lambda img, values=None: nmr_image(img, geo.mesh, scene.camera, frags.face_id, face_values=values,
                                                 background=0.0 if values is not None else scene.background,
                                                 cull_backfaces=settings.cull_backfaces)
        image = nmr(image)
        if settings.return_silhouette:
            ones = torch.ones(geo.mesh.faces.shape[0], 1, dtype=silhouette.dtype, device=silhouette.device)
            silhouette = nmr(silhouette[..., None], ones)[..., 0]
    return _result(image, frags, pixel_normals, settings, passes, silhouette)


def _run_soft(scene: Scene, settings: RenderSettings, passes: tuple, geo) -> RenderResult:
    """Soft rasterization (lecture 08): colours at the vertices (or faces), blended by ``soft_rasterize``; a
    texture is read per pixel and face and multiplied by them."""
    mesh, camera, mode = geo.mesh, scene.camera, settings.shading
    like = mesh.verts
    bg = as_tensor(scene.background, dtype=like.dtype, device=like.device).reshape(3)
    soft = dict(sigma=settings.sigma, gamma=settings.gamma, threshold=settings.soft_threshold,
                cull_backfaces=settings.cull_backfaces)
    silhouette = None
    if mode == "silhouette" or settings.return_silhouette:
        silhouette = soft_rasterize(mesh, camera, mode="silhouette", **soft)     # (H, W)
    if mode == "silhouette":                                                # one flat colour per mesh's
        table = torch.stack([as_tensor(m.base_color, dtype=like.dtype, device=like.device).expand(3)
                             for m in scene.materials])                     # material, as in hard mode
        image = soft_rasterize(mesh, camera, mode="color", face_colors=table[geo.face_mesh], background=bg,
                               blend=settings.soft_blend, **soft)
    else:
        table = torch.stack([as_tensor(m.base_color, dtype=like.dtype, device=like.device).expand(3)
                             for m in scene.materials])
        base = table[geo.vert_mesh]                                         # (V, 3) material colour
        if "vertex_colors" in passes:
            has = torch.tensor([m.vert_colors is not None for m in scene.meshes], device=like.device)
            base = torch.where(has[geo.vert_mesh][:, None], _per_vertex(scene.meshes, "vert_colors", 3, like),
                               base)
        one = len(set(map(id, scene.materials))) == 1
        texture = _soft_texture(scene, like) if "texture" in passes else {}  # read per pair, times the lighting
        if "lighting" in passes and mode == "flat":                         # one colour per face, at its centroid
            points = mesh.verts[mesh.faces].mean(1)
            mat = scene.materials[0] if one else _face_material((scene.materials, geo.face_mesh),
                                                                 torch.arange(len(points), device=like.device), points)
            diffuse, specular = light_terms(points, mesh.face_normals(), view_directions(points, camera),
                                            scene.lights, mat)
            colors = dict(face_colors=diffuse, specular=specular) if texture else \
                dict(face_colors=base[mesh.faces].mean(1) * diffuse + specular)
        elif "lighting" in passes:                                          # Gouraud: lit at the vertices
            mat = scene.materials[0] if one else _face_material((scene.materials, geo.vert_mesh),
                                                                 torch.arange(len(like), device=like.device), like)
            normals = _vertex_normals(scene.meshes, like)
            diffuse, specular = light_terms(like, normals, view_directions(like, camera), scene.lights, mat)
            colors = dict(vertex_colors=diffuse, specular=specular) if texture else \
                dict(vertex_colors=base * diffuse + specular)
        else:
            colors = {} if texture else dict(vertex_colors=base)
        image = soft_rasterize(mesh, camera, mode="color", background=bg, blend=settings.soft_blend, **colors,
                               **texture, **soft)
    if settings.clamp:
        image = image.clamp(0, 1)
    frags = rasterize(mesh, camera, cull_backfaces=settings.cull_backfaces) if "rasterize" in passes else None
    normals = None
    if settings.return_normals:
        normals = _pixel_normals(geo, frags, _vertex_normals(scene.meshes, like), flat=mode == "flat")
    return RenderResult(image=image, depth=frags.depth if settings.return_depth else None, normals=normals,
                        silhouette=silhouette if settings.return_silhouette else None, fragments=frags,
                        passes=passes)


def _soft_texture(scene, like) -> dict:
    """The texture and uvs of a one-mesh scene, as ``soft_rasterize`` takes them (the soft path reads the
    texture per (pixel, face) pair, bilinearly, whatever ``texture_filter``)."""
    if len(scene.meshes) > 1:
        raise ValueError("visibility='soft' draws the texture of a one-mesh scene; join the meshes first "
                         "(course.mesh.join_meshes puts their textures into one atlas) or set textures=False")
    mesh = scene.meshes[0]
    return dict(texture=as_tensor(mesh.texture, dtype=like.dtype, device=like.device)[..., :3],
                uvs=as_tensor(mesh.uvs, dtype=like.dtype, device=like.device))


def _shade(scene, geo, frags, settings, passes, depth_range=None, spacing=1.0, shadows=None):
    """The colour of every fragment, (..., 3), and per-pixel normals when asked for; any fragments shape.
    shadows: the shadow maps of the lights that cast shadows ({light index: ShadowMap})."""
    material_color, base = _base_color(scene, geo, frags, settings, passes, spacing)   # texture / vertex colours
    vert_normals, pixel_normals = _normals(scene, geo, frags, settings, passes)
    lit = _light(scene, geo, frags, settings.shading, base, vert_normals, shadows,
                 settings.shadow_pcf) if "lighting" in passes else None
    return _pick_color(settings.shading, scene, frags, material_color, base, lit, pixel_normals,
                       depth_range), pixel_normals


def _edge_keys(geo, settings) -> torch.Tensor:
    """(F,) integers: faces with equal keys show no jump across a shared edge. Flat shading gives every
    face its own colour; otherwise the colour changes only between meshes (materials) and at seams."""
    if settings.shading == "flat":
        return torch.arange(geo.mesh.faces.shape[0], device=geo.mesh.faces.device)
    return geo.face_mesh


def _supersample(scene, geo, frags, settings, passes, image, silhouette, shadows=None):
    """Replace pixels of the one-sample image by the box filter of k x k samples: all of them, or (adaptive)
    those a discontinuity touches. Returns the image, the silhouette (covered fraction) and the passes run."""
    H, W = frags.shape
    k, ran = settings.samples, ("supersample",)
    pixels = None
    if settings.antialias == "adaptive":
        ran = ("detect_edges",)
        marked = discontinuity_pixels(geo.mesh, scene.camera, _edge_keys(geo, settings),
                                      cull_backfaces=settings.cull_backfaces, seams=settings.shading != "flat")
        pixels = marked.reshape(-1).nonzero().squeeze(1)
        if pixels.numel() == 0:                                              # no edge crosses a pixel: done
            return image, silhouette, ran
        ran += ("supersample",)
    sf = sample_fragments(geo.mesh, scene.camera, k, jitter=settings.jitter, seed=settings.seed, pixels=pixels,
                          cull_backfaces=settings.cull_backfaces)           # (P, S)
    if sf.mask.any():
        color, _ = _shade(scene, geo, sf, settings, passes, _depth_range(frags), 1 / k, shadows)
    else:
        color = torch.zeros(*sf.shape, 3, dtype=image.dtype, device=image.device)
    value = resolve(_composite(color, sf, scene.background, settings))      # (P, 3)
    cover = resolve(sf.mask.to(image.dtype)[..., None])[:, 0]               # (P,)
    if pixels is None:
        return value.view(H, W, 3), cover.view(H, W), ran
    # the other pixels' one sample stands for k² equal ones, summed the same way (bit-identical results)
    image = resolve(image.reshape(-1, 1, 3).expand(-1, k * k, -1))
    image = image.index_put((pixels,), value).view(H, W, 3)
    silhouette = silhouette.reshape(-1).index_put((pixels,), cover).view(H, W)
    return image, silhouette, ran


def _normals(scene, geo, frags, settings, passes):
    """Vertex normals (V, 3) and, when they are shown or returned, per-pixel normals (H, W, 3)."""
    if "normals" not in passes:
        return None, None
    vert_normals = _vertex_normals(scene.meshes, geo.mesh.verts)             # (V, 3)
    if settings.shading == "normals" or settings.return_normals:
        return vert_normals, _pixel_normals(geo, frags, vert_normals, flat=settings.shading == "flat")
    return vert_normals, None


def _pick_color(mode, scene, frags, material_color, base, lit, pixel_normals, depth_range=None) -> torch.Tensor:
    """(H, W, 3) the colour the shading mode shows (a pass forced on for another mode is left unused)."""
    if mode in LIT_MODES and lit is not None:
        return lit
    if mode == "silhouette":
        return material_color
    if mode == "wireframe":
        return as_tensor(scene.background, dtype=base.dtype, device=base.device).reshape(3).expand_as(base)
    if mode == "depth":
        return _depth_image(frags, depth_range).to(base.dtype)
    if mode == "normals":
        return (pixel_normals + 1) / 2
    return base                                                              # unlit, or lit without lights


def _result(image, frags, pixel_normals, settings, ran, silhouette=None) -> RenderResult:
    if settings.return_silhouette and silhouette is None:
        silhouette = frags.mask.to(image.dtype)
    return RenderResult(
        image=image,
        depth=frags.depth if settings.return_depth else None,
        normals=pixel_normals if settings.return_normals else None,
        silhouette=silhouette if settings.return_silhouette else None,
        fragments=frags,
        passes=tuple(ran),
    )
