"""Triangle meshes: the `Mesh` record, its normals, and loading any format trimesh reads.

Shapes: V vertices, F faces, Ht x Wt texture texels.

Conventions this module relies on (the full list is in DESIGN.md):

- ``faces`` is (F, 3) int64 into ``verts`` (V, 3). A face is front-facing when its vertices appear
  counter-clockwise to the viewer; its normal ``(v1 - v0) x (v2 - v0)`` points out of the front face.
- ``uvs`` are per vertex, u to the right and v up (OBJ / OpenGL). A texture is (Ht, Wt, 3) with row 0
  at the top, so uv (0, 0) is the bottom-left corner of the image.
- Colours are floats in [0, 1]. Integer colours (vertex colours or textures) are read as 0..255.

The bundled models (`cube`, `icosphere`, `plane`, `torus`, `teapot`, `checker_texture`,
`default_scene_mesh`) live in `course.models`, which builds them with this module's `Mesh`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from .tensors import _check_device, _check_dtype

__all__ = ["Mesh", "join_meshes", "load_mesh"]

_FLOAT_DTYPES = (torch.float32, torch.float64)


class Mesh:
    """A triangle mesh with optional per-vertex colours, normals, uvs and a texture image.

    Args:
        verts: (V, 3) float vertex positions. float32 and float64 tensors are kept as they are (the same
            tensor object, so a ``verts`` that requires grad stays the leaf you optimise); integer or
            half-precision input becomes float32. Every other attribute takes its dtype and device.
        faces: (F, 3) integer vertex indices, counter-clockwise seen from the front; stored as int64.
        vert_colors: (V, 3) colours in [0, 1] (integers are read as 0..255), or None.
        vert_normals: (V, 3) normals to use instead of the computed ones, or None.
        uvs: (V, 2) texture coordinates, u right and v up, or None.
        texture: (Ht, Wt, 3) or (Ht, Wt, 4) image, row 0 at the top; alpha is dropped and integers are
            read as 0..255. Needs ``uvs``.

    Raises:
        TypeError: an input is not a numeric array / tensor, or faces are not integers.
        ValueError: a shape does not match, an index is out of range, or a value is NaN / inf.
    """

    def __init__(self, verts, faces, *, vert_colors=None, vert_normals=None, uvs=None, texture=None):
        self.verts = _check_verts(verts)
        V = self.verts.shape[0]
        self.faces = _check_faces(faces, V, self.verts.device)
        self.vert_colors = _check_per_vertex(vert_colors, "vert_colors", 3, self.verts, colour=True)
        self.vert_normals = _check_per_vertex(vert_normals, "vert_normals", 3, self.verts)
        self.uvs = _check_per_vertex(uvs, "uvs", 2, self.verts)
        self.texture = _check_texture(texture, self.verts)
        if self.texture is not None and self.uvs is None:
            raise ValueError("a texture needs per-vertex texture coordinates: pass uvs with shape (V, 2)")

    # ---- basic facts -------------------------------------------------------------------------
    @property
    def num_verts(self) -> int:
        return self.verts.shape[0]

    @property
    def num_faces(self) -> int:
        return self.faces.shape[0]

    @property
    def dtype(self) -> torch.dtype:
        return self.verts.dtype

    @property
    def device(self) -> torch.device:
        return self.verts.device

    def __repr__(self) -> str:
        extras = [name for name in ("vert_colors", "vert_normals", "uvs") if getattr(self, name) is not None]
        if self.texture is not None:
            extras.append("texture {}x{}".format(*self.texture.shape[:2]))
        dtype = str(self.dtype).replace("torch.", "")
        return (f"Mesh(V={self.num_verts}, F={self.num_faces}, {dtype}, {self.device}"
                + (f", with {', '.join(extras)})" if extras else ")"))

    # ---- geometry ----------------------------------------------------------------------------
    def _face_cross(self) -> torch.Tensor:
        """(F, 3) ``(v1 - v0) x (v2 - v0)``: the face normal scaled by twice the face's area."""
        v0, v1, v2 = self.verts[self.faces].unbind(dim=1)  # each (F, 3)
        return torch.linalg.cross(v1 - v0, v2 - v0, dim=-1)

    def face_normals(self) -> torch.Tensor:
        """(F, 3) unit normals ``normalize((v1 - v0) x (v2 - v0))``; zero for zero-area faces, never NaN."""
        return _safe_normalize(self._face_cross())

    def face_areas(self) -> torch.Tensor:
        """(F,) triangle areas, ``|(v1 - v0) x (v2 - v0)| / 2``."""
        return 0.5 * torch.linalg.vector_norm(self._face_cross(), dim=-1)

    def vertex_normals(self) -> torch.Tensor:
        """(V, 3) unit vertex normals: the stored ``vert_normals`` (normalised) if given, else area-weighted.

        Area weighting sums the unnormalised cross products ``(v1 - v0) x (v2 - v0)`` (length = twice
        the area) of the faces around each vertex and normalises the sum, so big faces count more and
        slivers hardly at all. A vertex with no faces, or only zero-area ones, gets a zero normal.
        """
        if self.vert_normals is not None:
            return _safe_normalize(self.vert_normals)
        cross = self._face_cross()  # (F, 3)
        corner_normals = cross.repeat_interleave(3, dim=0)  # (3F, 3): one copy per corner
        summed = torch.zeros_like(self.verts).index_add(0, self.faces.reshape(-1), corner_normals)
        return _safe_normalize(summed)

    # ---- conversions -------------------------------------------------------------------------
    def to(self, device=None, dtype=None) -> "Mesh":
        """A copy on ``device`` with float attributes in ``dtype`` (faces stay int64); None keeps each."""
        if dtype is not None and dtype not in _FLOAT_DTYPES:
            raise TypeError(f"dtype must be torch.float32 or torch.float64 (a mesh holds float32 or float64 "
                            f"values), got dtype={dtype!r}")
        device = _check_device(device)
        moved = {name: _move(getattr(self, name), device, dtype)
                 for name in ("verts", "vert_colors", "vert_normals", "uvs", "texture")}
        moved["faces"] = _move(self.faces, device, None)
        return _assemble(**moved)

    def transformed(self, M) -> "Mesh":
        """The mesh with ``M`` (4, 4) applied to its vertices: ``x' = M @ [x, 1]``, divided by w.

        Stored normals go through the inverse-transpose of M's upper-left 3x3 (exact for affine M).
        A mirroring M (negative determinant) would turn counter-clockwise faces clockwise, so the
        face winding is flipped too: a closed mesh stays outward-facing. Gradients flow to M and verts.
        """
        M = _to_tensor(M, "M")
        _check_numeric(M, "M")
        M = M.to(device=self.device, dtype=self.dtype)
        if M.shape != (4, 4):
            raise ValueError(f"M must be a (4, 4) matrix, got shape {tuple(M.shape)}")
        if not bool(torch.isfinite(M.detach()).all()):
            raise ValueError("M contains NaN or inf")
        linear = M[:3, :3]
        verts_moved = self.verts @ linear.T + M[:3, 3]  # (V, 3) linear part and translation
        w = self.verts @ M[3, :3] + M[3, 3]  # (V,) homogeneous coordinate, 1 for affine M
        if bool((w.detach() == 0).any()):
            raise ValueError(f"M sends vertex {int((w.detach() == 0).nonzero()[0, 0])} to infinity "
                             "(homogeneous w = 0)")
        det = torch.linalg.det(linear.detach()).item()
        normals = self.vert_normals
        if normals is not None:
            if abs(det) <= 1e-12 * float(torch.linalg.matrix_norm(linear.detach())) ** 3:  # relative to M's size
                raise ValueError("M's 3x3 part is singular, so the stored vertex normals cannot be transformed")
            normals = _safe_normalize(normals @ torch.linalg.inv(linear))  # rows: (A^-T n)^T = n^T A^-1
        faces = self.faces[:, [0, 2, 1]] if det < 0 else self.faces
        return _assemble(verts=verts_moved / w[:, None], faces=faces, vert_colors=self.vert_colors,
                         vert_normals=normals, uvs=self.uvs, texture=self.texture)


def join_meshes(meshes) -> Mesh:
    """One mesh holding all of ``meshes`` (same dtype and device), faces offset to the joined verts.

    Vertex colours, normals and uvs are kept when every mesh has them. Textures are kept when every
    mesh has one: equal textures are shared; different ones are placed side by side in one atlas
    (shorter ones padded at the top) and the uvs remapped into each mesh's tile. Each tile's uvs are
    clamped half a texel inside it, which reproduces clamp-to-edge lookups at the tile's border
    (an atlas cannot repeat a texture, so uvs outside [0, 1] are clamped too).
    """
    if isinstance(meshes, Mesh) or not hasattr(meshes, "__iter__"):
        raise TypeError(f"meshes must be a sequence of Mesh objects, got {type(meshes).__name__}")
    meshes = list(meshes)
    if not meshes:
        raise ValueError("join_meshes needs at least one mesh")
    for i, mesh in enumerate(meshes):
        if not isinstance(mesh, Mesh):
            raise TypeError(f"join_meshes takes Mesh objects, item {i} is a {type(mesh).__name__}")
        if (mesh.dtype, mesh.device) != (meshes[0].dtype, meshes[0].device):
            raise ValueError(f"join_meshes needs one dtype and device: mesh 0 is {meshes[0].dtype} on "
                             f"{meshes[0].device}, mesh {i} is {mesh.dtype} on {mesh.device}; use .to() first")
    offsets = np.cumsum([0] + [mesh.num_verts for mesh in meshes[:-1]])
    joined = {"verts": torch.cat([mesh.verts for mesh in meshes]),
              "faces": torch.cat([mesh.faces + int(off) for mesh, off in zip(meshes, offsets)])}
    for name in ("vert_colors", "vert_normals", "uvs"):
        values = [getattr(mesh, name) for mesh in meshes]
        joined[name] = torch.cat(values) if all(v is not None for v in values) else None
    if all(mesh.texture is not None for mesh in meshes):  # a texture implies uvs
        joined["uvs"], joined["texture"] = _texture_atlas(meshes)
    return _assemble(**joined)


def _texture_atlas(meshes):
    """(uvs (V, 2), texture (Ht, Wt, 3)) for joined meshes: one shared texture, or tiles side by side."""
    textures = [mesh.texture for mesh in meshes]
    if all(t is textures[0] or (t.shape == textures[0].shape and torch.equal(t, textures[0])) for t in textures):
        return torch.cat([mesh.uvs for mesh in meshes]), textures[0]
    height = max(t.shape[0] for t in textures)
    width = sum(t.shape[1] for t in textures)
    tiles, uvs, left = [], [], 0
    for mesh, tex in zip(meshes, textures):
        Ht, Wt = tex.shape[:2]
        tiles.append(torch.cat([tex.new_zeros(height - Ht, Wt, 3), tex]))  # pad on top: v = 0 stays at the bottom
        half_texel = mesh.uvs.new_tensor([0.5 / Wt, 0.5 / Ht])
        uv = torch.minimum(torch.maximum(mesh.uvs, half_texel), 1 - half_texel)  # stay off the neighbours
        uvs.append(torch.stack([(left + uv[:, 0] * Wt) / width, uv[:, 1] * Ht / height], dim=-1))
        left += Wt
    return torch.cat(uvs), torch.cat(tiles, dim=1)


# ---- loading ---------------------------------------------------------------------------------
def load_mesh(path, *, dtype=None, device=None, srgb_textures: bool = True) -> Mesh:
    """Read a triangle mesh from any file trimesh reads (OBJ, PLY, STL, GLB / glTF, OFF, ...).

    A file holding several objects (a scene) becomes one mesh (trimesh packs their textures into one
    atlas). Kept from the file: per-vertex uvs and the texture image (OBJ + MTL, glTF), and per-vertex
    colours (PLY, glTF); polygons are triangulated; STL corners are merged into shared vertices.
    Normals are not read: `Mesh.vertex_normals` computes them from the geometry. ``dtype`` defaults to
    torch's default dtype (float32 unless changed).

    Shading works on linear RGB, but 8-bit image textures are stored sRGB-encoded by convention (glTF
    requires it for base colour; painted and photographed OBJ textures are sRGB too). So with
    ``srgb_textures=True`` (default) the texture is decoded to linear with
    :func:`course.shading.srgb_to_linear`; ``srgb_textures=False`` keeps the stored values (a texture that
    holds linear data, such as one written from a linear image without encoding). Vertex colours are
    kept as stored. The bundled models' textures (``models.checker_texture``) are generated linear and
    never pass through here.

    Raises:
        FileNotFoundError: ``path`` does not exist.
        ValueError: the file cannot be read or holds no triangles.
    """
    import trimesh  # imported here: it is slow to import and only loading needs it

    if not isinstance(path, (str, Path)):
        raise TypeError(f"path must be a str or pathlib.Path, got {type(path).__name__}")
    dtype, device = _check_dtype(dtype), _check_device(device)
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such mesh file: {path}")
    try:
        loaded = trimesh.load(str(path), force="mesh", process=False)
    except Exception as error:  # trimesh raises many kinds; the user needs the file name and the reason
        raise ValueError(f"could not read mesh {path}: {error}") from error
    if isinstance(loaded, trimesh.Scene):
        loaded = loaded.to_mesh() if loaded.geometry else None
    if not isinstance(loaded, trimesh.Trimesh):
        raise ValueError(f"could not read mesh {path}: it holds {type(loaded).__name__}, not triangles")
    if path.suffix.lower() == ".stl":
        loaded.merge_vertices()  # STL stores every triangle's corners separately: share them again
    if len(loaded.vertices) == 0 or len(loaded.faces) == 0:
        raise ValueError(f"mesh file {path} holds no triangles ({len(loaded.vertices)} vertices, "
                         f"{len(loaded.faces)} faces)")
    attributes = _trimesh_visuals(loaded, srgb_textures)
    verts = torch.as_tensor(np.asarray(loaded.vertices), dtype=dtype or torch.get_default_dtype(), device=device)
    faces = torch.as_tensor(np.asarray(loaded.faces, dtype=np.int64), device=device)
    return Mesh(verts, faces, **attributes)


def _trimesh_visuals(loaded, srgb_textures: bool = True) -> dict:
    """Mesh keyword arguments (uvs, texture or vert_colors) from a trimesh mesh's visual; the texture is
    decoded from sRGB to linear (float64 in [0, 1]) when ``srgb_textures``, else left as stored (uint8)."""
    visual = loaded.visual
    if visual.kind == "vertex":
        return {"vert_colors": np.asarray(visual.vertex_colors)[:, :3]}  # uint8 RGBA -> RGB
    uv = getattr(visual, "uv", None)
    if visual.kind != "texture" or uv is None or len(uv) != len(loaded.vertices):
        return {}
    material = visual.material
    image = getattr(material, "image", None)  # SimpleMaterial (OBJ + MTL)
    if image is None:
        image = getattr(material, "baseColorTexture", None)  # PBRMaterial (glTF)
    if image is None or min(image.size) <= 2:                  # trimesh's 2x2 placeholder: no real image
        return {}
    texture = np.asarray(image.convert("RGB"))                  # (Ht, Wt, 3) uint8
    if srgb_textures:
        from course.shading import srgb_to_linear
        texture = srgb_to_linear(torch.from_numpy(texture.astype(np.float64) / 255)).numpy()  # (Ht, Wt, 3) linear
    return {"uvs": np.asarray(uv, dtype=np.float64), "texture": texture}


# ---- validation (the messages are the user interface) -----------------------------------------
def _to_tensor(x, name: str) -> torch.Tensor:
    """A tensor from a tensor, numpy array or nested list (numpy dtypes kept, lists of floats -> float32)."""
    if isinstance(x, torch.Tensor):
        return x
    if isinstance(x, np.ndarray):
        if x.dtype == object or x.dtype.kind not in "biuf":
            raise TypeError(f"{name} must hold numbers, got a numpy array of dtype {x.dtype}")
        if not (x.flags.writeable and x.flags.c_contiguous):
            x = np.array(x)  # torch cannot share a read-only buffer (e.g. an image array)
        return torch.from_numpy(x)
    if isinstance(x, (list, tuple)):
        try:
            return torch.as_tensor(x)
        except (TypeError, ValueError, RuntimeError) as error:
            raise TypeError(f"{name} must be a rectangular array of numbers: {error}") from None
    raise TypeError(f"{name} must be a torch tensor or numpy array, got {type(x).__name__}")


def _check_numeric(x: torch.Tensor, name: str) -> None:
    if x.dtype == torch.bool or x.dtype.is_complex:
        raise TypeError(f"{name} must hold real numbers, got dtype {x.dtype}")


def _check_finite(x: torch.Tensor, name: str, what: str) -> None:
    bad = ~torch.isfinite(x.detach()).reshape(x.shape[0], -1).all(dim=1)
    if bad.any():
        first = int(bad.nonzero()[0, 0])
        raise ValueError(f"{name} has {int(bad.sum())} {what} with NaN or inf values, the first at index {first}")


def _check_verts(verts) -> torch.Tensor:
    verts = _to_tensor(verts, "verts")
    _check_numeric(verts, "verts")
    if verts.ndim != 2 or verts.shape[-1] != 3:
        raise ValueError(f"verts must have shape (V, 3), got {tuple(verts.shape)}")
    if verts.shape[0] == 0:
        raise ValueError("the mesh is empty: verts has 0 vertices")
    if verts.dtype not in _FLOAT_DTYPES:
        verts = verts.to(torch.float32)
    _check_finite(verts, "verts", "vertices")
    return verts


def _check_faces(faces, num_verts: int, device) -> torch.Tensor:
    faces = _to_tensor(faces, "faces")
    _check_numeric(faces, "faces")
    if faces.dtype.is_floating_point:
        raise TypeError(f"faces must hold integer vertex indices, got dtype {faces.dtype}")
    if faces.ndim != 2 or faces.shape[-1] != 3:
        hint = " (quads? split each into two triangles)" if faces.ndim == 2 and faces.shape[-1] == 4 else ""
        raise ValueError(f"faces must have shape (F, 3){hint}, got {tuple(faces.shape)}")
    if faces.shape[0] == 0:
        raise ValueError("the mesh is empty: faces has 0 triangles")
    faces = faces.to(device=device, dtype=torch.int64)
    largest, smallest = int(faces.max()), int(faces.min())
    if largest >= num_verts:
        raise ValueError(f"faces index vertex {largest} but the mesh has {num_verts} vertices")
    if smallest < 0:
        raise ValueError(f"faces index vertex {smallest}: indices must lie in 0..{num_verts - 1}")
    return faces


def _as_colour(x: torch.Tensor, name: str) -> torch.Tensor:
    """Integer colours 0..255 -> floats in [0, 1]; float colours unchanged."""
    if x.dtype.is_floating_point:
        return x
    if x.numel() and (int(x.min()) < 0 or int(x.max()) > 255):
        raise ValueError(f"{name} holds integers outside 0..255 ({int(x.min())}..{int(x.max())}); "
                         "pass floats in [0, 1] or integers in 0..255")
    return x.to(torch.float32) / 255.0


def _check_per_vertex(x, name: str, width: int, verts: torch.Tensor, colour: bool = False):
    if x is None:
        return None
    x = _to_tensor(x, name)
    _check_numeric(x, name)
    V = verts.shape[0]
    if x.ndim != 2 or x.shape != (V, width):
        raise ValueError(f"{name} must have shape ({V}, {width}), one row per vertex, got {tuple(x.shape)}")
    x = _as_colour(x, name) if colour else x
    _check_finite(x, name, "vertices")
    return x.to(device=verts.device, dtype=verts.dtype)


def _check_texture(texture, verts: torch.Tensor):
    if texture is None:
        return None
    texture = _to_tensor(texture, "texture")
    _check_numeric(texture, "texture")
    if texture.ndim != 3 or texture.shape[-1] not in (3, 4):
        hint = " (channels first? use texture.permute(1, 2, 0))" if texture.ndim == 3 and texture.shape[0] in (3, 4) else ""
        raise ValueError(f"texture must have shape (Ht, Wt, 3) or (Ht, Wt, 4){hint}, got {tuple(texture.shape)}")
    if texture.shape[0] == 0 or texture.shape[1] == 0:
        raise ValueError(f"texture is empty: shape {tuple(texture.shape)}")
    if texture.shape[-1] == 4:
        texture = texture[..., :3]  # drop alpha
    texture = _as_colour(texture, "texture")
    _check_finite(texture, "texture", "rows")
    return texture.to(device=verts.device, dtype=verts.dtype)


# ---- small helpers ---------------------------------------------------------------------------
def _safe_normalize(x: torch.Tensor) -> torch.Tensor:
    """(..., 3) unit vectors along the last dim; exactly zero (with zero gradient) where x is ~zero."""
    length = torch.linalg.vector_norm(x, dim=-1, keepdim=True)
    ok = length > torch.finfo(x.dtype).tiny ** 0.5  # tiny**0.5 keeps 1 / length finite in backward
    return torch.where(ok, x / torch.where(ok, length, torch.ones_like(length)), torch.zeros_like(x))


def _move(x, device, dtype):
    if x is None:
        return None
    return x.to(device=device if device is not None else x.device, dtype=dtype if dtype is not None else x.dtype)


def _assemble(**fields) -> Mesh:
    """A Mesh from already-validated tensors, skipping the checks (used by to / transformed / join)."""
    mesh = Mesh.__new__(Mesh)
    for name in ("verts", "faces", "vert_colors", "vert_normals", "uvs", "texture"):
        setattr(mesh, name, fields.get(name))
    return mesh
