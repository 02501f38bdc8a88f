"""The compiled kernels' cold start: ``python -m course bench kernels``.

A Numba kernel is compiled the first time it runs in a process that finds no cache, and loaded from the cache
in every later process (``course.kernels``). This measures both, each in a fresh Python process with an empty
cache directory of its own (``NUMBA_CACHE_DIR``): the first process compiles every kernel for float32 and
float64 (``kernels.warm_up``), the second loads them. ``cold_start_line`` is the one-line summary the
raster and ray-tracing benchmarks print.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile

__all__ = ["cold_start", "cold_start_line", "add_arguments", "run"]

DESCRIPTION = "compiled kernels: compile time in a first process, load time from the cache in a second"
REPEAT = 1

_CODE = ("import json, sys, time\n"
         "start = time.perf_counter()\n"
         "from course import kernels\n"
         "import numba\n"
         "imported = time.perf_counter() - start\n"
         "times = kernels.warm_up(json.loads(sys.argv[1]))\n"
         "print(json.dumps(dict(import_s=imported, **times)))\n")


def _one_process(env, only=None) -> dict:
    out = subprocess.run([sys.executable, "-c", _CODE, json.dumps(only)], capture_output=True, text=True, env=env,
                         timeout=600)
    if out.returncode != 0:
        raise RuntimeError(f"kernel warm-up failed: {out.stderr.strip()[-500:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def cold_start(only=None) -> dict:
    """{"compile": {kernel: seconds, "import_s": ...}, "load": {...}}: a first process with an empty cache
    compiles, a second one loads (every kernel, or those named in ``only``). Raises RuntimeError when Numba is not
    installed."""
    from .. import kernels
    if not kernels.available():
        raise RuntimeError("Numba is not installed: the kernels do not run here")
    only = None if only is None else list(only)
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        return {"compile": _one_process(env, only), "load": _one_process(env, only)}


def cold_start_line(out=print) -> dict | None:
    """Measure ``cold_start`` and print one line; returns it (None when Numba is missing)."""
    try:
        cs = cold_start()
    except (RuntimeError, OSError, subprocess.SubprocessError) as err:
        out(f"kernels' cold start not measured: {err}")
        return None
    total = lambda d: sum(v for k, v in d.items() if k != "import_s")     # noqa: E731
    out(f"kernels' cold start: compiled in {total(cs['compile']):.1f} s in a first process (import "
        f"{cs['compile']['import_s']:.2f} s), loaded from the cache in {total(cs['load']):.2f} s in a second "
        f"(python -m course bench kernels: per kernel)")
    return cs


def add_arguments(parser) -> None:
    """No options of its own."""


def run(args) -> list[dict]:
    cs = cold_start()
    names = [k for k in cs["compile"] if k != "import_s"]
    print(f"{'kernel':<12}{'compile s':>11}{'load s':>9}")
    print("-" * 32)
    rows = []
    for name in ["import_s"] + names:
        label = "import" if name == "import_s" else name
        print(f"{label:<12}{cs['compile'][name]:>11.2f}{cs['load'][name]:>9.3f}")
        rows.append(dict(kernel=label, compile_s=cs["compile"][name], load_s=cs["load"][name]))
    print("compile: a first process with an empty cache (NUMBA_CACHE_DIR); load: a second process, same cache. "
          "Each kernel for float32 and float64 (course.kernels.warm_up).")
    return rows
