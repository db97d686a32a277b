"""A measured run as an inverse-design target (``tau_mm,released_mm3``), with the simulated bench's constants.

The real simulation-to-bench calibration (paper section 4.3) is a later issue; until then seconds map to
tau with :data:`labapp.simbench.SECONDS_PER_MM` and grams to mm^3 with the print density 1.32 g/cm^3.
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from analysis import BenchCalibration, analyze_run
from labapp.simbench import DENSITY_G_PER_MM3, SECONDS_PER_MM
from labapp.storage import atomic_write

log = logging.getLogger(__name__)

NOMINAL_NOTE = (f"measured curves become targets with nominal constants ({SECONDS_PER_MM:g} s per mm of tau, "
                f"{DENSITY_G_PER_MM3 * 1000:g} g/cm^3); the simulation-to-bench calibration of paper section 4.3 "
                "is a later issue")


def curve_to_target(t_s: np.ndarray, released_g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Seconds and grams to tau (mm) and released volume (mm^3), made non-decreasing from (0, 0)."""
    t = np.asarray(t_s, float)
    keep = t >= 0
    tau = np.concatenate([[0.0], t[keep] / SECONDS_PER_MM])
    vol = np.concatenate([[0.0], np.maximum.accumulate(np.clip(np.asarray(released_g, float)[keep], 0, None))])
    vol /= DENSITY_G_PER_MM3
    _, first = np.unique(tau, return_index=True)
    return tau[first], vol[first]


def run_to_target_csv(run_folder: Path, out_csv: Path, calibration: BenchCalibration | None = None) -> Path:
    """Analyse a run folder (its own ``calibration.json`` unless one is given) and write its smoothed
    release as a ``tau_mm,released_mm3`` target CSV.

    Raises
    ------
    FileNotFoundError
        If no calibration is given and the run has none.
    """
    run_folder = Path(run_folder)
    if calibration is None:
        cal_path = run_folder / "calibration.json"
        if not cal_path.is_file():
            raise FileNotFoundError(f"{run_folder} has no calibration.json; give a bench calibration")
        calibration = BenchCalibration.load(cal_path)
    curve = analyze_run(run_folder, calibration)
    tau, vol = curve_to_target(curve.t_s, curve.released_g)
    rows = "tau_mm,released_mm3\n" + "".join(f"{a:.6f},{b:.4f}\n" for a, b in zip(tau, vol))
    atomic_write(Path(out_csv), rows.encode())
    log.info("target %s from %s: %d points, %.1f mm^3 over %.2f mm", out_csv, run_folder, len(tau), vol[-1], tau[-1])
    return Path(out_csv)
