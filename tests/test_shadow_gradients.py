"""Hard shadows in closed form (course.shadows.gradients): the image against ray tracing with shadow rays, every
gradient method against float64 central differences, float32 against float64, degenerate configurations."""
import math

import pytest
import torch

from course.camera import Camera
from course.mesh import Mesh
from course.shadows.gradients import (SCENES, shadow_image_gradient, shadow_raytrace, shadow_scene,
                                     shadowed_coverage, split_by_shadows)

AMBIENT = 0.3


def _weights(size, dtype=torch.float64, seed=0):
    return torch.rand(size, size, 3, generator=torch.Generator().manual_seed(seed), dtype=torch.float64).to(dtype)


def _rel(a, b):
    return float((a - b).norm() / b.norm().clamp_min(1e-300))


# ----------------------------------------------------------------------------------- the image, the model

@pytest.mark.parametrize("orthographic", [False, True])
@pytest.mark.parametrize("name", SCENES)
def test_image_matches_supersampled_ray_tracing(name, orthographic):
    """The exact image is the limit of ray tracing with shadow rays: a 24 × 24 regular grid per pixel errs
    only in pixels an edge crosses (at most a few sub-sample rows, ≤ 0.1), and little on average; a wrong
    shadow would be off by (1 - a) c ≥ 0.2 over whole pixels."""
    mesh, cam, colors, light = shadow_scene(name, 12, orthographic=orthographic)
    image = shadowed_coverage(mesh, cam, colors, light, AMBIENT)
    ref = shadow_raytrace(mesh, cam, colors, light, AMBIENT, supersample=24)
    err = (image - ref).abs()
    assert float(err.max()) < 0.1 and float(err.mean()) < 2e-3
    unlit = shadowed_coverage(mesh, cam, colors, light, 1.0)                # ambient 1: no shadows at all
    assert float((unlit - image).abs().max()) > 0.1                         # the scene has a visible shadow


def test_faces_turned_away_are_all_shadow_and_the_fold_shadows_itself():
    mesh, _, _, light = shadow_scene("fold")
    split = split_by_shadows(mesh, light)
    v = mesh.verts[mesh.faces]
    n = torch.linalg.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0], dim=1)
    away = (n @ -light) <= 0                                                # the wall
    assert away.any() and not split.lit[away[split.source]].any()
    floor = split.source == 0                                               # partly in the wall's shadow
    assert split.lit[floor].any() and (~split.lit[floor]).any()


def test_split_pieces_tile_each_face():
    """The lit and shadowed triangles of a face cover it exactly: their areas add up to the face's."""
    mesh, _, _, light = shadow_scene("crossing")
    split = split_by_shadows(mesh, light)
    area = lambda v: torch.linalg.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0], dim=1).norm(dim=1) / 2
    pieces = torch.zeros(mesh.faces.shape[0], dtype=torch.float64).index_add(
        0, split.source, area(split.verts[split.faces]))
    assert torch.allclose(pieces, area(mesh.verts[mesh.faces]), rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("name", ["crossing", "fold"])
def test_split_mesh_has_no_t_junctions(name):
    """No vertex of the split mesh lies inside an edge of a triangle: the boundary term counts an edge shared
    by two triangles half from each side, and a T-junction would make both sides count it in full."""
    mesh, _, _, light = shadow_scene(name)
    split = split_by_shadows(mesh, light)
    P = split.verts.detach()
    a = P[split.faces].reshape(-1, 3)
    b = P[split.faces.roll(-1, 1)].reshape(-1, 3)
    e = b - a                                                               # (E, 3) every triangle edge
    t = ((P[None] - a[:, None]) * e[:, None]).sum(-1) / (e * e).sum(-1)[:, None]   # (E, V) along the edge
    off = (P[None] - a[:, None] - t[..., None] * e[:, None]).norm(dim=-1)  # (E, V) off the edge's line
    assert not ((off < 1e-9) & (t > 1e-6) & (t < 1 - 1e-6)).any()


@pytest.mark.parametrize("orthographic", [False, True])
def test_cropping_to_the_view_changes_nothing_in_the_image(orthographic):
    """``split_by_shadows(..., view=camera)`` drops what lies over 2 px outside the image: fewer triangles,
    the same exact image as the whole split mesh."""
    from course.coverage import exact_coverage
    mesh, cam, colors, light = shadow_scene("crossing", 12, orthographic=orthographic)
    whole, cropped = split_by_shadows(mesh, light), split_by_shadows(mesh, light, view=cam)
    assert cropped.faces.shape[0] < whole.faces.shape[0]
    images = [exact_coverage(Mesh(s.verts, s.faces), cam, s.colors(colors, AMBIENT)) for s in (whole, cropped)]
    assert torch.allclose(images[0], images[1], atol=1e-12)


# -------------------------------------------------------------------------------------------- gradients

# (scene, orthographic, the vertex rows finite differences check: occluder and receiver vertices)
# Vertices of the cube are left out: moving one creases a face of the cube (two coplanar triangles), and a
# crease casts a shadow on one side only (a kink, where central differences average the two sides). So is
# the floor's height under the cube, which stands on it (touching, ``test_occluder_touching_its_receiver``).
CASES = [("floater", False, [3, 4, 5, 2]), ("floater", True, [3, 5, 0]), ("crossing", False, [11, 13]),
         ("grazing", False, [3, 4, 5, 1]), ("fold", False, [4, 5]), ("box", True, [])]


@pytest.mark.parametrize("name,orthographic,rows", CASES)
def test_exact_and_reynolds_match_converged_central_differences(name, orthographic, rows):
    """d L / d (occluder and receiver vertices, the light's direction) by autograd through the closed form and
    by the boundary term of the split mesh (Reynolds), against float64 central differences shown converged
    (steps 1e-5 and 1e-6 agree)."""
    mesh, cam, colors, light = shadow_scene(name, 10, orthographic=orthographic)
    w = _weights(10)
    args = (mesh, cam, colors, light, w)
    fd6 = shadow_image_gradient(*args, method="finite_differences", ambient=AMBIENT, wrt=("verts", "light"),
                                step=1e-6, vertices=rows)
    fd5 = shadow_image_gradient(*args, method="finite_differences", ambient=AMBIENT, wrt=("verts", "light"),
                                step=1e-5, vertices=rows)
    exact = shadow_image_gradient(*args, method="exact", ambient=AMBIENT, wrt=("verts", "light"))
    rey = shadow_image_gradient(*args, method="reynolds", ambient=AMBIENT, wrt=("verts", "light"))
    for k in range(2):
        sel = slice(None) if k == 1 else rows
        if k == 0 and not rows:
            continue
        assert _rel(fd5[k][sel], fd6[k][sel]) < 1e-5                       # converged
        assert float(fd6[k][sel].norm()) > 0                                # the shadow moves the image
        assert _rel(exact[k][sel], fd6[k][sel]) < 1e-5
        assert _rel(rey[k][sel], fd6[k][sel]) < 1e-5
    assert _rel(rey[1], exact[1]) < 1e-9                                   # to rounding
    if name != "box":         # every vertex; in "box" the floor's height is a kink (the cube stands on it)
        assert _rel(rey[0], exact[0]) < 1e-9


def test_camera_translation_gradient():
    mesh, cam, colors, light = shadow_scene("floater", 10)
    w = _weights(10)
    fd = shadow_image_gradient(mesh, cam, colors, light, w, method="finite_differences", wrt=("t",))[0]
    exact = shadow_image_gradient(mesh, cam, colors, light, w, method="exact", wrt=("t",))[0]
    rey = shadow_image_gradient(mesh, cam, colors, light, w, method="reynolds", wrt=("t",))[0]
    assert _rel(exact, fd) < 1e-5 and _rel(rey, fd) < 1e-5
    exact_R = shadow_image_gradient(mesh, cam, colors, light, w, method="exact", wrt=("R",))[0]
    rey_R = shadow_image_gradient(mesh, cam, colors, light, w, method="reynolds", wrt=("R",))[0]
    assert _rel(rey_R, exact_R) < 1e-9


def test_edge_sampling_mean_matches_exact():
    """Edge sampling is unbiased: the mean of 8 seeds lies within 4 standard errors of the exact gradient."""
    mesh, cam, colors, light = shadow_scene("floater", 10)
    w = _weights(10)
    exact = shadow_image_gradient(mesh, cam, colors, light, w, method="exact", wrt=("light",))[0]
    runs = torch.stack([shadow_image_gradient(mesh, cam, colors, light, w, method="edge_sampling", wrt=("light",),
                                              samples=4000, seed=s)[0] for s in range(8)])
    stderr = runs.std(0) / 8 ** 0.5
    assert ((runs.mean(0) - exact).abs() <= 4 * stderr + 1e-9).all()
    assert float(stderr.max()) > 0                                          # it is a random estimate


@pytest.mark.parametrize("name", ["floater", "fold", "grazing"])
def test_float32_agrees_with_float64(name):
    """A float32 scene gets float32 images and gradients close to float64's (the split runs in float64, the
    coverage in float32). Scenes with the cube are left out: the floor's height is a kink there (it stands on
    the floor), and float32's rounding may put the scene on the other side of it."""
    mesh, cam, colors, light = shadow_scene(name, 10)
    mesh32, cam32, colors32, light32 = shadow_scene(name, 10, dtype=torch.float32)
    w = _weights(10)
    assert _rel(shadowed_coverage(mesh32, cam32, colors32, light32).double(),
                shadowed_coverage(mesh, cam, colors, light)) < 1e-5
    for method in ("exact", "reynolds"):
        g64 = shadow_image_gradient(mesh, cam, colors, light, w, method=method, wrt=("verts", "light"))
        g32 = shadow_image_gradient(mesh32, cam32, colors32, light32, w.float(), method=method,
                                    wrt=("verts", "light"))
        assert g32[0].dtype == torch.float32
        assert _rel(g32[0].double(), g64[0]) < 1e-3 and _rel(g32[1].double(), g64[1]) < 1e-3


# ----------------------------------------------------------------------------------------- degenerate

def _all_finite(mesh, cam, colors, light, size):
    w = _weights(size)
    for method in ("exact", "reynolds", "edge_sampling"):
        g = shadow_image_gradient(mesh, cam, colors, light, w, method=method, wrt=("verts", "light"))
        assert all(torch.isfinite(x).all() for x in g), method
    return w


def test_light_parallel_to_the_floor():
    """Light along the floor: the floor is at grazing incidence, so all shadow (as ray tracing says)."""
    mesh, cam, colors, _ = shadow_scene("floater", 10)
    light = torch.tensor([1.0, 0.0, 0.3], dtype=torch.float64)
    split = split_by_shadows(mesh, light)
    assert not split.lit[split.source == 0].any()
    image = shadowed_coverage(mesh, cam, colors, light, AMBIENT)
    assert float((image - shadow_raytrace(mesh, cam, colors, light, AMBIENT, supersample=16)).abs().mean()) < 3e-3
    _all_finite(mesh, cam, colors, light, 10)


def test_occluder_edge_on_a_pixel_border():
    """Seen from above (orthographic, 1 world unit = 2 px), the occluder's edge x = 0.2 at height 1 casts,
    under light travelling (0.3, -1, 0), the shadow edge x = 0.5, which lies on a pixel border. Every method
    is finite, and the boundary methods give the same one-sided derivative as exact."""
    verts = torch.tensor([[-2, 0, -2], [2, 0, -2], [2, 0, 2], [-2, 0, 2],
                          [0.2, 1.0, -1.0], [0.2, 1.0, 1.0], [-1.0, 1.0, 0.3]], dtype=torch.float64)
    mesh = Mesh(verts, torch.tensor([[0, 2, 1], [0, 3, 2], [4, 6, 5]]))
    cam = Camera.look_at((0.0, 5.0, 0.0), (0.0, 0.0, 0.0), up=(0.0, 0.0, -1.0), ortho_height=5.0,
                         width=10, height=10, dtype=torch.float64)
    colors = torch.tensor([[0.8, 0.7, 0.6], [0.6, 0.7, 0.8], [0.9, 0.2, 0.2]], dtype=torch.float64)
    light = torch.tensor([0.3, -1.0, 0.0], dtype=torch.float64)
    split = split_by_shadows(mesh, light)
    x = cam.project(split.verts[split.faces[~split.lit].reshape(-1)])[0][:, 0]
    assert bool(((x - 6.0).abs() < 1e-12).any())                           # the shadow edge on the border
    w = _all_finite(mesh, cam, colors, light, 10)
    exact = shadow_image_gradient(mesh, cam, colors, light, w, method="exact", wrt=("verts", "light"))
    rey = shadow_image_gradient(mesh, cam, colors, light, w, method="reynolds", wrt=("verts", "light"))
    assert _rel(rey[0], exact[0]) < 1e-6 and _rel(rey[1], exact[1]) < 1e-6


def test_occluder_touching_its_receiver():
    """A vertex of the occluder on the floor (and the cube standing on it): finite gradients."""
    mesh, cam, colors, light = shadow_scene("floater", 10)
    verts = mesh.verts.clone()
    verts[5, 1] = 0.0                                                       # one corner down on the floor
    mesh = Mesh(verts, mesh.faces)
    image = shadowed_coverage(mesh, cam, colors, light, AMBIENT)
    assert float((image - shadow_raytrace(mesh, cam, colors, light, AMBIENT, supersample=16)).abs().mean()) < 3e-3
    _all_finite(mesh, cam, colors, light, 10)
    _all_finite(*shadow_scene("box", 10), 10)


# ----------------------------------------------------------------------------------------- bad input

def test_bad_input_speaks_clearly():
    mesh, cam, colors, light = shadow_scene("floater", 8)
    w = _weights(8)
    with pytest.raises(ValueError, match="zero"):
        shadowed_coverage(mesh, cam, colors, torch.zeros(3, dtype=torch.float64))
    with pytest.raises(ValueError, match="light must be a direction of shape"):
        shadowed_coverage(mesh, cam, colors, torch.ones(2, 3, dtype=torch.float64))
    with pytest.raises(ValueError, match="NaN"):
        shadowed_coverage(mesh, cam, colors, torch.tensor([0.0, float("nan"), 1.0]))
    bad = mesh.verts.clone()
    bad[0, 0] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        shadowed_coverage(Mesh(bad, mesh.faces), cam, colors, light)
    with pytest.raises(ValueError, match="ambient"):
        shadowed_coverage(mesh, cam, colors, light, ambient=1.5)
    with pytest.raises(ValueError, match="face_colors"):
        shadowed_coverage(mesh, cam, colors[:1], light)
    with pytest.raises(ValueError, match="method"):
        shadow_image_gradient(mesh, cam, colors, light, w, method="soft")
    with pytest.raises(ValueError, match="weights"):
        shadow_image_gradient(mesh, cam, colors, light, w[:4], method="exact")
    with pytest.raises(ValueError, match="wrt"):
        shadow_image_gradient(mesh, cam, colors, light, w, method="exact", wrt=("focal",))
    with pytest.raises(TypeError, match="no options"):
        shadow_image_gradient(mesh, cam, colors, light, w, method="exact", samples=3)


# ------------------------------------------------------------------------------------------ point lights

def _point(light):
    """A point light about 3 units from the origin toward where the scene's sun comes from."""
    return -3 * light / light.norm() + torch.tensor([0.2, 0.5, 0.1], dtype=light.dtype)


@pytest.mark.parametrize("name", ["floater", "crossing"])
def test_point_light_image_matches_ray_tracing(name):
    mesh, cam, colors, light = shadow_scene(name, 12)
    lamp = _point(light)
    image = shadowed_coverage(mesh, cam, colors, lamp, AMBIENT, point=True)
    ref = shadow_raytrace(mesh, cam, colors, lamp, AMBIENT, supersample=24, point=True)
    err = (image - ref).abs()
    assert float(err.max()) < 0.1 and float(err.mean()) < 2e-3
    assert float((shadowed_coverage(mesh, cam, colors, lamp, 1.0, point=True) - image).abs().max()) > 0.1


def test_point_light_gradients_match_central_differences():
    """d L / d (occluder vertices, the light's position) for a point light: exact, Reynolds, converged FD."""
    mesh, cam, colors, light = shadow_scene("floater", 10)
    lamp = _point(light)
    w = _weights(10)
    kw = dict(ambient=AMBIENT, point=True, wrt=("verts", "light"))
    fd6 = shadow_image_gradient(mesh, cam, colors, lamp, w, method="finite_differences", step=1e-6,
                                vertices=[3, 4, 5], **kw)
    fd5 = shadow_image_gradient(mesh, cam, colors, lamp, w, method="finite_differences", step=1e-5,
                                vertices=[3, 4, 5], **kw)
    exact = shadow_image_gradient(mesh, cam, colors, lamp, w, method="exact", **kw)
    rey = shadow_image_gradient(mesh, cam, colors, lamp, w, method="reynolds", **kw)
    for k, sel in ((0, slice(3, 6)), (1, slice(None))):
        assert _rel(fd5[k][sel], fd6[k][sel]) < 1e-5 and float(fd6[k][sel].norm()) > 0
        assert _rel(exact[k][sel], fd6[k][sel]) < 1e-5 and _rel(rey[k][sel], fd6[k][sel]) < 1e-5


def test_point_light_inside_the_scene_is_refused():
    mesh, cam, colors, _ = shadow_scene("floater", 8)
    with pytest.raises(ValueError, match="inside the scene"):
        shadowed_coverage(mesh, cam, colors, torch.tensor([0.0, 0.5, 0.0], dtype=torch.float64), point=True)


# ------------------------------------------------------------------------------ random overlapping occluders

def _two_occluders(seed):
    """The floor and two random triangles floating over it, one above the other: their shadows overlap on the
    floor (a union of shadows), and the upper one shadows the lower one."""
    gen = torch.Generator().manual_seed(seed)
    mesh, cam, colors, light = shadow_scene("floater", 12)
    centre = torch.tensor([[-0.2, 1.4, 0.0], [0.1, 0.7, 0.1]], dtype=torch.float64)
    tris = centre[:, None, :] + 1.0 * (torch.rand(2, 3, 3, generator=gen, dtype=torch.float64) - 0.5)
    verts = torch.cat([mesh.verts[:3], tris.reshape(6, 3)])
    faces = torch.tensor([[0, 1, 2], [3, 4, 5], [6, 7, 8]])
    v = verts[faces]
    up = torch.linalg.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0], dim=1)[:, 1] > 0
    faces = torch.where(up[:, None], faces, faces.flip(1))                  # every face up, toward the light
    colors = 0.3 + 0.6 * torch.rand(3, 3, generator=gen, dtype=torch.float64)
    return Mesh(verts, faces), cam, colors, light


@pytest.mark.parametrize("seed,lower_shadowed", [(0, False), (2, True), (3, True)])
def test_overlapping_shadows_image_and_gradients(seed, lower_shadowed):
    """Seed 2's triangles pass through each other (each shadows a part of the other)."""
    mesh, cam, colors, light = _two_occluders(seed)
    split = split_by_shadows(mesh, light)
    assert bool((~split.lit[split.source == 2]).any()) == lower_shadowed
    image = shadowed_coverage(mesh, cam, colors, light, AMBIENT)
    ref = shadow_raytrace(mesh, cam, colors, light, AMBIENT, supersample=24)
    assert float((image - ref).abs().max()) < 0.1 and float((image - ref).abs().mean()) < 2e-3
    w = _weights(12, seed=seed)
    kw = dict(ambient=AMBIENT, wrt=("verts", "light"))
    exact = shadow_image_gradient(mesh, cam, colors, light, w, method="exact", **kw)
    rey = shadow_image_gradient(mesh, cam, colors, light, w, method="reynolds", **kw)
    assert _rel(rey[0], exact[0]) < 1e-9 and _rel(rey[1], exact[1]) < 1e-9
    fd = shadow_image_gradient(mesh, cam, colors, light, w, method="finite_differences", vertices=[3, 6], **kw)
    assert _rel(exact[0][[3, 6]], fd[0][[3, 6]]) < 1e-5 and _rel(exact[1], fd[1]) < 1e-5


@pytest.mark.parametrize("lift, elevation", [(1e-5, 1e-4), (1e-3, 0.0524), (1e-7, 1e-4)])
def test_the_ray_traced_reference_converges_at_grazing_light(lift, elevation):
    """A thin occluder just above the floor, the sun barely above the horizon: ``shadow_raytrace`` stayed 0.25
    off the exact image at 24² and 48² samples (its shadow rays started 1e-4 of the diagonal above the surface,
    over the occluder, and shifted the grazing edge by offset / tan(elevation)); it now converges like any box
    filter, the largest pixel error falling ~4× per doubling of the samples."""
    mesh, cam, colors, light = shadow_scene("floater", 16)
    v = mesh.verts.clone()
    v[3:, 1] = torch.tensor([0.2, 2.0, 1.0], dtype=torch.float64) * lift
    mesh = Mesh(v, mesh.faces)
    across = torch.tensor([float(light[0]), 0.0, float(light[2])], dtype=torch.float64)
    light = across / across.norm() * math.cos(elevation) - torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64) * math.sin(elevation)
    exact = shadowed_coverage(mesh, cam, colors, light, AMBIENT)
    err = [float((shadow_raytrace(mesh, cam, colors, light, AMBIENT, supersample=s) - exact).abs().max())
           for s in (12, 24)]
    assert err[1] < 0.02 and err[1] < err[0] / 1.8, err                     # measured 0.0199, 0.0093


def _aligned_scene(kind, off):
    """The floater seen along its light: an orthographic camera ``off`` rad from a directional light, or a
    perspective camera ``off`` units from a point light (~4 units from the scene)."""
    mesh, _, colors, light = shadow_scene("floater", 12)
    if kind == "directional":
        u = light / light.norm()
        axis = torch.linalg.cross(u, torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64))
        forward = u * math.cos(off) + axis / axis.norm() * math.sin(off)
        target = torch.tensor([0.3, 0.3, 0.3], dtype=torch.float64)
        cam = Camera.look_at(target - 5 * forward, target, up=(0.0, 0.0, 1.0), ortho_height=3.0, width=12,
                             height=12, dtype=torch.float64)
        return mesh, cam, colors, light, False
    lamp = torch.tensor([1.0, 4.0, 0.8], dtype=torch.float64)
    eye = lamp + off * torch.tensor([0.6, 0.0, 0.8], dtype=torch.float64)
    cam = Camera.look_at(eye, (0.0, 0.4, 0.1), fov_y=50.0, width=12, height=12, dtype=torch.float64)
    return mesh, cam, colors, lamp, True


@pytest.mark.parametrize("kind, off", [("directional", 1e-7), ("directional", 1e-9), ("directional", 2e-10),
                                       ("point", 1e-6), ("point", 1e-7), ("point", 1e-9)])
def test_reynolds_is_exact_near_a_camera_looking_along_the_light(kind, off):
    """An occluder's silhouette and its own shadow's edge a sliver apart on screen: the boundary term asked the
    z-buffer 1e-6 px beside each edge, stepped over the sliver and counted the jump twice (the occluder's
    gradient 71 % off at 1e-7 rad, 100 % at 1e-9; 86 % and 100 % with the camera 1e-7 and 1e-9 units from a point
    light). Now Reynolds equals the exact gradient to rounding, and both equal converged central differences."""
    mesh, cam, colors, light, point = _aligned_scene(kind, off)
    w = _weights(12)
    kw = dict(ambient=AMBIENT, wrt=("verts", "light"), point=point)
    exact = shadow_image_gradient(mesh, cam, colors, light, w, method="exact", **kw)
    rey = shadow_image_gradient(mesh, cam, colors, light, w, method="reynolds", **kw)
    rows = [3, 4, 5]                                                        # the occluder: its steps move no
    fd6 = shadow_image_gradient(mesh, cam, colors, light, w, method="finite_differences", step=1e-6,  # alignment
                                vertices=rows, **kw)
    fd5 = shadow_image_gradient(mesh, cam, colors, light, w, method="finite_differences", step=1e-5,
                                vertices=rows, **kw)
    assert _rel(fd5[0][rows], fd6[0][rows]) < 1e-5 and float(fd6[0][rows].norm()) > 0.1
    assert _rel(exact[0][rows], fd6[0][rows]) < 1e-5
    assert _rel(rey[0][rows], fd6[0][rows]) < 1e-5
    assert _rel(rey[0], exact[0]) < 1e-9 and _rel(rey[1], exact[1]) < 1e-8


@pytest.mark.parametrize("kind", ["directional", "point"])
def test_the_boundary_methods_refuse_a_camera_on_the_lights_line_of_sight(kind):
    """Exactly aligned the shadow hides behind its occluder and its edge lies on the silhouette: no probe can
    tell them apart, so the boundary methods refuse (naming the limit); exact is still right."""
    mesh, cam, colors, light, point = _aligned_scene(kind, 0.0)
    w = _weights(12)
    kw = dict(ambient=AMBIENT, wrt=("verts",), point=point)
    for method in ("reynolds", "edge_sampling"):
        with pytest.raises(ValueError, match="looks along the light"):
            shadow_image_gradient(mesh, cam, colors, light, w, method=method, **kw)
    exact, = shadow_image_gradient(mesh, cam, colors, light, w, method="exact", **kw)
    fd, = shadow_image_gradient(mesh, cam, colors, light, w, method="finite_differences", step=1e-6,
                                vertices=[3, 4, 5], **kw)
    assert _rel(exact[3:6], fd[3:6]) < 1e-5
