"""When the enclosed voids of designed solids open, against the rate over the middle 80% of the release.

    python -m studies.void_openings RUN_DIR [RUN_DIR ...] [--figure docs/figures/NAME.png]

For each run folder (written by `sfr design`): the printed solid of ``density.npz`` is simulated
(eqs. 5-7); each enclosed void (`design.fabrication.printability.enclosed_voids`) opens at the smallest
dissolution time u among its voxels, printed in mm of tau and as a fraction of the binary solid's
own 10%-90% span. Then the binary solid's rate on the 20 sub-intervals of that span, relative to its
mean there (`design.inverse.rate.rate_deviation`'s windows). The figure draws those rates with each void's
opening time marked.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy import ndimage

from design.forward.simulator import simulate
from design.inverse.rate import MID_HI, MID_INTERVALS, MID_LO


def window_rates(tau: np.ndarray, curve: np.ndarray) -> tuple[float, float, np.ndarray]:
    """``(tau_10, tau_90, rates)``: the 10%-90% span and the rate on each sub-interval over its mean."""
    lo, hi = np.interp([MID_LO * curve[-1], MID_HI * curve[-1]], curve, tau)
    edges = np.linspace(lo, hi, MID_INTERVALS + 1)
    values = np.interp(edges, tau, curve)
    rates = np.diff(values) / np.diff(edges)
    return float(lo), float(hi), rates / ((values[-1] - values[0]) / (hi - lo))


def void_openings(solid: np.ndarray, dx_mm: float) -> list[tuple[int, float]]:
    """``(voxels, opening u in mm)`` of each enclosed void of a full solid, largest first."""
    labels, count = ndimage.label(np.pad(~solid, 1, constant_values=True))
    outside = labels[0, 0, 0]  # the padding: the medium around the grid
    labels = labels[1:-1, 1:-1, 1:-1]
    u = simulate(solid.astype(float), dx_mm).u_mm
    found = [(int(np.count_nonzero(labels == k)), float(u[labels == k].min()))
             for k in range(1, count + 1) if k != outside]
    return sorted(found, reverse=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--figure", type=Path)
    args = parser.parse_args()
    panels = []
    for run in args.runs:
        data = np.load(run / "density.npz")
        solid = data["solid"].astype(bool)
        curves = np.loadtxt(run / "curves.csv", delimiter=",", skiprows=1)
        lo, hi, rates = window_rates(curves[:, 0], curves[:, 3])
        openings = void_openings(solid, float(data["dx_mm"]))
        print(f"{run.name}: span {lo:.3f}-{hi:.3f} mm, rate deviation {np.max(np.abs(rates - 1)):.1%}, "
              f"{len(openings)} enclosed void(s)")
        for voxels, u in openings:
            print(f"  void of {voxels} voxels opens at u = {u:.3f} mm ({(u - lo) / (hi - lo):.2f} of the span)")
        print("  rates / mean: " + " ".join(f"{r:.3f}" for r in rates))
        panels.append((run.name, lo, hi, rates, openings))
    if args.figure:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.2), sharey=True, squeeze=False)
        for ax, (name, lo, hi, rates, openings) in zip(axes[0], panels):
            centres = (np.arange(MID_INTERVALS) + 0.5) / MID_INTERVALS
            ax.step(centres, rates, where="mid", color="k")
            ax.axhspan(0.95, 1.05, color="0.9")
            for voxels, u in openings:
                ax.axvline((u - lo) / (hi - lo), color="tab:red", lw=0.8 + 2.0 * voxels / max(v for v, _ in openings))
            ax.set_title(f"{name}: {len(openings)} enclosed void(s)", fontsize=9)
            ax.set_xlabel("fraction of the 10%-90% span")
            ax.set_xlim(0, 1)
        axes[0][0].set_ylabel("binary rate / mean")
        fig.tight_layout()
        fig.savefig(args.figure, dpi=120)
        print(f"figure: {args.figure}")


if __name__ == "__main__":
    main()
