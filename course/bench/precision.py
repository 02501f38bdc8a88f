"""The precision benchmark: ``python -m course bench precision [--repeat N]``.

float32 against float64 on the scenes where float32 is hard, as run time against error. Each float32 render
is compared with a float64 render of the *same* float32 inputs (vertices and camera upcast exactly), so the
error is the renderer's own rounding, not the inputs'. Errors are taken where both renders see the same face
and away from edges (every float64 barycentric above 1e-3): the relative depth error (median, 99th
percentile, maximum) and the largest barycentric error at the 99th percentile.

=================  ==========================================================================
scene              what makes it hard
=================  ==========================================================================
subpixel           81,920 faces in 64×64 pixels: most triangles cover no pixel centre
subpixel-ortho     the same, orthographic
far                an object of size 1e4, 6e4 from the origin, seen from 1.7e4 away
far-ortho          the same, orthographic
moved-1e5          a unit sphere and its camera, both moved 1.2e5 from the origin
teapot             an ordinary scene: the teapot at 256²
=================  ==========================================================================

The worst pixels lie on faces seen almost edge-on, where the depth at a pixel centre is itself
ill-conditioned (relative error about float32's epsilon over the cosine between the ray and the normal).
"""
from __future__ import annotations

import torch

from ..camera import Camera
from ..mesh import Mesh
from ..models import icosphere, teapot
from ..raster import rasterize
from .timing import time_side_by_side

__all__ = ["SCENES", "scene", "errors", "bench_precision", "add_arguments", "run"]

DESCRIPTION = "float32 against float64 on hard scenes: time and depth / barycentric error"


def _subpixel(orthographic: bool):
    view = dict(ortho_height=2.5) if orthographic else dict(fov_y=40)
    return icosphere(6), Camera.look_at((0.3, 0.5, 3.0), (0, 0, 0), width=64, height=64, **view)


def _far(orthographic: bool):
    centre = torch.tensor([5e4, 2e4, -3e4])
    ball = icosphere(4, radius=5e3)
    eye = (centre + torch.tensor([6e3, 4e3, 1.5e4])).tolist()
    view = dict(ortho_height=1.2e4, near=0.0) if orthographic else dict(fov_y=40, near=10.0)
    return Mesh(ball.verts + centre, ball.faces), Camera.look_at(eye, centre.tolist(), width=128, height=128,
                                                                 far=1e6, **view)


def moved(distance: float):
    """A unit icosphere and a camera 3.3 away from it, both moved by ``distance`` × (1, -0.66, 0.33)."""
    ball = icosphere(4, radius=1.0)
    shift = torch.tensor([1.0, -0.66, 0.33]) * distance
    camera = Camera.look_at((shift + torch.tensor([1.2, 0.8, 3.0])).tolist(), shift.tolist(), fov_y=40,
                            width=96, height=96, far=1e6)
    return Mesh(ball.verts + shift, ball.faces), camera


SCENES = {
    "subpixel": lambda: _subpixel(False),
    "subpixel-ortho": lambda: _subpixel(True),
    "far": lambda: _far(False),
    "far-ortho": lambda: _far(True),
    "moved-1e5": lambda: moved(1e5),
    "teapot": lambda: (teapot(dtype=torch.float32),
                       Camera.look_at((2.5, 2.0, 3.5), (0, 0.3, 0), fov_y=40, width=256, height=256)),
}


def scene(name: str):
    """(mesh, camera) of a precision scene, float32."""
    mesh, camera = SCENES[name]()
    return mesh.to(dtype=torch.float32), camera.to(dtype=torch.float32)


def errors(mesh, camera) -> dict:
    """Errors of a float32 render of (mesh, camera) against float64 on the same float32 inputs.

    Returns ``depth`` (relative, (N,)) and ``bary`` (largest of the three, (N,)) at the N pixels where both
    renders see the same face away from its edges, and ``same``, the fraction of covered pixels (float64)
    where the two renders see the same face.
    """
    mesh32, cam32 = mesh.to(dtype=torch.float32), camera.to(dtype=torch.float32)
    f32 = rasterize(mesh32, cam32)
    f64 = rasterize(mesh32.to(dtype=torch.float64), cam32.to(dtype=torch.float64))
    same = (f32.face_id == f64.face_id) & f64.mask
    inner = same & (f64.bary.min(-1).values > 1e-3)
    return dict(depth=((f32.depth.double() - f64.depth).abs() / f64.depth)[inner],
                bary=(f32.bary.double() - f64.bary).abs().amax(-1)[inner],
                same=float(same.sum()) / max(int(f64.mask.sum()), 1))


def bench_precision(names=tuple(SCENES), repeat: int = 7, out=print) -> list[dict]:
    """float32 and float64 renders timed side by side, and the float32 error, per scene."""
    rows = []
    for name in names:
        mesh, camera = scene(name)
        mesh64, camera64 = mesh.to(dtype=torch.float64), camera.to(dtype=torch.float64)
        ms32, ms64 = time_side_by_side([lambda: rasterize(mesh, camera), lambda: rasterize(mesh64, camera64)],
                                       repeat)
        e = errors(mesh, camera)
        q = torch.quantile(e["depth"], torch.tensor([0.5, 0.99], dtype=torch.float64))
        rows.append(dict(scene=name, faces=mesh.num_faces, ms32=ms32, ms64=ms64, same=e["same"],
                         depth_p50=float(q[0]), depth_p99=float(q[1]), depth_max=float(e["depth"].max()),
                         bary_p99=float(torch.quantile(e["bary"], 0.99))))
    head = (f"{'scene':<16}{'faces':>8}{'f32 ms':>9}{'f64 ms':>9}{'same face':>11}"
            f"{'depth p50':>11}{'p99':>9}{'max':>9}{'bary p99':>10}")
    lines = [head, "-" * len(head)]
    lines += [f"{r['scene']:<16}{r['faces']:>8,}{r['ms32']:>9.1f}{r['ms64']:>9.1f}{100 * r['same']:>10.2f}%"
              f"{r['depth_p50']:>11.1e}{r['depth_p99']:>9.1e}{r['depth_max']:>9.1e}{r['bary_p99']:>10.1e}"
              for r in rows]
    out("relative depth error and barycentric error of float32 against float64 (same inputs)\n"
        + "\n".join(lines))
    return rows


def add_arguments(parser) -> None:
    """The options of ``python -m course bench precision``."""
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))


def run(args) -> list[dict]:
    return bench_precision(args.scenes, args.repeat)
