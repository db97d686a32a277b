"""Why the physical correction takes a step: a design's print against its extraction level, and one correction round
at steps 1, 1/2 and 1/4 from the same design.

For each source (benchmarks/untuned_shapes.py) this runs the default design of `sfr design` at the resolution
(`design.files.rundir.run_design`, in RUNS/<shape>_<space>_<resolution>, resumed when finished) and keeps the state
of its first correction round (`design.inverse.defect.RoundState`): the design x the rounds start from. It prints

- x's mass, its extraction level (`design.fabrication.extract.mass_preserving_level`), and for levels 0.4-0.6 the
  volume of the contour (the print), the voxels at or above the level and the print's true fit
  (`design.inverse.defect.check_print`'s evaluator and lattice);
- for each step s, one round of `DesignConfig.correction_evals` evaluations from x aimed at G(x) + s (C* - P(x))
  (`design.inverse.defect.aimed_bias`), as the rounds run it: the print's fit, the change of the design's mass and
  of the bias b = G - P (RMS), and how far the grid misses its aim (RMS), in % of the target's final release.

    python -m studies.correction_step RUNS SHAPE:SPACE [SHAPE:SPACE ...] [--resolution 128]
"""
from __future__ import annotations

import argparse
import copy
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks import untuned_shapes

STEPS = (1.0, 0.5, 0.25)
LEVELS = (0.4, 0.45, 0.5, 0.55, 0.6)


class _Memory:
    def save(self, checkpoint, wait=True):
        pass

    def wait(self):
        pass


def first_round_start(name: str, space: str, resolution: int, runs: Path) -> tuple[Path, np.ndarray]:
    """The run folder of the default design and the design its first correction round started from (flat)."""
    import design.files.rounds as rounds_file
    from design.files.rundir import run_design
    from design.inverse.config import DesignConfig

    folder = runs / f"{name}_{space}_{resolution}"
    start = folder / "first_round_start.npy"
    if start.exists():
        return folder, np.load(start)
    stl = runs / f"{name}.stl"
    untuned_shapes.source(name).export(stl)
    states, save = [], rounds_file.RoundFile.save

    def keep(self, state):
        states.append(copy.deepcopy(state))
        save(self, state)

    rounds_file.RoundFile.save = keep
    try:
        run_design(DesignConfig(target=str(stl), space=space, resolution=resolution), folder)
    finally:
        rounds_file.RoundFile.save = save
    np.save(start, states[0].x_start)
    return folder, states[0].x_start


def study(name: str, space: str, resolution: int, runs: Path) -> None:
    from design.fabrication.extract import density_mesh, mass_preserving_level
    from design.files.records import load_config
    from design.files.targets_io import load_problem
    from design.forward.reference import reference_release
    from design.inverse.defect import aimed_bias, check_print, correction_plan, retargeted, round_beta
    from design.inverse.objective import rel_rmse
    from design.inverse.optimize import HISTORY_COLUMNS, Checkpoint, build_objective, optimise

    folder, x0 = first_round_start(name, space, resolution, runs)
    config = load_config(folder)
    problem = load_problem(config)
    objective = build_objective(problem, config)
    beta = objective.beta = round_beta(config)
    goal = problem.target.released_mm3
    final = goal[-1]

    def rms(curve):
        return 100 * float(np.sqrt(np.mean(curve ** 2))) / final

    dv = objective.space.dx_mm ** 3
    full = objective.space.unfold(objective.density(x0.reshape(objective.space.var_shape)))
    start = check_print(objective, problem, x0.reshape(objective.space.var_shape))
    cells = 128
    print(f"{name} {space} {resolution}: mass {full.sum() * dv:.1f} mm^3, level {mass_preserving_level(full):.3f}, "
          f"print {100 * start.fit:.3f}%")
    for level in LEVELS:
        mesh = density_mesh(full, objective.space.dx_mm, problem.origin_mm, level=level)
        fit = rel_rmse(reference_release(mesh, problem.target.tau_mm, cells=cells).released_mm3, goal)
        print(f"  level {level:.2f}: print {mesh.volume:.1f} mm^3, voxels at or above {np.sum(full >= level) * dv:.1f} "
              f"mm^3, print's fit {100 * fit:.3f}%")
    first = correction_plan(config)[1]
    for step in STEPS:
        bias = aimed_bias(start, goal, step)
        aimed = retargeted(problem, config, bias)
        saved = Checkpoint(x=x0, best_x=x0, best_value=np.inf, stage=0,
                           history=np.zeros((first, len(HISTORY_COLUMNS))), beta=beta)
        outcome = optimise(aimed, problem, replace(config, beta=beta, beta_final=beta,
                                                   max_iter=first + config.correction_evals), _Memory(), saved=saved)
        after = check_print(objective, problem, outcome.best_x)
        print(f"  step {step:.2f}: print {100 * after.fit:.3f}% ({after.pieces} piece(s)), mass "
              f"{100 * (after.grid_mm3[-1] - start.grid_mm3[-1]) / final:+.2f}%, bias change "
              f"{rms(after.bias_mm3 - start.bias_mm3):.2f}%, grid misses its aim by {rms(after.grid_mm3 - goal - bias):.2f}%",
              flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path)
    parser.add_argument("cases", nargs="+", metavar="SHAPE:SPACE")
    parser.add_argument("--resolution", type=int, default=128)
    args = parser.parse_args()
    args.runs.mkdir(parents=True, exist_ok=True)
    for case in args.cases:
        name, _, space = case.partition(":")
        study(name, space, args.resolution, args.runs)


if __name__ == "__main__":
    main()
