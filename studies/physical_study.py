"""Side by side: ways to make the printed solid's true release meet the physical target (docs/design.md#physical-correction).

For every source of `benchmarks.untuned_shapes` and design space, design runs with the defaults
(`design.inverse.config.DesignConfig`) and the source's reference release as the target are judged by the reference
evaluator (`design.forward.reference`); the methods:

- ``none``: a run without correction (``physical_correction="none"``, ``max_iter`` evaluations);
- ``defect``: the default run: the first optimisation, then the defect-correction rounds of
  `design.inverse.defect` within the same ``max_iter`` evaluations (in a CSV, ``defect_final_beta`` and
  ``defect_double_beta`` are rows of the rounds at the final beta and at twice it, where the default
  `design.inverse.defect.ROUND_BETA_FACTOR` is the other);
- ``fine``: the defect run's first optimisation, then a last stage on a grid twice as fine started from the
  upsampled design variables at the final beta, of half the rounds' evaluations (each costs about eight).

Each row: the print's true fit (rel. RMSE of the reference release of the printed solid against the reference
release of the source, % of the target's final release), the design grid's fit (the density's release on the
design grid against the same target), pieces, and seconds (the optimisation, and each method's addition).
Rows are appended to the CSV as they finish; a row already in it is not run again.

    python -m studies.physical_study CSV [--resolution 64] [--spaces nfc,extruded] [--shapes a,b] [--methods ...]
    python -m studies.physical_study CSV --table      # the CSV as the Markdown table of docs/design.md

Last line: ``rows: <count>``.
"""
from __future__ import annotations

import argparse
import csv
import time
from dataclasses import replace
from pathlib import Path

from benchmarks import untuned_shapes
from benchmarks.designs import MemoryRounds, NoStore, judge, source_problem, warm_up

COLUMNS = ("shape", "space", "resolution", "method", "true_fit", "grid_fit", "pieces", "seconds", "extra_seconds",
           "evaluations")


def _done(path: Path) -> set[tuple[str, str, str, str]]:
    if not path.exists():
        return set()
    with path.open() as handle:
        return {(r["shape"], r["space"], r["resolution"], r["method"]) for r in csv.DictReader(handle)}


def _append(path: Path, row: dict) -> None:
    new = not path.exists()
    with path.open("a", newline="") as handle:
        writer = csv.DictWriter(handle, COLUMNS)
        if new:
            writer.writeheader()
        writer.writerow(row)
        handle.flush()


def study_case(name: str, space: str, resolution: int, methods: tuple[str, ...], path: Path, done: set,
               max_iter: int) -> None:
    from design.inverse.config import DesignConfig
    from design.inverse.defect import correction_plan, final_beta, optimise_physical
    from design.inverse.multistart import upsample
    from design.inverse.optimize import build_objective, optimise

    todo = [m for m in methods if (name, space, str(resolution), m) not in done]
    if not todo:
        return
    mesh = untuned_shapes.source(name)
    config = DesignConfig(target=f"{name}.stl", space=space, resolution=resolution, max_iter=max_iter)
    problem = source_problem(name, mesh, config)

    def row(method, judged, seconds, extra, evaluations):
        fit, grid_fit, pieces = judged
        r = {"shape": name, "space": space, "resolution": resolution, "method": method,
             "true_fit": f"{100 * fit:.4f}", "grid_fit": f"{100 * grid_fit:.4f}", "pieces": pieces,
             "seconds": f"{seconds:.1f}", "extra_seconds": f"{extra:.1f}", "evaluations": evaluations}
        _append(path, r)
        print(",".join(str(r[c]) for c in COLUMNS), flush=True)

    if "none" in todo:
        plain = replace(config, physical_correction="none")
        objective = build_objective(problem, plain)
        t0 = time.perf_counter()
        outcome = optimise(objective, problem, plain, NoStore())
        row("none", judge(objective, problem, outcome.best_x), time.perf_counter() - t0, 0.0, len(outcome.history))
    if "defect" not in todo and "fine" not in todo:
        return
    objective = build_objective(problem, config)
    rounds = MemoryRounds()
    t0 = time.perf_counter()
    outcome, objective = optimise_physical(objective, problem, config, NoStore(), rounds)
    seconds = time.perf_counter() - t0
    first = rounds.states[0]
    first_seconds = float(outcome.history[first.start - 1][-1])
    if "defect" in todo:
        row("defect", judge(objective, problem, outcome.best_x), seconds, seconds - first_seconds,
            len(outcome.history))
    if "fine" in todo:  # a last stage on a grid twice as fine, from the first optimisation's design
        n_rounds, _ = correction_plan(config)
        evals = max(1, n_rounds * config.correction_evals // 2)
        t1 = time.perf_counter()
        beta = final_beta(config)
        stage = replace(config, resolution=2 * resolution, beta=beta, beta_final=beta, max_iter=evals,
                        physical_correction="none")
        fine_problem = source_problem(name, mesh, stage)
        fine_objective = build_objective(fine_problem, stage)
        x_main = first.x_start.reshape(objective.space.var_shape)
        x_fine = upsample(x_main, problem.dx_mm, fine_objective.space.var_shape, fine_problem.dx_mm)
        fine = optimise(fine_objective, fine_problem, stage, NoStore(), start=lambda o, p: x_fine)
        extra = time.perf_counter() - t1
        row("fine", judge(fine_objective, fine_problem, fine.best_x), first_seconds + extra, extra,
            first.start + len(fine.history))


def table(path: Path) -> str:
    """The rows of a study CSV as a Markdown table: one line per shape and space, the methods side by side."""
    with path.open() as handle:
        rows = list(csv.DictReader(handle))
    cases: dict[tuple[str, str, str], dict[str, dict]] = {}
    for r in rows:
        cases.setdefault((r["shape"], r["space"], r["resolution"]), {})[r["method"]] = r
    others = ("defect_final_beta", "defect_double_beta", "fine")
    lines = ["| shape | space | true fit, none | **true fit, defect (default)** | true fit, "
             + " / ".join(o.replace("_", " ") for o in others) + " | design grid, none / defect | pieces, none / "
             "defect | seconds, none / defect |", "|---|---|---|---|---|---|---|---|"]
    extrusions = set(untuned_shapes.EXTRUSIONS)

    def fit(by, m, key="true_fit"):
        return f"{float(by[m][key]):.2f}%" if m in by else "-"

    for (shape, space, _), by in cases.items():
        label = f"{shape}{' (extrusion)' if shape in extrusions else ''}"
        lines.append(f"| {label} | {space} | {fit(by, 'none')} | **{fit(by, 'defect')}** | "
                     + " / ".join(fit(by, o) for o in others) + f" | {fit(by, 'none', 'grid_fit')} / "
                     f"{fit(by, 'defect', 'grid_fit')} | " + " / ".join(by[m]["pieces"] if m in by else "-"
                                                                         for m in ("none", "defect"))
                     + " | " + " / ".join(f"{float(by[m]['seconds']):.0f}" if m in by else "-"
                                          for m in ("none", "defect")) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csv", type=Path)
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--spaces", default="nfc,extruded")
    parser.add_argument("--shapes", default=",".join(untuned_shapes.BUILDERS))
    parser.add_argument("--methods", default="none,defect,fine")
    parser.add_argument("--max-iter", type=int, default=500)
    parser.add_argument("--table", action="store_true", help="print the CSV as a Markdown table and stop")
    args = parser.parse_args()
    if args.table:
        print(table(args.csv))
        return
    args.csv.parent.mkdir(parents=True, exist_ok=True)
    warm_up()
    methods = tuple(args.methods.split(","))
    for name in args.shapes.split(","):
        for space in args.spaces.split(","):
            study_case(name, space, args.resolution, methods, args.csv, _done(args.csv), args.max_iter)
    print(f"rows: {len(_done(args.csv))}")


if __name__ == "__main__":
    main()
