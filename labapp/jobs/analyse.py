"""Analyse a run: a run folder or a plain image folder to its release curve (`sfr analyze RUN`)."""
from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from analysis import BenchCalibration, RunCurve, analyze_run, write_cells_csv, write_curve_csv
from analysis.curve import DEFAULT_ORDER, DEFAULT_WINDOW_S
from labapp.errors import UsageError
from labapp.figures.release_plot import draw_release
from labapp.jobs.compare import release_summary
from labapp.records import operators
from labapp.records.audit import Action
from labapp.records.audit import append as audit
from labapp.records.fileio import atomic_path, atomic_write
from labapp.records.lock import folder_lock
from labapp.records.outpaths import ANALYSIS_SUBFOLDER, FolderKind, OutPathError, check_out

RUN_CALIBRATION = "calibration.json"
"""A run's own bench calibration, used when none is given (as ``sfr design`` and ``sfr compare`` do)."""


@dataclass(frozen=True)
class AnalysisOutputs:
    """What :func:`analyse_run` wrote: the curve and the files."""

    curve: RunCurve
    out: Path
    files: tuple[Path, ...]


def run_calibration(run: str | Path, calibration: str | Path | None) -> Path:
    """The bench calibration to analyse ``run`` with: ``calibration`` if given, else the run's own.

    Raises
    ------
    UsageError
        When none is given and the run holds no ``calibration.json``.
    """
    if calibration is not None:
        return Path(calibration)
    own = Path(run) / RUN_CALIBRATION
    if not own.is_file():
        raise UsageError(f"{run} holds no {RUN_CALIBRATION} of its own; give the bench calibration with "
                         "--calibration CAL.json (made by sfr calibrate-bench)")
    return own


def _check_out(out: Path, inputs: list, run: Path) -> Path:
    """`check_out` for the analysis folder of ``run``, naming a source package (``analysis/`` of a checkout) as such."""
    try:
        checked = check_out(out, FolderKind.ANALYSIS, inputs, analysed=run, replace=True)   # its cell cache reused
    except OutPathError:
        if (Path(out) / "__init__.py").is_file():
            raise OutPathError(f"--out {Path(out).resolve()} is a Python package of the software (it holds "
                               "__init__.py), not an output folder; leave --out out to write RUN/analysis, or "
                               "give a new folder name") from None
        raise
    other = _analysed_run(checked)
    if other is not None and other.resolve() != run.resolve() and other.name != run.name:
        raise OutPathError(f"--out {checked} holds the analysis of {other}, another run; its results are never "
                           "overwritten: choose a new folder")
    return checked


def _analysed_run(folder: Path) -> Path | None:
    """The run whose analysis ``folder`` holds (its ``summary.json``), None when it holds none."""
    try:
        return Path(json.loads((folder / "summary.json").read_text())["run"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def writes_into_record(run: str | Path, out: str | Path | None = None) -> bool:
    """Whether analysing ``run`` into ``out`` (default ``RUN/analysis``) writes into a recorded run's folder: the
    analysis is then audited (``reanalyse``, with the reason given) and needs an operator."""
    run = Path(run)
    out = Path(out) if out is not None else run / ANALYSIS_SUBFOLDER
    return (run / "run.json").is_file() and run.resolve() in out.resolve().parents


def analyse_run(run: str | Path, calibration: str | Path | None = None, out: str | Path | None = None, *,
                interval_s: float | None = None, water_g: float | None = None, window_s: float | None = None,
                order: int | None = None, workers: int | None = None, reduce: int | None = None,
                plot: bool = True, progress: Callable[[int, int], None] | None = None,
                reason: str | None = None) -> AnalysisOutputs:
    """Analyse a run folder or a plain image folder into ``curve.csv``, ``cells.csv``, ``summary.json`` (with
    MDT, DE and the ranked model fits of the release) and ``curve.png``.

    Parameters
    ----------
    run : path
        Run folder or plain image folder.
    calibration : path, optional
        Bench calibration JSON (default: the run's own ``calibration.json``, :func:`run_calibration`).
    out : path, optional
        Output folder (default ``RUN/analysis``); it also holds the cell cache.
    window_s, order : optional
        Savitzky-Golay window (s) and order (defaults: ``analysis.curve.DEFAULT_WINDOW_S``/``DEFAULT_ORDER``).
    reason : str, optional
        Why a recorded run is analysed again (its audit trail's ``reanalyse`` entry says it).
    progress : callable, optional
        ``progress(done, total)`` frames; it may raise ``KeyboardInterrupt`` to stop after a frame (the frames
        analysed so far stay in the cell cache of ``out``, no other output is written).

    Raises
    ------
    UsageError
        For an ``--out`` that would overwrite something or is being written by another command, or a run
        without a calibration of its own when none is given.
    analysis.AnalysisError
        For unreadable frames, manifests or calibrations (the message names them).
    """
    run = Path(run)
    default_out = run / ANALYSIS_SUBFOLDER
    out = Path(out) if out is not None else default_out
    into_record = writes_into_record(run, out)
    operator = operators.require(f"analysing {run} into its record") if into_record else None
    calibration = run_calibration(run, calibration)
    inputs = [calibration] if out.resolve() == default_out.resolve() else [calibration, run]
    out = _check_out(out, inputs, run)
    cal = BenchCalibration.load(calibration)
    with folder_lock(out):
        curve = analyze_run(run, cal, interval_s=interval_s, workers=workers, progress=progress, reduce=reduce,
                            cache_dir=out, water_g=water_g,
                            window_s=DEFAULT_WINDOW_S if window_s is None else window_s,
                            order=DEFAULT_ORDER if order is None else order)
        files = [out / "curve.csv", out / "cells.csv", out / "summary.json"]
        for path, write in ((files[0], write_curve_csv), (files[1], write_cells_csv)):
            with atomic_path(path) as tmp:      # a full disk leaves the file as it was, no partial one
                write(curve, tmp)
        atomic_write(files[2], (json.dumps(_analysis_summary(curve, run), indent=2) + "\n").encode())
        if plot:
            files.append(out / "curve.png")
            with atomic_path(files[-1]) as tmp:
                _plot_curve(curve, tmp)
    if into_record:
        audit(run, Action.REANALYSE, f"analysed {len(curve.files)} frames into {out.relative_to(run.resolve())} with "
              f"calibration {Path(calibration).name}", operator=operator, reason=reason)
    return AnalysisOutputs(curve, out, tuple(files))


def _analysis_summary(curve: RunCurve, run: Path) -> dict[str, Any]:
    """``summary.json`` of an analysis: the run's totals and its release metrics (MDT, DE, model fits)."""
    return {"run": str(run), "frames": len(curve.files), "duration_s": float(curve.t_s[-1] - curve.t_s[0]),
            "water_g": curve.water_g, "object_mass_g": curve.object_mass_g,
            "final_released_g": float(curve.released_g[-1]),
            "release": release_summary(curve.t_s, curve.released_g, curve.object_mass_g, str(run))}


def _plot_curve(curve: RunCurve, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4), dpi=120)
    draw_release(ax, curve)
    ax.set_xlabel("time (min)")
    ax.legend(loc="lower right")
    ax.set_title("release curve (linearised sRGB, mirror-normalised)")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
