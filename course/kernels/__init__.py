"""Compiled twins of the discrete stages: which face a ray or a pixel sees, as Numba loops (lectures 03 and 07).

The renderer answers two discrete questions over and over: *which triangle does this ray hit first?*
(``BVH.intersect``) and *which triangle is nearest at this pixel?* (the z-buffer of ``rasterize``). The torch
versions answer them for every ray or pixel at once, as chains of vectorised operations over index tensors:
the data-parallel way a GPU wants, and the way lecture 03 and 07 teach. On a CPU each of those operations is
a separate pass over memory, where a renderer written in C keeps one ray or one triangle in registers from
start to finish. The loops here are that C renderer, written in Python and compiled by Numba: each is the
textbook pseudocode (one ray and its stack; one triangle and its rows), and each names the torch function
it must agree with, face id for face id.

* ``traverse.closest_hits``: a stack-based walk of the course's own BVH with the watertight test
  (twin of ``BVH._traverse`` and ``intersect._watertight``).
* ``screen.screen_triangles``: stage 1 of ``rasterize``, face by face: near/far, back faces, orientation,
  on screen or not (twin of ``raster._screen_triangles``; faces crossing the near plane are clipped in torch).
* ``zbuffer.nearest_faces``: scan conversion of every screen triangle with the top-left rule and a float64
  depth test (twin of ``scan._spans`` and ``scan._zbuffer``).
* ``surface.pixel_surface``: the per-pixel barycentrics and depth of ``raster._visible_surface``, where no
  gradient is recorded (with a gradient, the torch code runs, so autograd sees every step).
* ``points.visible_at``: the z-buffer asked at arbitrary points, for the boundary term of visibility
  gradients (twin of ``boundary._visible_at``).
* ``samples.sample_faces``: the sub-pixel sample z-buffer of supersampling (twin of ``scan._sample_zbuffer``).

What is compiled is "which face" (the split nvdiffrast and PyTorch3D make), and, only where no gradient is
recorded, the barycentrics and depth of that face with the torch code's arithmetic. Wherever autograd
records (``raster._records_graph``), the barycentrics, depth and everything after them are the torch code,
so every gradient is unchanged.

**Which path runs.** CPU tensors take the kernels when Numba is installed; CUDA tensors always take the
torch path. ``set_backend("torch")`` (or the environment variable ``COURSE_KERNELS=torch``) forces the torch
path everywhere, and ``using("torch")`` does so inside a ``with`` block, so a lecture can time one against
the other and the tests run both. ``backend()`` says which is in force.

**Compilation.** Each kernel is compiled the first time it runs with a new argument type (1-10 s) and
cached on disk (``cache=True``): next to this file in ``__pycache__``, or, where the package is installed
read-only, in Numba's per-user cache directory (``NUMBA_CACHE_DIR`` overrides both); a second process loads
it in a few hundredths of a second. ``warm_up()`` compiles every kernel in advance (``python -m course
bench`` reports the times).

**Threads.** The ray kernel runs its rays in parallel on ``torch.get_num_threads()`` threads (Numba's
``prange``), so ``torch.set_num_threads(1)`` gives one thread to both. The other kernels are one loop each.
"""
from __future__ import annotations

import contextlib
import os
import threading
import time

__all__ = ["BACKENDS", "available", "backend", "set_backend", "using", "active", "warm_up", "threads", "buffer",
           "scratch"]

BACKENDS = ("numba", "torch")
_backend = os.environ.get("COURSE_KERNELS", "numba").strip().lower() or "numba"
if _backend not in BACKENDS:
    raise ValueError(f"COURSE_KERNELS must be one of {BACKENDS}, got {_backend!r}")

try:                                                                        # a dependency, but guard anyway
    import numba  # noqa: F401
    _AVAILABLE, _WHY = True, ""
except ImportError as err:                                                  # pragma: no cover
    _AVAILABLE, _WHY = False, f"Numba is not installed ({err}); `pip install numba`"


def available() -> bool:
    """True when Numba can be imported (the kernels can run)."""
    return _AVAILABLE


def backend() -> str:
    """The backend in force: "numba" (kernels on CPU tensors, when Numba is available) or "torch"."""
    return _backend


def set_backend(name: str) -> str:
    """Choose "numba" or "torch" for every later call; returns the previous choice."""
    global _backend
    if name not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {name!r}")
    previous, _backend = _backend, name
    return previous


@contextlib.contextmanager
def using(name: str):
    """``with using("torch"): ...`` runs the block on the given backend, then restores the previous one."""
    previous = set_backend(name)
    try:
        yield
    finally:
        set_backend(previous)


def active(*tensors) -> bool:
    """Should a kernel run on these tensors? The "numba" backend, Numba installed, every tensor on the CPU."""
    return _backend == "numba" and _AVAILABLE and all(t.device.type == "cpu" for t in tensors)


def threads() -> int:
    """Threads for the parallel kernels: torch's thread count, at most Numba's pool."""
    import numba
    import torch
    return max(1, min(torch.get_num_threads(), numba.config.NUMBA_NUM_THREADS))


def buffer(shape, dtype, fill=None):
    """A CPU tensor for a kernel's output, allocated by numpy: numpy asks the OS for huge pages on large
    buffers, which makes their first touch about ten times cheaper than a fresh ``torch.empty`` of 8 MB (the
    page faults of a 1024² image's buffers otherwise cost more than the z-buffer itself). fill: a value, or
    None to leave it uninitialised."""
    import numpy as np
    import torch
    array = np.empty(shape, dtype=torch.empty(0, dtype=dtype).numpy().dtype)
    if fill is not None:
        array.fill(fill)
    return torch.from_numpy(array)


_scratch = threading.local()


def scratch(name: str, size: int, dtype):
    """A kernel's working buffer (not an output), kept per thread and reused while it is large enough: the
    z-buffer's keys would otherwise be fresh memory every call, paid for in page faults. Returns a (size,)
    CPU tensor with undefined contents; valid until the next ``scratch(name, ...)`` on this thread."""
    import torch
    held = getattr(_scratch, name, None)
    if held is None or held.numel() < size or held.dtype != dtype:
        with torch.inference_mode(False):                                   # kept for later calls: never an
            held = buffer(max(size, 1), dtype)                              # inference-mode tensor
        setattr(_scratch, name, held)
    return held[:size]


def warm_up(only=None) -> dict:
    """Compile (or load from the cache) every kernel (or those named in ``only``: "screen", "zbuffer", "surface",
    "traverse", "points", "samples") for float32 and float64; returns seconds per kernel."""
    if not _AVAILABLE:
        raise RuntimeError(_WHY)
    from . import points, samples, screen, surface, traverse, zbuffer
    times = {}
    for name, module in (("screen", screen), ("zbuffer", zbuffer), ("surface", surface), ("traverse", traverse),
                         ("points", points), ("samples", samples)):
        if only is not None and name not in only:
            continue
        start = time.perf_counter()
        module.warm_up()
        times[name] = time.perf_counter() - start
    return times
