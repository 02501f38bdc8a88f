"""Inverse rendering: images in, a scene out (lecture 10; the losses and Large Steps also serve 11 and 13).

What each module is:

* ``losses``: Kato et al.'s silhouette IoU loss and the IoU metric, the smoothness, Laplacian and edge-length
  regularisers, L2 and PSNR.
* ``common``: what the fits share: their histories and results, the views they train and judge on (a ring,
  a Fibonacci sphere), hard silhouettes, held-out IoU, self-intersections, the loops' helpers.
* ``silhouettes``: a mesh from silhouettes, a sphere deformed by soft rasterization or NMR.
* ``shaded``: a mesh from shaded images: the visual hull, then soft or Reynolds gradients, Large Steps or Adam.
* ``pose``: a camera from one image, by five gradients, with several starts and an image pyramid.
* ``texture``: a UV texture and vertex colours from images. ``views``: a mesh fitted with learned views (MVTN).
* ``carve``: the visual hull on a grid, meshed by surface nets. ``large_steps``: Nicolet et al.'s
  parameterisation and their Adam. ``metrics``: a fitted mesh judged in 3D (Chamfer, normal consistency).

Exported here: every public name of the fits (``common``, ``silhouettes``, ``shaded``, ``pose``: what
``course.fit`` exported before the split, so ``from course.inverse import fit_camera`` reads as it did) and the
entry points of the others. Until 2026-11 these were top-level modules (``course.fit``, ``course.losses``,
``course.large_steps``, ``course.carve``, ``course.shape_metrics``, ``course.fit_texture``,
``course.fit_views``); the old names still import, with a warning that names the new place (``course._moved``).
"""
from .pose import CAMERA_METHODS, camera_problem, center_error, fit_camera, rotation_error
from .common import (CameraFit, FitHistory, SilhouetteFit, circle_views, hard_silhouettes, held_out_iou,
                     self_intersections, sphere_views, start_verts)
from .losses import iou, psnr, silhouette_iou_loss, smoothness_loss
from .metrics import chamfer_distance, f_score, normal_consistency, shape_metrics
from .shaded import (GRADIENTS, SKY, ImageFit, ShadedData, coverage_masks, fit_mesh_from_images, held_out_psnr,
                     shaded_data, shaded_face_colors, shaded_images)
from .silhouettes import fit_mesh_from_silhouettes, fit_silhouettes
from .texture import fit_texture_from_images, fit_vertex_colors_from_images
from .views import fit_with_learned_views

__all__ = ["FitHistory", "SilhouetteFit", "CameraFit", "circle_views", "sphere_views", "hard_silhouettes",
           "held_out_iou", "self_intersections", "start_verts", "fit_silhouettes", "fit_mesh_from_silhouettes",
           "SKY", "GRADIENTS", "ImageFit", "ShadedData", "shaded_data", "fit_mesh_from_images", "shaded_images",
           "held_out_psnr", "coverage_masks", "shaded_face_colors", "CAMERA_METHODS", "camera_problem", "fit_camera",
           "rotation_error", "center_error", "iou", "psnr", "silhouette_iou_loss", "smoothness_loss",
           "chamfer_distance", "f_score", "normal_consistency", "shape_metrics", "fit_texture_from_images",
           "fit_vertex_colors_from_images", "fit_with_learned_views"]
