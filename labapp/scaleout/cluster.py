"""Where sweeps and batch analyses run: a Dask `LocalCluster` sized to this machine, or an existing
scheduler (`dask scheduler` / `dask worker`, SLURM through dask-jobqueue; see docs/scale.md).

The workers write run folders themselves, so with a remote scheduler they must see the output folder
at the same path as this process (a shared filesystem, as on any cluster).
"""
from __future__ import annotations

import contextlib
import logging
import math
import signal
import threading
import warnings
from typing import Iterator

import psutil

from design.threads import cores as design_cores
from labapp.errors import LabError
from labapp.jobs.meshunits import BASE_MEMORY_BYTES, design_memory_bytes

log = logging.getLogger(__name__)

CONNECT_TIMEOUT_S = 20.0
WORKER_ENVIRON = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
"""Environment of local workers: one BLAS/OpenMP thread each, as Dask's default, but without its
``MALLOC_TRIM_THRESHOLD_``: setting that fixes glibc's mmap threshold, so every large array a design
allocates becomes a fresh mapping with its page faults (one design took 15.3 s instead of 8.6 s)."""


class ClusterError(LabError):
    """The scheduler cannot be reached or the local cluster cannot start."""


def design_memory_gb(resolution: int, space: str = "nfc") -> float:
    """Peak memory of one design of `resolution` voxels along its longest side, GB (cubic domain bound)."""
    return design_memory_bytes(resolution, space) / 1e9


def local_worker_count(task_memory_gb: float, *, cores: int | None = None, memory_gb: float | None = None) -> int:
    """Single-threaded workers this machine can run side by side: one per core, as many as the
    available memory holds at `task_memory_gb` each (at least one)."""
    cores = cores or design_cores()
    if memory_gb is None:
        memory_gb = psutil.virtual_memory().available / 1e9
    return max(1, min(cores, math.floor(0.9 * memory_gb / task_memory_gb)))


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, *, workers: int | None = None,
                task_memory_gb: float = BASE_MEMORY_BYTES / 1e9) -> Iterator["distributed.Client"]:  # noqa: F821
    """A `distributed.Client` on `scheduler`, or on a new `LocalCluster` closed on exit.

    Parameters
    ----------
    scheduler : str or None
        ``tcp://HOST:PORT`` of a running scheduler; None starts a local cluster.
    workers : int or None
        Local cluster: the number of single-threaded worker processes (default `local_worker_count`).
        Remote scheduler: wait until this many workers have joined.
    task_memory_gb : float
        Peak memory of one task, GB; sizes the default local cluster.

    Raises
    ------
    ClusterError
        The scheduler does not answer within `CONNECT_TIMEOUT_S`, or `workers` < 1.
    """
    import dask
    from distributed import Client, LocalCluster

    logging.getLogger("distributed").setLevel(max(logging.WARNING, logging.getLogger().level))
    if workers is not None and workers < 1:
        raise ClusterError(f"--workers must be >= 1, got {workers}")
    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ClusterError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from exc
        try:
            if workers:
                log.info("waiting for %d workers at %s", workers, scheduler)
                client.wait_for_workers(workers)
            yield client
        finally:
            client.close()
        return
    n = workers or local_worker_count(task_memory_gb)
    # workers ignore SIGINT (the disposition is inherited): Ctrl-C in a terminal reaches the whole
    # process group, and only this process should decide how running tasks stop
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if _main_thread() else None
    try:
        # another cluster's dashboard on 8787 moves this one to a free port, which `dashboard_link` reports
        with dask.config.set({"distributed.nanny.pre-spawn-environ": WORKER_ENVIRON}), warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Port 8787 is already in use", category=UserWarning)
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, memory_limit="auto",
                                   dashboard_address=":8787", silence_logs=logging.ERROR)
    except Exception as exc:  # noqa: BLE001 -- any start-up failure is reported the same way
        raise ClusterError(f"cannot start a local Dask cluster of {n} workers: {exc}") from exc
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
    try:
        with Client(cluster) as client:
            yield client
    finally:
        cluster.close()


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def dashboard_link(client) -> str | None:
    """The Dask dashboard's address, or None when the scheduler serves none."""
    try:
        info = client.scheduler_info()
    except Exception:  # noqa: BLE001 -- a closing client has no dashboard to show
        return None
    if "dashboard" not in info.get("services", {}):
        return None
    return client.dashboard_link
