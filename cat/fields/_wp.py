"""Warp helpers shared by the field modules (device choice, array conversion)."""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import warp as wp


def get_device(device: str | None = None) -> wp.context.Device:
    """Warp device: the given one, else CUDA when present, else the CPU."""
    wp.init()
    if device is None:
        return wp.get_device("cuda:0") if wp.is_cuda_available() else wp.get_device("cpu")
    return wp.get_device(str(device))


def to_wp(a, dtype, device) -> wp.array:
    """Numpy array → Warp array (C-contiguous copy of the right dtype)."""
    np_dtype = {wp.float32: np.float32, wp.int32: np.int32, wp.uint8: np.uint8}[dtype]
    return wp.array(np.ascontiguousarray(a, dtype=np_dtype), dtype=dtype, device=device)


_POOL: ThreadPoolExecutor | None = None
_IN_POOL = threading.local()


def _in_pool(task: Callable[[], object]) -> object:
    _IN_POOL.active = True
    try:
        return task()
    finally:
        _IN_POOL.active = False


def run_concurrently(*tasks: Callable[[], object]) -> list:
    """Run callables concurrently: the first in the calling thread, the others in a small thread pool.

    Warp CPU launches release the GIL, so two single-core launches use two cores. Exceptions propagate.
    Called from inside a pool task it runs everything inline (no nested waits on the pool)."""
    global _POOL
    if len(tasks) == 1 or getattr(_IN_POOL, "active", False):
        return [t() for t in tasks]
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=max(1, min(4, (os.cpu_count() or 2) - 1)))
    futures = [_POOL.submit(_in_pool, t) for t in tasks[1:]]
    try:
        first = tasks[0]()
    finally:
        rest = [f.result() for f in futures]
    return [first, *rest]
