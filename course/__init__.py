"""A differentiable renderer written from scratch in torch, and the course built on it.

The pipeline::

    Mesh + Camera ──project──▶ screen-space triangles ──rasterize──▶ Fragments ──shade──▶ image
                                                     (or k × k samples per pixel, box-filtered: antialiasing)

Conventions (fixed; ``tests/test_conventions.py`` pins each one):

* World space is right-handed with +y up.
* Camera: ``λ [x, y, 1]ᵀ = K [R | t] [X, 1]ᵀ`` with ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` in pixels,
  ``x_cam = R @ x_world + t``, OpenCV axes: +x right, +y down, +z forward (depth positive in front).
* Images are (H, W, C) with row 0 at the top. Pixel (row i, column j) covers [j, j+1) × [i, i+1); its
  centre is (j + 0.5, i + 0.5).
* ``faces`` (F, 3) int64 index ``verts`` (V, 3); a face is front-facing when its vertices appear
  counter-clockwise to the viewer. Rasterization follows the top-left fill rule.
* Texture coordinates: u right, v up; texture images are stored row 0 at the top.
* Colour is linear RGB in [0, 1] and shading is linear; sRGB encoding happens only for display and PNG
  output, and 8-bit image textures are decoded from sRGB on load. Random functions take a ``torch.Generator`` or a seed.
* Functions accept numpy arrays or tensors, return tensors, and keep the input's dtype and device; what is
  made from nothing (the bundled models, ``load_mesh``) takes torch's default dtype (float32 unless changed).

Shape letters used in every docstring: V vertices, F faces, H × W image, C channels, N points or rays,
S samples.

The ``render()`` function lives in ``course.render`` (``from course.render import render``); it is not
re-exported here, so that ``course.render`` always names the module.
"""
from .antialias import adaptive_supersample, exact_coverage, supersample
from .camera import (Camera, axis_angle_to_matrix, euler_to_matrix, homogeneous, intrinsics_from_fov, look_at,
                     pixel_rays, project_points, transform_points, world_to_camera)
from .mesh import Mesh, join_meshes, load_mesh
from .models import checker_texture, cube, default_scene_mesh, icosphere, plane, teapot, torus
from .raster import Fragments, interpolate, rasterize, rasterize_naive
from .raytrace import BVH, raycast
from .render import RenderResult, RenderSettings, Scene
from .shading import (AmbientLight, DirectionalLight, Material, PointLight, blinn_phong, lambert, linear_to_srgb,
                      phong, sample_texture, srgb_to_linear)
from .shadows import SpotLight, shadow_factor, shadow_map
from .nmr import nmr_image, nmr_rasterize
from .soft import soft_rasterize
from .inverse.losses import iou, psnr, silhouette_iou_loss, smoothness_loss
from .inverse import fit_camera, fit_mesh_from_silhouettes
from .inverse.texture import fit_texture_from_images, fit_vertex_colors_from_images
from .inverse.views import fit_with_learned_views
from .shadows.gradients import shadow_image_gradient, shadowed_coverage, split_by_shadows
from .shadows.fit import fit_light_direction
from .shadows.art import fit_shadow_art
from .learning.shapes import make_shape
from .learning.data import make_dataset, voxel_iou, voxelize
from .learning.reconstruction import MeshReconstructor, load_pretrained_reconstructor, train_reconstructor
from .learning.mvtn import MultiViewClassifier

from . import _moved

_moved.install()                     # old module paths (course.shadow_gradients, ...) import with a warning

__version__ = "0.1.0"

__all__ = [
    # meshes
    "Mesh", "load_mesh", "join_meshes", "cube", "icosphere", "plane", "torus", "teapot", "checker_texture",
    "default_scene_mesh",
    # cameras
    "Camera", "look_at", "axis_angle_to_matrix", "euler_to_matrix", "homogeneous", "transform_points",
    "world_to_camera", "project_points", "pixel_rays", "intrinsics_from_fov",
    # rasterization
    "Fragments", "rasterize", "rasterize_naive", "interpolate",
    # antialiasing
    "supersample", "adaptive_supersample", "exact_coverage",
    # shadows and ray tracing
    "shadow_map", "shadow_factor", "SpotLight", "BVH", "raycast",
    # differentiable rasterization
    "soft_rasterize", "nmr_rasterize", "nmr_image",
    # inverse rendering
    "silhouette_iou_loss", "smoothness_loss", "iou", "psnr", "fit_mesh_from_silhouettes", "fit_camera",
    "fit_texture_from_images", "fit_vertex_colors_from_images", "fit_with_learned_views",
    # differentiable shadows
    "shadowed_coverage", "shadow_image_gradient", "split_by_shadows", "fit_light_direction", "fit_shadow_art",
    # learning through the renderer
    "make_shape", "make_dataset", "voxelize", "voxel_iou", "MeshReconstructor", "train_reconstructor",
    "load_pretrained_reconstructor", "MultiViewClassifier",
    # shading and rendering
    "AmbientLight", "DirectionalLight", "PointLight", "Material", "lambert", "phong", "blinn_phong",
    "sample_texture", "linear_to_srgb", "srgb_to_linear", "Scene", "RenderSettings", "RenderResult",
]
