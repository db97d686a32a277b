"""Seconds per L-BFGS iteration of inverse design vs one scikit-fmm forward solve on the same grid.

For each reduced grid N^3 (nfc, octant symmetry: the full design is (2N)^3) this runs `sfr design`'s
engine (`design.optimize.run_design`) on a zero-order target for a fixed number of evaluations and
reads seconds per evaluation from its history (optimisation with its default checkpoints; setup and
output writing excluded),
over the steady state only: the evaluations after nlopt's L-BFGS memory has filled (its step costs
grow with the number of stored pairs, up to `lbfgs_memory`). The split between our objective and
gradient and nlopt's own work is timed around `DesignObjective.evaluate`. The baseline is
`skfmm.travel_time` (first order) on the same N^3 grid with the same slowness as the uniform start,
timed in the same process. Peak memory is the process's maximum resident set size.

    python benchmarks/bench_design.py [--quick]

Last line: ``iter_over_skfmm_128: <ratio>`` (``iter_over_skfmm_64`` with --quick).
"""
from __future__ import annotations

import argparse
import json
import resource
import tempfile
import time
from pathlib import Path

import numpy as np
import skfmm

from design.objective import DesignObjective
from design.optimize import run_design
from design.problem import DesignConfig, prepare


def skfmm_seconds(rho: np.ndarray, dx_mm: float, repeats: int) -> float:
    """Best-of-``repeats`` wall time of a first-order scikit-fmm travel-time solve, s."""
    phi = np.pad(np.ones(rho.shape), 1, constant_values=-1.0)  # front on the padding layer
    speed = np.pad(1.0 / (rho + (1.0 - rho) * 1e-6), 1, constant_values=1.0)
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        skfmm.travel_time(phi, speed, dx=dx_mm, order=1)
        best = min(best, time.perf_counter() - t0)
    return best


class _EvaluationTimer:
    """Wraps `DesignObjective.evaluate` to record the wall time of every call, s."""

    def __init__(self) -> None:
        self.seconds: list[float] = []
        self._evaluate = DesignObjective.evaluate

    def __enter__(self) -> "_EvaluationTimer":
        timer, evaluate = self, self._evaluate

        def timed(objective, x):
            t0 = time.perf_counter()
            result = evaluate(objective, x)
            timer.seconds.append(time.perf_counter() - t0)
            return result

        DesignObjective.evaluate = timed
        return self

    def __exit__(self, *exc) -> None:
        DesignObjective.evaluate = self._evaluate


def bench(n_reduced: int, evaluations: int, steady_from: int) -> dict:
    """One grid size: seconds per evaluation from evaluation `steady_from` on, skfmm seconds, their ratio."""
    config = DesignConfig(target="zero-order:final=0.15,duration=0.2", space="nfc", resolution=2 * n_reduced,
                          domain_mm=(20.0, 20.0, 20.0), max_iter=evaluations)  # default checkpoints included
    problem = prepare(config)
    objective = DesignObjective(problem.space, problem.target.released_mm3, problem.target.total_time_mm,
                                radius_vox=config.radius_vox, beta=config.beta, w_binary=config.w_binary)
    rho0 = objective.density(objective.uniform_start())
    base = skfmm_seconds(rho0, problem.dx_mm, repeats=3)
    with tempfile.TemporaryDirectory() as tmp, _EvaluationTimer() as timer:
        run_design(config, Path(tmp) / "run")
        history = np.loadtxt(Path(tmp) / "run" / "history.csv", delimiter=",", skiprows=1, ndmin=2)
    # history row k holds the elapsed time at the end of evaluation k + 1
    window = history[steady_from - 1:, -1]
    per_eval = float((window[-1] - window[0]) / (len(window) - 1))
    objective_s = float(np.mean(timer.seconds[steady_from:len(history)]))
    return {"n_reduced": n_reduced, "full": 2 * n_reduced, "evaluations": len(history),
            "steady_from": steady_from, "seconds_per_iteration": per_eval, "objective_seconds": objective_s,
            "optimizer_seconds": per_eval - objective_s, "skfmm_seconds": base, "ratio": per_eval / base,
            "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 ** 2}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="64^3 only, few evaluations")
    args = parser.parse_args()
    # L-BFGS keeps lbfgs_memory = 10 pairs, full after ~11 evaluations; --quick stops before that
    sizes = [(64, 8, 2)] if args.quick else [(64, 30, 13), (128, 26, 13)]
    results = [bench(n, evals, steady) for n, evals, steady in sizes]
    for r in results:
        print(json.dumps(r))
    for r in results:
        print(f"{r['n_reduced']}^3 reduced ({r['full']}^3 full), evaluations {r['steady_from']}-{r['evaluations']}: "
              f"{r['seconds_per_iteration']:.3f} s/iteration (objective + gradient {r['objective_seconds']:.3f} s, "
              f"nlopt {r['optimizer_seconds']:.3f} s), skfmm {r['skfmm_seconds']:.3f} s, ratio {r['ratio']:.2f}, "
              f"peak RSS {r['peak_rss_gb']:.2f} GB")
    last = results[-1]
    print(f"iter_over_skfmm_{last['n_reduced']}: {last['ratio']:.3f}")


if __name__ == "__main__":
    main()
