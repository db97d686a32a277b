"""The jobs of the bench application, one function each, called by the `sfr` commands and the GUI alike.

============================  ==========================================  ======================
job                           function                                    `sfr` command
============================  ==========================================  ======================
analyse a run                 :func:`analyse_run`                         ``analyze``
calibrate a series            :func:`calibrate_series`                    ``calibrate-bench``
simulate                      :func:`simulate`                            ``simulate``
design                        :func:`design`                              ``design``
start a run                   :func:`new_run`                             ``run``
resume an interrupted run     :func:`resume_run`                          ``run --resume``
verify a folder               :func:`verify`                              ``verify``
calibrate the simulation      :func:`calibrate_sim` (``labapp.simcal``)    ``calibrate-sim``
sweep design settings         :func:`run_sweep` (``labapp.sweep``)          ``sweep``
analyse many runs             :func:`analyse_many` (``labapp.batch``)       ``analyze RUN...``
Monte Carlo simulation        :func:`simulate_mc_job` (``labapp.mcsim``)    ``simulate --model mc``
============================  ==========================================  ======================

Each job checks its output path (:mod:`labapp.outpaths`) and its inputs before any work, raises
:class:`labapp.errors.UsageError` (or the package's own error) for bad input, and reports progress
through a plain callable. An acquisition (new or resumed run) is a procedure the engine walks; the job
builds and checks it, the caller walks it with :class:`labapp.engine.Engine`.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from labapp.errors import UsageError
from labapp.outpaths import ANALYSIS_SUBFOLDER, check_data_dir, check_out

log = logging.getLogger(__name__)

__all__ = ["AnalysisOutputs", "DESIGN_DEFAULTS", "SimulationOutputs", "TARGET_SOURCE", "analyse_many", "analyse_run",
           "calibrate_series", "calibrate_sim", "design", "design_folder", "new_run", "resume_run", "run_sweep",
           "simulate", "simulate_mc_job", "simulation_grid", "verify"]


# -- analyse a run -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class AnalysisOutputs:
    """What :func:`analyse_run` wrote: the curve (an ``analysis.RunCurve``) and the files."""

    curve: Any
    out: Path
    files: tuple[Path, ...]


def analyse_run(run: str | Path, calibration: str | Path, out: str | Path | None = None, *,
                interval_s: float | None = None, water_g: float | None = None, window_s: float | None = None,
                order: int | None = None, workers: int | None = None, reduce: int | None = None,
                plot: bool = True, progress: Callable[[int, int], None] | None = None) -> AnalysisOutputs:
    """Analyse a run folder or a plain image folder into ``curve.csv``, ``cells.csv``, ``summary.json`` (with
    MDT, DE and the ranked model fits of the release) and ``curve.png``.

    Parameters
    ----------
    run : path
        Run folder or plain image folder.
    calibration : path
        Bench calibration JSON.
    out : path, optional
        Output folder (default ``RUN/analysis``); it also holds the cell cache.
    window_s, order : optional
        Savitzky-Golay window (s) and order (defaults: ``analysis.curve.DEFAULT_WINDOW_S``/``DEFAULT_ORDER``).
    progress : callable, optional
        ``progress(done, total)`` frames.

    Raises
    ------
    UsageError
        For an ``--out`` that would overwrite something.
    analysis.AnalysisError
        For unreadable frames, manifests or calibrations (the message names them).
    """
    from analysis import BenchCalibration, analyze_run, write_cells_csv, write_curve_csv
    from analysis.curve import DEFAULT_ORDER, DEFAULT_WINDOW_S

    run = Path(run)
    default_out = run / ANALYSIS_SUBFOLDER
    out = Path(out) if out is not None else default_out
    inputs = [calibration] if out.resolve() == default_out.resolve() else [calibration, run]
    out = check_out(out, "analysis", inputs)
    cal = BenchCalibration.load(calibration)
    out.mkdir(parents=True, exist_ok=True)
    curve = analyze_run(run, cal, interval_s=interval_s, workers=workers, progress=progress, reduce=reduce,
                        cache_dir=out, water_g=water_g,
                        window_s=DEFAULT_WINDOW_S if window_s is None else window_s,
                        order=DEFAULT_ORDER if order is None else order)
    files = [out / "curve.csv", out / "cells.csv", out / "summary.json"]
    write_curve_csv(curve, files[0])
    write_cells_csv(curve, files[1])
    files[2].write_text(json.dumps(_analysis_summary(curve, run), indent=2) + "\n")
    if plot:
        files.append(out / "curve.png")
        _plot_curve(curve, files[-1])
    return AnalysisOutputs(curve, out, tuple(files))


def _analysis_summary(curve, run: Path) -> dict[str, Any]:
    """``summary.json`` of an analysis: the run's totals and its release metrics (MDT, DE, model fits)."""
    from labapp.compare import release_summary

    return {"run": str(run), "frames": len(curve.files), "duration_s": float(curve.t_s[-1] - curve.t_s[0]),
            "water_g": curve.water_g, "object_mass_g": curve.object_mass_g,
            "final_released_g": float(curve.released_g[-1]),
            "release": release_summary(curve.t_s, curve.released_g, curve.object_mass_g, str(run))}


def _plot_curve(curve, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from labapp.release_plot import draw_release

    fig, ax = plt.subplots(figsize=(7, 4), dpi=120)
    draw_release(ax, curve)
    ax.set_xlabel("time (min)")
    ax.legend(loc="lower right")
    ax.set_title("release curve (linearised sRGB, mirror-normalised)")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# -- calibrate a series --------------------------------------------------------------------------------
def calibrate_series(folder: str | Path, out: str | Path, *, water_g: float = 500.0,
                     crop: tuple[int, int, int] | None = None, grid: int = 10, mirror_col: float | None = None,
                     mirror: bool = True, reduce: int = 1, camera: dict[str, str] | None = None):
    """Fit the bench calibration of a series folder (images + ``masses.csv``) and save it to ``out``.

    ``crop`` (x, y, size px) defaults to the series' recorded crop (``run.json``), else
    ``analysis.default_geometry``. Returns the ``analysis.BenchCalibration``.

    Raises
    ------
    UsageError
        For an ``out`` that exists, is an input or lies inside a record, a malformed ``masses.csv``
        (named row and field), or a recorded crop that cannot be read.
    analysis.AnalysisError
        For unreadable images or a fit that is not possible.
    """
    from analysis import CropGeometry, default_geometry
    from labapp.calseries import MASSES_CSV, _image_shape, fit_series, read_masses

    folder = Path(folder)
    if not folder.is_dir():
        raise UsageError(f"{folder} is not a folder; give the calibration-series folder holding {MASSES_CSV}")
    out = check_out(out, "calibration", [folder / MASSES_CSV], file=True)
    if not water_g > 0:
        raise UsageError(f"water mass {water_g} g: expected > 0 g")
    files, masses = read_masses(folder)
    crop = crop or _recorded_crop(folder)
    if crop:
        geometry = CropGeometry(*crop, grid, mirror_col, mirror)
    else:
        base = default_geometry(_image_shape(files[0]) if files[0].is_file() else (0, 0), grid)
        geometry = CropGeometry(base.x, base.y, base.size, grid, mirror_col, mirror)
    cal = fit_series(files, masses, geometry, water_g, camera, reduce)
    out.parent.mkdir(parents=True, exist_ok=True)
    cal.save(out)
    return cal


def _recorded_crop(folder: Path) -> tuple[int, int, int] | None:
    """The crop a series recorded by `sfr lab`/`sfr run` stored in its run.json (x, y, size px), if any."""
    try:
        meta = json.loads((folder / "run.json").read_text())
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as exc:
        raise UsageError(f"{folder / 'run.json'} cannot be read: {exc}") from exc
    if "crop" not in meta:
        return None
    try:
        crop = meta["crop"]
        return int(crop["x"]), int(crop["y"]), int(crop["size"])
    except (KeyError, TypeError, ValueError) as exc:
        raise UsageError(f"{folder / 'run.json'}: crop is not {{x, y, size}} in px: {exc}") from exc


# -- simulate ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SimulationOutputs:
    """What :func:`simulate` wrote: the ``design.Release``, its summary and the output folder."""

    release: Any
    summary: dict[str, Any]
    out: Path
    warnings: tuple[str, ...]


def simulation_grid(source: str, *, resolution: int | None = None, voxel_size_mm: float | None = None,
                    symmetry: str = "", units: str = "mm") -> tuple[Any, float, tuple[bool, ...], list[str]]:
    """The density grid a simulation of ``source`` (mesh, ``sample:NAME`` or density array) runs on.

    A mesh is scaled from ``units`` to mm, checked for an implausible size (warnings naming the likely
    unit error) and its grid's memory estimated before anything is allocated.

    Returns
    -------
    rho : ndarray of float in [0, 1]
    dx_mm : float
    mirror : tuple of bool
    warnings : list of str
    """
    from design.meshio import DENSITY_SUFFIXES
    from design.pipeline import DEFAULT_RESOLUTION, SAMPLE_PREFIX, input_grid, mesh_grid
    from design.shapes import sample_shape
    from labapp.meshunits import SIMULATE_BYTES_PER_VOXEL, check_memory, grid_shape, load_mesh_mm, size_warnings

    if Path(source).suffix.lower() in DENSITY_SUFFIXES and not source.startswith(SAMPLE_PREFIX):
        if units != "mm":
            raise UsageError("--units applies to meshes; a density array's voxel size is in mm")
        rho, dx, mirror = input_grid(source, resolution=resolution, voxel_size_mm=voxel_size_mm, symmetry=symmetry)
        return rho, dx, mirror, []
    mesh = (sample_shape(source[len(SAMPLE_PREFIX):]) if source.startswith(SAMPLE_PREFIX)
            else load_mesh_mm(source, units))
    dx = voxel_size_mm or float(mesh.extents.max()) / (resolution or DEFAULT_RESOLUTION)
    warnings = size_warnings(mesh.extents, float(mesh.volume), dx, source)
    for w in warnings:
        log.warning("%s", w)
    check_memory(grid_shape(mesh.extents, dx), SIMULATE_BYTES_PER_VOXEL, f"simulating {source}")
    rho, dx, mirror = mesh_grid(mesh, resolution=resolution, voxel_size_mm=voxel_size_mm, symmetry=symmetry)
    return rho, dx, mirror, warnings


def simulate(source: str, out: str | Path, *, resolution: int | None = None, voxel_size_mm: float | None = None,
             symmetry: str = "", units: str = "mm",
             progress: Callable[[str], None] | None = None) -> SimulationOutputs:
    """Simulate the release of a mesh, ``sample:NAME`` or density array into ``out`` (release.csv,
    summary.json, release.png); the grid comes from :func:`simulation_grid`.

    Raises
    ------
    UsageError
        For an ``out`` that is an input or another command's folder, or a grid that would not fit in memory.
    design.DesignError
        For an unreadable or invalid input.
    """
    import time

    import numpy as np

    from design import simulate as forward

    say = progress or (lambda message: None)
    out = check_out(out, "simulation", [source])
    start = time.perf_counter()
    say(f"[1/3] loading and voxelising {source} ...")
    rho, dx, mirror, warnings = simulation_grid(source, resolution=resolution, voxel_size_mm=voxel_size_mm,
                                                symmetry=symmetry, units=units)
    say(f"[2/3] fast marching {rho.size:,} voxels of {dx:.4g} mm ({time.perf_counter() - start:.1f} s) ...")
    release = forward(rho, dx, mirror=mirror)
    seconds = time.perf_counter() - start
    say(f"[3/3] writing {out}/ ({seconds:.1f} s)")
    out.mkdir(parents=True, exist_ok=True)
    np.savetxt(out / "release.csv", np.column_stack([release.tau_mm, release.released_mm3]), delimiter=",",
               header="tau_mm,released_mm3", comments="", fmt="%.9g")
    summary = {"input": source, "units": units, "volume_mm3": release.volume_mm3,
               "total_time_mm": release.total_time_mm, "voxels": int(rho.size), "grid_shape": list(rho.shape),
               "voxel_size_mm": dx, "mirror": list(mirror), "dtau_mm": release.dtau_mm, "seconds": seconds,
               "warnings": warnings}
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    _plot_release(release.tau_mm, release.released_mm3, out / "release.png", source)
    return SimulationOutputs(release, summary, out, tuple(warnings))


def _plot_release(tau_mm, released_mm3, path: Path, title: str) -> None:
    """The cumulative curve and its rate dC/dtau, one above the other."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(6, 6), constrained_layout=True)
    top.plot(tau_mm, released_mm3)
    top.set_ylabel("released volume C (mm$^3$)")
    top.set_title(f"simulated release: {title}")
    bottom.plot(tau_mm, np.gradient(released_mm3, tau_mm))
    bottom.set_ylabel("rate dC/d$\\tau$ (mm$^3$/mm)")
    bottom.set_xlabel("dissolution time $\\tau$ (mm dissolved)")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    fig.savefig(path, dpi=120)
    plt.close(fig)


# -- design --------------------------------------------------------------------------------------------
def _design_defaults() -> dict[str, Any]:
    from design.problem import DesignConfig

    return {f.name: f.default for f in dataclasses.fields(DesignConfig) if f.default is not dataclasses.MISSING}


#: The design settings every face starts from (``design.problem.DesignConfig``'s own defaults).
DESIGN_DEFAULTS: dict[str, Any] = _design_defaults()
TARGET_SOURCE = "target_source.json"
_MESH_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".3mf")


def design_folder(data_dir: str | Path, name: str) -> Path:
    """The folder of a new design run started from the GUI: ``DATA/designs/<YYYYmmdd-HHMMSS>_<name>``."""
    import time

    from labapp.storage import sanitize_name

    return Path(data_dir) / "designs" / f"{time.strftime('%Y%m%d-%H%M%S')}_{sanitize_name(name)}"


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _copy_target(target: str, out: Path, units: str) -> str:
    """Record a file or folder target in ``target_source.json`` (path and SHA-256); copy a simulation-unit
    target (CSV, mesh scaled from ``units`` to mm) into the run folder and return the copy's path, which the
    run then optimises. A measured (physical) target is turned into its CSV in the run folder by
    ``labapp.targets.design_from_target``; here only its source is recorded."""
    from labapp.targets import is_physical

    source = Path(target)
    if not source.exists():
        return target
    record: dict[str, Any] = {"source": str(source.resolve()), "units": units,
                              "sha256": _sha256(source) if source.is_file() else None, "copy": None}
    if source.is_file() and not is_physical(source):
        suffix = source.suffix.lower()
        copy = out / f"target_input{suffix}"
        if suffix in _MESH_SUFFIXES:
            from labapp.meshunits import load_mesh_mm, size_warnings

            mesh = load_mesh_mm(source, units)
            for w in size_warnings(mesh.extents, float(mesh.volume), source=str(source)):
                log.warning("%s", w)
            if units != "mm":
                copy = out / "target_input.stl"
                mesh.export(copy)
            else:
                shutil.copyfile(source, copy)
        else:
            shutil.copyfile(source, copy)
        record.update(copy=copy.name, copy_sha256=_sha256(copy))
        target = str(copy.resolve())
    elif units != "mm":
        raise UsageError("--units applies to a mesh target")
    (out / TARGET_SOURCE).write_text(json.dumps(record, indent=2) + "\n")
    return target


def _check_target_unchanged(out: Path) -> list[str]:
    """On resume: warnings when the original target changed since the run started; refuses a run whose own
    copy of the target is missing or altered."""
    try:
        record = json.loads((out / TARGET_SOURCE).read_text())
    except FileNotFoundError:
        return []
    except (OSError, ValueError) as exc:
        raise UsageError(f"{out / TARGET_SOURCE} cannot be read: {exc}") from exc
    if record.get("copy"):
        copy = out / record["copy"]
        if not copy.is_file() or _sha256(copy) != record["copy_sha256"]:
            raise UsageError(f"{copy}: the run's copy of its target is missing or altered (SHA-256 differs from "
                             f"{TARGET_SOURCE}); the run cannot be resumed on the target it started with")
    source = Path(record["source"])
    if record.get("sha256") and (not source.is_file() or _sha256(source) != record["sha256"]):
        used = f"the copy taken at the start ({record['copy']})" if record.get("copy") else \
            "the target curve written at the start"
        return [f"the target {source} has changed (or is gone) since this run started; resuming with {used}"]
    return []


def design(config, out: str | Path, *, resume: bool = False, units: str = "mm", simcal=None,
           bench_calibration=None, on_iteration: Callable | None = None,
           should_stop: Callable[[], bool] | None = None, on_warning: Callable[[str], None] | None = None):
    """Start (``config``: a ``design.problem.DesignConfig``) or resume (``resume=True``) a design run in ``out``.

    A new run records a file target's path and SHA-256 in ``target_source.json`` and optimises a copy in
    the run folder (a mesh scaled from ``units`` to mm), so ``--resume`` uses the target the run started
    with; a changed original is reported through ``on_warning`` (default: the log). A start that is rejected
    (invalid or infeasible target, bad settings, not enough memory) removes what it wrote, so a corrected
    rerun into the same ``out`` is not blocked. The optimisation itself, with a measured target and the
    physical prediction through ``simcal``, is ``labapp.targets.design_from_target``.

    Returns
    -------
    result : design.optimize.DesignResult
    physical : dict or None
        The summary with the physical prediction (None without ``simcal``).

    Raises
    ------
    UsageError
        For an ``out`` that is another command's folder (or a design run, without ``resume``), or a grid
        that would not fit in memory.
    design.DesignError
        For an invalid configuration or target, an infeasible target, or a resume mismatch.
    """
    from labapp.meshunits import design_memory_bytes, require_memory
    from labapp.targets import design_from_target

    warn = on_warning or (lambda message: log.warning("%s", message))
    out = Path(out)
    run = dict(simcal=simcal, bench_calibration=bench_calibration, on_iteration=on_iteration,
               should_stop=should_stop)
    if resume:
        if not (out / "config.json").is_file():
            raise UsageError(f"{out} holds no design run to resume (no config.json); start one with --target")
        for w in _check_target_unchanged(out):
            warn(w)
        return design_from_target(None, out, resume=True, **run)
    out = check_out(out, "design", [config.target], replace=False)
    existed = out.exists()
    before = set(out.iterdir()) if existed else set()
    source = target = config.target
    try:
        n = config.resolution
        require_memory(design_memory_bytes(n, config.space), f"designing at resolution {n} ({config.space})")
        out.mkdir(parents=True, exist_ok=True)
        target = _copy_target(source, out, units)
        return design_from_target(dataclasses.replace(config, target=target), out, **run)
    except Exception as exc:
        if (out / "checkpoint.npz").exists():
            raise
        for path in (set(out.iterdir()) - before) if out.exists() else ():   # rejected: leave no trace
            shutil.rmtree(path) if path.is_dir() else path.unlink()
        if not existed and out.exists() and not any(out.iterdir()):
            out.rmdir()
        if target != source and target in str(exc) and type(exc).__init__ is Exception.__init__:
            raise type(exc)(str(exc).replace(target, source)) from exc   # name the operator's file, not the copy
        raise


# -- acquisition: new run, resume ----------------------------------------------------------------------
def new_run(config, bench, data_dir: str | Path, calibration=None):
    """A :class:`labapp.procedures.RunProcedure` for a new run in ``data_dir`` (checked, nothing written).

    Raises
    ------
    UsageError
        If ``data_dir`` is a file or lies inside a record or another command's folder.
    """
    from labapp.procedures import RunProcedure

    return RunProcedure(config, bench, check_data_dir(data_dir), calibration)


def resumable(folder: str | Path):
    """The snapshot of an interrupted acquisition run; anything else is refused without writing a byte.

    Raises
    ------
    UsageError
        Naming what ``folder`` is instead: not a run folder, a calibration series or other kind, a run
        that finished (complete, stopped, aborted, failed), or one still being written.
    """
    from labapp.outpaths import folder_kind
    from labapp.storage import StorageError, read_run

    folder = Path(folder)
    try:
        snap = read_run(folder)
    except StorageError:
        kind = folder_kind(folder)
        what = "does not exist" if not folder.exists() else \
            f"is not a run folder ({'no run.json' if kind is None or kind in ('other', 'images') else kind})"
        raise UsageError(f"{folder} {what}; only an interrupted acquisition run can be resumed") from None
    kind = snap.meta.get("kind", "run")
    if kind != "run":
        raise UsageError(f"{folder} is a {kind or 'folder of unknown kind'}, not an acquisition run; only an "
                         "interrupted acquisition run can be resumed")
    if snap.live:
        raise UsageError(f"{folder} is being written by process {snap.meta.get('writer_pid')}; it is not "
                         "interrupted")
    if snap.status != "interrupted":
        raise UsageError(f"{folder} finished ({snap.status}); only an interrupted run can be resumed. "
                         "A finished run is a record: start a new run instead")
    if "config" not in snap.meta:
        raise UsageError(f"{folder}/run.json has no run settings (config); it cannot be resumed")
    return snap


def resume_run(folder: str | Path, bench, calibration=None):
    """A :class:`labapp.procedures.RunProcedure` continuing the interrupted run in ``folder``.

    Call :func:`resumable` first to learn from ``run.json`` whether the run was simulated (and build the
    matching bench); this checks again and refuses a bench of the other kind.

    Raises
    ------
    UsageError
        As :func:`resumable`, or when the bench is simulated and the run was not (or the reverse).
    """
    from labapp.procedures import RunProcedure

    snap = resumable(folder)
    if bool(snap.meta.get("simulated")) != bool(bench.simulated):
        raise UsageError(f"{folder} was recorded on a {'simulated' if snap.meta.get('simulated') else 'real'} "
                         f"bench; it cannot be resumed on a {'simulated' if bench.simulated else 'real'} one")
    return RunProcedure.resume(Path(folder), bench, calibration)


# -- verify --------------------------------------------------------------------------------------------
def verify(folder: str | Path):
    """Check a folder against its manifests; returns a :class:`labapp.storage.VerifyReport` (never raises
    for a bad folder: what is wrong is in the report)."""
    from labapp.storage import verify_run

    return verify_run(Path(folder))


# -- jobs with modules of their own (imported last: they call the jobs above) ----------------------------
from labapp.batch import analyse_many  # noqa: E402
from labapp.mcsim import simulate_mc_job  # noqa: E402
from labapp.simcal import calibrate_sim  # noqa: E402
from labapp.sweep import run_sweep  # noqa: E402
