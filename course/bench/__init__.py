"""Benchmarks: run time against error, side by side in one run.

``python -m course bench NAME [options]`` runs one benchmark; each lives in its own module, one per topic:

* ``raster`` (``course.bench.raster``): the rasterizer on the four standard scenes S1-S4, with and without
  back-face culling, optionally side by side with OpenGL.
* ``skips`` (``course.bench.skips``): each pass ``render()`` skips, timed with and without the skip, and the
  largest pixel difference between the two images.

The timing helpers they share (``time_it``, ``time_side_by_side``) live in ``course.bench.timing``. Timings
are for comparing methods side by side on one machine; tests never assert them.
"""
from __future__ import annotations

import argparse
import json

import torch

from .raster import SCENES, bench_raster, scene
from .skips import bench_skips
from .timing import time_it, time_side_by_side

__all__ = ["SCENES", "scene", "time_it", "time_side_by_side", "bench_raster", "bench_skips", "cli"]

BENCHES = {"raster": "rasterizer on the four standard scenes (S1-S4)",
           "skips": "each pass render() skips: time with and without, and the image difference"}


def cli(argv) -> int:
    parser = argparse.ArgumentParser(prog="python -m course bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("which", choices=sorted(BENCHES), help="; ".join(f"{k}: {v}" for k, v in BENCHES.items()))
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    parser.add_argument("--repeat", type=int, default=7, help="timed runs per measurement (median reported)")
    parser.add_argument("--vs", choices=["opengl"], help="also render with OpenGL and report the time ratio")
    parser.add_argument("--no-memory", action="store_true", help="skip the peak-memory measurement")
    parser.add_argument("--json", help="also write the rows to this JSON file")
    args = parser.parse_args(argv)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    if args.which == "skips":
        rows = bench_skips(args.repeat)
    else:
        rows = bench_raster(args.scenes, args.repeat, vs_opengl=args.vs == "opengl", memory=not args.no_memory)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    return 0
