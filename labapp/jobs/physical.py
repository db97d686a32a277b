"""Physical curves into and out of the simulator through a simulation calibration (``simcal.json``).

- a measured curve (grams over seconds) becomes an inverse-design target in simulation units
  (:func:`write_target_csv`), made feasible: a monotone least-squares fit projected onto the isoperimetric bound;
- a simulated release becomes ``release_physical.csv`` (:func:`write_release_physical`);
- a finished design gets ``curves_physical.csv``, ``rel_rmse_physical`` and a report in grams over hours
  (:func:`write_design_physical`).

There is no other bridge: without a calibration, a physical curve cannot become a target.
"""
from __future__ import annotations

import csv
import dataclasses
import json
import logging
import os
from pathlib import Path

import numpy as np

from design.files.records import load_summary
from design.files.rundir import finished_run, run_design
from design.inverse.targets import ISO_TOLERANCE, isotonic_fit, project_isoperimetric, resample_monotone
from labapp.jobs import bands
from labapp.jobs.compare import prediction_metrics
from labapp.records import operators
from labapp.records.audit import Action
from labapp.records.audit import append as audit
from labapp.records.curvefiles import CURVE_FILES, PhysicalCurve
from labapp.records.fileio import atomic_write
from labapp.records.simcal import SimCalError, SimCalFile, curve_of

log = logging.getLogger(__name__)

TARGET_CSV = "target_from_measurement.csv"
"""The simulation-units target a physical curve becomes, written into the design folder."""
_PREDICTION_SAMPLES = 600


def is_physical(spec: str | Path) -> bool:
    """Whether a design target names a physical curve: a run or curve folder, or a CSV with ``t_s``."""
    path = Path(spec)
    if path.is_dir():
        return (path / "frames.csv").is_file() or any((path / n).is_file() for n in CURVE_FILES)
    if path.suffix.lower() != ".csv" or not path.is_file():
        return False
    try:
        with open(path, newline="") as fh:
            header = [h.strip() for h in next(csv.reader(fh), [])]
    except (OSError, UnicodeDecodeError):
        return False
    return "t_s" in header


@dataclasses.dataclass(frozen=True)
class MeasuredTarget:
    """A measured curve written as a design target (:func:`write_target_csv`), and what was changed to make it
    one: grams are of released solid; percentages are of ``mass_g``.

    Attributes
    ----------
    csv : Path
        The target CSV; beside it ``<stem>.json`` holds these notes.
    mass_g : float
        The object's weighed mass, else the curve's final (fitted) release, g: the base of the percentages.
    mass_basis : str
        ``weighed`` or ``final release``.
    noise_g : float
        The measurement's noise, g (standard deviation, robust, from its second differences).
    fit_max_g : float
        Largest change by the monotone least-squares fit, g.
    projection_max_g : float
        Largest lowering by the projection onto the isoperimetric bound, g.
    points_lowered : int
        Samples the projection moved.
    """

    csv: Path
    mass_g: float
    mass_basis: str
    noise_g: float
    fit_max_g: float
    projection_max_g: float
    points_lowered: int

    def pct(self, grams: float) -> float:
        """``grams`` in % of :attr:`mass_g`."""
        return 100.0 * grams / self.mass_g if self.mass_g > 0 else float("nan")

    def text(self) -> str:
        """What was changed, one clause (logs, ``<stem>.json``); :func:`adjustment_line` is the sentence shown."""
        return (f"measured target adjusted to a feasible curve: monotone least-squares fit (changes up to "
                f"{self.pct(self.fit_max_g):.2f} % of the {self.mass_basis} mass {self.mass_g:.4g} g), then "
                f"{self.points_lowered} points lowered onto the isoperimetric bound (up to "
                f"{self.pct(self.projection_max_g):.2f} %); the measurement's noise is "
                f"{_about_pct(self.pct(self.noise_g))}")

    def notes(self) -> dict:
        """The record written beside the CSV."""
        return {"method": "isotonic (monotone least-squares) fit of the released grams, then projection onto "
                          f"the isoperimetric bound relaxed by {TARGET_SLACK:g} (design.inverse.targets."
                          "project_isoperimetric); columns t_s, measured_g, target_g give both curves",
                "mass_g": self.mass_g, "mass_basis": self.mass_basis,
                "noise_g": self.noise_g, "noise_pct": self.pct(self.noise_g),
                "fit_max_g": self.fit_max_g, "fit_max_pct": self.pct(self.fit_max_g),
                "projection_max_g": self.projection_max_g, "projection_max_pct": self.pct(self.projection_max_g),
                "points_lowered": self.points_lowered, "text": self.text()}


def _about_pct(value: float) -> str:
    """A small percentage in words: "about 0.37 %", "below 0.01 %" (never "about 0.00 %")."""
    return "below 0.01 %" if 0 <= value < 0.01 else f"about {value:.2g} %" if value < 1 else f"about {value:.3g} %"


def adjustment_line(target: MeasuredTarget) -> str:
    """The sentence `sfr design` prints and the design launcher shows for a measured target: how much making
    it feasible changed it (:meth:`MeasuredTarget.text`, as a sentence)."""
    text = target.text()
    return f"{text[:1].upper()}{text[1:]}."


def read_measured_target(csv_path: str | Path) -> MeasuredTarget | None:
    """The notes :func:`write_target_csv` left beside ``csv_path`` (``<stem>.json``); None when there are none
    (the target was not a measured curve).

    Raises
    ------
    SimCalError
        When the notes exist but are not readable or lack a field.
    """
    path = Path(csv_path).with_suffix(".json")
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text())
        return MeasuredTarget(Path(csv_path), float(doc["mass_g"]), str(doc["mass_basis"]), float(doc["noise_g"]),
                              float(doc["fit_max_g"]), float(doc["projection_max_g"]), int(doc["points_lowered"]))
    except (OSError, ValueError, TypeError, KeyError) as exc:
        raise SimCalError(f"{path}: not the notes of a measured target ({type(exc).__name__}: {exc}); expected "
                          "mass_g, mass_basis, noise_g, fit_max_g, projection_max_g, points_lowered") from exc


END_SAMPLES = 5
"""The last samples of a measured curve are fitted as one level (their mean), not as the highest of them."""
REFINE = 8
"""A measured target is written on a tau grid this many times finer than its samples."""
TARGET_SLACK = 0.5 * ISO_TOLERANCE
"""A measured target is projected onto the isoperimetric bound relaxed by half the feasibility check's slack:
the other half is the margin for its resampling onto the design grid."""


def noise_sd(values: np.ndarray) -> float:
    """Standard deviation of white noise on a smooth sampled curve: 1.4826 MAD of the second differences over
    sqrt(6) (a second difference of white noise has variance 6 sigma^2; the curve's own curvature is small)."""
    d2 = np.diff(np.asarray(values, float), 2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0)) if d2.size else 0.0


def after_lag(curve: PhysicalCurve, simcal: SimCalFile) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A measured curve from the end of the calibration's wetting lag, where the model's clock starts: ``(t_s,
    measured_g, fitted_g)`` starting at (lag, 0), ``fitted_g`` the monotone least-squares fit of the grams
    (:func:`design.inverse.targets.isotonic_fit`, the last `END_SAMPLES` as one level).

    Raises
    ------
    SimCalError
        Fewer than 2 samples after the lag.
    """
    lag = simcal.cal.lag_s
    t = np.asarray(curve.t_s, float)
    keep = t > lag
    if np.count_nonzero(keep) < 2:
        raise SimCalError(f"{curve.source}: fewer than 2 samples after the calibration's wetting lag of {lag:.0f} s; "
                          "a design target needs the measured release")
    t = np.concatenate([[lag], t[keep]])
    measured = np.concatenate([[0.0], np.asarray(curve.released_g, float)[keep]])
    return t, measured, np.concatenate([[0.0], np.clip(isotonic_fit(measured[1:], END_SAMPLES), 0.0, None)])


def write_target_csv(curve: PhysicalCurve, simcal: SimCalFile, out_csv: Path) -> MeasuredTarget:
    """Write a measured curve as a feasible ``tau_mm,released_mm3`` target through the calibration.

    The curve is taken from the end of the calibration's wetting lag on (t >= lag, 0 without one) and starts at
    (lag, 0), where the model's clock starts (tau = 0); its released grams are replaced by their
    monotone least-squares fit (:func:`design.inverse.targets.isotonic_fit`), mapped to simulation units (water:
    the run's own when it records one, else the calibration's), and lowered where needed onto the isoperimetric
    bound the feasibility check applies (:func:`design.inverse.targets.project_isoperimetric`), so that noise
    does not make the target infeasible. The CSV also lists ``t_s``, ``measured_g`` and ``target_g``, and
    ``<stem>.json`` beside it says how much was changed.
    """
    # the model's clock starts when the calibrated wetting lag ends: the simulated print's release is compared with
    # the measured curve delayed by the lag (what the bench measures before it is nothing a design can shape)
    t, measured, fitted = after_lag(curve, simcal)
    water = curve.water_g or simcal.water_g
    tau_knots, vol_knots = simcal.cal.to_simulation(t, fitted, water)
    # the monotone fit between the samples as the design reads a curve (PCHIP), on a grid REFINE times finer,
    # projected there: the design's own resampling of the result then averages over several fine intervals
    tau = np.linspace(0.0, tau_knots[-1], REFINE * (tau_knots.size - 1) + 1)
    vol = resample_monotone(tau_knots, vol_knots, tau)
    adjusted = project_isoperimetric(tau, vol, TARGET_SLACK)
    grams = adjusted * simcal.cal.g_per_mm3
    t_fine = np.interp(tau, tau_knots, t)
    at_knots = np.interp(t, t_fine, grams)
    weighed = curve.object_mass_g is not None and curve.object_mass_g > 0
    result = MeasuredTarget(Path(out_csv), float(curve.object_mass_g if weighed else fitted[-1]),
                            "weighed" if weighed else "final release", noise_sd(measured[1:]),
                            float(np.max(np.abs(fitted - measured))), float(np.max(fitted - at_knots)),
                            int(np.count_nonzero(at_knots < fitted - 1e-12 * max(fitted[-1], 1e-300))))
    rows = "tau_mm,released_mm3,t_s,target_g\n" + "".join(
        f"{a:.7f},{b:.6f},{c:.3f},{d:.7f}\n" for a, b, c, d in zip(tau, adjusted, t_fine, grams))
    atomic_write(Path(out_csv), rows.encode())
    atomic_write(Path(out_csv).with_suffix(".json"), (json.dumps(result.notes(), indent=2) + "\n").encode())
    log.info("target %s from %s: %d points, %.1f mm^3 over %.3f mm; %s", out_csv, curve.source, len(tau),
             adjusted[-1], tau[-1], result.text())
    return result


def physical_times(simcal: SimCalFile, tau_mm: np.ndarray, released_mm3: np.ndarray, water_g: float) -> np.ndarray:
    """Uniform times from 0 to when the simulated curve ends (its full dissolution, after the wetting lag), s."""
    end = simcal.cal.clock_s(tau_mm, np.asarray(released_mm3, float) * simcal.cal.g_per_mm3, water_g)[-1] \
        + simcal.cal.lag_s
    return np.linspace(0.0, end, _PREDICTION_SAMPLES)


def write_release_physical(tau_mm: np.ndarray, released_mm3: np.ndarray, simcal: SimCalFile, out_dir: Path,
                           water_g: float | None = None, title: str = "", simulate_at=None) -> Path:
    """``release_physical.csv`` (``t_s,released_g,conc_g_per_kg``, and the band's ``released_g_q05,released_g_q95``
    when the calibration stores one: :mod:`labapp.jobs.bands`) and ``release_physical.png``.

    Parameters
    ----------
    tau_mm, released_mm3 : (K,) ndarray of float
        A simulated release.
    simcal : SimCalFile
    out_dir : Path
    water_g : float, optional
        Bath water, g (default: the calibration's).
    simulate_at : callable, optional
        ``simulate_at(physics) -> (tau_mm, released_mm3)``: the band's print physics spread
        (:func:`labapp.jobs.bands.source_simulator`).
    """
    water = water_g or simcal.water_g
    t = physical_times(simcal, tau_mm, released_mm3, water)
    grams = simcal.cal.to_physical(tau_mm, released_mm3, t, water)
    band = bands.prediction_band(simcal, tau_mm, released_mm3, t, water, simulate_at)
    lo, hi = bands.quantile_columns()
    rows = ("t_s,released_g,conc_g_per_kg" + ("" if band is None else f",released_g_{lo},released_g_{hi}") + "\n"
            + "".join(f"{a:.2f},{b:.6f},{b / water * 1000.0:.6f}" + ("" if band is None else
                      f",{band[0][i]:.6f},{band[1][i]:.6f}") + "\n" for i, (a, b) in enumerate(zip(t, grams))))
    path = Path(out_dir) / "release_physical.csv"
    atomic_write(path, rows.encode())
    plot_physical(path.with_suffix(".png"), [(t, grams, "predicted release", "-")],
                   f"predicted release {title}\n{simcal.describe()}", band=bands.band_series(t, band))
    return path


def plot_physical(path: Path, series: list[tuple[np.ndarray, np.ndarray, str, str]], title: str,
                  band: tuple[np.ndarray, np.ndarray, np.ndarray, str] | None = None) -> None:
    """Draw released grams over hours: ``series`` of (t_s, g, label, line style), and an optional shaded
    ``band`` (t_s, low g, high g, label)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=110)
    if band is not None:
        t, low, high, label = band
        ax.fill_between(np.asarray(t) / 3600.0, low, high, color="C2", alpha=0.25, label=label)
    for t, g, label, style in series:
        ax.plot(np.asarray(t) / 3600.0, g, style, lw=1.8, label=label)
    ax.set_xlabel("time since drop (h)")
    ax.set_ylabel("released (g)")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def write_design_physical(design_dir: Path, simcal: SimCalFile, target: PhysicalCurve | None = None) -> dict:
    """The physical prediction of a finished design: ``curves_physical.csv``, summary fields, ``report.png``.

    ``curves_physical.csv`` has ``t_s,target_released_g,design_released_g``: the measured target at its own
    times (or the simulated target mapped through the calibration), and the print's predicted release
    (``print_mm3``: design.stl by exact surface distances; a design recorded before it, its binary solid on
    the design grid; mass from ``g_per_mm3``). ``summary.json`` gains ``rel_rmse_physical`` (RMS of the
    difference over the target's final grams), ``print_mass_g`` at the calibrated density, ``simcal`` and
    ``release_metrics`` (MDT, DE and model fits of design and target, f2 of the design against the target);
    the simulation-units report is kept as ``report_simulation.png`` and ``report.png`` shows grams over
    hours.

    Returns
    -------
    dict
        The updated summary.

    Raises
    ------
    SimCalError
        If the design folder has no ``curves.csv`` or ``summary.json``.
    """
    design_dir = Path(design_dir)
    try:
        data = np.genfromtxt(design_dir / "curves.csv", delimiter=",", names=True)
        summary = load_summary(design_dir)
    except (OSError, ValueError) as exc:
        raise SimCalError(f"{design_dir}: no finished design to predict ({exc})") from exc
    achieved = "print_mm3" if "print_mm3" in data.dtype.names else "binary_mm3"
    tau, binary = np.asarray(data["tau_mm"], float), np.asarray(data[achieved], float)
    water = (target.water_g if target is not None else None) or simcal.water_g
    cal = simcal.cal
    if target is not None:
        t, target_g = target.t_s[target.t_s >= 0], target.released_g[target.t_s >= 0]
    else:
        target_mm3 = np.asarray(data["target_mm3"], float)
        t = physical_times(simcal, tau, target_mm3, water)
        target_g = cal.to_physical(tau, target_mm3, t, water)
    design_g = cal.to_physical(tau, binary, t, water) if binary[-1] > 0 else np.zeros_like(t)
    band = bands.design_band(design_dir, simcal, tau, binary, t, water) if binary[-1] > 0 else None
    if band is not None:
        summary["band"] = bands.band_summary(band, target_g)
    lo, hi = bands.quantile_columns()
    rows = ("t_s,target_released_g,design_released_g" + ("" if band is None else
            f",design_released_g_{lo},design_released_g_{hi}") + "\n" + "".join(
        f"{a:.2f},{b:.6f},{c:.6f}" + ("" if band is None else f",{band[0][i]:.6f},{band[1][i]:.6f}") + "\n"
        for i, (a, b, c) in enumerate(zip(t, target_g, design_g))))
    atomic_write(design_dir / "curves_physical.csv", rows.encode())
    final = float(np.max(target_g)) if np.max(target_g) > 0 else 1.0
    summary["rel_rmse_physical"] = float(np.sqrt(np.mean((design_g - target_g) ** 2)) / final)
    summary["print_mass_g"] = float(summary.get("volume_mm3") or binary[-1]) * cal.g_per_mm3
    summary["print_mass_basis"] = f"calibrated density {cal.g_per_mm3 * 1000:.4g} g/cm^3 ({simcal.path})"
    summary["simcal"] = {"path": str(simcal.path), "model": cal.model, "seconds_per_mm": cal.seconds_per_mm,
                         "g_per_mm3": cal.g_per_mm3, "saturation_g_per_kg": cal.saturation_g_per_kg,
                         "wetting_lag_s": cal.lag_s, "water_g": water}
    summary["release_metrics"] = prediction_metrics(t, target_g, design_g)
    atomic_write(design_dir / "summary.json", (json.dumps(summary, indent=2) + "\n").encode())
    report, kept = design_dir / "report.png", design_dir / "report_simulation.png"
    if report.exists() and not kept.exists():
        os.replace(report, kept)
    label = "measured target" if target is not None else "target"
    channel = summary.get("min_channel_mm")
    plot_physical(report, [(t, target_g, label, "-"), (t, design_g, "design (printed solid, predicted)", "--")],
                   f"rel. RMSE {100 * summary['rel_rmse_physical']:.2f}% of final, print mass "
                   f"{summary['print_mass_g']:.3f} g, narrowest channel "
                   f"{'none' if channel is None else format(channel, '.2f') + ' mm'}\n{simcal.describe()}",
                   band=bands.band_series(t, band))
    return summary


def with_print_physics(config, simcal: SimCalFile):
    """The design settings with a simulation calibration's print physics: the forward model's anisotropy and
    swelling width (its shut channels, and the print's minimum open channel width) and the print offset
    (``design.stl`` is the designed solid shrunk by it). The physical correction takes its default again: on at
    the print's anisotropy, off with swelling, which its reference evaluator does not model
    (``design.inverse.config.DesignConfig``)."""
    physics = simcal.physics
    correction = None if config.physical_correction == "defect" else config.physical_correction
    return dataclasses.replace(config, anisotropy=physics["anisotropy"], print_offset_mm=physics["offset_mm"],
                               swelling_mm=physics["swelling_mm"], physical_correction=correction)


def design_from_target(config, out_dir: str | Path, *, simcal: SimCalFile | None = None, bench_calibration=None,
                       on_iteration=None, should_stop=None, resume: bool = False):
    """Run (or resume) an inverse design whose target may be a physical curve; the job behind ``sfr design``
    and the GUI's design launcher.

    Parameters
    ----------
    config : design.inverse.config.DesignConfig or None
        Its ``target`` may be a measured curve (a run folder, ``curve.csv`` or any ``t_s,released_g`` CSV):
        it then becomes ``target_from_measurement.csv`` in ``out_dir`` through ``simcal``. None to resume.
    out_dir : str or Path
        The design folder.
    simcal : SimCalFile, optional
        Required for a physical target; with any target it adds the physical prediction, and a new run designs
        for its print physics (:func:`with_print_physics`; a resume keeps the settings it started with).
    bench_calibration : analysis.BenchCalibration, optional
        For a run folder target (default: the run's own ``calibration.json``).
    on_iteration, should_stop, resume
        As in ``design.files.rundir.run_design``.

    Returns
    -------
    result : design.files.rundir.DesignResult
    summary : dict or None
        The summary with the physical prediction (None without ``simcal``).

    Raises
    ------
    SimCalError
        A physical target without a calibration, or an unreadable target.
    """
    out_dir = Path(out_dir)
    if resume:  # a run that finished with all its outputs: nothing to do, nothing written
        done = finished_run(out_dir, config)
        if done is not None and (simcal is None or "simcal" in done.outputs.summary):
            return done, done.outputs.summary if simcal is not None else None
    operator = operators.require(f"designing into {out_dir}")
    if simcal is not None and config is not None and not resume:
        config = with_print_physics(config, simcal)
    record = out_dir / "target_measured.json"
    measured: PhysicalCurve | None = None
    if config is not None and is_physical(config.target):
        if simcal is None:
            raise SimCalError(f"target {config.target} is a physical curve (grams over seconds): give the "
                              "simulation calibration (--simcal simcal.json, made by sfr calibrate-sim) that maps "
                              "it to simulation units")
        if (out_dir / "config.json").exists() and not resume:
            raise SimCalError(f"{out_dir} already holds a design run; resume it or choose another folder")
        measured = curve_of(config.target, bench_calibration)
        out_dir.mkdir(parents=True, exist_ok=True)
        target = write_target_csv(measured, simcal, out_dir / TARGET_CSV)
        _write_measured(record, measured)
        config = dataclasses.replace(config, target=str(target.csv.resolve()))
    elif resume and record.is_file():
        measured = _read_measured(record)
    out_dir.mkdir(parents=True, exist_ok=True)
    audit(out_dir, Action.RESUME if resume else Action.DESIGN,
          "design resumed" if resume else f"design started: target {config.target}, space {config.space}, "
          f"resolution {config.resolution}", operator=operator)
    result = run_design(config, out_dir, on_iteration=on_iteration, should_stop=should_stop, resume=resume)
    summary = None
    if simcal is not None:  # written last; a run whose outputs lack it (cut short) gets it now
        summary = (result.outputs.summary if result.unchanged and "simcal" in result.outputs.summary
                   else write_design_physical(result.out_dir, simcal, measured))
    _name_operator(result.out_dir, operator)
    audit(out_dir, Action.DESIGN_END, f"design {result.status}", operator=operator)
    return result, summary


def _name_operator(design_dir: Path, operator: str) -> None:
    """Add ``operator`` (who ran the design) to the design's ``summary.json``, when it has one."""
    path = design_dir / "summary.json"
    if path.is_file():
        summary = json.loads(path.read_text())
        if summary.get("operator") == operator:
            return
        summary["operator"] = operator
        atomic_write(path, (json.dumps(summary, indent=2) + "\n").encode())


def _write_measured(path: Path, curve: PhysicalCurve) -> None:
    doc = {"source": curve.source, "water_g": curve.water_g, "object_mass_g": curve.object_mass_g,
           "t_s": [float(v) for v in curve.t_s], "released_g": [float(v) for v in curve.released_g]}
    atomic_write(path, json.dumps(doc).encode())


def _read_measured(path: Path) -> PhysicalCurve:
    doc = json.loads(path.read_text())
    return PhysicalCurve(np.asarray(doc["t_s"], float), np.asarray(doc["released_g"], float),
                         doc.get("object_mass_g"), doc.get("water_g"), doc["source"])


def predict_mesh(mesh: str | Path, simcal: SimCalFile, water_g: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A mesh's predicted release in physical units: simulated at the calibration's resolution with its print
    physics (anisotropy, surface offset, swelling width) at the print's exact volume, corrected for the grid's bias
    against the reference evaluator as the calibration's releases were (:func:`labapp.jobs.bands.source_simulator`),
    mapped.

    Parameters
    ----------
    mesh : str or Path
        Mesh file (mm) or ``sample:NAME``.
    simcal : SimCalFile
    water_g : float, optional
        Bath water, g (default: the calibration's).

    Returns
    -------
    t_s, released_g : (Q,) ndarray of float
    """
    tau, vol = bands.source_simulator(str(mesh), simcal.resolution, method=simcal.release_method)(simcal.physics)
    water = water_g or simcal.water_g
    t = physical_times(simcal, tau, vol, water)
    return t, simcal.cal.to_physical(tau, vol, t, water)


def predict_mesh_band(mesh: str | Path, simcal: SimCalFile, water_g: float | None = None
                      ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
    """:func:`predict_mesh` with the prediction's band (:func:`labapp.jobs.bands.prediction_band`; None for a
    calibration file without one): the GUI's overlays and the demo's picture."""
    simulate_at = bands.source_simulator(str(mesh), simcal.resolution, method=simcal.release_method)
    tau, vol = simulate_at(simcal.physics)
    water = water_g or simcal.water_g
    t = physical_times(simcal, tau, vol, water)
    return t, simcal.cal.to_physical(tau, vol, t, water), bands.prediction_band(simcal, tau, vol, t, water, simulate_at)
