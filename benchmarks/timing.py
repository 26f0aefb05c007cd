"""Timing helper shared by the benchmark scripts (run them as ``python benchmarks/NAME.py``)."""

from __future__ import annotations

import time


def best_of(fn, repeat: int = 3, *, warmup: bool = False):
    """``(seconds, result)``: the fastest of ``repeat`` calls of ``fn`` (after one
    untimed call with ``warmup``: lazy imports, allocators, CUDA kernels)."""
    out = fn() if warmup else None
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out
