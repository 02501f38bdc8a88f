"""Bad input gets a clear error that names the argument and the problem, never a silent wrong result.

One parametrised test per family of public functions: wrong dtypes, non-integer, negative or bool counts,
degenerate cameras, empty meshes, NaN / inf, wrong shapes, out-of-range indices, zero-size images. Each case
checks the exception type and that the message names the argument (``pytest.raises(..., match=...)``). The
inputs are tiny, so nothing here can hang. The last tests check that legitimate inputs are still accepted.
"""
import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from course import camera as C
from course import inverse as fit, models, raster, raytrace, shading, shadows, textures, viz
from course.inverse import losses, texture as fit_texture, views as fit_views
from course.camera import Camera
from course.mesh import Mesh, join_meshes, load_mesh
from course.render import RenderSettings, Scene, render
from course.framing import frame_camera
from course.tensors import as_tensor

NAN, INF = math.nan, math.inf
EYE3 = torch.eye(3)
K = torch.tensor([[10.0, 0.0, 4.0], [0.0, 10.0, 4.0], [0.0, 0.0, 1.0]])
T = torch.tensor([0.0, 0.0, 5.0])
TRI = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def cam(**kw):
    return Camera.look_at((0.0, 0.0, 5.0), fov_y=40.0, width=8, height=8, **kw)


def ns(verts=TRI, faces=((0, 1, 2),)):
    """A duck-typed mesh: rasterize, raycast and BVH take anything with verts and faces tensors."""
    return SimpleNamespace(verts=verts, faces=torch.as_tensor(faces))


def check(call, error, message):
    with pytest.raises(error, match=message):
        call()


# ------------------------------------------------------------------------------------------- tensors

@pytest.mark.parametrize("call, error, message", [
    (lambda: as_tensor([1.0], dtype="float", name="x"), TypeError, r"dtype must be a torch.dtype.*'float'"),
    (lambda: as_tensor([1.0], dtype=torch.int64, name="x"), TypeError, "dtype must be a floating torch.dtype"),
    (lambda: as_tensor([1.0], device="float", name="x"), TypeError, r"device must be a torch.device.*'float'"),
    (lambda: as_tensor(torch.ones(2, dtype=torch.complex64), name="x"), TypeError, "x must hold real numbers"),
    (lambda: as_tensor("abc", name="x"), TypeError, "x must be a tensor or array of numbers"),
], ids=["dtype str", "dtype int", "device", "complex", "string"])
def test_tensors(call, error, message):
    check(call, error, message)


# -------------------------------------------------------------------------------------------- camera

def K_with(**entries):
    k = K.clone()
    for (i, j), v in ((tuple(int(c) for c in name[1:]), v) for name, v in entries.items()):
        k[i, j] = v
    return k


@pytest.mark.parametrize("call, error, message", [
    (lambda: Camera(K_with(k22=0.0), EYE3, T, 8, 8), ValueError, r"K's last row must be \(0, 0, 1\)"),
    (lambda: Camera(K_with(k21=1.0), EYE3, T, 8, 8), ValueError, r"K's last row must be \(0, 0, 1\)"),
    (lambda: Camera(K_with(k00=0.0), EYE3, T, 8, 8), ValueError, r"K has a zero focal length"),
    (lambda: Camera(K_with(k11=0.0), EYE3, T, 8, 8), ValueError, r"K has a zero focal length"),
    (lambda: Camera(K_with(k02=NAN), EYE3, T, 8, 8), ValueError, "K contains NaN"),
    (lambda: Camera(torch.eye(4), EYE3, T, 8, 8), ValueError, r"K must have shape \(3, 3\)"),
    (lambda: Camera(K, 2 * EYE3, T, 8, 8), ValueError, "R must be a rotation matrix"),
    (lambda: Camera(K, torch.diag(torch.tensor([1.0, 1.0, -1.0])), T, 8, 8), ValueError, r"R must be a rotation.*det"),
    (lambda: Camera(K, torch.zeros(3, 3), T, 8, 8), ValueError, "R must be a rotation matrix"),
    (lambda: Camera(K, EYE3, [0.0, INF, 0.0], 8, 8), ValueError, "t contains NaN or inf"),
    (lambda: Camera(K, EYE3, [0.0, 0.0], 8, 8), ValueError, r"t must have shape \(3,\)"),
    (lambda: Camera(K, EYE3, T, True, 8), ValueError, "width must be a positive integer, got the bool"),
    (lambda: Camera(K, EYE3, T, 8.0, 8), ValueError, "width must be a positive integer, got 8.0"),
    (lambda: Camera(K, EYE3, T, 8, 0), ValueError, "height must be a positive integer, got 0"),
    (lambda: Camera(K, EYE3, T, 8, "8"), ValueError, "height must be a positive integer"),
    (lambda: Camera(K, EYE3, T, 8, 8, near=0.0), ValueError, "near must be > 0"),
    (lambda: Camera(K, EYE3, T, 8, 8, near=NAN), ValueError, "near must be a finite number"),
    (lambda: Camera(K, EYE3, T, 8, 8, near="a"), ValueError, "near must be a real number"),
    (lambda: Camera(K, EYE3, T, 8, 8, near=5.0, far=1.0), ValueError, "need near < far"),
    (lambda: Camera(K, EYE3, T, 8, 8, far=NAN), ValueError, "far must be a finite number"),
    (lambda: Camera(K, EYE3, T, 8, 8, orthographic="no"), ValueError, "orthographic must be True or False"),
    (lambda: cam(dtype="float"), TypeError, r"dtype must be a torch.dtype.*'float'"),
    (lambda: cam(dtype=torch.int32), TypeError, "dtype must be a floating torch.dtype"),
    (lambda: Camera.look_at((0.0, 0.0, 5.0), fov_y=NAN, width=8, height=8), ValueError, "fov_y must be a finite"),
    (lambda: Camera.look_at((0.0, 0.0, 5.0), fov_y=180.0, width=8, height=8), ValueError, "fov_y must be < 180"),
    (lambda: Camera.look_at((0.0, 0.0, 5.0), ortho_height=0.0, width=8, height=8), ValueError,
     "ortho_height must be > 0"),
    (lambda: Camera.look_at((0.0, 0.0, 5.0), fov_y=40.0, width=8.5, height=8), ValueError, "width must be a"),
    (lambda: Camera.look_at((0.0, 0.0, 5.0), up=(0.0, 0.0, 0.0), fov_y=40.0, width=8, height=8), ValueError,
     "up must be a non-zero vector"),
    (lambda: cam().to(dtype="double"), TypeError, "dtype must be a torch.dtype"),
    (lambda: C.intrinsics_from_fov(40.0, 0, 8), ValueError, "width must be a positive integer"),
    (lambda: C.intrinsics_from_fov(40.0, 8, 8, dtype="float"), TypeError, "dtype must be a torch.dtype"),
    (lambda: C.project_points(torch.zeros(2, 3), K_with(k22=0.0), EYE3, T), ValueError, "K's last row"),
    (lambda: C.project_points(torch.full((2, 3), NAN), K, EYE3, T), ValueError, "points contains NaN"),
    (lambda: C.pixel_rays(torch.zeros(3, 3), EYE3, T, 4, 4), ValueError, "K's last row"),
    (lambda: C.pixel_rays(K, EYE3, T, 2.5, 4), ValueError, "width must be a positive integer"),
    (lambda: C.pixel_rays(K, EYE3, T, 4, True), ValueError, "height must be a positive integer"),
    (lambda: C.axis_angle_to_matrix([NAN, 0.0, 0.0]), ValueError, "axis_angle contains NaN"),
    (lambda: C.euler_to_matrix([0.0, 0.0, 0.0], order=3), ValueError, "order must be a permutation"),
    (lambda: C.transform_points(torch.zeros(4, 4), torch.zeros(1, 3)), ValueError, "M sends point 0 to infinity"),
], ids=lambda x: None)
def test_camera(call, error, message):
    check(call, error, message)


# ------------------------------------------------------------------------------------- mesh and models

@pytest.mark.parametrize("call, error, message", [
    (lambda: Mesh(TRI, [[0, 1, 2.7]]), TypeError, "faces must hold integer vertex indices"),
    (lambda: Mesh(TRI, np.array([[0.0, 1.0, 2.0]])), TypeError, "faces must hold integer vertex indices"),
    (lambda: Mesh(TRI, [[0, 1, 3]]), ValueError, "faces index vertex 3"),
    (lambda: Mesh(TRI, [[0, 1, -1]]), ValueError, "faces index vertex -1"),
    (lambda: Mesh(torch.zeros(0, 3), torch.zeros(0, 3, dtype=torch.long)), ValueError, "verts has 0 vertices"),
    (lambda: Mesh(TRI, torch.zeros(0, 3, dtype=torch.long)), ValueError, "faces has 0 triangles"),
    (lambda: Mesh(torch.full((3, 3), NAN), [[0, 1, 2]]), ValueError, "verts has 3 vertices with NaN"),
    (lambda: models.cube().to(dtype="float"), TypeError, "dtype must be torch.float32 or torch.float64"),
    (lambda: models.cube().to(device="gpu0"), TypeError, "device must be a torch.device"),
    (lambda: models.cube().transformed(torch.full((4, 4), NAN)), ValueError, "M contains NaN or inf"),
    (lambda: join_meshes(3), TypeError, "meshes must be a sequence of Mesh"),
    (lambda: load_mesh(3), TypeError, "path must be a str or pathlib.Path"),
    (lambda: load_mesh("x.obj", dtype="float"), TypeError, "dtype must be a torch.dtype"),
    (lambda: models.cube(dtype="float"), TypeError, "dtype must be a torch.dtype"),
    (lambda: models.teapot(2, dtype=torch.int64), TypeError, "dtype must be a floating torch.dtype"),
    (lambda: models.cube(0.0), ValueError, "size must be > 0"),
    (lambda: models.cube(NAN), ValueError, "size must be a finite number"),
    (lambda: models.icosphere(1.5), ValueError, "subdivisions must be a non-negative integer"),
    (lambda: models.icosphere(True), ValueError, "subdivisions must be a non-negative integer, got the bool"),
    (lambda: models.icosphere(-1), ValueError, "subdivisions must be a non-negative integer"),
    (lambda: models.icosphere(1, radius=-1.0), ValueError, "radius must be > 0"),
    (lambda: models.plane(subdivisions=0), ValueError, "subdivisions must be a positive integer"),
    (lambda: models.torus(n_major=3.5), ValueError, "n_major must be an integer >= 3"),
    (lambda: models.torus(major=0.3, minor=0.35), ValueError, "major must be larger than minor"),
    (lambda: models.teapot(2.5), ValueError, "resolution must be a positive integer"),
    (lambda: models.checker_texture(4.5), ValueError, "size must be a positive integer"),
    (lambda: models.checker_texture(8, 0), ValueError, "checks must be a positive integer"),
], ids=lambda x: None)
def test_mesh_and_models(call, error, message):
    check(call, error, message)


# ------------------------------------------------------------------------------------ rasterization

@pytest.mark.parametrize("call, error, message", [
    (lambda: raster.rasterize(ns(faces=[[0.0, 1.0, 2.7]]), cam()), TypeError, "mesh.faces must hold integer"),
    (lambda: raster.rasterize(ns(faces=[[0, 1, 5]]), cam()), ValueError, "mesh.faces index vertex 5"),
    (lambda: raster.rasterize(ns(faces=[[0, 1, -2]]), cam()), ValueError, "mesh.faces holds a negative"),
    (lambda: raster.rasterize(ns(verts=TRI.numpy()), cam()), ValueError, "mesh.verts must be a .* torch tensor"),
    (lambda: raster.rasterize(ns(verts=TRI.bool()), cam()), TypeError, "mesh.verts must hold real numbers"),
    (lambda: raster.rasterize(ns(verts=torch.full((3, 3), NAN)), cam()), ValueError, "mesh.verts contains NaN"),
    (lambda: raster.rasterize(models.cube(), None), TypeError, "camera must be a course.camera.Camera"),
    (lambda: raster.rasterize(models.cube(), cam(), cull_backfaces="no"), ValueError, "cull_backfaces must be"),
    (lambda: raster.rasterize(models.cube(), cam(), samples=[[NAN, 0.5]]), ValueError, "sample offsets"),
    (lambda: raster.rasterize(models.cube(), cam(), pixels=[0.5]), ValueError, "pixels must be"),
    (lambda: raster.rasterize(models.cube(), cam(), pixels=[64]), ValueError, "pixel indices must lie"),
    (lambda: raster.rasterize_naive(ns(faces=[[0.0, 1.0, 2.0]]), cam()), TypeError, "mesh.faces must hold integer"),
    (lambda: raster.interpolate(torch.zeros(3, 2), raster.rasterize(Mesh(TRI, [[0, 1, 2]]), cam()),
                                torch.tensor([[0.0, 1.0, 2.7]])), TypeError, "faces must hold integer"),
    (lambda: raster.interpolate(torch.zeros(3, 2), raster.rasterize(Mesh(TRI, [[0, 1, 2]]), cam()), [[0, 1, -1]]),
     ValueError, "faces holds a negative"),
    (lambda: raster.interpolate(torch.full((3, 2), NAN), raster.rasterize(Mesh(TRI, [[0, 1, 2]]), cam()),
                                [[0, 1, 2]]), ValueError, "attr contains NaN"),
    (lambda: raster.interpolate(torch.zeros(3, 2), None, [[0, 1, 2]]), TypeError, "fragments must be Fragments"),
    (lambda: raster.edge_function([0.0, 0.0, 0.0], [1.0, 0.0], [0.0, 1.0]), ValueError,
     r"a must have shape \(\.\.\., 2\)"),
    (lambda: raster.edge_function(torch.zeros(2, 2), torch.zeros(3, 2), torch.zeros(2)), ValueError,
     "a, b and p must broadcast"),
    (lambda: raster.inside_triangle([[NAN, 0.0], [1.0, 0.0], [0.0, 1.0]], [[0.2, 0.2]]), ValueError,
     "tri contains NaN"),
    (lambda: raster.barycentric_2d([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], [[INF, 0.2]]), ValueError,
     "points contains NaN"),
    (lambda: raster.perspective_correct_bary([[0.3, 0.3, 0.4]], [0.0, 1.0, 1.0]), ValueError, "z holds a zero depth"),
    (lambda: raster.perspective_correct_bary([[0.3, 0.7]], [1.0, 1.0, 1.0]), ValueError, r"bary_screen must have"),
    (lambda: raster.zbuffer_resolve([0], [1.0], [0], 2.5), ValueError, "num_pixels must be a non-negative integer"),
    (lambda: raster.zbuffer_resolve([0], [1.0], [0], True), ValueError, "num_pixels must be a non-negative integer"),
    (lambda: raster.zbuffer_resolve([0.7], [1.0], [0], 2), TypeError, "pixel_index must hold integer"),
    (lambda: raster.zbuffer_resolve([0], [1.0], [0.7], 2), TypeError, "face_id must hold integer"),
    (lambda: raster.clip_polygon_near(torch.eye(3), NAN), ValueError, "near must be a finite number"),
    (lambda: raster.clip_polygon_near(torch.full((3, 3), NAN), 0.1), ValueError, "tri_cam contains NaN"),
    (lambda: raster.pixel_triangle_pairs(torch.zeros(1, 3, 2), 2.5, 2), ValueError, "width must be a non-negative"),
    (lambda: raster.pixel_triangle_pairs(torch.full((1, 3, 2), NAN), 2, 2), ValueError, "xy contains NaN"),
    (lambda: raster.pixel_triangle_pairs(torch.zeros(1, 3, 2), 2, 2, mask=torch.ones(4)), TypeError,
     "mask must be a bool tensor"),
], ids=lambda x: None)
def test_rasterization(call, error, message):
    check(call, error, message)


# ------------------------------------------------------------------------------------------ ray tracing

BVH = raytrace.BVH(models.cube())
PTS = torch.tensor([[0.0, 0.0, 3.0], [0.0, 3.0, 0.0]])


@pytest.mark.parametrize("call, error, message", [
    (lambda: raytrace.raycast(ns(faces=[[0.0, 1.0, 2.7]]), cam()), TypeError, "mesh.faces must hold integer"),
    (lambda: raytrace.raycast(models.cube(), cam(), bvh="x"), ValueError, "bvh must be a BVH"),
    (lambda: raytrace.BVH(ns(faces=[[0.0, 1.0, 2.0]])), TypeError, "mesh.faces must hold integer"),
    (lambda: raytrace.BVH(None), TypeError, "mesh must have verts"),
    (lambda: raytrace.BVH(models.cube(), leaf_size=2.5), ValueError, "leaf_size must be a positive integer"),
    (lambda: raytrace.BVH(models.cube(), leaf_size=True), ValueError, "leaf_size must be a positive integer"),
    (lambda: BVH.intersect(PTS, -PTS, packet=0), ValueError, "packet must be a positive integer"),
    (lambda: BVH.intersect(PTS, -PTS, chunk=0), ValueError, "chunk must be a positive integer"),
    (lambda: BVH.intersect(PTS, -PTS, t_min="a"), ValueError, "t_min must be a number"),
    (lambda: BVH.intersect(PTS, -PTS, any_hit="no"), ValueError, "any_hit must be True or False"),
    (lambda: BVH.intersect(torch.full((2, 3), NAN), -PTS), ValueError, "origins and directions must be finite"),
    (lambda: raytrace.visible(PTS, torch.zeros(3), BVH, directional=True), ValueError,
     "light must be a non-zero direction"),
    (lambda: raytrace.visible(PTS, torch.ones(3), BVH, directional="yes"), ValueError, "directional must be True"),
    (lambda: raytrace.visible(torch.full((2, 3), NAN), torch.ones(3), BVH), ValueError, "points contains NaN"),
    (lambda: raytrace.visible(PTS, torch.ones(3), BVH, normals=torch.full((2, 3), NAN)), ValueError,
     "normals contains NaN"),
    (lambda: raytrace.visible(PTS, torch.ones(3), BVH, offset="a"), ValueError, "offset must be a real number"),
    (lambda: raytrace.visible(PTS, torch.ones(3), BVH, offset=-1.0), ValueError, "offset must be >= 0"),
    (lambda: raytrace.visible(PTS, [NAN, 0.0, 0.0], BVH), ValueError, "light contains NaN"),
    (lambda: raytrace.rectangle_light_samples([0, 0, 0], [1, 0, 0], [0, 1, 0], 2.5), ValueError,
     "n_points must be a non-negative integer"),
    (lambda: raytrace.rectangle_light_samples([0, 0, 0], [1, 0, 0], [0, 1, 0], 2, grid=True), ValueError,
     "grid must be a positive integer"),
    (lambda: raytrace.rectangle_light_samples([0, 0, 0], [1, 0, 0], [2, 0, 0], 2), ValueError,
     "edge1 and edge2 must span a rectangle"),
    (lambda: raytrace.rectangle_light_samples([0, 0, 0], [NAN, 0, 0], [0, 1, 0], 2), ValueError,
     "edge1 contains NaN"),
    (lambda: raytrace.rectangle_light_samples([0, 0, 0], [1, 0, 0], [0, 1, 0], 2, seed="a"), ValueError,
     "seed must be a non-negative integer"),
    (lambda: raytrace.disk_light_samples([0, 0, 0], [0, 1, 0], INF, 2), ValueError, "radius must be a finite"),
    (lambda: raytrace.disk_light_samples([0, 0, 0], [0, 0, 0], 1.0, 2), ValueError, "normal must be a non-zero"),
    (lambda: raytrace.disk_light_samples([0, 0, NAN], [0, 1, 0], 1.0, 2), ValueError, "centre contains NaN"),
    (lambda: raytrace.intersect_triangles(torch.full((1, 3), NAN), torch.ones(1, 3), torch.zeros(1, 3, 3)),
     ValueError, "origins contains NaN"),
    (lambda: raytrace.moller_trumbore(torch.zeros(1, 3), torch.ones(1, 3), torch.full((1, 3, 3), INF)),
     ValueError, "tris contains NaN or inf"),
    (lambda: raytrace.ray_box(torch.zeros(1, 3), torch.ones(1, 3), torch.ones(1, 3), torch.zeros(1, 3)),
     ValueError, "lo must not exceed hi"),
    (lambda: raytrace.ray_box(torch.zeros(1, 3), torch.full((1, 3), NAN), torch.zeros(1, 3), torch.ones(1, 3)),
     ValueError, "directions contains NaN"),
    (lambda: raytrace.morton_codes(torch.zeros(2, 2)), ValueError, r"points must have shape \(N, 3\)"),
    (lambda: raytrace.morton_codes(torch.full((2, 3), NAN)), ValueError, "points contains NaN"),
], ids=lambda x: None)
def test_ray_tracing(call, error, message):
    check(call, error, message)


# ------------------------------------------------------------------------------------------ shadows

SUN = shading.DirectionalLight()
SM = shadows.shadow_map(models.cube(), SUN, 8)


@pytest.mark.parametrize("call, error, message", [
    (lambda: shadows.light_camera(SUN, models.cube(), resolution=True), ValueError, "resolution must be a positive"),
    (lambda: shadows.light_camera(SUN, models.cube(), resolution="8"), ValueError, "resolution must be a positive"),
    (lambda: shadows.light_camera(SUN, models.cube(), resolution=8, margin="a"), ValueError, "margin must be a real"),
    (lambda: shadows.light_camera(SUN, ((0.0, 0.0, 0.0), INF), resolution=8), ValueError, "bounding radius"),
    (lambda: shadows.light_camera(shadows.SpotLight(angle=NAN), models.cube(), resolution=8), ValueError,
     r"SpotLight.angle must be in \(0, 180\)"),
    (lambda: shadows.shadow_map(None, SUN, 8), TypeError, "expected a Mesh or a non-empty sequence"),
    (lambda: shadows.shadow_map(models.cube(), SUN, 8, cull_backfaces="yes"), ValueError, "cull_backfaces must be"),
    (lambda: shadows.shadow_factor(PTS, None, SM, pcf=3.0), ValueError, "pcf must be an odd integer"),
    (lambda: shadows.shadow_factor(PTS, None, SM, bias="a"), ValueError, "bias must be a real number"),
    (lambda: shadows.shadow_factor(PTS, None, SM, slope_bias=-1.0), ValueError, "slope_bias must be >= 0"),
    (lambda: shadows.shadow_factor(PTS, None, SM, max_slope=NAN), ValueError, "max_slope must be a finite"),
    (lambda: shadows.shadow_factor(PTS, torch.full((2, 3), NAN), SM), ValueError, "normals contains NaN"),
    (lambda: shadows.pcf(torch.zeros(0, 0), torch.zeros(1, 2), torch.zeros(1)), ValueError, "depth_map must be one"),
    (lambda: shadows.pcf(torch.full((4, 4), NAN), torch.zeros(1, 2), torch.zeros(1)), ValueError,
     "depth_map contains NaN"),
    (lambda: shadows.pcf(torch.zeros(4, 4), torch.zeros(1, 2), torch.full((1,), NAN)), ValueError,
     "depths contains NaN"),
    (lambda: shadows.pcf(torch.zeros(4, 4), torch.zeros(1, 2), torch.zeros(1), k="3"), ValueError,
     "k must be an odd integer"),
    (lambda: shadows.biased_depth(torch.tensor([NAN]), 1.0, 0.0, 0.0, 0.0), ValueError, "z contains NaN"),
    (lambda: shadows.biased_depth(torch.ones(2), torch.ones(3), 0.0, 0.0, 0.0), ValueError, "texel must be a scalar"),
    (lambda: shadows.biased_lit(torch.ones(1), torch.ones(1), 1.0, 0.0, "a", 0.0), ValueError, "bias must be a real"),
    (lambda: shadows.light_space(PTS, K_with(k22=0.0), EYE3, T), ValueError, "K's last row"),
    (lambda: shadows.area_light_samples("disk", (0, 0, 0), (0, 1, 0), 1.0, 2.0), ValueError,
     "n must be a positive integer"),
    (lambda: shadows.area_light_samples("disk", (0, 0, 0), (0, 1, 0), "big", 2), ValueError, "size must be positive"),
    (lambda: shadows.area_light_samples("disk", (0, 0, 0), (0, 1, 0), 1.0, 2, dtype="float"), TypeError,
     "dtype must be a torch.dtype"),
    (lambda: shadows.area_shadow_factor(PTS, None, models.cube(), torch.ones(1, 3) * 3, resolution=8, fov=NAN),
     ValueError, r"fov must be in \(0, 180\)"),
    (lambda: shadows.area_shadow_factor(PTS, None, models.cube(), torch.ones(1, 3) * 3, resolution=8,
                                        light_normal=(0, 0, 0)), ValueError, "light_normal must be a non-zero"),
], ids=lambda x: None)
def test_shadows(call, error, message):
    check(call, error, message)


# ---------------------------------------------------------------------------------- shading, textures

N1 = torch.tensor([[0.0, 0.0, 1.0]])


def frags():
    return raster.rasterize(models.cube(), cam())


@pytest.mark.parametrize("call, error, message", [
    (lambda: shading.normalize(torch.full((1, 3), NAN)), ValueError, "vector contains NaN"),
    (lambda: shading.lambert(torch.ones(2, 3), torch.ones(3, 3), (1, 1, 1)), ValueError, "light_dir must have shape"),
    (lambda: shading.lambert(N1, N1, (1.0, 1.0)), ValueError, r"albedo must have shape \(\.\.\., 3\)"),
    (lambda: shading.lambert(torch.ones(2), N1, (1, 1, 1)), ValueError, r"normal must have shape \(\.\.\., 3\)"),
    (lambda: shading.blinn_phong(N1, N1, N1, -1.0), ValueError, "shininess must be >= 0"),
    (lambda: shading.phong(N1, N1, N1, NAN), ValueError, "shininess contains NaN"),
    (lambda: shading.light_terms(torch.zeros(1, 3), N1, N1, shading.DirectionalLight()), TypeError,
     "lights must be a sequence of lights"),
    (lambda: shading.light_terms(torch.zeros(1, 3), N1, N1, [shading.DirectionalLight(direction=(0, 0, 0))]),
     ValueError, "DirectionalLight.direction must be a non-zero vector"),
    (lambda: shading.light_terms(torch.zeros(1, 3), N1, N1, [shading.PointLight(position=(0, NAN, 0))]),
     ValueError, "PointLight.position contains NaN"),
    (lambda: shading.light_terms(torch.zeros(1, 3), N1, N1, [shading.DirectionalLight(color=(1, 1))]),
     ValueError, "light color must be one number or RGB"),
    (lambda: shading.light_terms(torch.zeros(1, 3), N1, N1, [shading.DirectionalLight(intensity=NAN)]),
     ValueError, "light intensity contains NaN"),
    (lambda: shading.shade(torch.zeros(1, 3), N1, N1, (1, 1, 1), [shading.DirectionalLight()],
                           shading.Material(diffuse=(1.0, 1.0))), ValueError, "material.diffuse must be"),
    (lambda: shading.shade(torch.zeros(1, 3), N1, N1, (1, 1), [shading.DirectionalLight()]), ValueError,
     r"base_color must have shape"),
    (lambda: shading.view_directions(torch.zeros(1, 3), None), TypeError, "camera must be a course.camera.Camera"),
    (lambda: shading.flat_shading(models.cube(), None, cam(), [], shading.Material(), (1, 1, 1)), TypeError,
     "fragments must be Fragments"),
    (lambda: shading.wireframe_overlay(torch.zeros(8, 8, 3), models.cube(), frags(), cam(), width=NAN),
     ValueError, "width must be a finite number"),
    (lambda: shading.wireframe_overlay(torch.zeros(4, 4, 3), models.cube(), frags(), cam()), ValueError,
     r"image must have the fragments' shape"),
    (lambda: shading.wireframe_overlay(torch.zeros(8, 8, 3), models.cube(), frags(), cam(), color=(1, 1)),
     ValueError, r"color must be RGB"),
    (lambda: shading.linear_to_srgb(torch.tensor([NAN])), ValueError, "linear colour contains NaN"),
    (lambda: shading.srgb_to_linear(torch.tensor([1 + 1j])), TypeError, "sRGB colour must hold real numbers"),
    (lambda: textures.sample_texture(torch.zeros(2, 2, 3), torch.full((1, 2), NAN)), ValueError, "uv contains NaN"),
    (lambda: textures.sample_texture(torch.full((2, 2, 3), NAN), torch.zeros(1, 2)), ValueError,
     "texture contains NaN"),
    (lambda: textures.sample_texture(torch.zeros(2, 2, 0), torch.zeros(1, 2)), ValueError, "texture must have shape"),
    (lambda: textures.mip_level(torch.ones(1, 2), torch.ones(1, 2), (0, 4)), ValueError,
     "texture_size must be a positive integer"),
    (lambda: textures.mip_level(torch.ones(1, 2), torch.ones(1, 2), (4, 4, 4)), ValueError,
     r"texture_size must be \(Ht, Wt\)"),
    (lambda: textures.mip_level(torch.full((1, 2), NAN), torch.ones(1, 2), (4, 4)), ValueError, "duv_dx contains NaN"),
    (lambda: textures.mip_pyramid(torch.full((2, 2, 3), INF)), ValueError, "texture contains NaN or inf"),
    (lambda: textures.sample_texture_mip(torch.zeros(4, 4, 3), torch.zeros(1, 2), torch.zeros(1, 2),
                                         torch.full((1, 2), NAN)), ValueError, "duv_dy contains NaN"),
    (lambda: textures.uv_derivatives(torch.zeros(3, 2), torch.tensor([[0.0, 1.0, 2.7]]),
                                     raster.rasterize(Mesh(TRI, [[0, 1, 2]]), cam()), TRI, cam()),
     TypeError, "faces must hold integer"),
    (lambda: textures.uv_derivatives(torch.zeros(3, 2), [[0, 1, 2]], raster.rasterize(Mesh(TRI, [[0, 1, 2]]), cam()),
                                     TRI, None), TypeError, "camera must be a course.camera.Camera"),
    (lambda: textures.uv_derivatives(torch.full((3, 2), NAN), [[0, 1, 2]],
                                     raster.rasterize(Mesh(TRI, [[0, 1, 2]]), cam()), TRI, cam()),
     ValueError, "uvs contains NaN"),
], ids=lambda x: None)
def test_shading_and_textures(call, error, message):
    check(call, error, message)


# ------------------------------------------------------------------------------------- render, framing

@pytest.mark.parametrize("call, error, message", [
    (lambda: Scene(models.cube(), cam(), background=(NAN, 0.0, 0.0)), ValueError, "background must be 3 numbers"),
    (lambda: Scene(models.cube(), cam(), lights=shading.DirectionalLight()), TypeError,
     "lights must be a sequence of lights"),
    (lambda: Scene(models.cube(), cam(), lights=[3]), TypeError, "scene light 0 is a int"),
    (lambda: RenderSettings(shadow_resolution=True), ValueError, "shadow_resolution must be a positive int"),
    (lambda: RenderSettings(shadow_pcf=True), ValueError, "shadow_pcf must be a positive odd int"),
    (lambda: RenderSettings(samples=2.0), ValueError, "samples .* must be a positive int"),
    (lambda: RenderSettings(wireframe_width="a"), ValueError, "wireframe_width must be a real number"),
    (lambda: RenderSettings(wireframe_color=(1.0, 1.0)), ValueError, "wireframe_color must be 3"),
    (lambda: RenderSettings(seed=1.5), ValueError, "seed must be a non-negative integer"),
    (lambda: RenderSettings(sigma="a"), ValueError, "sigma must be a real number"),
    (lambda: RenderSettings(clamp="yes"), ValueError, "clamp must be True or False"),
    (lambda: render(Scene(models.cube(), cam()), "phong"), TypeError, "settings must be a RenderSettings"),
    (lambda: frame_camera(models.cube(), width=0, height=8), ValueError, "width must be a positive integer"),
    (lambda: frame_camera(models.cube(), width=8, height=8, fov_y=0.0), ValueError, "fov_y must be > 0"),
    (lambda: frame_camera(models.cube(), width=8, height=8, margin=NAN), ValueError, "margin must be a finite"),
    (lambda: frame_camera(models.cube(), width=8, height=8, direction=(0, 0, 0)), ValueError,
     "direction must be a non-zero vector"),
    (lambda: frame_camera(models.cube(), width=8, height=8, eye=(0.0, 0.0, 0.0)), ValueError, "eye must not be"),
    (lambda: frame_camera([], width=8, height=8), TypeError, "meshes must be a Mesh"),
], ids=lambda x: None)
def test_render_and_framing(call, error, message):
    check(call, error, message)


# ------------------------------------------------------------------------------------------- losses

SIL = torch.rand(4, 4, generator=torch.Generator().manual_seed(0))


@pytest.mark.parametrize("call, error, message", [
    (lambda: losses.iou(SIL, SIL, threshold=NAN), ValueError, "threshold must be a finite number"),
    (lambda: losses.iou(SIL, SIL, threshold="a"), ValueError, "threshold must be a real number"),
    (lambda: losses.iou(torch.zeros(0, 0), torch.zeros(0, 0)), ValueError, "pred must be an .* not empty"),
    (lambda: losses.silhouette_iou_loss(SIL.to(torch.complex64), SIL), TypeError, "pred must hold real numbers"),
    (lambda: losses.interior_edges([[0, 1, 2.7]]), ValueError, "faces must be .* integer vertex indices"),
    (lambda: losses.interior_edges([[0, 1, -1]]), ValueError, "faces holds a negative vertex index"),
    (lambda: losses.interior_edges(torch.ones(1, 3, dtype=torch.bool)), ValueError, "faces must hold integer"),
    (lambda: losses.edge_length_loss(models.cube(), target_length=NAN), ValueError, "target_length must be a finite"),
    (lambda: losses.edge_length_loss(models.cube(), target_length=-1.0), ValueError, "target_length must be >= 0"),
    (lambda: losses.psnr(torch.rand(4, 4, 3), torch.rand(4, 4, 3), mask=torch.full((4, 4), 0.5)), ValueError,
     "mask must hold 0 / 1"),
    (lambda: losses.l1_loss(torch.ones(2, dtype=torch.complex64), torch.ones(2)), TypeError,
     "pred must hold real numbers"),
], ids=lambda x: None)
def test_losses(call, error, message):
    check(call, error, message)


# -------------------------------------------------------------------------------------------- fits

@pytest.mark.parametrize("call, error, message", [
    (lambda: fit.circle_views(2.5), ValueError, "n must be a positive integer"),
    (lambda: fit.circle_views(True), ValueError, "n must be a positive integer, got the bool"),
    (lambda: fit.circle_views(2, distance=0.0), ValueError, "distance must be > 0"),
    (lambda: fit.circle_views(2, elevations=()), ValueError, "elevations must be a non-empty sequence"),
    (lambda: fit.circle_views(2, size=0), ValueError, "width must be a positive integer"),
    (lambda: fit.sphere_views(0), ValueError, "n must be a positive integer"),
    (lambda: fit.hard_silhouettes(models.cube(), []), ValueError, "cameras must be a non-empty list"),
    (lambda: fit.rotation_error(torch.eye(3), torch.eye(4)), ValueError, r"R2 must have shape \(3, 3\)"),
    (lambda: fit.rotation_error(torch.full((3, 3), NAN), torch.eye(3)), ValueError, "R1 contains NaN"),
    (lambda: fit.center_error("a", cam()), TypeError, "camera must be a Camera"),
    (lambda: fit.shaded_face_colors(models.cube(), light=(0, 0, 0)), ValueError, "light must be a non-zero"),
    (lambda: fit.camera_problem(models.cube(), axis=(0, 0, 0)), ValueError, "axis must be a non-zero vector"),
    (lambda: fit.fit_silhouettes(models.cube(), fit.circle_views(1, size=8), steps=True), ValueError,
     "steps must be a non-negative integer"),
    (lambda: fit.fit_mesh_from_silhouettes(models.cube(), n_views=2.5, steps=0, size=8), ValueError,
     "n_views must be a positive integer"),
    (lambda: fit_views.view_camera(0.1, 0.2, size=0), ValueError, "width must be a positive integer"),
    (lambda: fit_views.view_camera(NAN, 0.2), ValueError, "angles contains NaN"),
    (lambda: fit_views.ring_angles(2.5), ValueError, "n must be a positive integer"),
    (lambda: fit_views.ring_angles(2, dtype="float"), TypeError, "dtype must be a torch.dtype"),
    (lambda: fit_views.separation_penalty(torch.zeros(2), 10.0), ValueError, r"angles must have shape \(N, 2\)"),
    (lambda: fit_views.default_separation(0), ValueError, "n must be a positive integer"),
    (lambda: fit_texture.smooth_vertex_colors(models.cube(), "a"), ValueError, "seed must be a non-negative integer"),
    (lambda: fit_texture.smooth_vertex_colors(models.cube(), frequency=NAN), ValueError, "frequency must be a finite"),
], ids=lambda x: None)
def test_fits(call, error, message):
    check(call, error, message)


# --------------------------------------------------------------------------------------------- figures

@pytest.mark.parametrize("call, error, message", [
    (lambda: viz.show_image(np.zeros((0, 4, 3))), ValueError, "image must be a non-empty"),
    (lambda: viz.show_image(np.zeros((4, 4, 2))), ValueError, "image must be a non-empty"),
    (lambda: viz.image_grid([]), ValueError, "images must be a non-empty list"),
    (lambda: viz.image_grid([np.zeros((2, 2))], titles=["a", "b"]), ValueError, "titles must be None or one per"),
    (lambda: viz.image_grid([np.zeros((2, 2))], cols=1.5), ValueError, "cols must be a positive integer"),
    (lambda: viz.pixel_grid(0, 4), ValueError, "width must be a positive integer"),
    (lambda: viz.plot_image_points(np.zeros((2, 3)), 4, 4), ValueError, r"pixels must have shape \(N, 2\)"),
    (lambda: viz.plot_points_3d(np.zeros((2, 2))), ValueError, r"points must have shape \(N, 3\)"),
    (lambda: viz.save_gif([np.zeros((2, 2))], "x.gif", loop=True), ValueError, "loop must be a non-negative"),
], ids=lambda x: None)
def test_figures(call, error, message):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    try:
        check(call, error, message)
    finally:
        plt.close("all")


# ------------------------------------------------------------------------------- legitimate inputs pass

def test_legitimate_cameras_are_accepted():
    """numpy, float64, int K, requires-grad K/R/t, R from a differentiable axis-angle, R perturbed by a
    finite-difference step (image_gradient's 1e-3 on R's entries), orthographic with near = 0, far = inf."""
    base = cam(dtype=torch.float64)
    Camera(base.K.numpy(), base.R.numpy(), base.t.numpy(), np.int64(8), 8)
    Camera(K.long(), EYE3, T, 8, 8)
    w = torch.tensor([0.1, -0.2, 0.3], dtype=torch.float64, requires_grad=True)
    R = C.axis_angle_to_matrix(w)
    c = Camera(base.K.clone().requires_grad_(), R, base.t.clone().requires_grad_(), 8, 8)
    c.project(torch.zeros(1, 3, dtype=torch.float64))[0].sum().backward()
    assert w.grad is not None and torch.isfinite(w.grad).all()
    R_fd = base.R.clone()
    R_fd[0, 1] += 1e-3
    Camera(base.K, R_fd, base.t, 8, 8)
    Camera(torch.eye(3), torch.eye(3), torch.zeros(3), 8, 8, near=0.0, far=10.0, orthographic=True)
    Camera(K, EYE3, T, 8, 8, far=INF)
    Camera.look_at((0.0, 0.0, 5.0), ortho_height=2.0, width=8, height=8, near=0.0)
    assert C.intrinsics_from_fov(40.0, np.int32(8), 8).dtype == torch.get_default_dtype()


def test_legitimate_meshes_and_counts_are_accepted():
    mesh = Mesh(np.array(TRI.numpy(), dtype=np.float64), np.array([[0, 1, 2]], dtype=np.int32))
    assert mesh.dtype == torch.float64 and mesh.faces.dtype == torch.int64
    fr = raster.rasterize(mesh, cam(dtype=torch.float64), cull_backfaces=np.bool_(False))
    raster.interpolate(np.zeros((3, 2)), fr, np.array([[0, 1, 2]]))
    assert models.icosphere(np.int64(1)).num_faces == 80
    assert shadows.pcf(torch.zeros(4, 4), torch.zeros(1, 2), torch.zeros(1), k=np.int64(3)).shape == (1,)
    raytrace.visible(PTS, torch.tensor([0.0, -1.0, 0.0]), BVH, directional=True)
    raytrace.visible(PTS, torch.ones(3) * 4, BVH, normals=torch.zeros(2, 3))   # no normal: t_min = offset
    shadows.pcf(torch.full((4, 4), INF), torch.zeros(1, 2), torch.zeros(1))   # empty texels are +inf
    textures.sample_texture(torch.zeros(2, 2, 3), torch.tensor([[INF, -INF]]))   # clamps to the edge
    Scene(models.cube(), cam(), lights=None)
