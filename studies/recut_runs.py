"""Binary fit of finished design runs cut at rho = 1/2 and at the mass-preserving level.

Listed in docs/benchmarks.md#tools-for-design-experiments.

Reads each run folder's ``density.npz`` and ``curves.csv`` (nothing is written into the folders),
thresholds the full density at 1/2 (the paper's cut) and at `design.fabrication.extract.mass_preserving_level`
(the level `sfr design` extracts at), simulates both solids with `design.files.printed.solid_release`, and prints one
markdown row per run: binary rel. RMSE, pieces and, for a target with a zero-order middle, the rate
deviation over the solid's middle 80% (`design.inverse.rate.rate_deviation`).

    python -m studies.recut_runs RUN_FOLDER [RUN_FOLDER ...]

Thresholding equals re-voxelising the contour mesh at the same level
(tests/design/fabrication/test_design_extract.py), so the 1/2 column reproduces a run's own ``rel_rmse_binary``
when the run was cut at 1/2.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from design.fabrication.extract import count_pieces, mass_preserving_level
from design.files.printed import solid_release
from design.inverse.objective import rel_rmse
from design.inverse.rate import rate_deviation


def recut(folder: Path) -> dict:
    """Binary fit, pieces and rate deviation of one run at both levels."""
    data = np.load(folder / "density.npz")
    curves = np.loadtxt(folder / "curves.csv", delimiter=",", skiprows=1)
    tau, target = curves[:, 0], curves[:, 1]
    rho_full, dx, mirror = data["rho_full"], float(data["dx_mm"]), tuple(bool(m) for m in data["mirror"])
    row = {}
    for name, level in (("half", 0.5), ("mass", mass_preserving_level(rho_full))):
        solid = rho_full >= level
        curve = solid_release(solid, dx, mirror, float(tau[-1]), float(tau[1] - tau[0]))
        row[name] = {"level": level, "binary": rel_rmse(curve, target), "pieces": count_pieces(solid),
                     "rate_dev": rate_deviation(tau, curve) if curve[-1] > curve[0] else float("nan")}
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path, help="run folders written by `sfr design`")
    args = parser.parse_args()
    print("| run | binary fit at 1/2 | pieces | rate dev. | level | binary fit at the level | pieces | rate dev. |")
    print("|---|---|---|---|---|---|---|---|")
    for folder in args.runs:
        r = recut(folder)
        h, m = r["half"], r["mass"]
        print(f"| {folder} | {h['binary']:.2%} | {h['pieces']} | {h['rate_dev']:.1%} | {m['level']:.3f} | "
              f"{m['binary']:.2%} | {m['pieces']} | {m['rate_dev']:.1%} |", flush=True)


if __name__ == "__main__":
    main()
