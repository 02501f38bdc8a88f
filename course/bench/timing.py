"""Timing helpers of the benchmarks: median wall times, one function or several side by side.

Timings are for comparing methods side by side on one machine; tests never assert them.
"""
from __future__ import annotations

import statistics
import time

__all__ = ["time_it", "time_side_by_side"]


def time_it(fn, repeat: int, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` in milliseconds."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return 1000 * statistics.median(times)


def time_side_by_side(fns, repeat: int, warmup: int = 1) -> list[float]:
    """Median wall times (ms) of several functions, run in turn inside each repetition, so that a machine
    slowing down or speeding up during the run affects all of them alike."""
    for fn in fns:
        for _ in range(warmup):
            fn()
    times = [[] for _ in fns]
    for _ in range(repeat):
        for fn, ts in zip(fns, times):
            start = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - start)
    return [1000 * statistics.median(ts) for ts in times]
