"""Default designs of untuned shapes (benchmarks/untuned_shapes.py) and the true fit of their prints, one CSV row each.

Each design is `design.files.rundir.run_design` with `DesignConfig`'s defaults for the shape's mesh, the space and
the resolution (resumed when its folder already holds a run). A row: the print's true fit (``rel_rmse_print`` of
``summary.json``) and the same figure recomputed here from ``design.stl`` and the source mesh by the reference
evaluator (`design.forward.reference`, its default lattice), the design grid's fit, pieces, seconds, evaluations and
the print's fit after each correction round (``rounds.npz``).

    python benchmarks/physical_default.py OUT_CSV RUNS_DIR SHAPE:SPACE [SHAPE:SPACE ...] [--resolution 128]

Last line: ``rows: <count>``.
"""
from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np
import trimesh

sys.path.insert(0, str(Path(__file__).resolve().parent))
import untuned_shapes  # noqa: E402


def design_row(name: str, space: str, resolution: int, runs: Path) -> dict:
    from design.files.rundir import run_design
    from design.forward.reference import reference_release
    from design.inverse.objective import rel_rmse
    from design.inverse.problem import DesignConfig

    folder = runs / f"{name}_{space}_{resolution}"
    stl = runs / f"{name}.stl"
    untuned_shapes.source(name).export(stl)
    resume = (folder / "config.json").exists()
    t0 = time.perf_counter()
    result = run_design(None if resume else DesignConfig(target=str(stl), space=space, resolution=resolution),
                        folder, resume=resume)
    wall = time.perf_counter() - t0
    s = result.outputs.summary
    tau = np.genfromtxt(folder / "curves.csv", delimiter=",", names=True)["tau_mm"]
    goal = reference_release(trimesh.load_mesh(stl), tau).released_mm3
    again = rel_rmse(reference_release(trimesh.load_mesh(folder / "design.stl"), tau).released_mm3, goal)
    fits = ""
    if (folder / "rounds.npz").exists():
        with np.load(folder / "rounds.npz") as rounds:
            fits = ";".join(f"{100 * f:.3f}" for f in rounds["fits"])
    summary_fit = s.get("rel_rmse_print")  # None in a summary written before it was recorded
    grid_fit = s.get("rel_rmse_design_grid_binary", s.get("rel_rmse_binary"))
    return {"shape": name, "space": space, "resolution": resolution,
            "true_fit": "-" if summary_fit is None else f"{100 * summary_fit:.4f}",
            "recomputed": f"{100 * again:.4f}", "grid_fit": "-" if grid_fit is None else f"{100 * grid_fit:.4f}",
            "pieces": s["pieces"], "seconds": f"{s['seconds']:.0f}", "wall": f"{wall:.0f}",
            "iterations": s["iterations"], "round_fits": fits}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csv", type=Path)
    parser.add_argument("runs", type=Path)
    parser.add_argument("cases", nargs="+", metavar="SHAPE:SPACE")
    parser.add_argument("--resolution", type=int, default=128)
    args = parser.parse_args()
    args.runs.mkdir(parents=True, exist_ok=True)
    for case in args.cases:
        name, _, space = case.partition(":")
        row = design_row(name, space, args.resolution, args.runs)
        new = not args.csv.exists()
        with args.csv.open("a", newline="") as handle:
            writer = csv.DictWriter(handle, list(row))
            if new:
                writer.writeheader()
            writer.writerow(row)
        print(",".join(str(v) for v in row.values()), flush=True)
    with args.csv.open() as handle:
        print(f"rows: {sum(1 for _ in handle) - 1}")


if __name__ == "__main__":
    main()
