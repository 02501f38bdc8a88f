"""Setting up a scene quickly: a camera that frames the meshes, and a default pair of lights (lectures 04-06,
``python -m course render``). ``course.render`` re-exports both."""
from __future__ import annotations

import math

import torch

from course.camera import Camera
from course.mesh import Mesh
from course.shading import AmbientLight, DirectionalLight, normalize
from course.tensors import _check_count, _check_real, _check_shape, as_tensor

__all__ = ["frame_camera", "default_lights"]


def frame_camera(meshes, *, width: int, height: int, fov_y: float = 40.0, eye=None,
                 direction=(0.6, 0.45, 1.0), margin: float = 1.05) -> Camera:
    """A perspective camera that sees the whole bounding sphere of ``meshes`` (one Mesh or a sequence).

    The camera looks at the sphere's centre from ``eye`` if given (world space), else from ``direction``
    (from the centre toward the camera) at the distance where the sphere, grown by ``margin``, just fits
    the narrower field of view. near/far hug the sphere.
    """
    if not isinstance(meshes, (Mesh, list, tuple)):
        raise TypeError(f"meshes must be a Mesh or a sequence of Mesh, got {type(meshes).__name__}")
    meshes = (meshes,) if isinstance(meshes, Mesh) else tuple(meshes)
    if not meshes or not all(isinstance(m, Mesh) for m in meshes):
        raise TypeError("meshes must be a Mesh or a non-empty sequence of Mesh")
    width, height = _check_count(width, "width"), _check_count(height, "height")
    fov_y = _check_real(fov_y, "fov_y", low=0, high=180, low_open=True, high_open=True)
    margin = _check_real(margin, "margin", low=0, low_open=True)
    verts = torch.cat([m.verts.detach() for m in meshes])                    # (V, 3) world
    center = (verts.min(0).values + verts.max(0).values) / 2
    radius = float((verts - center).norm(dim=-1).max().clamp_min(1e-6)) * margin
    half = math.atan(math.tan(math.radians(fov_y) / 2) * min(1.0, width / height))   # narrower half-angle
    if eye is None:
        direction = as_tensor(direction, dtype=verts.dtype, device=verts.device, name="direction")
        _check_shape(direction, (3,), "direction")
        if float(direction.norm()) == 0:
            raise ValueError("direction must be a non-zero vector (from the scene's centre toward the camera)")
        toward_eye = normalize(direction)
        eye = center + toward_eye * (radius / math.sin(half))
    eye = as_tensor(eye, dtype=verts.dtype, device=verts.device, name="eye")
    _check_shape(eye, (3,), "eye")
    dist = float((eye - center).norm())
    if dist == 0:
        raise ValueError("eye must not be the centre of the meshes' bounding box: the camera would look nowhere")
    up = (0.0, 1.0, 0.0) if float(normalize(eye - center)[1].abs()) < 0.99 else (0.0, 0.0, -1.0)
    return Camera.look_at(eye, center, up, fov_y=fov_y, width=width, height=height,
                          near=max(dist - 1.5 * radius, 1e-3 * dist), far=dist + 1.5 * radius)


def default_lights() -> tuple:
    """A soft ambient fill and a key light from the upper left, in front (travelling down-right-back)."""
    return (AmbientLight(intensity=0.25), DirectionalLight(direction=(0.5, -0.7, -0.6), intensity=0.9))
