"""The printed solid of finished design runs re-simulated on finer grids (docs/results.md).

Reads each run folder's ``design.stl``, ``density.npz`` and ``curves.csv`` (nothing is written into
the folders), re-voxelises the mesh over the run's design domain on voxels 1, 2, ... times smaller
than the design grid's (`design.outputs.fine_release`, the same function as the ``fine`` curve of
`sfr design`) and prints one markdown row per run: the rate deviation over the solid's own middle
80% (`design.rate.rate_deviation`) and the rel. RMSE against the run's target at each factor.
Factor 1 reproduces the run's own binary solid.

    python benchmarks/printed_grid.py RUN_FOLDER [RUN_FOLDER ...] [--factors 1 2 3]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import trimesh

from design.objective import rel_rmse
from design.outputs import fine_release
from design.rate import rate_deviation


def printed_figures(folder: Path, factors: list[int]) -> list[tuple[float, float]]:
    """(rate deviation, rel. RMSE) of one run's printed mesh at each factor."""
    data = np.load(folder / "density.npz")
    curves = np.genfromtxt(folder / "curves.csv", delimiter=",", names=True)
    tau, target = curves["tau_mm"], curves["target_mm3"]
    mesh = trimesh.load(folder / "design.stl")
    grid = (float(data["dx_mm"]), data["origin_mm"], data["rho_full"].shape, tuple(bool(m) for m in data["mirror"]))
    rows = []
    for factor in factors:
        curve = fine_release(mesh, *grid, float(tau[-1]), float(tau[1] - tau[0]), factor=factor)
        rows.append((rate_deviation(tau, curve), rel_rmse(curve, target)))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--factors", nargs="+", type=int, default=[1, 2, 3])
    args = parser.parse_args()
    head = " | ".join(f"voxel / {f}: rate dev., rel. RMSE" for f in args.factors)
    print(f"| run | {head} |\n|---|" + "---|" * len(args.factors))
    for run in args.runs:
        cells = " | ".join(f"{100 * dev:.2f}%, {100 * fit:.2f}%" for dev, fit in printed_figures(run, args.factors))
        print(f"| {run} | {cells} |", flush=True)


if __name__ == "__main__":
    main()
