"""Accuracy of the bench analysis against the fixtures' ground truth, with and without mirror normalisation.

    .venv/bin/python -m benchmarks.accuracy_analysis [--quick] [--figures docs/figures]

Calibrates on fixtures/bench/calibration, analyses fixtures/bench/run (another "day": 5 % dimmer light,
other drift phase, intrusions in ~15 % of the frames) and compares every frame's concentration with the
rendered truth. Prints one line per variant; the last line is the headline
``rms_error_percent_of_final: <value>`` (mirror normalisation on, per-frame values, no smoothing).
"""
from __future__ import annotations

import argparse
import csv
import dataclasses
import json
from pathlib import Path

import cv2
import numpy as np

from analysis import CropGeometry, analyze_run, estimate_concentration, fit_bench_calibration, read_cells, smooth_curve

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "fixtures" / "bench"


def _calibrate(geometry: CropGeometry, reduce: int):
    with open(BENCH / "calibration" / "masses.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    water_g = json.loads((BENCH / "calibration" / "truth.json").read_text())["scene"]["water_g"]
    cells = np.array([read_cells(BENCH / "calibration" / r["file"], geometry, reduce=reduce) for r in rows])
    conc = np.array([float(r["added_mass_g"]) for r in rows]) / water_g * 1000.0
    return fit_bench_calibration(cells, conc, geometry, water_g, reduce=reduce)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="skip the reduce=2/4 variants and figures")
    parser.add_argument("--figures", type=Path, help="write accuracy figures (PNG) to this folder")
    args = parser.parse_args()

    with open(BENCH / "run" / "truth.csv", newline="") as fh:
        truth = {r["file"]: (float(r["conc_g_per_kg"]), bool(r["intrusions"])) for r in csv.DictReader(fh)}
    crop = json.loads((BENCH / "calibration" / "truth.json").read_text())["crop"]
    variants = [("mirror", True, 1, True), ("no-mirror", False, 1, True), ("mirror, no reference", True, 1, False)]
    if not args.quick:
        variants += [("mirror, reduce=2", True, 2, True), ("mirror, reduce=4", True, 4, True)]
    results = {}
    for name, mirror, reduce, use_reference in variants:
        geometry = CropGeometry(*crop, mirror_normalise=mirror)
        cal = _calibrate(geometry, reduce)
        curve = analyze_run(BENCH / "run", cal, workers=2)
        if not use_reference:
            conc = np.array([estimate_concentration(c, cal).conc_g_per_kg for c in curve.cells])
            curve = dataclasses.replace(curve, conc_g_per_kg=conc,
                                        conc_smooth_g_per_kg=smooth_curve(curve.t_s, conc))
        true = np.array([truth[f][0] for f in curve.files])
        hit = np.array([truth[f][1] for f in curve.files])
        final = true.max()
        err = curve.conc_g_per_kg - true
        rms = 100 * np.sqrt(np.mean(err ** 2)) / final
        rms_hit = 100 * np.sqrt(np.mean(err[hit] ** 2)) / final
        rms_smooth = 100 * np.sqrt(np.mean((curve.conc_smooth_g_per_kg - true) ** 2)) / final
        print(f"{name:24s} rms {rms:6.3f} %  (frames with intrusions {rms_hit:6.3f} %, n={hit.sum()}; "
              f"smoothed {rms_smooth:6.3f} %; max {100 * np.abs(err).max() / final:6.3f} %) of {final:.3f} g/kg")
        results[name] = (curve, true, rms)
    if args.figures:
        _figures(results, args.figures)
    print(f"rms_error_percent_of_final: {results['mirror'][2]:.3f}")


def _figures(results: dict, folder: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder.mkdir(parents=True, exist_ok=True)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 6), dpi=110, sharex=True)
    curve, true, _ = results["mirror"]
    minutes = curve.t_s / 60
    top.plot(minutes, true, "k-", lw=1, label="truth")
    top.plot(minutes, curve.conc_g_per_kg, "C0.", ms=4, label="mirror-normalised")
    top.plot(minutes, results["no-mirror"][0].conc_g_per_kg, "C3x", ms=3, label="no mirror normalisation")
    top.set_ylabel("concentration (g/kg)")
    top.legend(loc="lower right")
    for name, style in (("mirror", "C0.-"), ("no-mirror", "C3x-")):
        c, t, rms = results[name]
        bottom.plot(c.t_s / 60, 100 * (c.conc_g_per_kg - t) / t.max(), style, ms=3, lw=0.5,
                    label=f"{name}: rms {rms:.2f} %")
    bottom.set_ylabel("error (% of final)")
    bottom.set_xlabel("time (min)")
    bottom.legend()
    fig.tight_layout()
    fig.savefig(folder / "analysis_accuracy.png")
    plt.close(fig)

    x, y, size = json.loads((BENCH / "calibration" / "truth.json").read_text())["crop"]
    frame = cv2.imread(str(BENCH / "run" / "frame_0030.jpg"))
    width = frame.shape[1]
    for i in range(11):
        step = round(i * size / 10)
        cv2.line(frame, (x + step, y), (x + step, y + size), (0, 0, 255), 1)
        cv2.line(frame, (x, y + step), (x + size, y + step), (0, 0, 255), 1)
    cv2.rectangle(frame, (width - 1 - x - size, y), (width - 1 - x, y + size), (0, 160, 0), 2)
    cv2.line(frame, (width // 2, 0), (width // 2, frame.shape[0]), (255, 0, 0), 1)
    cv2.imwrite(str(folder / "analysis_crop.png"), frame)

    cal = _calibrate(CropGeometry(x, y, size), 1)
    with open(BENCH / "calibration" / "masses.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    cells = np.array([read_cells(BENCH / "calibration" / r["file"], CropGeometry(x, y, size)) for r in rows])
    conc = np.array([float(r["added_mass_g"]) for r in rows]) / cal.water_g * 1000.0
    fig, ax = plt.subplots(figsize=(6, 4), dpi=110)
    grid = np.linspace(0, conc.max(), 100)
    for n, (r, c) in enumerate(((0, 0), (5, 5), (9, 9), (2, 8))):
        ax.plot(conc, cells[:, r, c], "o", color=f"C{n}", ms=4)
        ax.plot(grid, cal.t0[r, c] * np.exp(-cal.k[r, c] * grid), "-", color=f"C{n}",
                label=f"cell ({r},{c}): k = {cal.k[r, c]:.4f} +/- {cal.k_sigma[r, c]:.4f} kg/g")
    ax.set_xlabel("concentration (g/kg)")
    ax.set_ylabel("normalised transmittance")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(folder / "analysis_calibration.png")
    plt.close(fig)


if __name__ == "__main__":
    main()
