"""The skips benchmark: ``python -m course bench skips [--repeat N]``.

It times each pass ``render()`` skips (lighting for an unlit scene, texture lookups for a silhouette, the
autograd graph when nothing requires a gradient, back faces of a closed mesh) against the same render with
the work forced back on, and reports the largest pixel difference (0: the skip is exact).
"""
from __future__ import annotations

from ..camera import Camera
from ..models import icosphere, teapot
from .timing import time_side_by_side

__all__ = ["bench_skips", "add_arguments", "run"]

DESCRIPTION = "each pass render() skips: time with and without, and the image difference"


def _skip_cases():
    """(name, scene, settings, passes forced back on) — one per skip ``render`` makes."""
    from ..render import RenderSettings, Scene, default_lights, frame_camera
    mesh = teapot(resolution=12)
    cam = frame_camera([mesh], width=384, height=384)
    lit, unlit = Scene(mesh, cam, lights=default_lights()), Scene(mesh, cam)
    closed = icosphere(6)
    sphere_cam = Camera.look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov_y=40.0, width=384, height=384)
    return [
        ("unlit: no normals, no lighting", unlit, RenderSettings(shading="unlit"), ("normals", "lighting")),
        ("silhouette: no texture lookups", lit, RenderSettings(shading="silhouette"), ("texture",)),
        ("no grad: no autograd graph", lit, RenderSettings(shading="phong"), ("autograd",)),
        ("closed mesh: back faces culled", Scene(closed, sphere_cam, lights=default_lights()),
         RenderSettings(shading="phong", cull_backfaces=True), None),
    ]


def bench_skips(repeat: int = 5, out=print) -> list[dict]:
    """Each skip of ``render``: time with the skip and with the work forced back on, and the largest pixel
    difference between the two images (0 means the skip is exact)."""
    from dataclasses import replace

    from ..render import render
    rows = []
    for name, sc, settings, forced in _skip_cases():
        if forced is None:                                                  # the skip is a setting
            slow_settings, force = replace(settings, cull_backfaces=False), ()
        else:
            slow_settings, force = settings, forced
        fast = render(sc, settings).image
        slow = render(sc, slow_settings, _force=force).image
        ms_skip, ms_full = time_side_by_side([lambda: render(sc, settings),
                                              lambda: render(sc, slow_settings, _force=force)], repeat)
        rows.append(dict(skip=name, ms_skip=ms_skip, ms_full=ms_full,
                         max_diff=float((fast.detach() - slow.detach()).abs().max())))
    head = f"{'skip':<34}{'with skip ms':>14}{'without ms':>12}{'speed-up':>10}{'max |diff|':>12}"
    lines = [head, "-" * len(head)]
    lines += [f"{r['skip']:<34}{r['ms_skip']:>14.1f}{r['ms_full']:>12.1f}{r['ms_full'] / r['ms_skip']:>9.2f}×"
              f"{r['max_diff']:>12.1e}" for r in rows]
    out("\n".join(lines))
    return rows


def add_arguments(parser) -> None:
    """``python -m course bench skips`` has no options of its own."""


def run(args) -> list[dict]:
    return bench_skips(args.repeat)
