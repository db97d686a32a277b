"""Tabulate design run folders as markdown and copy their report pictures to docs/figures.

    python -m studies.design_results RUN_DIR [RUN_DIR ...] [--figures docs/figures]

For each run folder (written by `sfr design`) prints one markdown table row from summary.json; for
analytic zero-order targets it also prints `design.inverse.rate.rate_deviation` of the achieved release
rate over the middle 80% of the release, against the curve's own mean rate and against the
target's constant rate (docs/design.md#from-density-to-print-designfabricationextractpy-designfilesoutputspy).
Last line: ``runs: <count>``.
"""
from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import numpy as np

from design.files.records import load_summary
from design.inverse.rate import rate_deviation, rate_deviation_vs_target


def zero_order_deviation(curves: np.ndarray) -> dict[str, dict[str, float]]:
    """`design.inverse.rate.rate_deviation` of the density and binary curves of a zero-order run.

    ``own``: over each curve's own 10%-90% span against its own mean rate (summary.json's
    ``rate_dev_mid80``, the figure the requirement is judged by); ``vs_target``: over the target's
    10%-90% span against the target's mean rate there (``rate_dev_mid80_vs_target``).
    """
    tau, target = curves[:, 0], curves[:, 1]
    out: dict[str, dict[str, float]] = {"own": {}, "vs_target": {}}
    for name, col in (("density", 2), ("binary", 3)):
        out["own"][name] = rate_deviation(tau, curves[:, col])
        out["vs_target"][name] = rate_deviation_vs_target(tau, curves[:, col], target)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--figures", type=Path, help="copy each report.png here as design_<run>.png")
    args = parser.parse_args()
    print("| run | space | grid (reduced) | evals | s/eval | rel. RMSE density | rel. RMSE binary | IoU | pieces "
          "| mass (g) | narrowest channel (mm) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for run in args.runs:
        s = load_summary(run)
        iou = "-" if s["iou_with_source"] is None else f"{s['iou_with_source']:.3f}"
        chan = "none" if s["min_channel_mm"] is None else f"{s['min_channel_mm']:.2f}"
        print(f"| {run.name} | {s['space']} | {'x'.join(map(str, s['reduced_shape']))} | {s['iterations']} "
              f"| {s['seconds_per_iteration']:.3f} | {s['rel_rmse_density']:.3%} | {s['rel_rmse_design_grid_binary']:.3%} "
              f"| {iou} | {s['pieces']} | {s['print_mass_g']:.3f} | {chan} |")
        if s["target"].startswith("analytic:zero-order"):
            curves = np.loadtxt(run / "curves.csv", delimiter=",", skiprows=1)
            dev = zero_order_deviation(curves)
            print(f"\n{run.name}: zero-order rate deviation over the middle 80% (density / binary): "
                  f"own mean {dev['own']['density']:.1%} / {dev['own']['binary']:.1%}, "
                  f"vs target {dev['vs_target']['density']:.1%} / {dev['vs_target']['binary']:.1%}\n")
        if args.figures:
            args.figures.mkdir(parents=True, exist_ok=True)
            shutil.copy(run / "report.png", args.figures / f"design_{run.name}.png")
    print(f"runs: {len(args.runs)}")


if __name__ == "__main__":
    main()
