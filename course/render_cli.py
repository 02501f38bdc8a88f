"""``python -m course render [MESH] --out FILE.png [options]``: the bundled default scene, or any mesh trimesh
reads, rendered to a PNG with the course's renderer."""
from __future__ import annotations

import argparse
import sys

import torch

from course.framing import default_lights, frame_camera
from course.render import (ANTIALIAS_MODES, SHADING_MODES, SHADOW_MODES, TEXTURE_FILTERS, RenderSettings, Scene,
                           render)

__all__ = ["cli"]


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m course render",
                                description="Render a mesh (default: the bundled textured teapot) to a PNG.")
    p.add_argument("mesh", nargs="?", help="mesh file (any format trimesh reads); omit for the default scene")
    p.add_argument("--out", required=True, help="output PNG path (8-bit, sRGB-encoded from the linear render)")
    p.add_argument("--size", nargs=2, type=int, metavar=("W", "H"), help="image size in pixels")
    p.add_argument("--width", type=int, help="image width in pixels (default 512)")
    p.add_argument("--height", type=int, help="image height in pixels (default: the width)")
    p.add_argument("--eye", nargs=3, type=float, metavar=("X", "Y", "Z"), help="camera position (world)")
    p.add_argument("--fov", type=float, default=40.0, help="vertical field of view in degrees (default 40)")
    p.add_argument("--shading", default="phong", choices=SHADING_MODES, help="shading mode (default phong)")
    p.add_argument("--wireframe", action="store_true", help="draw the visible edges on top")
    p.add_argument("--antialias", default="none", choices=ANTIALIAS_MODES,
                   help="none (one sample per pixel, the default), supersample (k x k samples in every pixel) or "
                        "adaptive (k x k only where an edge crosses the pixel)")
    p.add_argument("--samples", type=int, default=4, metavar="K", help="samples per axis when antialiasing (4)")
    p.add_argument("--shadows", default="none", choices=SHADOW_MODES,
                   help="none (default), map (shadow maps) or rays (shadow rays through a BVH) for the key light")
    p.add_argument("--texture-filter", default="bilinear", choices=TEXTURE_FILTERS,
                   help="texture lookup: nearest, bilinear (default) or trilinear (mipmaps)")
    p.add_argument("--background", nargs=3, type=float, default=(1.0, 1.0, 1.0), metavar=("R", "G", "B"),
                   help="background colour, linear RGB in [0, 1] (default white)")
    return p


def _image_size(args) -> tuple[int, int]:
    if args.size and (args.width or args.height):
        raise ValueError("give either --size W H or --width/--height, not both")
    width, height = args.size or (args.width or args.height or 512, args.height or args.width or 512)
    if width < 1 or height < 1:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    return width, height


def _save_png(image: torch.Tensor, path: str, srgb: bool = True) -> None:
    """Write a linear RGB image (H, W, 3) as an 8-bit PNG: clamped to [0, 1], sRGB-encoded (IEC 61966-2-1,
    what PNG viewers assume) unless ``srgb=False``, then rounded to 0..255."""
    from PIL import Image
    from course.shading import linear_to_srgb
    image = image.detach().clamp(0, 1)
    if srgb:
        image = linear_to_srgb(image)
    pixels = (image.cpu().numpy() * 255 + 0.5).astype("uint8")
    Image.fromarray(pixels, mode="RGB").save(path, format="PNG")


def cli(argv: list[str]) -> int:
    """``python -m course render [MESH] --out FILE.png [options]``; returns the exit code."""
    try:
        args = _parser().parse_args(argv)
    except SystemExit as exit_:                                              # --help or a usage error
        return int(exit_.code or 0)
    from course import mesh as mesh_module
    from course import models
    try:
        width, height = _image_size(args)
        if args.mesh is None:
            mesh = models.default_scene_mesh()
        else:
            try:
                mesh = mesh_module.load_mesh(args.mesh)
            except Exception as err:                                         # any failure of a user's file
                message = str(err) if args.mesh in str(err) else f"cannot read mesh {args.mesh!r}: {err}"
                raise ValueError(message) from err
        mesh = mesh.to(dtype=torch.float32)
        camera = frame_camera(mesh, width=width, height=height, fov_y=args.fov, eye=args.eye)
        scene = Scene(mesh, camera, lights=default_lights(), background=args.background)
        result = render(scene, RenderSettings(shading=args.shading, wireframe=args.wireframe,
                                              antialias=args.antialias, samples=args.samples,
                                              texture_filter=args.texture_filter, shadows=args.shadows))
        _save_png(result.image, args.out)
    except (ValueError, TypeError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    print(f"wrote {args.out} ({width}x{height})")
    return 0
