"""Learning through the renderer: shape families, their rendered data, a network trained through soft
rasterization, and learned views (lecture 13).

* ``shapes``: the procedural shape families (seven; one held out), each a closed mesh from a few parameters.
* ``data``: their rendered views, splits and voxel grids (``voxelize``, ``voxel_iou``), the cameras' convention.
* ``reconstruction``: single-image reconstruction: an encoder deforming a sphere, trained on the silhouette IoU
  over views through soft rasterization, judged by voxel IoU and Chamfer against retrieval and the sphere; the
  shipped network (``load_pretrained_reconstructor``).
* ``mvtn``: MVTN's learned views (Hamdi et al. 2021) against a fixed circle.

Exported here: the entry points; the rest from their modules. Until 2026-11 these were the top-level modules
``course.shapes``, ``course.shape_data``, ``course.learn`` and ``course.mvtn``; the old names still import, with
a warning that names the new place (``course._moved``).
"""
from .data import make_dataset, voxel_iou, voxelize
from .mvtn import MultiViewClassifier
from .reconstruction import MeshReconstructor, load_pretrained_reconstructor, train_reconstructor
from .shapes import make_shape

__all__ = ["make_shape", "make_dataset", "voxelize", "voxel_iou", "MeshReconstructor", "train_reconstructor",
           "load_pretrained_reconstructor", "MultiViewClassifier"]
