"""A sweep of 8 small designs on the local Dask cluster against the same 8 one after another in one process.

Both go through `labapp.scaleout.sweep.run_sweep` on the same spec (a 2 x 2 x 2 grid of w_binary, radius and
beta on the pill target, nfc, resolution 48, 300 evaluations; ``--quick``: resolution 24, 40 evaluations,
one round), into fresh folders. A `LocalCluster` sized by `labapp.scaleout.cluster` (one single-threaded worker
per core here) is started and warmed up (imports, compiled kernels), as this process is by a warm-up
design. Then ``--rounds`` rounds (default 3) each run the sweep serially (``client=None``) and then on
the running cluster, so that a change in the machine's load shows in one round, not in one side.

Resolution 48 keeps a design's working set (a few MB) in a core's caches: at larger resolutions
designs side by side contend for the memory bus, as two plain processes do, which caps any
scheduler's speed-up below the number of cores; ``--resolution 80`` shows it.

Overhead per task, set against a design's own time: Dask's round trip (the mean time of `NOOP_TASKS`
empty tasks, submitted at once and gathered), and the workers' idle time (workers x wall on the
cluster less the designs' task seconds, per task: scheduling, the imbalance at the end). The designs'
own slowdown on the cluster (task seconds on the cluster over the same in the serial run) and the
load average before each round are printed beside them.

    python -m benchmarks.bench_sweep [--quick] [--workers N] [--resolution R] [--rounds K]

Last line: ``sweep_speedup = X``, the median over rounds of serial wall / wall on the running,
warmed-up cluster (both sides with their kernels loaded; a cluster serves many sweeps). The first
round's figure with the cluster's start-up and warm-up is printed above it.
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from labapp.scaleout.sweep import run_sweep
from labapp.scaleout.sweepspec import parse_spec

RESOLUTION, MAX_ITER, ROUNDS = 48, 300, 3
"""The benchmark's designs (small: their working set stays in cache) and its serial/cluster rounds."""

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
    run_sweep(parse_spec(SPEC.format(resolution=16, max_iter=3).split("[grid]")[0]), folder, contact_sheet=False)


def _warm_up_worker(folder: str) -> None:
    import os

    _warm_up(Path(folder) / str(os.getpid()))


def _noop(i: int) -> int:
    return i


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="resolution 24, 40 evaluations, one round")
    parser.add_argument("--workers", type=int, help="local cluster workers (default: sized to the machine)")
    parser.add_argument("--resolution", type=int, help=f"design resolution (default {RESOLUTION})")
    parser.add_argument("--rounds", type=int, default=ROUNDS, help=f"serial/cluster rounds (default {ROUNDS})")
    args = parser.parse_args()

    from labapp.scaleout.cluster import dask_client, design_memory_gb

    resolution, max_iter, rounds = (24, 40, 1) if args.quick else (RESOLUTION, MAX_ITER, args.rounds)
    resolution = args.resolution or resolution
    spec = parse_spec(SPEC.format(resolution=resolution, max_iter=max_iter))
    n = len(spec.combinations)
    print(f"{n} designs: pill, nfc, resolution {resolution}, {max_iter} evaluations; {rounds} rounds")
    with tempfile.TemporaryDirectory(prefix="bench_sweep_") as tmp:
        tmp = Path(tmp)
        _warm_up(tmp / "warm")
        t0 = time.perf_counter()
        with dask_client(workers=args.workers, task_memory_gb=design_memory_gb(resolution)) as client:
            workers = len(client.scheduler_info()["workers"])
            client.run(_warm_up_worker, str(tmp / "warm-workers"))  # imports and kernels, as in this process
            start_s = time.perf_counter() - t0
            results = [_round(spec, tmp / f"round{k}", client) for k in range(rounds)]
            t3 = time.perf_counter()
            client.gather(client.map(_noop, range(NOOP_TASKS)))
            noop_s = (time.perf_counter() - t3) / NOOP_TASKS
    print(f"local cluster of {workers} workers started and warmed up in {start_s:.1f} s")
    print("round | load before | serial s (per design) | cluster s | design on cluster / serial | idle per task "
          "| speedup")
    for k, r in enumerate(results):
        idle = (workers * r.cluster_s - sum(r.task_s)) / n
        print(f"{k + 1} | {r.load:.2f} | {r.serial_s:.1f} ({r.serial_s / n:.2f}) | {r.cluster_s:.1f} | "
              f"{sum(r.task_s) / sum(r.serial_task_s):.2f} | {idle:.2f} s ({idle * n / r.serial_s:.1%}) | "
              f"{r.serial_s / r.cluster_s:.2f}")
    statuses = sorted({s for r in results for s in r.statuses})
    print(f"statuses {statuses}; same evaluations per design in every run: {all(r.same for r in results)}")
    print(f"Dask's round trip {noop_s * 1e3:.1f} ms ({noop_s * n / results[0].serial_s:.3%} of a design)")
    speedups = sorted(r.serial_s / r.cluster_s for r in results)
    median = speedups[len(speedups) // 2]
    first = results[0]
    print(f"speedup of the first round counting the cluster's start-up and warm-up: "
          f"{first.serial_s / (first.cluster_s + start_s):.2f}")
    print(f"speedups {', '.join(f'{x:.2f}' for x in speedups)} (spread {speedups[-1] - speedups[0]:.2f})")
    print(f"sweep_speedup = {median:.2f}")


@dataclass
class _Round:
    """One serial sweep and the same sweep on the cluster, s."""

    serial_s: float
    cluster_s: float
    serial_task_s: list
    task_s: list
    statuses: set
    same: bool
    load: float


def _round(spec, folder: Path, client) -> _Round:
    """The sweep one after another in this process, then on the running cluster, into fresh folders."""
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    serial = run_sweep(spec, folder / "serial", contact_sheet=False)
    t1 = time.perf_counter()
    parallel = run_sweep(spec, folder / "cluster", client, contact_sheet=False)
    t2 = time.perf_counter()
    failed = [r for r in serial.rows + parallel.rows if r["status"] == "failed"]
    if failed:
        raise SystemExit(f"bench_sweep: {len(failed)} designs failed; the first: {failed[0]['error']}")
    return _Round(t1 - t0, t2 - t1, _task_seconds(folder / "serial"), _task_seconds(folder / "cluster"),
                  {r["status"] for r in serial.rows + parallel.rows},
                  [r["iterations"] for r in serial.rows] == [r["iterations"] for r in parallel.rows], load)


def _task_seconds(sweep_dir: Path) -> list[float]:
    """Per-task seconds of `run_combination` on the workers, from sweep.log's finish lines."""
    lines = (sweep_dir / "sweep.log").read_text().splitlines()
    return [float(line.rsplit(" in ", 1)[1].split()[0]) for line in lines if " finish " in line]


if __name__ == "__main__":
    main()
