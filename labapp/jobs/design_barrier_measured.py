"""A two-material design from a measured curve through a simulation calibration with a barrier.

``sfr design --target MEASURED --simcal SIMCAL --barrier-speed`` (no number: the calibration's own barrier speed,
fitted from coated prints by :mod:`labapp.jobs.calibrate_barrier`; a number overrides it):

- the measured curve (grams over seconds: a run folder, ``curve.csv`` or any ``t_s,released_g`` CSV) becomes a
  ``tau_mm,released_mm3`` target through the calibration (:func:`write_barrier_target`): its monotone
  least-squares fit, nothing before the release rises out of the measurement's error, then smoothed over 5 % of the
  release's span (`SMOOTH_FRACTION`), mapped by the calibration's
  rate, density and wetting lag. It is not projected onto one material's isoperimetric bound: a delay or a pause
  is what the barrier is for;
- the two-material design (:func:`labapp.jobs.design_barrier.design_barrier`) runs on it;
- the finished design's print release is mapped back to grams over seconds (:func:`write_physical`):
  ``curves_physical.csv`` (``t_s,measured_g,target_g,design_released_g``) and ``physical.json`` (the relative RMS
  against the measured curve, the barrier speed used and where it came from).
"""
from __future__ import annotations

import dataclasses
import json
import tempfile
from pathlib import Path

import numpy as np

from design.inverse.twomaterial_problem import TwoMaterialSettings
from labapp.errors import UsageError
from labapp.jobs.physical import after_lag, noise_sd
from labapp.records.curvefiles import PhysicalCurve
from labapp.records.fileio import atomic_write
from labapp.records.outpaths import FolderKind, check_out
from labapp.records.simcal import SimCalFile, curve_of, load_simcal

NOISE_FLOOR = 3.0
START_FRACTION = END_FRACTION = 0.05
"""A measured target releases nothing until its monotone fit exceeds NOISE_FLOOR noise standard deviations and
START_FRACTION of its final release, and all of it once within END_FRACTION of its final level: there the fit of a
flat stretch is the measurement's error (white noise, and level shifts that last minutes: 0.01-0.015 g on the
simulated bench, 2-3 % of a 0.6 g print), which would shorten the delay asked or add a
pause and a last pulse at the end. The start found is late, and the end early, by the time the release takes to
cover that level (5 % of its span for a constant rate)."""
SMOOTH_FRACTION = 0.05
"""After its start, a measured target is the moving average of its monotone fit over this fraction of the release's
span: a monotone fit turns each dip of the measurement (its error, about 1 % of a sub-gram print on the simulated
bench) into a flat step, which the two-material design would read as a pause to build a barrier layer for."""
MEASURED_JSON = "measured_target.json"
"""The design folder's record of a measured target: the calibration, the curve and what was changed."""
PHYSICAL_CSV, PHYSICAL_JSON = "curves_physical.csv", "physical.json"


def barrier_speed_of(simcal: SimCalFile) -> tuple[float, float]:
    """The calibration's barrier speed and its standard error.

    Raises
    ------
    UsageError
        For a calibration made without coated prints.
    """
    if simcal.barrier is None:
        raise UsageError(f"--barrier-speed without a number takes the calibration's barrier speed, and {simcal.path} has "
                         "none: calibrate with coated prints (a barrier_mesh column in the set file) or give the speed")
    return float(simcal.barrier["speed"]), float(simcal.barrier["error"])


def write_barrier_target(curve: PhysicalCurve, simcal: SimCalFile, out_csv: Path) -> dict:
    """Write a measured curve as a ``tau_mm,released_mm3`` two-material target (module docstring); return its notes.

    Raises
    ------
    SimCalError
        Fewer than 2 samples after the calibration's wetting lag.
    """
    t, measured, fitted = after_lag(curve, simcal)
    noise = noise_sd(measured[1:])
    floor = fitted < max(NOISE_FLOOR * noise, START_FRACTION * fitted[-1])
    fitted[floor] = 0.0
    fitted[fitted > (1.0 - END_FRACTION) * fitted[-1]] = fitted[-1]     # the end, as the start, within the error
    fitted = _smoothed(t, fitted, int(np.count_nonzero(floor)))
    water = curve.water_g or simcal.water_g
    tau, vol = simcal.cal.to_simulation(t, fitted, water)
    rows = "tau_mm,released_mm3,t_s,target_g\n" + "".join(
        f"{a:.7f},{b:.6f},{c:.3f},{d:.7f}\n" for a, b, c, d in zip(tau, vol, t, fitted))
    atomic_write(Path(out_csv), rows.encode())
    return {"source": str(curve.source), "water_g": water, "noise_g": noise,
            "zeroed_until_s": float(t[floor][-1]) if floor.any() else None,
            "fit_max_g": float(np.max(np.abs(fitted - measured))),
            "t_s": t.tolist(), "measured_g": measured.tolist(), "target_g": fitted.tolist()}


def _smoothed(t: np.ndarray, fitted: np.ndarray, start: int) -> np.ndarray:
    """``fitted`` from sample ``start`` on, averaged over `SMOOTH_FRACTION` of the span after it (monotone stays
    monotone; the samples at the ends average what they have)."""
    span = t[-1] - t[min(start, t.size - 1)]
    half = 0.5 * SMOOTH_FRACTION * span
    out = fitted.copy()
    for i in range(start, t.size):
        window = (t >= t[i] - half) & (t <= t[i] + half) & (np.arange(t.size) >= start)
        out[i] = float(np.mean(fitted[window]))
    return out


def design_barrier_measured(settings: TwoMaterialSettings, out: str | Path, simcal: SimCalFile, *,
                            bench_calibration=None, speed_source: str = "given", reference: bool = True,
                            on_iteration=None, should_stop=None):
    """A two-material design whose target (``settings.target``) is a measured curve; returns the design's result.

    Parameters
    ----------
    settings : TwoMaterialSettings
        With the measured curve as ``target`` and the barrier speed to design with.
    out : str or Path
    simcal : SimCalFile
        The calibration that maps the curve to simulation units (and the design back).
    bench_calibration : analysis.BenchCalibration, optional
        For a run-folder target (default: the run's own calibration).
    speed_source : str
        Where the barrier speed came from (``calibrated`` or ``given``), for ``physical.json``.

    Raises
    ------
    UsageError, SimCalError, design.DesignError
        As :func:`labapp.jobs.design_barrier.design_barrier`, and for an unreadable curve.
    """
    from labapp.jobs.design_barrier import design_barrier

    source = settings.target
    curve = curve_of(source, bench_calibration)
    out = check_out(out, FolderKind.DESIGN, [source, simcal.path])
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "target_from_measurement.csv"
        notes = write_barrier_target(curve, simcal, csv)
        result = design_barrier(dataclasses.replace(settings, target=str(csv)), out, reference=reference,
                                on_iteration=on_iteration, should_stop=should_stop)
    notes.update(simcal=str(Path(simcal.path).resolve()), measured=str(source), speed_source=speed_source)
    if simcal.barrier is not None:
        notes.update(calibrated_speed=simcal.barrier["speed"], calibrated_speed_error=simcal.barrier["error"])
    atomic_write(out / MEASURED_JSON, (json.dumps(notes, indent=2) + "\n").encode())
    write_physical(out)
    return result


def write_physical(out: str | Path) -> dict | None:
    """``curves_physical.csv`` and ``physical.json`` of a finished design from a measured target; None when the run
    in ``out`` has no measured target or has not finished.

    The print's release (the reference evaluator's, else the design grid's) is mapped to grams over seconds by the
    calibration at the measured times, with its own drug volume's mass (the calibration's density).
    """
    out = Path(out)
    if not (out / MEASURED_JSON).is_file() or not (out / "summary.json").is_file():
        return None
    notes = json.loads((out / MEASURED_JSON).read_text())
    summary = json.loads((out / "summary.json").read_text())
    simcal = load_simcal(notes["simcal"])
    data = np.genfromtxt(out / "release.csv", delimiter=",", names=True)
    column = "print_reference_mm3" if "print_reference_mm3" in data.dtype.names else "print_grid_mm3"
    t = np.asarray(notes["t_s"], float)
    measured, target = np.asarray(notes["measured_g"], float), np.asarray(notes["target_g"], float)
    designed = simcal.cal.to_physical(data["tau_mm"], data[column], t, notes["water_g"])
    rows = "t_s,measured_g,target_g,design_released_g\n" + "".join(
        f"{a:.3f},{b:.7f},{c:.7f},{d:.7f}\n" for a, b, c, d in zip(t, measured, target, designed))
    atomic_write(out / PHYSICAL_CSV, rows.encode())
    scale = float(np.max(measured))
    physical = {"rel_rmse_physical": float(np.sqrt(np.mean((designed - measured) ** 2)) / scale),
                "rel_rmse_target": float(np.sqrt(np.mean((designed - target) ** 2)) / scale),
                "release_from": column, "print_mass_g": float(summary["drug"]["volume_mm3"] * simcal.cal.g_per_mm3),
                "barrier_speed": summary["barrier_speed"], "speed_source": notes["speed_source"],
                "calibrated_speed": notes.get("calibrated_speed"),
                "calibrated_speed_error": notes.get("calibrated_speed_error"), "simcal": notes["simcal"]}
    atomic_write(out / PHYSICAL_JSON, (json.dumps(physical, indent=2) + "\n").encode())
    return physical
