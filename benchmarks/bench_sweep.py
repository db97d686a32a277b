"""A sweep of 8 small designs on the local Dask cluster against the same 8 one after another in one process.

Both runs go through `labapp.sweep.run_sweep` on the same spec (a 2 x 2 x 2 grid of w_binary, radius and
beta on the pill target, nfc, resolution 80, 300 evaluations; ``--quick``: resolution 24, 40
evaluations), into separate folders, in the same invocation: first in this process (``client=None``,
after a warm-up design that loads the compiled kernels, as a long-lived process would have them), then on
a `LocalCluster` sized by `labapp.cluster` (one single-threaded worker per core here). The cluster's wall
time includes starting it and warming its workers up the same way (imports, compiled kernels); it is
also given without that start-up.

Overhead per task, set against a design's own time (its mean wall time in the serial run): Dask's
round trip (the mean time of `NOOP_TASKS` empty tasks, submitted at once and gathered), and the
workers' idle time (workers x wall on the running cluster less the designs' task seconds, per task:
scheduling, the imbalance at the end). The designs' own slowdown on the cluster (two of them sharing
the cores, caches and memory bus, and any other load) is printed beside them, with the load average.

    python benchmarks/bench_sweep.py [--quick] [--workers N]

Last line: ``sweep_speedup = X``: serial wall / wall on the running, warmed-up cluster (both sides with
their kernels loaded; a cluster serves many sweeps). The figure with the cluster's start-up and warm-up
is printed above it.
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

NOOP_TASKS = 200
"""Empty tasks timed on the cluster: Dask's own cost per task (submit, schedule, run, gather)."""
SPEC = """target = "pill"
space = "nfc"
resolution = {resolution}
max_iter = {max_iter}
[grid]
w_binary = [10, 20]
radius_vox = [2.0, 3.0]
beta = [3.0, 5.0]
"""


def _warm_up(folder: Path) -> None:
    from labapp.sweep import run_sweep
    from labapp.sweepspec import parse_spec

    run_sweep(parse_spec(SPEC.format(resolution=16, max_iter=3).split("[grid]")[0]), folder, contact_sheet=False)


def _warm_up_worker(folder: str) -> None:
    import os

    _warm_up(Path(folder) / str(os.getpid()))


def _noop(i: int) -> int:
    return i


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="resolution 24, 40 evaluations")
    parser.add_argument("--workers", type=int, help="local cluster workers (default: sized to the machine)")
    args = parser.parse_args()

    from labapp.cluster import dask_client, design_memory_gb
    from labapp.sweep import run_sweep
    from labapp.sweepspec import parse_spec

    resolution, max_iter = (24, 40) if args.quick else (80, 300)
    spec = parse_spec(SPEC.format(resolution=resolution, max_iter=max_iter))
    n = len(spec.combinations)
    loads = [os.getloadavg()[0]]
    print(f"{n} designs: pill, nfc, resolution {resolution}, {max_iter} evaluations")
    with tempfile.TemporaryDirectory(prefix="bench_sweep_") as tmp:
        tmp = Path(tmp)
        _warm_up(tmp / "warm")
        t0 = time.perf_counter()
        serial = run_sweep(spec, tmp / "serial", contact_sheet=False)
        serial_s = time.perf_counter() - t0
        loads.append(os.getloadavg()[0])
        own = [float(r["seconds"]) for r in serial.rows]
        t0 = time.perf_counter()
        with dask_client(workers=args.workers, task_memory_gb=design_memory_gb(resolution)) as client:
            workers = len(client.scheduler_info()["workers"])
            client.run(_warm_up_worker, str(tmp / "warm-workers"))  # imports and kernels, as in this process
            t1 = time.perf_counter()
            parallel = run_sweep(spec, tmp / "cluster", client, contact_sheet=False)
            t2 = time.perf_counter()
            task_s = _task_seconds(tmp / "cluster")
            t3 = time.perf_counter()
            client.gather(client.map(_noop, range(NOOP_TASKS)))
            noop_s = (time.perf_counter() - t3) / NOOP_TASKS
        loads.append(os.getloadavg()[0])
        cluster_s, running_s, start_s = t2 - t0, t2 - t1, t1 - t0
    statuses = sorted({r["status"] for r in serial.rows + parallel.rows})
    same = [r["iterations"] for r in serial.rows] == [r["iterations"] for r in parallel.rows]
    idle = (workers * running_s - sum(task_s)) / n
    per_design = serial_s / n
    print(f"statuses {statuses}; same evaluations per design in both runs: {same}")
    print(f"1-min load average: {loads[0]:.2f} before, {loads[1]:.2f} after the serial run, {loads[2]:.2f} after "
          f"the cluster run (2 cores; anything above the run's own 1 or 2 is other work)")
    print(f"serial, one process: {serial_s:.1f} s ({per_design:.2f} s per design; optimisation alone "
          f"{sum(own) / n:.2f} s)")
    print(f"local cluster, {workers} workers: {cluster_s:.1f} s with start-up ({start_s:.1f} s), "
          f"{running_s:.1f} s on the running cluster")
    print(f"per task on the cluster: the design {sum(task_s) / n:.2f} s ({sum(task_s) / n / per_design:.2f} x "
          f"its serial time: two designs share the cores and memory), Dask's round trip {noop_s * 1e3:.1f} ms "
          f"({noop_s / per_design:.3%} of a design), workers idle or waiting {idle:.2f} s per task "
          f"({idle / per_design:.1%})")
    print(f"speedup counting the cluster's start-up and warm-up: {serial_s / cluster_s:.2f}")
    print(f"sweep_speedup = {serial_s / running_s:.2f}")


def _task_seconds(sweep_dir: Path) -> list[float]:
    """Per-task seconds of `run_combination` on the workers, from sweep.log's finish lines."""
    lines = (sweep_dir / "sweep.log").read_text().splitlines()
    return [float(line.rsplit(" in ", 1)[1].split()[0]) for line in lines if " finish " in line]


if __name__ == "__main__":
    main()
