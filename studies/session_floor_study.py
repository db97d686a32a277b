"""Default designs with and without the optimiser's session floor (docs/design.md#optimiser-sessions-start-inside-the-bounds).

With the cosine bound map a variable at exactly 0 or 1 has a zero gradient in z, so a design binary in rho_hat
stalls every later optimiser session (`design.inverse.optimize.SESSION_FLOOR`). For each source of
`benchmarks.untuned_shapes` this runs the default design (`design.inverse.defect.optimise_physical`, the
source's reference release as the target) twice, with the floor (``floor``; 1e-3 where the space has none) and
with it set to 0 (``none``),
and prints the print's true fit (reference evaluator, default lattice), the design grid's fit, the pieces, the
evaluations the run made, its seconds, and the rho_hat variables within 1e-12 of a bound at the end (how many,
and how many of them have dJ/d rho_hat pointing inside: trapped by the map).

    python -m studies.session_floor_study [--shapes a,b] [--space extruded] [--resolution 64]

Last line: ``cases: <count>``.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks import untuned_shapes
from benchmarks.designs import MemoryRounds, NoStore, judge, source_problem, warm_up

SATURATED = 1e-12
"""A variable this close to 0 or 1 counts as at the bound."""


def trapped(objective, x: np.ndarray) -> tuple[int, int]:
    """(variables at a bound, those of them whose dJ/d rho_hat points inside) of design variables ``x``."""
    g = objective.evaluate(x).grad
    low, high = x < SATURATED, x > 1.0 - SATURATED
    return int(np.count_nonzero(low | high)), int(np.count_nonzero((low & (g < 0)) | (high & (g > 0))))


def run_case(name: str, space: str, resolution: int, floor: float) -> str:
    """One default design of source ``name`` with `SESSION_FLOOR` = ``floor``; its table row."""
    from design.inverse import optimize
    from design.inverse.config import DesignConfig
    from design.inverse.defect import optimise_physical

    mesh = untuned_shapes.source(name)
    config = DesignConfig(target=f"{name}.stl", space=space, resolution=resolution)
    problem = source_problem(name, mesh, config)
    default = optimize.SESSION_FLOOR
    optimize.SESSION_FLOOR = {space: floor}
    try:
        t0 = time.perf_counter()
        outcome, objective = optimise_physical(optimize.build_objective(problem, config), problem, config,
                                               NoStore(), MemoryRounds())
        seconds = time.perf_counter() - t0
    finally:
        optimize.SESSION_FLOOR = default
    fit, grid_fit, pieces = judge(objective, problem, outcome.best_x)
    at_bound, inside = trapped(objective, outcome.best_x)
    return (f"| {name} | {space} | {'floor' if floor > 0 else 'none'} | {100 * fit:.2f}% | {100 * grid_fit:.2f}% | "
            f"{pieces} | {len(outcome.history)} | {seconds:.0f} | {at_bound} / {inside} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shapes", default="triaxial_ellipsoid,tilted_capsule,star_prism,cross_prism,c_ring")
    parser.add_argument("--space", default="extruded")
    parser.add_argument("--resolution", type=int, default=64)
    args = parser.parse_args()
    from design.inverse.optimize import SESSION_FLOOR

    floor = SESSION_FLOOR.get(args.space, 1e-3)  # the floor an nfc design would get
    warm_up()
    print("| shape | space | session floor | print's true fit | design grid's fit | pieces | evaluations | seconds | "
          "at a bound / trapped |")
    print("|---|---|---|---|---|---|---|---|---|")
    cases = 0
    for name in args.shapes.split(","):
        for value in (0.0, floor):
            print(run_case(name, args.space, args.resolution, value), flush=True)
            cases += 1
    print(f"cases: {cases}")


if __name__ == "__main__":
    main()
