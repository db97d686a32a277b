"""Design quality of two optimisers on the same problems and evaluation budget (docs/benchmarks.md#tools-for-design-experiments).

For every target (the shipped sample shapes in the nfc and extruded spaces, and a zero-order
curve) this runs `design.files.rundir.run_design` once per optimiser and start with the same
configuration and ``--max-iter`` evaluations, keeping each run folder under ``--out``, and prints
one markdown row: evaluations used, best J, rel. RMSE of the density's and of the binary solid's
release curve (the fit judged), the binary solid's final release against the target's (its mass
error, which sets most of the binary fit's differences), the binary solid's rate deviation for the
zero-order target, seconds per evaluation, and the first evaluation at which the two optimisers'
J histories differ ("none": identical through the shorter history).

    python -m studies.optimizer_quality --out runs/quality [--resolution 64] [--max-iter 300]
        [--optimizers LD_LBFGS lbfgs] [--seeds 0] [--targets ...] [--spaces nfc extruded]
        [--product-defaults]

Starts: the uniform start of section 5.2, and with ``--seeds K`` also K starts perturbed by
multiplicative noise of `PERTURBATION` (seeds 1..K). Both optimisers are local and the objective
is piecewise smooth and non-convex, so one start decides little: a perturbation of the start by a
few per cent can move the binary fit of one optimiser by several percentage points. With seeds, a row
gives the median over the starts and the range, and the verdict compares medians.

"same" means the binary fits differ by at most `SAME_PCT` percentage points. Last line:
``not_worse: <count>/<designs compared>`` (the second optimiser against the first).
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from design.errors import DesignError
from design.files.records import load_summary
from design.files.rundir import run_design
from design.geometry.shapes import SAMPLE_SHAPES
from design.inverse.config import DesignConfig

ZERO_ORDER = "zero-order:final=0.3,duration=0.1"
"""A zero-order target: 30% of the domain volume released at a constant rate, ending at a tenth of T."""
SAME_PCT = 0.02
"""Binary fits closer than this many percentage points of rel. RMSE count as the same."""
PERTURBATION = 0.02
"""Relative standard deviation of the noise on a perturbed start's variables."""


def perturbed_start(seed: int):
    """A `run_design` start: the uniform start times ``1 + PERTURBATION N(0, 1)``, within (0, 1)."""
    def start(objective, problem) -> np.ndarray:
        x0 = objective.uniform_start(problem.start_region)
        noise = np.random.default_rng(seed).standard_normal(x0.shape)
        return np.clip(x0 * (1.0 + PERTURBATION * noise), 1e-3, 1.0 - 1e-3)
    return start


def run_one(target: str, space: str, optimizer: str, seed: int, args: argparse.Namespace) -> dict:
    """One design run (seed 0: the uniform start); its summary's headline numbers."""
    paper = {} if args.product_defaults else {"radius_vox": args.radius_vox, "allow_pieces": True}
    config = DesignConfig(target=target, space=space, resolution=args.resolution, max_iter=args.max_iter,
                          optimizer=optimizer, starts=1, robust_eta=0.0,  # one design per run
                          **paper)  # one run per optimiser and seed
    folder = args.out / f"{target.split(':')[0]}_{space}_{optimizer}" / f"seed{seed}"
    result = run_design(config, folder, start=perturbed_start(seed) if seed else None)
    s = load_summary(folder)
    dev = (s.get("rate_dev_mid80") or {}).get("binary")
    curves = np.loadtxt(folder / "curves.csv", delimiter=",", skiprows=1)
    target_mm3, binary_mm3 = curves[-1, 1], curves[-1, 3]
    history = np.loadtxt(folder / "history.csv", delimiter=",", skiprows=1, ndmin=2)[:, 1]
    return {"evals": result.iterations, "J": result.best_value, "J_history": history, "density": s["rel_rmse_density"],
            "binary": s["rel_rmse_design_grid_binary"], "mass": binary_mm3 / target_mm3 - 1.0,
            "rate_dev": dev if dev is not None else float("nan"), "per_eval": s.get("seconds_per_iteration") or 0.0}


def first_difference(a: np.ndarray, b: np.ndarray) -> int | None:
    """1-based evaluation at which two J histories first differ; None if equal through the shorter."""
    n = min(a.size, b.size)
    differ = np.flatnonzero(a[:n] != b[:n])
    return int(differ[0]) + 1 if differ.size else None


def _cell(runs: list[dict], key: str, fmt: str) -> str:
    """The value of one run, or the median over starts with the range."""
    values = [r[key] for r in runs]
    if len(values) == 1:
        return format(values[0], fmt)
    return f"{format(statistics.median(values), fmt)} ({format(min(values), fmt)} to {format(max(values), fmt)})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder for the run folders (must not exist)")
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--max-iter", type=int, default=300)
    parser.add_argument("--radius-vox", type=float, default=4.0, help="smoothing radius, voxels (paper: 4)")
    parser.add_argument("--product-defaults", action="store_true",
                        help="`sfr design`'s defaults (radius in mm, connectivity term) instead of the paper's "
                             "r = 4 voxels with pieces allowed")
    parser.add_argument("--optimizers", nargs=2, default=["LD_LBFGS", "lbfgs"], metavar=("OLD", "NEW"))
    parser.add_argument("--seeds", type=int, default=0, help="perturbed starts besides the uniform one")
    parser.add_argument("--targets", nargs="*", default=[*SAMPLE_SHAPES, ZERO_ORDER])
    parser.add_argument("--spaces", nargs="*", default=["nfc", "extruded"])
    args = parser.parse_args()
    if args.seeds < 0:
        parser.error(f"--seeds must be >= 0, got {args.seeds}")
    if args.out.exists():
        parser.error(f"{args.out} exists; choose a new folder (runs are never overwritten)")
    args.out.mkdir(parents=True)
    old, new = args.optimizers
    if args.seeds:
        print(f"median (range) over {args.seeds + 1} starts\n")
    print(f"| target | space | evals {old} / {new} | best J {old} / {new} | rel. RMSE density | "
          f"rel. RMSE binary {old} / {new} | binary solid's final mass error | rate dev. binary | s/eval | "
          f"first differing evaluation | new vs old |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    compared = not_worse = 0
    t0 = time.perf_counter()
    for target in args.targets:
        name = target.split(':')[0]
        for space in args.spaces:
            try:
                a, b = ([run_one(target, space, o, seed, args) for seed in range(args.seeds + 1)] for o in (old, new))
            except DesignError as exc:  # e.g. a target infeasible on a coarse grid
                print(f"| {name} | {space} | not run: {str(exc).splitlines()[0]} ||||||||", flush=True)
                continue
            median_a, median_b = (statistics.median(r["binary"] for r in runs) for runs in (a, b))
            diff_pct = 100.0 * (median_b - median_a)
            verdict = "better" if diff_pct < -SAME_PCT else "same" if diff_pct <= SAME_PCT else "worse"
            compared += 1
            not_worse += verdict != "worse"
            dev = f"{_cell(a, 'rate_dev', '.1%')} / {_cell(b, 'rate_dev', '.1%')}" if target == ZERO_ORDER else "-"
            firsts = [first_difference(ra["J_history"], rb["J_history"]) for ra, rb in zip(a, b)]
            first = ", ".join("none" if f is None else str(f) for f in firsts)
            print(f"| {name} | {space} | {_cell(a, 'evals', '.0f')} / {_cell(b, 'evals', '.0f')} | "
                  f"{_cell(a, 'J', '.5g')} / {_cell(b, 'J', '.5g')} | "
                  f"{_cell(a, 'density', '.3%')} / {_cell(b, 'density', '.3%')} | "
                  f"{_cell(a, 'binary', '.3%')} / {_cell(b, 'binary', '.3%')} | "
                  f"{_cell(a, 'mass', '+.2%')} / {_cell(b, 'mass', '+.2%')} | {dev} | "
                  f"{_cell(a, 'per_eval', '.3f')} / {_cell(b, 'per_eval', '.3f')} | {first} | {verdict} |", flush=True)
    print(f"wall time {time.perf_counter() - t0:.0f} s")
    print(f"not_worse: {not_worse}/{compared}")


if __name__ == "__main__":
    main()
