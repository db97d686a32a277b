"""Array work split over the cores: each thread computes its own contiguous part, so the values are those of
one pass (no sum changes its order), in a fraction of the wall time.

numpy's ufuncs and the ``nogil`` numba kernels release the GIL, so the parts run side by side.
"""
from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

MIN_PART = 1 << 17
"""The fewest elements a thread gets, 2^17 (1 MB of doubles): below it starting a thread costs more than it saves."""

_pools: dict[int, ThreadPoolExecutor] = {}
if hasattr(os, "register_at_fork"):  # a forked child has none of its parent's threads: it starts its own pools
    os.register_at_fork(after_in_child=_pools.clear)


def cores() -> int:
    """The cores this process may use (its CPU affinity where the system tells it)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def thread_count() -> int:
    """Threads for a process's array work: ``OMP_NUM_THREADS`` when the process is granted a count (a Dask worker's
    nanny sets it to 1, so that side-by-side designs do not oversubscribe the cores), else `cores`."""
    try:
        return max(1, int(os.environ["OMP_NUM_THREADS"]))
    except (KeyError, ValueError):
        return cores()


def in_parts(work: Callable[[int, int], object], size: int) -> None:
    """Call ``work(start, stop)`` on contiguous ranges that cover ``[0, size)``, one per thread, and wait for all.

    ``work`` must write only its own range of its outputs. Fewer threads than `thread_count` where a part would
    hold fewer than `MIN_PART` elements; one call in this thread for small arrays.
    """
    parts = max(1, min(thread_count(), size // MIN_PART))
    if parts == 1:
        work(0, size)
        return
    bounds = [size * k // parts for k in range(parts + 1)]
    pool = _pools.get(parts)
    if pool is None:
        pool = _pools[parts] = ThreadPoolExecutor(parts - 1, thread_name_prefix="sfr-parts")
    futures = [pool.submit(work, a, b) for a, b in zip(bounds[:-2], bounds[1:-1])]
    work(bounds[-2], bounds[-1])  # the last part in this thread
    for future in futures:
        future.result()
