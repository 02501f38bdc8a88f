"""Tests for course.mesh and the bundled models: validation, normals, transforms, primitives, loading."""
import math

import numpy as np
import pytest
import torch

from course.mesh import Mesh, join_meshes, load_mesh
from course.models import checker_texture, cube, default_scene_mesh, icosphere, plane, teapot, torus

SQRT3 = math.sqrt(3.0)


def tetrahedron(dtype=torch.float32):
    """Corner tetrahedron (0, e_x, e_y, e_z), faces counter-clockwise from outside."""
    verts = torch.tensor([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=dtype)
    faces = torch.tensor([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])  # -z, -y, -x, slanted
    return Mesh(verts, faces)


def weld_by_position(mesh):
    """(F, 3) faces re-indexed so vertices at identical positions share one index (undoes uv seams)."""
    _, ids = np.unique(mesh.verts.detach().cpu().numpy(), axis=0, return_inverse=True)
    return ids.reshape(-1)[mesh.faces.cpu().numpy()]


def assert_closed_and_consistent(faces):
    """Every edge in exactly two faces, and every directed edge once (neighbours agree on winding)."""
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    _, counts = np.unique(directed, axis=0, return_counts=True)
    assert counts.max() == 1, "a directed edge appears twice: two neighbouring faces disagree on winding"
    _, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    assert (counts == 2).all(), "an edge is not shared by exactly two faces: the surface has a hole"


def signed_volume(mesh):
    v0, v1, v2 = mesh.verts.double()[mesh.faces].unbind(1)
    return float((v0 * torch.linalg.cross(v1, v2, dim=-1)).sum() / 6)


def uv_winding(mesh):
    """(F,) sign of each face's triangle in uv space: +1 when the texture is not mirrored."""
    uv = mesh.uvs[mesh.faces]  # (F, 3, 2)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    return torch.sign(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


# ---- validation ------------------------------------------------------------------------------
TRI_VERTS = [[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]


@pytest.mark.parametrize("verts, faces, error, match", [
    (np.zeros((4, 2)), [[0, 1, 2]], ValueError, r"verts must have shape \(V, 3\), got \(4, 2\)"),
    (np.zeros((0, 3)), np.zeros((0, 3), int), ValueError, "mesh is empty: verts has 0 vertices"),
    (TRI_VERTS, np.zeros((0, 3), int), ValueError, "mesh is empty: faces has 0 triangles"),
    (TRI_VERTS, [[0.0, 1.0, 2.0]], TypeError, "faces must hold integer vertex indices"),
    (TRI_VERTS, [[0, 1, 2, 0]], ValueError, r"faces must have shape \(F, 3\) \(quads\?"),
    (np.zeros((800, 3)), [[0, 1, 2], [812, 3, 4]], ValueError, "faces index vertex 812 but the mesh has 800 vertices"),
    (TRI_VERTS, [[0, -1, 2]], ValueError, r"faces index vertex -1: indices must lie in 0\.\.2"),
    ("verts", [[0, 1, 2]], TypeError, "verts must be a torch tensor or numpy array, got str"),
    (np.array([["a", "b", "c"]]), [[0, 0, 0]], TypeError, "verts must hold numbers"),
    (np.ones((3, 3), bool), [[0, 1, 2]], TypeError, "verts must hold real numbers"),
])
def test_bad_geometry_is_named(verts, faces, error, match):
    with pytest.raises(error, match=match):
        Mesh(verts, faces)


def test_nonfinite_vertices_are_counted_and_located():
    verts = np.zeros((6, 3))
    verts[3, 1], verts[5, 0] = np.nan, np.inf
    with pytest.raises(ValueError, match="verts has 2 vertices with NaN or inf values, the first at index 3"):
        Mesh(verts, [[0, 1, 2]])


@pytest.mark.parametrize("kwargs, match", [
    ({"vert_colors": np.zeros((2, 3))}, r"vert_colors must have shape \(3, 3\), one row per vertex, got \(2, 3\)"),
    ({"vert_normals": np.zeros((3, 2))}, r"vert_normals must have shape \(3, 3\)"),
    ({"uvs": np.zeros((3, 3))}, r"uvs must have shape \(3, 2\)"),
    ({"uvs": np.full((3, 2), np.nan)}, "uvs has 3 vertices with NaN or inf values, the first at index 0"),
    ({"uvs": np.zeros((3, 2)), "texture": np.zeros((8, 8))}, r"texture must have shape \(Ht, Wt, 3\) or \(Ht, Wt, 4\)"),
    ({"uvs": np.zeros((3, 2)), "texture": np.zeros((3, 8, 8))}, r"channels first\? use texture.permute"),
    ({"uvs": np.zeros((3, 2)), "texture": np.zeros((0, 8, 3))}, "texture is empty"),
    ({"texture": np.zeros((8, 8, 3))}, "a texture needs per-vertex texture coordinates"),
    ({"vert_colors": np.full((3, 3), 300)}, r"vert_colors holds integers outside 0\.\.255"),
])
def test_bad_attributes_are_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Mesh(TRI_VERTS, [[0, 1, 2]], **kwargs)


# ---- dtype, device, autograd -----------------------------------------------------------------
@pytest.mark.parametrize("given, kept", [
    (torch.float32, torch.float32), (torch.float64, torch.float64), (torch.float16, torch.float32),
    (torch.int64, torch.float32)])
def test_vertex_dtype_kept_and_attributes_follow(given, kept):
    verts = torch.tensor(TRI_VERTS).to(given)
    mesh = Mesh(verts, np.array([[0, 1, 2]], np.int32), uvs=np.zeros((3, 2), np.float32),
                vert_colors=np.full((3, 3), 255, np.uint8), texture=np.zeros((2, 2, 4), np.uint8))
    assert mesh.dtype == kept and mesh.faces.dtype == torch.int64
    assert mesh.uvs.dtype == mesh.vert_colors.dtype == mesh.texture.dtype == kept
    assert torch.equal(mesh.vert_colors, torch.ones(3, 3, dtype=kept))  # 255 -> 1.0
    assert mesh.texture.shape == (2, 2, 3)  # alpha dropped
    assert mesh.face_normals().dtype == mesh.vertex_normals().dtype == mesh.face_areas().dtype == kept


def test_numpy_float64_stays_float64_and_lists_become_float32():
    assert Mesh(np.array(TRI_VERTS), [[0, 1, 2]]).dtype == torch.float64
    assert Mesh(TRI_VERTS, [[0, 1, 2]]).dtype == torch.float32


def test_verts_that_require_grad_stay_the_same_leaf():
    verts = torch.tensor(TRI_VERTS + [[0, 0, 1]], requires_grad=True)
    mesh = Mesh(verts, [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    assert mesh.verts is verts
    (mesh.vertex_normals().sum() + mesh.face_areas().sum()).backward()
    assert verts.grad is not None and torch.isfinite(verts.grad).all()


def test_to_converts_float_attributes_and_keeps_faces():
    mesh = teapot(resolution=2).to(dtype=torch.float64)
    assert mesh.dtype == mesh.uvs.dtype == mesh.texture.dtype == torch.float64
    assert mesh.faces.dtype == torch.int64 and mesh.device == torch.device("cpu")
    with pytest.raises(TypeError, match="float32 or float64"):
        mesh.to(dtype=torch.int32)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a GPU")
def test_device_is_kept_on_gpu():
    mesh = Mesh(torch.tensor(TRI_VERTS, device="cuda"), [[0, 1, 2]], uvs=np.zeros((3, 2)))
    assert mesh.faces.device.type == mesh.uvs.device.type == mesh.face_normals().device.type == "cuda"
    assert teapot(resolution=2, device="cuda").to(device="cpu").texture.device.type == "cpu"


def test_repr_is_short():
    assert repr(cube()) == "Mesh(V=8, F=12, float32, cpu)"
    assert repr(teapot(resolution=2)).endswith("with uvs, texture 256x256)")


# ---- normals and areas -----------------------------------------------------------------------
def test_tetrahedron_face_normals_and_areas():
    mesh = tetrahedron(torch.float64)
    expected = torch.tensor([[0, 0, -1], [0, -1, 0], [-1, 0, 0], [1 / SQRT3] * 3], dtype=torch.float64)
    torch.testing.assert_close(mesh.face_normals(), expected)
    torch.testing.assert_close(mesh.face_areas(), torch.tensor([0.5, 0.5, 0.5, SQRT3 / 2], dtype=torch.float64))


def test_tetrahedron_vertex_normals_are_area_weighted():
    normals = tetrahedron(torch.float64).vertex_normals()
    # at e_x: cross products (0,0,-1) + (0,-1,0) + (1,1,1) sum to (1,0,0): the big slanted face wins
    torch.testing.assert_close(normals[1], torch.tensor([1.0, 0, 0], dtype=torch.float64))
    torch.testing.assert_close(normals[0], -torch.ones(3, dtype=torch.float64) / SQRT3)
    # an unweighted mean of unit face normals would point elsewhere
    unweighted = torch.tensor([0, 0, -1.0]) + torch.tensor([0, -1.0, 0]) + torch.ones(3) / SQRT3
    assert torch.linalg.vector_norm(unweighted / unweighted.norm() - normals[1].float()) > 0.5


def test_cube_normals_point_out():
    mesh = cube(size=2.0)
    normals, centres = mesh.face_normals(), mesh.verts[mesh.faces].mean(1)
    torch.testing.assert_close(normals, torch.sign(centres) * (centres.abs() == 1))  # the axis of its side
    torch.testing.assert_close(mesh.face_areas(), torch.full((12,), 2.0))
    assert ((mesh.vertex_normals() * mesh.verts).sum(1) > 0).all()
    torch.testing.assert_close(mesh.vertex_normals().norm(dim=1), torch.ones(8))


def test_degenerate_faces_and_isolated_vertices_stay_finite():
    verts = torch.tensor([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [5, 5, 5]], requires_grad=True)
    mesh = Mesh(verts, [[0, 1, 2], [0, 0, 3], [0, 1, 3]])  # collinear, repeated corner, normal; 4 isolated
    normals = mesh.face_normals()
    torch.testing.assert_close(normals[:2], torch.zeros(2, 3))
    torch.testing.assert_close(normals[2], torch.tensor([0.0, 0, 1]))
    vertex_normals = mesh.vertex_normals()
    torch.testing.assert_close(vertex_normals[4], torch.zeros(3))
    torch.testing.assert_close(vertex_normals[2], torch.zeros(3))  # only in the collinear face
    (normals.sum() + vertex_normals.sum() + mesh.face_areas().sum()).backward()
    assert torch.isfinite(verts.grad).all()


def test_stored_normals_are_returned_normalised():
    mesh = Mesh(TRI_VERTS, [[0, 1, 2]], vert_normals=[[0, 0, 2.0], [0, 3.0, 0], [0, 0, 0]])
    torch.testing.assert_close(mesh.vertex_normals(), torch.tensor([[0, 0, 1.0], [0, 1, 0], [0, 0, 0]]))


# ---- transforms and joining ------------------------------------------------------------------
def test_transformed_moves_verts_and_turns_normals_by_inverse_transpose():
    verts = torch.tensor(TRI_VERTS, dtype=torch.float64)
    mesh = Mesh(verts, [[0, 1, 2]], vert_normals=[[1.0, 1, 1]] * 3)
    M = torch.eye(4, dtype=torch.float64)
    M[:3, :3] = torch.diag(torch.tensor([2.0, 1.0, 1.0], dtype=torch.float64))  # stretch x
    M[:3, 3] = torch.tensor([1.0, 2.0, 3.0])
    moved = mesh.transformed(M)
    torch.testing.assert_close(moved.verts, verts * torch.tensor([2.0, 1, 1]) + torch.tensor([1.0, 2, 3]))
    expected = torch.tensor([0.5, 1.0, 1.0], dtype=torch.float64)
    torch.testing.assert_close(moved.vert_normals[0], expected / expected.norm())  # still perpendicular to the stretched surface
    assert moved.faces is mesh.faces


def test_mirroring_flips_winding_so_closed_meshes_stay_outward():
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    mesh = cube().transformed(mirror)
    centres = mesh.verts[mesh.faces].mean(1)
    assert ((mesh.face_normals() * centres).sum(1) > 0).all()


def test_transformed_passes_gradients_to_matrix_and_verts():
    M = torch.eye(4, requires_grad=True)
    verts = tetrahedron().verts.clone().requires_grad_(True)
    Mesh(verts, tetrahedron().faces).transformed(M).verts.sum().backward()
    assert M.grad is not None and verts.grad is not None
    with pytest.raises(ValueError, match=r"M must be a \(4, 4\) matrix"):
        cube().transformed(torch.eye(3))


def test_join_offsets_faces_and_keeps_shared_attributes():
    lift = np.eye(4)
    lift[1, 3] = 1.0
    a, b = plane(), plane().transformed(lift)
    joined = join_meshes([a, b, cube()])
    assert joined.num_verts == 4 + 4 + 8 and joined.num_faces == 2 + 2 + 12
    torch.testing.assert_close(joined.faces[4:], cube().faces + 8)
    assert joined.uvs is None  # the cube has none
    assert join_meshes([a, b]).uvs.shape == (8, 2)


def bilinear_lookup(texture, uv):
    """(N, C) bilinear colours at uv (N, 2), clamped to the edge; texel (r, c) centred at ((c+.5)/Wt, 1-(r+.5)/Ht)."""
    Ht, Wt = texture.shape[:2]
    x = (uv[:, 0] * Wt - 0.5).clamp(0, Wt - 1)  # continuous column, 0 at the first texel centre
    y = ((1 - uv[:, 1]) * Ht - 0.5).clamp(0, Ht - 1)  # continuous row, 0 at the top
    x0, y0 = x.floor().long().clamp(max=Wt - 2).clamp(min=0), y.floor().long().clamp(max=Ht - 2).clamp(min=0)
    x1, y1 = (x0 + 1).clamp(max=Wt - 1), (y0 + 1).clamp(max=Ht - 1)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    top = texture[y0, x0] * (1 - fx) + texture[y0, x1] * fx
    bottom = texture[y1, x0] * (1 - fx) + texture[y1, x1] * fx
    return top * (1 - fy) + bottom * fy


def test_join_shares_equal_textures_and_packs_different_ones():
    pot = teapot(resolution=2)
    assert join_meshes([pot, pot]).texture is pot.texture
    red = torch.zeros(4, 2, 3)
    red[..., 0] = torch.linspace(0, 1, 4)[:, None]  # varies with v
    flat = Mesh(plane().verts, plane().faces, uvs=plane().uvs * 0.9 + 0.05, texture=red)
    joined = join_meshes([pot, flat])
    assert joined.texture.shape == (256, 256 + 2, 3)
    for part, start in ((pot, 0), (flat, pot.num_verts)):
        uv = joined.uvs[start:start + part.num_verts]
        torch.testing.assert_close(bilinear_lookup(joined.texture, uv), bilinear_lookup(part.texture, part.uvs))


def test_join_rejects_mixed_dtypes_and_empty_lists():
    with pytest.raises(ValueError, match="join_meshes needs one dtype and device"):
        join_meshes([cube(), cube(dtype=torch.float64)])
    with pytest.raises(ValueError, match="at least one mesh"):
        join_meshes([])
    with pytest.raises(TypeError, match="item 1 is a str"):
        join_meshes([cube(), "cube"])


# ---- primitives ------------------------------------------------------------------------------
@pytest.mark.parametrize("make, volume", [
    (lambda: cube(size=2.0), 8.0),
    (lambda: icosphere(0), None),
    (lambda: icosphere(3, radius=2.0), 4 / 3 * math.pi * 8),
    (lambda: torus(major=1.0, minor=0.35), 2 * math.pi ** 2 * 1.0 * 0.35 ** 2),
])
def test_primitives_are_closed_consistent_and_outward(make, volume):
    mesh = make()
    assert_closed_and_consistent(weld_by_position(mesh))
    assert signed_volume(mesh) > 0  # positive: faces wind counter-clockwise seen from outside
    if volume is not None:
        assert signed_volume(mesh) == pytest.approx(volume, rel=0.02)
    assert (mesh.face_areas() > 0).all()


@pytest.mark.parametrize("subdivisions", range(6))
def test_icosphere_counts_and_radius(subdivisions):
    mesh = icosphere(subdivisions, radius=1.5, dtype=torch.float64)
    assert mesh.num_faces == 20 * 4 ** subdivisions and mesh.num_verts == 10 * 4 ** subdivisions + 2
    torch.testing.assert_close(mesh.verts.norm(dim=1), torch.full((mesh.num_verts,), 1.5, dtype=torch.float64))
    centres = mesh.verts[mesh.faces].mean(1)
    assert ((mesh.face_normals() * centres).sum(1) > 0).all()


def test_torus_normals_point_away_from_the_core_circle():
    mesh = torus()
    centres = mesh.verts[mesh.faces].mean(1)
    core = centres * torch.tensor([1.0, 0, 1])
    core = core / core.norm(dim=1, keepdim=True)  # nearest point on the unit core circle
    assert ((mesh.face_normals() * (centres - core)).sum(1) > 0).all()
    assert (uv_winding(mesh) > 0).all()


def test_plane_faces_up_with_unmirrored_uvs():
    mesh = plane(size=2.0, subdivisions=3)
    assert mesh.num_faces == 18 and mesh.num_verts == 16
    torch.testing.assert_close(mesh.face_normals(), torch.tensor([[0.0, 1, 0]]).expand(18, 3))
    corner = {tuple(v): tuple(uv) for v, uv in zip(mesh.verts.tolist(), mesh.uvs.tolist())}
    assert corner[(-1.0, 0.0, 1.0)] == (0.0, 0.0) and corner[(1.0, 0.0, -1.0)] == (1.0, 1.0)
    assert (uv_winding(mesh) > 0).all()


def test_checker_texture_shows_its_orientation():
    tex = checker_texture(size=64, checks=8)
    assert tex.shape == (64, 64, 3) and tex.min() >= 0 and tex.max() <= 1
    assert torch.equal(tex[60, 4], torch.ones(3))  # marker in the uv (0, 0) check: bottom-left
    assert not torch.equal(tex[4, 4], torch.ones(3)) and not torch.equal(tex[60, 60], torch.ones(3))
    light = tex[60, 4 + 8]  # light checks: red grows with u, green with v
    assert tex[60, 4 + 56, 0] > light[0] and tex[4 + 8, 4 + 8, 1] > light[1]


def test_teapot_is_textured_oriented_and_fits_the_unit_sphere():
    mesh = teapot(resolution=8)
    assert mesh.uvs is not None and mesh.texture.shape == (256, 256, 3)
    assert mesh.num_faces == 32 * 8 * 8 * 2 - 8 * 8  # pole triangles of lid and bottom removed
    assert (mesh.face_areas() > 0).all()
    radius = mesh.verts.norm(dim=1).max()
    assert 0.99 < radius <= 1.0 + 1e-6
    extent = mesh.verts.max(0).values - mesh.verts.min(0).values
    assert extent[0] > extent[2] > extent[1]  # wide (spout to handle), deep, less tall: +y is up
    tip = mesh.verts[mesh.verts[:, 0].argmax()]
    assert tip[1] > 0.2  # the spout tip at +x rises well above the middle (y spans -0.47..0.47)
    faces = weld_by_position(mesh)
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    assert np.unique(directed, axis=0, return_counts=True)[1].max() == 1  # patches agree on winding
    assert signed_volume(mesh) > 0 and (uv_winding(mesh) > 0).all()


def test_teapot_lid_faces_up_and_bottom_faces_down():
    mesh = teapot(resolution=4, dtype=torch.float64)
    area_vectors = mesh.face_normals() * mesh.face_areas()[:, None]
    y = mesh.verts[mesh.faces].mean(1)[:, 1]
    assert area_vectors[y > y.max() - 0.05, 1].sum() > 0
    assert area_vectors[y < y.min() + 0.01, 1].sum() < 0


def test_default_scene_is_the_textured_teapot():
    mesh = default_scene_mesh(dtype=torch.float64)
    assert mesh.dtype == torch.float64 and mesh.num_faces == teapot().num_faces and mesh.texture is not None


# ---- loading ---------------------------------------------------------------------------------
trimesh = pytest.importorskip("trimesh")


def to_trimesh(mesh, image=None, colors=None):
    from PIL import Image

    visual = None
    if image is not None:
        pixels = (image.numpy() * 255).round().astype(np.uint8)
        visual = trimesh.visual.TextureVisuals(uv=mesh.uvs.numpy(), image=Image.fromarray(pixels))
    return trimesh.Trimesh(mesh.verts.numpy(), mesh.faces.numpy(), process=False, visual=visual,
                           vertex_colors=colors)


def sorted_rows(*columns):
    rows = torch.cat([c.double() for c in columns], dim=1).numpy().round(5)
    return rows[np.lexsort(rows.T[::-1])]


@pytest.mark.parametrize("suffix", ["obj", "glb"])
def test_textured_round_trip(tmp_path, suffix):
    mesh, image = torus(n_major=8, n_minor=6), checker_texture(size=32, checks=4)
    to_trimesh(mesh, image=image).export(tmp_path / f"ring.{suffix}")
    loaded = load_mesh(tmp_path / f"ring.{suffix}", srgb_textures=False)        # the file stores linear values raw
    assert loaded.num_faces == mesh.num_faces and loaded.dtype == torch.float32
    np.testing.assert_allclose(sorted_rows(loaded.verts, loaded.uvs), sorted_rows(mesh.verts, mesh.uvs), atol=1e-5)
    torch.testing.assert_close(loaded.texture, image, atol=0.5 / 255 + 1e-6, rtol=0)


def test_ply_round_trip_keeps_vertex_colours(tmp_path):
    mesh = icosphere(1)
    colors = np.random.default_rng(0).integers(0, 256, (mesh.num_verts, 4), dtype=np.uint8)
    to_trimesh(mesh, colors=colors).export(tmp_path / "ball.ply")
    loaded = load_mesh(tmp_path / "ball.ply", dtype=torch.float64)
    assert loaded.dtype == torch.float64
    expected = torch.as_tensor(colors[:, :3] / 255.0)
    np.testing.assert_allclose(sorted_rows(loaded.verts, loaded.vert_colors), sorted_rows(mesh.verts, expected),
                               atol=1e-5)


def test_stl_round_trip_shares_corners_again(tmp_path):
    mesh = icosphere(1)
    to_trimesh(mesh).export(tmp_path / "ball.stl")
    loaded = load_mesh(tmp_path / "ball.stl")
    assert (loaded.num_verts, loaded.num_faces) == (42, 80)
    assert_closed_and_consistent(loaded.faces.numpy())
    assert signed_volume(loaded) == pytest.approx(signed_volume(mesh), rel=1e-5)


def test_scene_becomes_one_mesh(tmp_path):
    scene = trimesh.Scene([to_trimesh(cube()), to_trimesh(icosphere(1)).apply_translation([3, 0, 0])])
    scene.export(tmp_path / "two.glb")
    loaded = load_mesh(tmp_path / "two.glb")
    assert loaded.num_faces == 12 + 80


def test_loading_errors_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such mesh file: .*missing.obj"):
        load_mesh(tmp_path / "missing.obj")
    garbled = tmp_path / "garbled.ply"
    garbled.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\nend_header\n\x00")
    with pytest.raises(ValueError, match="could not read mesh .*garbled.ply: "):
        load_mesh(garbled)
    empty = tmp_path / "empty.obj"
    empty.write_text("# nothing here\n")
    with pytest.raises(ValueError, match="empty.obj holds no triangles"):
        load_mesh(empty)


def test_teapot_has_no_unused_vertices():
    m = teapot()
    assert torch.equal(torch.unique(m.faces), torch.arange(m.num_verts))


def test_ply_with_uvs_but_no_image_has_no_texture(tmp_path):
    import trimesh
    t = trimesh.creation.box()
    visual = trimesh.visual.TextureVisuals(uv=np.random.default_rng(0).random((len(t.vertices), 2)))
    t.visual = visual
    path = tmp_path / "box.ply"
    t.export(path)
    assert load_mesh(path).texture is None


def test_bundled_models_and_load_mesh_take_torchs_default_dtype(tmp_path):
    """What is made from nothing follows torch.set_default_dtype (lectures print in float64); an explicit
    dtype wins."""
    trimesh = pytest.importorskip("trimesh")
    path = tmp_path / "tri.obj"
    trimesh.Trimesh(np.array(TRI_VERTS), [[0, 1, 2]], process=False).export(path)
    assert cube().verts.dtype == torch.float32 and load_mesh(path).verts.dtype == torch.float32
    before = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    try:
        pot = teapot(resolution=2)
        assert pot.verts.dtype == pot.uvs.dtype == pot.texture.dtype == torch.float64
        assert checker_texture(size=8).dtype == icosphere(1).verts.dtype == load_mesh(path).verts.dtype == torch.float64
        assert torus(dtype=torch.float32).verts.dtype == torch.float32
    finally:
        torch.set_default_dtype(before)
