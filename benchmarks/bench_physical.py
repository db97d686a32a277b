"""Design time with the physical correction against the named baseline without it, same resolution and evaluations.

For each source (benchmarks/untuned_shapes.py) and design space this runs the optimisation of `sfr design`
(`design.inverse.defect.optimise_physical`, the function `design.files.rundir.run_design` calls) twice with
`DesignConfig`'s defaults: ``physical_correction="none"`` (the baseline: ``max_iter`` evaluations on the design
grid) and the default ``"defect"`` (the first optimisation, then the correction rounds within the same
``max_iter`` evaluations, each round's print extracted and released by the reference evaluator). The outputs,
which are the same for both, are not timed. The kernels are compiled by a warm-up first. Each pair runs back to
back, so a slow period of the machine (other jobs) slows both.

    python benchmarks/bench_physical.py [--resolution 64] [--shapes a,b] [--spaces nfc,extruded] [--quick]

``--quick``: resolution 32 and one shape. Last line: ``defect_over_none_<resolution>: <median ratio>``.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import physical_study  # noqa: E402
import untuned_shapes  # noqa: E402


def seconds(name: str, space: str, resolution: int, correction: str) -> tuple[float, int]:
    """Wall time of one design's optimisation (with its correction rounds), s, and its evaluations."""
    from design.inverse.defect import optimise_physical
    from design.inverse.optimize import build_objective
    from design.inverse.problem import DesignConfig

    config = DesignConfig(target=f"{name}.stl", space=space, resolution=resolution, physical_correction=correction)
    problem = physical_study._problem(name, untuned_shapes.source(name), config)
    t0 = time.perf_counter()
    objective = build_objective(problem, config)
    outcome, _ = optimise_physical(objective, problem, config, physical_study._NoStore(),
                                   physical_study._Rounds())
    return time.perf_counter() - t0, len(outcome.history)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--shapes", default="rock,star_prism")
    parser.add_argument("--spaces", default="nfc,extruded")
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    resolution = 32 if args.quick else args.resolution
    shapes = args.shapes.split(",")[:1] if args.quick else args.shapes.split(",")
    physical_study._warm_up()
    ratios = []
    print(f"{'shape':<20} {'space':<9} {'none s':>8} {'defect s':>9} {'evals':>11} {'ratio':>6}")
    for name in shapes:
        for space in args.spaces.split(","):
            base, n_base = seconds(name, space, resolution, "none")
            corrected, n_corrected = seconds(name, space, resolution, "defect")
            ratios.append(corrected / base)
            print(f"{name:<20} {space:<9} {base:8.1f} {corrected:9.1f} {n_base:5d}/{n_corrected:<5d} "
                  f"{ratios[-1]:6.2f}", flush=True)
    print(f"spread: {min(ratios):.2f}-{max(ratios):.2f} over {len(ratios)} designs")
    print(f"defect_over_none_{resolution}: {float(np.median(ratios)):.2f}")


if __name__ == "__main__":
    main()
