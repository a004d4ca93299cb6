"""Warp helpers shared by the field modules (quiet start-up, device choice, array conversion)."""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import warp as wp

VERBOSE_ENV = "CAT_WARP_VERBOSE"
"""Set to 1 to see Warp's start-up banner, kernel-load lines and its native CUDA-driver warning."""


def warp_verbose() -> bool:
    return os.environ.get(VERBOSE_ENV, "0").strip().lower() not in ("", "0", "false", "no")


# Warp prints its banner and one line per kernel-module load at INFO level: keep them off users' terminals
# unless asked for (set before any module loads, i.e. when the first field module is imported).
if not warp_verbose():
    wp.config.log_level = wp.LOG_WARNING


@contextlib.contextmanager
def _native_stderr_silenced() -> Iterator[None]:
    """Send file descriptor 2 to /dev/null: Warp's native library prints its missing-CUDA-driver warning
    there directly (C ``stderr``), past Python's logging and past any replacement of ``sys.stderr``."""
    fd = 2
    with contextlib.suppress(AttributeError, OSError, ValueError):
        sys.stderr.flush()
    try:
        saved = os.dup(fd)
    except OSError:  # no descriptor 2 at all
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), fd)
        yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)


_INIT_LOCK = threading.Lock()
_INITIALISED = False


def init_warp(verbose: bool | None = None) -> None:
    """``wp.init()``, quiet unless ``verbose`` (default: the ``CAT_WARP_VERBOSE`` environment variable).

    Quiet means: no start-up banner, no kernel-load lines, no native "CUDA driver not found" warning.
    Warnings and errors about kernels still show."""
    global _INITIALISED
    verbose = warp_verbose() if verbose is None else verbose
    with _INIT_LOCK:
        if _INITIALISED:
            return
        if verbose:
            wp.config.log_level = wp.LOG_INFO
            wp.init()
        else:
            wp.config.log_level = wp.LOG_WARNING
            with _native_stderr_silenced():
                wp.init()
        _INITIALISED = True


def get_device(device: str | None = None) -> wp.context.Device:
    """Warp device: the given one, else CUDA when present, else the CPU."""
    init_warp()
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
