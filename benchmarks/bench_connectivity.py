"""Seconds per objective evaluation with and without the connectivity penalty J_conn.

nfc zero-order target in a 20 mm cube at resolution 256 (128^3 octant), at r = 4 voxels (distance
grid in blocks of 2) and at the default 1 mm radius (blocks of 6), at a hollow ball (a shell from 4 to 7
mm around the empty centre) with small noise: median of three
`DesignObjective.evaluate` calls each way, and of J_conn alone, with its tail (the default) and without
(``conn_tail=0``).

    python -m benchmarks.bench_connectivity [--resolution 256]

Last line: ``conn_share_default: <extra seconds / seconds without J_conn>``.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from design.fabrication.connectivity import TAIL_SLOPE
from design.inverse.config import DesignConfig
from design.inverse.objective import DesignObjective
from design.inverse.problem import Problem, prepare


def seconds(objective: DesignObjective, x: np.ndarray, repeats: int = 3) -> float:
    """Median wall time of `DesignObjective.evaluate` after one warm-up call, s."""
    objective.evaluate(x)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        objective.evaluate(x)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def make_objective(problem: Problem, radius: float, w_conn: float, conn_tail: float = TAIL_SLOPE) -> DesignObjective:
    """The benchmark's objective at smoothing radius ``radius`` voxels and J_conn weight ``w_conn``."""
    return DesignObjective(problem.space, problem.target.released_mm3, problem.target.total_time_mm,
                           radius_vox=radius, beta=3.0, w_binary=20.0, w_rate=1.0, w_conn=w_conn,
                           conn_tail=conn_tail)


def conn_seconds(objective: DesignObjective, x: np.ndarray, repeats: int = 3) -> float:
    """Median wall time of J_conn alone (value and gradient) at the design x, s."""
    rho = objective.density(x)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        objective.connectivity(rho, 1.0)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=256)
    args = parser.parse_args()
    config = DesignConfig(target="zero-order:final=0.15,duration=0.2", space="nfc", resolution=args.resolution,
                          domain_mm=(20.0, 20.0, 20.0))
    problem = prepare(config)
    centres = np.meshgrid(*[(np.arange(n) + 0.5) * problem.dx_mm for n in problem.space.var_shape], indexing="ij")
    r_mm = np.sqrt(sum(c ** 2 for c in centres))
    shell = np.where((r_mm > 4.0) & (r_mm < 7.0), 0.95, 0.05)
    share = 0.0
    for radius in (4.0, problem.radius_vox):
        x = np.clip(shell + np.random.default_rng(0).uniform(-0.05, 0.05, shell.shape), 0.0, 1.0)
        base = seconds(make_objective(problem, radius, 0.0), x)
        with_conn = make_objective(problem, radius, 20.0)
        conn = seconds(with_conn, x)
        alone = conn_seconds(with_conn, x)
        no_tail = conn_seconds(make_objective(problem, radius, 20.0, conn_tail=0.0), x)
        print(f"r = {radius:.2f} voxels: evaluate {base:.3f} s without J_conn, {conn:.3f} s with; "
              f"J_conn alone {alone:.4f} s ({alone / base:.1%}), without its tail {no_tail:.4f} s")
        share = alone / base
    print(f"conn_share_default: {share:.4f}")


if __name__ == "__main__":
    main()
