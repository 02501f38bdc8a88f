"""The splatting benchmark: ``python -m course bench splats [--counts N ...] [--sizes S ...]``.

``course.splats.render_gaussians`` (float64, the course's torch rasterizer of Gaussians) against the Gaussian
count and the image size: images per second forward, and forward + backward (the gradient of a weighted sum of
the image with respect to every parameter), beside the mesh rasterizer (``course.raster.rasterize`` plus flat
shading, its forward pass) drawing the teapot from the same camera at the same size. The Gaussians: N random
ones in the unit ball, standard deviations 0.01-0.04 (a few pixels at 128², as a fitted scene's), opacities
0.3-0.95, seeded. Times are medians of ``--repeat`` runs on this machine; use ``--threads 1`` for steady ones.

``--device cuda`` (where a CUDA device is): the Gaussians and the camera on that device, timed with the device
synchronised after each run, and each image's largest difference from the CPU's (``cpu_diff``: the same image
on both is the claim, to float64 rounding). The mesh column stays the CPU rasterizer's.
"""
from __future__ import annotations

import torch

from ..camera import Camera
from ..models import teapot
from ..raster import rasterize
from ..splats import render_gaussians
from .timing import time_side_by_side

__all__ = ["random_gaussians", "measure", "bench_splats", "add_arguments", "run"]

REPEAT = 3
DESCRIPTION = "Gaussian splatting: images per second against Gaussian count and image size, beside the mesh rasterizer"
COUNTS = (1000, 4000, 16000)
SIZES = (64, 128, 256)


def random_gaussians(n: int, seed: int = 0, dtype=torch.float64):
    """N Gaussians in the unit ball (module docstring): (means, scales, rotations, opacities, colors)."""
    g = torch.Generator().manual_seed(seed)
    direction = torch.randn(n, 3, generator=g, dtype=dtype)
    radius = torch.rand(n, 1, generator=g, dtype=dtype) ** (1 / 3)
    means = direction / direction.norm(dim=1, keepdim=True) * radius
    scales = 0.01 + 0.03 * torch.rand(n, 3, generator=g, dtype=dtype)
    q = torch.randn(n, 4, generator=g, dtype=dtype)
    rotations = q / q.norm(dim=1, keepdim=True)
    opacities = 0.3 + 0.65 * torch.rand(n, generator=g, dtype=dtype)
    colors = torch.rand(n, 3, generator=g, dtype=dtype)
    return means, scales, rotations, opacities, colors


def measure(counts=COUNTS, sizes=SIZES, repeat: int = REPEAT, device: str = "cpu"):
    """Rows: size, count, forward ms, forward + backward ms, mesh ms (the teapot, same camera and size), and
    with a device other than the CPU the largest |difference| of its image from the CPU's (``cpu_diff``)."""
    device = torch.device(device)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError("--device cuda: torch sees no CUDA device here")
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    rows = []
    mesh = teapot(8, dtype=torch.float64)
    for size in sizes:
        camera = Camera.look_at((0.0, 0.6, 3.2), (0.0, 0.0, 0.0), fov_y=40.0, width=size, height=size,
                                dtype=torch.float64)
        on = camera.to(device=device)
        weights = torch.rand(size, size, 3, generator=torch.Generator().manual_seed(1),
                             dtype=torch.float64).to(device)

        def mesh_image():
            return rasterize(mesh, camera).face_id
        for n in counts:
            cpu_scene = random_gaussians(n)
            scene = [v.to(device) for v in cpu_scene]

            def forward():
                with torch.no_grad():
                    image = render_gaussians(*scene, on)
                sync()
                return image

            def backward():
                leaves = [v.clone().requires_grad_() for v in scene]
                (render_gaussians(*leaves, on) * weights).sum().backward()
                sync()
            f, b, m = time_side_by_side([forward, backward, mesh_image], repeat)
            row = dict(size=size, count=n, device=str(device), forward_ms=f, backward_ms=b, mesh_ms=m,
                       faces=int(mesh.faces.shape[0]))
            if device.type != "cpu":
                with torch.no_grad():
                    row["cpu_diff"] = float((forward().cpu() - render_gaussians(*cpu_scene, camera)).abs().max())
            rows.append(row)
    return rows


def bench_splats(counts=COUNTS, sizes=SIZES, repeat=REPEAT, device="cpu"):
    rows = measure(counts, sizes, repeat, device)
    print(f"render_gaussians, float64, on {rows[0]['device']}; the teapot rasterized (CPU) from the same camera "
          "beside it")
    print(f"{'size':>5} {'gaussians':>10} {'forward ms':>11} {'img/s':>7} {'fwd+bwd ms':>11} {'mesh ms':>8} "
          f"{'mesh img/s':>10}")
    for r in rows:
        print(f"{r['size']:>5} {r['count']:>10} {r['forward_ms']:>11.1f} {1000 / r['forward_ms']:>7.1f} "
              f"{r['backward_ms']:>11.1f} {r['mesh_ms']:>8.2f} {1000 / r['mesh_ms']:>10.1f}"
              + (f"   |image - CPU's| {r['cpu_diff']:.1e}" if "cpu_diff" in r else ""))
    print(f"(the teapot: {rows[0]['faces']} faces)")
    return rows


def add_arguments(parser) -> None:
    parser.add_argument("--counts", nargs="+", type=int, default=list(COUNTS), help="Gaussian counts")
    parser.add_argument("--sizes", nargs="+", type=int, default=list(SIZES), help="image sizes (pixels a side)")
    parser.add_argument("--device", default="cpu", help="where the Gaussians are drawn: cpu (default) or cuda")


def run(args) -> list[dict]:
    return bench_splats(args.counts, args.sizes, args.repeat, args.device)
