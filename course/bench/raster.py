"""The rasterizer benchmark: ``python -m course bench raster [--scenes S1 ...] [--vs opengl] [--no-memory]``.

It times ``rasterize`` on the four standard scenes (an icosphere of radius 1 seen from distance 3 with a 40°
field of view):

=====  ============  ==========  ========
scene  subdivisions  faces       image
=====  ============  ==========  ========
S1     5             20,480      512²
S2     7             327,680     512²
S3     5             20,480      1024²
S4     3             1,280       256²
=====  ============  ==========  ========

and reports the median time, triangles and pixels per second, with and without back-face culling, and the
peak memory of one render (measured in a fresh process). With the compiled kernels in force (``course.kernels``,
the default on CPU tensors) it times the torch path too, side by side, and prints the kernels' cold start
(compile in a first process, load from the cache in a second). ``--vs opengl`` renders the same scenes with
OpenGL (moderngl on whatever driver EGL finds, Mesa's llvmpipe on a machine without a GPU) in the same run,
reports the time ratio, and checks that the two agree on the visible face of every pixel.
"""
from __future__ import annotations

import subprocess
import sys

import torch

from .. import kernels
from ..camera import Camera
from ..models import icosphere
from ..raster import rasterize
from .kernels import cold_start_line
from .timing import time_it, time_side_by_side

__all__ = ["SCENES", "scene", "bench_raster", "format_table", "add_arguments", "run"]

DESCRIPTION = "rasterizer on the four standard scenes (S1-S4)"

# name: (icosphere subdivisions, image size)
SCENES = {"S1": (5, 512), "S2": (7, 512), "S3": (5, 1024), "S4": (3, 256)}


def scene(name: str, dtype=torch.float32):
    """The mesh and camera of a standard scene."""
    subdivisions, size = SCENES[name]
    mesh = icosphere(subdivisions, radius=1.0, dtype=dtype)
    camera = Camera.look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov_y=40.0, width=size, height=size, dtype=dtype)
    return mesh, camera


def _peak_memory_mb(name: str, cull: bool) -> float:
    """Peak resident memory of one render in a fresh process, above the resident memory just before it (MB):
    the second render of the process, so loading the compiled kernels is not counted.

    Linux only: the peak (VmHWM) is reset through /proc/self/clear_refs before the render.
    """
    code = (
        "import torch; from course.bench.raster import scene; from course.raster import rasterize\n"
        f"m, c = scene({name!r})\n"
        f"rasterize(m, c, cull_backfaces={cull})\n"                        # compiled kernels loaded first
        "kb = lambda key: int(next(l.split()[1] for l in open('/proc/self/status') if l.startswith(key)))\n"
        "open('/proc/self/clear_refs', 'w').write('5'); base = kb('VmRSS:')\n"
        f"rasterize(m, c, cull_backfaces={cull})\n"
        "print((kb('VmHWM:') - base) / 1024)\n")
    try:
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
        return float(out.stdout.strip())
    except (ValueError, OSError, subprocess.SubprocessError):
        return float("nan")


# ------------------------------------------------------------------------------------- OpenGL (optional)

class _OpenGL:
    """The same scene through OpenGL: face id (gl_PrimitiveID) and depth, rendered and read back."""

    VERTEX = """#version 330
    uniform mat4 mvp;
    in vec3 in_pos;
    void main() { gl_Position = mvp * vec4(in_pos, 1.0); }"""
    FRAGMENT = """#version 330
    out int face;
    void main() { face = gl_PrimitiveID; }"""

    def __init__(self):
        import moderngl                                                     # optional dependency
        self.ctx = moderngl.create_standalone_context(backend="egl")
        self.prog = self.ctx.program(vertex_shader=self.VERTEX, fragment_shader=self.FRAGMENT)
        self.renderer = self.ctx.info["GL_RENDERER"]

    def prepare(self, mesh, camera, cull: bool):
        import moderngl
        W, H = camera.width, camera.height
        self.fbo = self.ctx.framebuffer(color_attachments=[self.ctx.renderbuffer((W, H), components=1, dtype="i4")],
                                        depth_attachment=self.ctx.depth_renderbuffer((W, H)))
        tris = mesh.verts[mesh.faces].reshape(-1, 3).float().numpy()       # unindexed: one id per triangle
        self.vao = self.ctx.vertex_array(self.prog, [(self.ctx.buffer(tris.tobytes()), "3f", "in_pos")])
        self.prog["mvp"].write(_gl_matrix(camera).T.contiguous().numpy().tobytes())
        self.ctx.enable(moderngl.DEPTH_TEST)
        if cull:
            self.ctx.enable(moderngl.CULL_FACE)
            self.ctx.front_face = "cw"                                      # y is not flipped: CCW on screen → CW in GL
        else:
            self.ctx.disable(moderngl.CULL_FACE)
        self.shape = (H, W)

    def render(self):
        self.fbo.use()
        self.fbo.clear(red=-1, depth=1.0)                                  # face -1 where nothing is drawn
        self.vao.render()
        face = self.fbo.read(components=1, dtype="i4")
        depth = self.fbo.read(attachment=-1, dtype="f4")
        return face, depth

    def face_ids(self) -> torch.Tensor:
        import numpy as np
        face, _ = self.render()
        ids = np.frombuffer(face, dtype=np.int32).reshape(self.shape).astype(np.int64)
        return torch.from_numpy(np.where(ids < 0, -1, ids))                 # the clear colour arrives as float bits


def _gl_matrix(camera) -> torch.Tensor:
    """Clip-space matrix reproducing the camera: x_ndc = 2 x_pix / W - 1, y_ndc = 2 y_pix / H - 1 (row 0 is
    read back first, so no flip), z_ndc in [-1, 1] between near and far."""
    K, n, f = camera.K.double(), camera.near, camera.far
    W, H = camera.width, camera.height
    P = torch.zeros(4, 4, dtype=torch.float64)
    P[0, 0], P[0, 2] = 2 * K[0, 0] / W, 2 * K[0, 2] / W - 1
    P[1, 1], P[1, 2] = 2 * K[1, 1] / H, 2 * K[1, 2] / H - 1
    P[2, 2], P[2, 3] = (f + n) / (f - n), -2 * f * n / (f - n)
    P[3, 2] = 1
    Rt = torch.eye(4, dtype=torch.float64)
    Rt[:3, :3], Rt[:3, 3] = camera.R.double(), camera.t.double()
    return (P @ Rt).float()


# -------------------------------------------------------------------------------------------- raster

def bench_raster(names=("S1", "S2", "S3", "S4"), repeat: int = 7, vs_opengl: bool = False,
                 memory: bool = True, out=print) -> list[dict]:
    """Time ``rasterize`` on the standard scenes; returns one row (dict) per scene and culling setting."""
    gl = None
    if vs_opengl:
        try:
            gl = _OpenGL()
            out(f"OpenGL renderer: {gl.renderer}")
        except Exception as err:                                            # no moderngl, no EGL driver
            out(f"--vs opengl skipped: OpenGL is not available here ({type(err).__name__}: {err}).\n"
                "  Install it with `pip install moderngl` and Mesa's EGL driver (Debian: libegl1 libegl-mesa0 "
                "libgl1-mesa-dri).")
    rows = []
    twin = kernels.backend() == "numba" and kernels.available()             # also time the torch path

    def on_torch(fn):
        def run():
            with kernels.using("torch"):
                return fn()
        return run

    for name in names:
        mesh, camera = scene(name)
        pixels = camera.width * camera.height
        fns = [lambda: rasterize(mesh, camera), lambda: rasterize(mesh, camera, cull_backfaces=True)]
        times = time_side_by_side(fns + ([on_torch(f) for f in fns] if twin else []), repeat)
        for k, cull in enumerate((False, True)):
            ms = times[k]
            row = dict(scene=name, faces=mesh.num_faces, size=camera.width, cull=cull, ms=ms,
                       mtri_s=mesh.num_faces / ms / 1e3, mpix_s=pixels / ms / 1e3)
            if twin:
                row["torch_ms"] = times[2 + k]
            if memory:
                row["peak_mb"] = _peak_memory_mb(name, cull)
            if gl is not None:
                gl.prepare(mesh, camera, cull)
                row["gl_ms"] = time_it(gl.render, repeat)
                ours = rasterize(mesh, camera, cull_backfaces=cull).face_id
                row["agree"] = float((gl.face_ids() == ours).double().mean())
            rows.append(row)
    out(format_table(rows))
    if twin:
        out("median ms: rasterize with the compiled kernels (course.kernels); torch ms: the torch path "
            "(COURSE_KERNELS=torch), side by side in the same run.")
        cold_start_line(out)
    return rows


def format_table(rows) -> str:
    gl = any("gl_ms" in r for r in rows)
    twin = any("torch_ms" in r for r in rows)
    head = f"{'scene':<6}{'faces':>9}{'image':>7}{'cull':>6}{'median ms':>11}{'Mtri/s':>9}{'Mpix/s':>9}"
    head += f"{'torch ms':>10}" if twin else ""
    head += f"{'peak MB':>9}" if any("peak_mb" in r for r in rows) else ""
    head += f"{'OpenGL ms':>11}{'ratio':>7}{'same face':>11}" if gl else ""
    lines = [head, "-" * len(head)]
    for r in rows:
        line = (f"{r['scene']:<6}{r['faces']:>9,}{str(r['size']) + '²':>7}{'yes' if r['cull'] else 'no':>6}"
                f"{r['ms']:>11.1f}{r['mtri_s']:>9.2f}{r['mpix_s']:>9.1f}")
        line += f"{r['torch_ms']:>10.1f}" if "torch_ms" in r else (" " * 10 if twin else "")
        line += f"{r['peak_mb']:>9.0f}" if "peak_mb" in r else ""
        if "gl_ms" in r:
            line += f"{r['gl_ms']:>11.2f}{r['ms'] / r['gl_ms']:>7.1f}{100 * r['agree']:>10.2f}%"
        lines.append(line)
    return "\n".join(lines)


# ---------------------------------------------------------------------------------- the command's options

def add_arguments(parser) -> None:
    """The options of ``python -m course bench raster``."""
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    parser.add_argument("--vs", choices=["opengl"], help="also render with OpenGL and report the time ratio")
    parser.add_argument("--no-memory", action="store_true", help="skip the peak-memory measurement")


def run(args) -> list[dict]:
    return bench_raster(args.scenes, args.repeat, vs_opengl=args.vs == "opengl", memory=not args.no_memory)
