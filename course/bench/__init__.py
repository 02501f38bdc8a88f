"""Benchmarks: run time against error, side by side in one run.

``python -m course bench NAME [options]`` runs one benchmark; each lives in its own module, one per topic:

* ``raster`` (``course.bench.raster``): the rasterizer on the four standard scenes S1-S4, with and without
  back-face culling, optionally side by side with OpenGL.
* ``skips`` (``course.bench.skips``): each pass ``render()`` skips, timed with and without the skip, and the
  largest pixel difference between the two images.
* ``precision`` (``course.bench.precision``): float32 against float64 on scenes where float32 is hard (sub-pixel
  triangles, far from the origin): time, and depth and barycentric error.
* ``aa`` (``course.bench.aa``): antialiasing — one sample, supersampling (regular, jittered), adaptive
  supersampling and exact coverage: time against RMSE to the exact image, a table and a Pareto plot.
* ``raytrace`` (``course.bench.raytrace``): BVH build, primary / shadow / incoherent rays per second, the
  speed-up over brute force, optionally side by side with Embree.
* ``shadows`` (``course.bench.shadows``): shadow maps (resolution, PCF) and area-light shadow maps against
  ray-traced shadows: time against error, a table and a Pareto plot.
* ``soft`` (``course.bench.soft``): the hard rasterizer, NMR's approximate gradient and soft rasterization
  (σ, γ, threshold) on S4: forward and forward+backward time, image error to the exact box-filtered image.
* ``gradients`` (``course.bench.gradients``): visibility gradients (finite differences, edge sampling,
  Reynolds, reparameterization, soft, NMR; optionally Mitsuba's projective sampling) against the exact
  gradient: time against error, a table and a Pareto plot.
* ``fit`` (``course.bench.fit``): lecture 10's fits (mesh, images, camera, texture, views) and camera batches:
  steps, time, final metric.
* ``style`` (``course.bench.style``): lecture 11's style transfer (soft, texture only, hard) and DeepDream at
  full size: time, style loss on held-out views, how far the outline moved.
* ``kernels`` (``course.bench.kernels``): the compiled kernels' cold start, compile and cache-load times.
* ``shadow-gradients`` (``course.bench.shadow_gradients``): the gradient of a shadowed image (exact, finite
  differences, Reynolds, edge sampling) against differentiable variance shadow maps: time against error, a
  table and a Pareto plot.
* ``shadow-art`` (``course.bench.shadow_art``): an occluder fitted to a target shadow (a star, a T, an L) with
  the exact, Reynolds and variance-shadow-map gradients: time, start and final shadow IoU.
* ``penumbra`` (``course.bench.penumbra``): the gradient of an area light's penumbra w.r.t. the occluders (exact,
  shadow rays, edge sampling, finite differences, variance shadow maps averaged over the light): bias, spread
  and time of each estimator against the exact one.
* ``splats`` (``course.bench.splats``): Gaussian splatting's images per second against the Gaussian count and
  the image size, forward and backward, beside the mesh rasterizer on the same views.
* ``representations`` (``course.bench.representations``): the teapot fitted by Gaussians, a density grid and
  the mesh: held-out PSNR, time, and where each fit's error lies (outline, the gap under the lid, shading,
  floaters, see-through).
* ``explorers`` (``course.bench.explorers``): every lecture explorer's redraw time as its controls move.
* ``learn`` (``course.bench.learn``): single-image reconstruction trained through the soft rasterizer, against
  retrieval and a sphere (voxel IoU and Chamfer per family), and MVTN's learned views against fixed ones.
* ``lectures`` (``course.bench.lectures``): each lecture's Run All in a fresh kernel, its seconds and its three
  slowest cells, against a budget of 60 s a lecture.
* ``grading`` (``course.bench.grading``): one Gradescope submission graded end to end (``run_autograder`` on a
  lecture's solution), the notebook's code as this user or, as root, as a user of its own.

A benchmark module holds its ``DESCRIPTION``, ``add_arguments(parser)`` (its own options), ``run(args)`` and
optionally ``REPEAT`` (its default number of timed runs, 7 otherwise),
and one line in ``BENCHES`` below makes it a sub-command; ``--repeat`` and ``--json`` are common to all.

The timing helpers they share (``time_it``, ``time_side_by_side``) live in ``course.bench.timing``. Timings
are for comparing methods side by side on one machine; tests never assert them.
"""
from __future__ import annotations

import argparse
import json
import os

import torch

from . import (aa, explorers, fit, gradients, grading, kernels, learn, lectures, precision, raster, raytrace,
               penumbra, representations, shadow_art, shadow_gradients, shadows, skips, soft, splats, style)
from .raster import SCENES, bench_raster, scene
from .skips import bench_skips
from .timing import time_it, time_side_by_side

__all__ = ["SCENES", "scene", "time_it", "time_side_by_side", "bench_raster", "bench_skips", "cli"]

# name -> module with DESCRIPTION, add_arguments(parser) and run(args) -> rows; a new benchmark adds one line
BENCHES = {"raster": raster, "skips": skips, "precision": precision, "aa": aa,
           "raytrace": raytrace, "shadows": shadows, "soft": soft, "gradients": gradients, "fit": fit,
           "kernels": kernels, "style": style, "shadow-gradients": shadow_gradients, "shadow-art": shadow_art,
           "penumbra": penumbra, "splats": splats, "representations": representations,
           "explorers": explorers, "learn": learn, "grading": grading, "lectures": lectures}


def cli(argv) -> int:
    parser = argparse.ArgumentParser(prog="python -m course bench", description=__doc__.split("\n\n")[0])
    which = parser.add_subparsers(dest="which", required=True, metavar="BENCH")
    for name, module in BENCHES.items():
        sub = which.add_parser(name, help=module.DESCRIPTION, description=module.DESCRIPTION)
        repeat = getattr(module, "REPEAT", 7)                                # slow benchmarks time fewer runs
        sub.add_argument("--repeat", type=int, default=repeat,
                         help=f"timed runs per measurement (median reported; default {repeat})")
        sub.add_argument("--json", help="also write the rows to this JSON file")
        sub.add_argument("--threads", type=int, help="threads for torch, the compiled kernels and OpenGL's "
                                                     "llvmpipe (default: their own choice); 1 gives steadier "
                                                     "timings on a machine shared with other jobs")
        module.add_arguments(sub)
    args = parser.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)                                 # the kernels follow torch's count
        os.environ["LP_NUM_THREADS"] = str(args.threads)                    # Mesa's llvmpipe, read at context creation
    from .. import kernels as compiled
    path = ("compiled kernels (Numba) on CPU tensors" if compiled.backend() == "numba" and compiled.available()
            else "the torch path (COURSE_KERNELS=torch)" if compiled.available() else "the torch path (no Numba)")
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads; discrete stages: {path}")
    rows = BENCHES[args.which].run(args)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    return 0
