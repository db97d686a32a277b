"""The printed solid of finished design runs re-simulated on finer grids (docs/benchmarks.md#tools-for-design-experiments).

Reads each run folder's ``design.stl``, ``density.npz`` and ``curves.csv`` (nothing is written into
the folders), re-voxelises the mesh over the run's design domain on voxels 1, 2, ... times smaller
than the design grid's (`design.files.printed.fine_release`) and prints one markdown row per run: the
rate deviation over the solid's own middle 80% (`design.inverse.rate.rate_deviation`) and the rel. RMSE
against the run's target at each factor. Factor 1 reproduces the run's own binary solid. The rel. RMSE
is against the run's ``target_mm3``: a source's physical release (runs of summary format 2), or its
release on the design grid (format 1).

    python -m studies.printed_grid RUN_FOLDER [RUN_FOLDER ...] [--factors 1 2 3] [--figure PNG]

``--figure`` also draws each run's rate deviation against the voxel size (runs named DESIGN/SETTING,
e.g. ``runs128/C05w8``, are grouped by DESIGN).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import trimesh

from design.files.printed import fine_release
from design.inverse.objective import rel_rmse
from design.inverse.rate import rate_deviation


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
    parser.add_argument("--figure", type=Path, help="PNG of rate deviation against voxel size")
    args = parser.parse_args()
    head = " | ".join(f"voxel / {f}: rate dev., rel. RMSE" for f in args.factors)
    print(f"| run | {head} |\n|---|" + "---|" * len(args.factors))
    figures = {}
    for run in args.runs:
        figures[run] = printed_figures(run, args.factors)
        cells = " | ".join(f"{100 * dev:.2f}%, {100 * fit:.2f}%" for dev, fit in figures[run])
        print(f"| {run} | {cells} |", flush=True)
    if args.figure:
        draw(figures, args.factors, args.figure)


def draw(figures: dict[Path, list[tuple[float, float]]], factors: list[int], path: Path) -> None:
    """One panel per design folder: each run's rate deviation against 1 / factor, the 5% aim dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups: dict[str, list[Path]] = {}
    for run in figures:
        groups.setdefault(run.parent.name or ".", []).append(run)
    fig, axes = plt.subplots(1, len(groups), figsize=(5 * len(groups), 4), sharey=True, squeeze=False)
    for ax, (group, runs) in zip(axes[0], groups.items()):
        for run in runs:
            ax.plot(factors, [100 * dev for dev, _ in figures[run]], "o-", label=run.name)
        ax.axhline(5.0, color="k", ls="--", lw=1)
        ax.set(title=group, xlabel="voxel size / design voxel size", xticks=factors,
               xticklabels=[f"1/{f}" if f > 1 else "1" for f in factors])
        ax.legend(fontsize=8)
    axes[0][0].set_ylabel("rate deviation, middle 80% (%)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main()
