"""A sweep of 8 small designs on the local Dask cluster against the same 8 one after another in one process.

Both runs go through `labapp.sweep.run_sweep` on the same spec (a 2 x 2 x 2 grid of w_binary, radius and
beta on the pill target, nfc, resolution 64, 150 evaluations; ``--quick``: resolution 24, 40
evaluations), into separate folders, in the same invocation: first in this process (``client=None``,
after a warm-up design that loads the compiled kernels, as a long-lived process would have them), then on
a `LocalCluster` sized by `labapp.cluster` (one single-threaded worker per core here). The cluster's wall
time includes starting it and its workers' first kernel loads; it is also given without the start-up.

Overhead per task: the cluster's worker-seconds (workers x wall, start-up excluded) less the designs'
own time (the sum of `run_combination`'s per-task seconds on the workers), per task: scheduling, data
movement, imbalance at the end and idle workers. It is set against the design's own time (mean per task
in the serial run).

    python benchmarks/bench_sweep.py [--quick] [--workers N]

Last line: ``sweep_speedup = X`` (serial wall / cluster wall, start-up included).
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="resolution 24, 40 evaluations")
    parser.add_argument("--workers", type=int, help="local cluster workers (default: sized to the machine)")
    args = parser.parse_args()

    from labapp.cluster import dask_client, design_memory_gb
    from labapp.sweep import run_sweep
    from labapp.sweepspec import parse_spec

    resolution, max_iter = (24, 40) if args.quick else (64, 150)
    spec = parse_spec(SPEC.format(resolution=resolution, max_iter=max_iter))
    n = len(spec.combinations)
    print(f"load average at start: {os.getloadavg()}")
    print(f"{n} designs: pill, nfc, resolution {resolution}, {max_iter} evaluations")
    with tempfile.TemporaryDirectory(prefix="bench_sweep_") as tmp:
        tmp = Path(tmp)
        _warm_up(tmp / "warm")
        t0 = time.perf_counter()
        serial = run_sweep(spec, tmp / "serial", contact_sheet=False)
        serial_s = time.perf_counter() - t0
        own = [float(r["seconds"]) for r in serial.rows]
        t0 = time.perf_counter()
        with dask_client(workers=args.workers, task_memory_gb=design_memory_gb(resolution)) as client:
            workers = len(client.scheduler_info()["workers"])
            t1 = time.perf_counter()
            parallel = run_sweep(spec, tmp / "cluster", client, contact_sheet=False)
            t2 = time.perf_counter()
            task_s = _task_seconds(tmp / "cluster")
        cluster_s, running_s, start_s = t2 - t0, t2 - t1, t1 - t0
    statuses = sorted({r["status"] for r in serial.rows + parallel.rows})
    same = [r["iterations"] for r in serial.rows] == [r["iterations"] for r in parallel.rows]
    overhead = (workers * running_s - sum(task_s)) / n
    print(f"statuses {statuses}; same evaluations per design in both runs: {same}")
    print(f"serial, one process: {serial_s:.1f} s ({serial_s / n:.2f} s per design; optimisation alone "
          f"{sum(own) / n:.2f} s)")
    print(f"local cluster, {workers} workers: {cluster_s:.1f} s with start-up ({start_s:.1f} s), "
          f"{running_s:.1f} s on the running cluster")
    print(f"per task on the cluster: design {sum(task_s) / n:.2f} s, overhead {overhead:.3f} s "
          f"({overhead / (serial_s / n):.1%} of a design's serial time)")
    print(f"speedup on the running cluster: {serial_s / running_s:.2f}")
    print(f"load average at end: {os.getloadavg()}")
    print(f"sweep_speedup = {serial_s / cluster_s:.2f}")


def _task_seconds(sweep_dir: Path) -> list[float]:
    """Per-task seconds of `run_combination` on the workers, from sweep.log's finish lines."""
    lines = (sweep_dir / "sweep.log").read_text().splitlines()
    return [float(line.rsplit(" in ", 1)[1].split()[0]) for line in lines if " finish " in line]


if __name__ == "__main__":
    main()
