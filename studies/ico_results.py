"""Tabulate ICO and NFC design runs of the same targets and draw their overhangs (docs/design.md#ico-weight-w_f).

    python -m studies.ico_results --pairs ICO_DIR NFC_DIR [ICO_DIR NFC_DIR ...] --figure PNG

Prints one markdown table row per run from its summary.json (binary fit, overhang fraction and
longest run, J_fab, time per evaluation and the ICO share of it), then the figure: for every
target, the NFC and ICO solids as side views (projection along y, build direction up) with the
overhanging voxels (`design.fabrication.printability.overhangs`) in red. Last line: ``pairs: <count>``.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from design.fabrication.printability import overhangs
from design.files.records import load_summary


def row(run: Path) -> str:
    s = load_summary(run)
    ico = s.get("ico") or {}
    share = ico.get("fab_time_share")
    return (f"| {s['target'].split(':', 1)[-1]} | {s['space']} | {s['full_shape']} | {s['iterations']} | "
            f"{s['seconds_per_iteration']:.2f} | {'-' if share is None else format(share, '.0%')} | "
            f"{s['rel_rmse_density']:.2%} | {s['rel_rmse_design_grid_binary']:.2%} | {s['overhang_fraction']:.2%} | "
            f"{s['max_overhang_run_mm']:.2f} | {'-' if not ico else format(ico['J_fab'], '.3f')} | {s['pieces']} |")


def side_view(solid: np.ndarray) -> np.ndarray:
    """RGB side view along y: grey where solid, red where any voxel on the line overhangs."""
    over = overhangs(solid).any(axis=1).T
    mass = solid.any(axis=1).T
    img = np.ones(mass.shape + (3,))
    img[mass] = (0.55, 0.55, 0.6)
    img[over] = (0.85, 0.1, 0.1)
    return img


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--pairs", nargs="+", type=Path, required=True, help="ICO run, NFC run, ... (same targets)")
    parser.add_argument("--figure", type=Path, required=True)
    args = parser.parse_args()
    if len(args.pairs) % 2:
        parser.error("--pairs takes ICO and NFC run folders in pairs")
    pairs = list(zip(args.pairs[::2], args.pairs[1::2]))
    print("| target | space | grid | evals | s/eval | ICO share | rel. RMSE density | rel. RMSE binary | "
          "overhang fraction | longest overhang run (mm) | J_fab | pieces |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for ico, nfc in pairs:
        print(row(nfc))
        print(row(ico))
    fig = Figure(figsize=(2.6 * len(pairs), 5.4), layout="constrained")
    FigureCanvasAgg(fig)
    for col, (ico, nfc) in enumerate(pairs):
        for r, run in enumerate((nfc, ico)):
            s = load_summary(run)
            with np.load(run / "density.npz") as data:
                solid = data["solid"]
            ax = fig.add_subplot(2, len(pairs), r * len(pairs) + col + 1)
            ax.imshow(side_view(solid), origin="lower", interpolation="nearest")
            ax.set_title(f"{s['target'].split(':', 1)[-1][:26]}\n{s['space']}: overhang {s['overhang_fraction']:.1%}",
                         fontsize=8)
            ax.axis("off")
    fig.suptitle("side views, build direction up; red: overhanging voxels (projected along y)", fontsize=9)
    fig.savefig(args.figure, dpi=110)
    print(f"pairs: {len(pairs)}")


if __name__ == "__main__":
    main()
