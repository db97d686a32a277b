"""Design time with the physical correction against the named baseline without it, same resolution and evaluations.

For each source (`benchmarks.untuned_shapes`) and design space this runs the optimisation of `sfr design`
(`design.inverse.defect.optimise_physical`, the function `design.files.rundir.run_design` calls) twice with
`DesignConfig`'s defaults: ``physical_correction="none"`` (the baseline: ``max_iter`` evaluations on the design
grid) and the default ``"defect"`` (the first optimisation, then the correction rounds within the same
``max_iter`` evaluations, each round's print extracted and released by the reference evaluator). The outputs,
which are the same for both, are not timed. The kernels are compiled by a warm-up first. Each pair runs back to
back. Each is timed by the wall clock and by the process's CPU time (every thread's, `time.process_time`): on a
machine that other jobs share, the wall time of one run depends on what else runs, its CPU time much less. Where
the baseline ends early (stalled) and the corrected run makes more evaluations, the ratio that compares the same
evaluations is the one per evaluation.

    python -m benchmarks.bench_physical [--resolution 64] [--shapes a,b] [--spaces nfc,extruded] [--quick]
        [--reference-per-voxel CELLS]

``--quick``: resolution 32 and one shape. ``--reference-per-voxel``: the rounds' lattice cells per design voxel in
every space timed, instead of `design.inverse.defect.REFERENCE_PER_VOXEL`. Last line:
``defect_over_none_<resolution>: <median ratio>``, the ratio of CPU time per evaluation.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks import untuned_shapes
from benchmarks.designs import MemoryRounds, NoStore, source_problem, warm_up


def seconds(name: str, space: str, resolution: int, correction: str) -> tuple[float, float, int]:
    """Wall time and CPU time of one design's optimisation (with its correction rounds), s, and its evaluations."""
    from design.inverse.config import DesignConfig
    from design.inverse.defect import optimise_physical
    from design.inverse.optimize import build_objective

    config = DesignConfig(target=f"{name}.stl", space=space, resolution=resolution, physical_correction=correction)
    problem = source_problem(name, untuned_shapes.source(name), config)
    t0, c0 = time.perf_counter(), time.process_time()
    objective = build_objective(problem, config)
    outcome, _ = optimise_physical(objective, problem, config, NoStore(),
                                   MemoryRounds())
    return time.perf_counter() - t0, time.process_time() - c0, len(outcome.history)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--shapes", default="rock,star_prism")
    parser.add_argument("--spaces", default="nfc,extruded")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--reference-per-voxel", type=float, metavar="CELLS")
    args = parser.parse_args()
    if args.reference_per_voxel is not None:
        from design.inverse import defect

        for space in args.spaces.split(","):
            defect.REFERENCE_PER_VOXEL[space] = args.reference_per_voxel
    resolution = 32 if args.quick else args.resolution
    shapes = args.shapes.split(",")[:1] if args.quick else args.shapes.split(",")
    warm_up()
    ratios = []
    print(f"{'shape':<20} {'space':<9} {'wall s, none/defect':>20} {'cpu s, none/defect':>19} {'evals':>11} "
          f"{'wall':>5} {'cpu':>5} {'cpu/eval':>8}")
    for name in shapes:
        for space in args.spaces.split(","):
            wall, cpu, n_base = seconds(name, space, resolution, "none")
            wall_c, cpu_c, n_corrected = seconds(name, space, resolution, "defect")
            ratios.append((cpu_c / n_corrected) / (cpu / n_base))
            print(f"{name:<20} {space:<9} {wall:9.1f}/{wall_c:<10.1f} {cpu:9.1f}/{cpu_c:<9.1f} "
                  f"{n_base:5d}/{n_corrected:<5d} {wall_c / wall:5.2f} {cpu_c / cpu:5.2f} {ratios[-1]:8.2f}", flush=True)
    print(f"spread of cpu/eval: {min(ratios):.2f}-{max(ratios):.2f} over {len(ratios)} designs")
    print(f"defect_over_none_{resolution}: {float(np.median(ratios)):.2f}")


if __name__ == "__main__":
    main()
