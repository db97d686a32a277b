"""Design quality of two optimisers on the same problems and evaluation budget (docs/results.md).

For every target (the shipped sample shapes in the nfc and extruded spaces, and a zero-order
curve) this runs `design.optimize.run_design` once per optimiser with the same configuration and
``--max-iter`` evaluations, keeping each run folder under ``--out``, and prints one markdown row:
evaluations used, best J, rel. RMSE of the density's and of the binary solid's release curve (the
fit judged), the binary solid's rate deviation for the zero-order target, and seconds per evaluation.

    python benchmarks/optimizer_quality.py --out runs/quality [--resolution 64] [--max-iter 300]
        [--optimizers LD_LBFGS lbfgs]

"same" means the binary fits differ by at most `SAME_PCT` percentage points. Last line:
``not_worse: <count>/<runs compared>`` (the second optimiser against the first).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from design.errors import DesignError
from design.optimize import run_design
from design.problem import DesignConfig
from design.shapes import SAMPLE_SHAPES

ZERO_ORDER = "zero-order:final=0.3,duration=0.1"
"""The zero-order target of docs/results.md ("Zero-order")."""
SAME_PCT = 0.02
"""Binary fits closer than this many percentage points of rel. RMSE count as the same."""


def run_one(target: str, space: str, optimizer: str, args: argparse.Namespace) -> dict:
    """One design run; its summary's headline numbers."""
    config = DesignConfig(target=target, space=space, resolution=args.resolution, max_iter=args.max_iter,
                          optimizer=optimizer, radius_vox=args.radius_vox, allow_pieces=True)
    folder = args.out / f"{target.split(':')[0]}_{space}_{optimizer}"
    t0 = time.perf_counter()
    result = run_design(config, folder)
    s = json.loads((folder / "summary.json").read_text())
    dev = (s.get("rate_dev_mid80") or {}).get("binary")
    return {"evals": result.iterations, "J": result.best_value, "density": s["rel_rmse_density"],
            "binary": s["rel_rmse_binary"], "rate_dev": dev, "seconds": time.perf_counter() - t0,
            "per_eval": s.get("seconds_per_iteration") or 0.0, "status": result.status}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder for the run folders (must not exist)")
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--max-iter", type=int, default=300)
    parser.add_argument("--radius-vox", type=float, default=4.0, help="smoothing radius, voxels (paper: 4)")
    parser.add_argument("--optimizers", nargs=2, default=["LD_LBFGS", "lbfgs"], metavar=("OLD", "NEW"))
    parser.add_argument("--targets", nargs="*", default=[*SAMPLE_SHAPES, ZERO_ORDER])
    args = parser.parse_args()
    if args.out.exists():
        parser.error(f"{args.out} exists; choose a new folder (runs are never overwritten)")
    args.out.mkdir(parents=True)
    old, new = args.optimizers
    print(f"| target | space | evals {old} / {new} | best J {old} / {new} | rel. RMSE density | "
          f"rel. RMSE binary {old} / {new} | rate dev. binary | s/eval | new vs old |")
    print("|---|---|---|---|---|---|---|---|---|")
    compared = not_worse = 0
    for target in args.targets:
        for space in ("nfc", "extruded"):
            try:
                a, b = (run_one(target, space, o, args) for o in (old, new))
            except DesignError as exc:  # e.g. a target infeasible on a coarse grid
                print(f"| {target.split(':')[0]} | {space} | not run: {str(exc).splitlines()[0]} |||||||", flush=True)
                continue
            diff_pct = 100.0 * (b["binary"] - a["binary"])
            verdict = "better" if diff_pct < -SAME_PCT else "same" if diff_pct <= SAME_PCT else "worse"
            compared += 1
            not_worse += verdict != "worse"
            dev = "-" if a["rate_dev"] is None or target != ZERO_ORDER else f"{a['rate_dev']:.1%} / {b['rate_dev']:.1%}"
            print(f"| {target.split(':')[0]} | {space} | {a['evals']} / {b['evals']} | {a['J']:.5g} / {b['J']:.5g} | "
                  f"{a['density']:.3%} / {b['density']:.3%} | {a['binary']:.3%} / {b['binary']:.3%} | {dev} | "
                  f"{a['per_eval']:.3f} / {b['per_eval']:.3f} | {verdict} |", flush=True)
    print(f"not_worse: {not_worse}/{compared}")


if __name__ == "__main__":
    main()
