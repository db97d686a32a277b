"""The simulation-to-bench calibration as a job: measured runs + meshes -> ``simcal.json`` (paper section 4.3).

:func:`calibrate_sim` is what ``sfr calibrate-sim`` and the GUI's calibration wizard call: it reads a set
file (``run,mesh,object_mass_g``, :mod:`labapp.records.simcalset`), reads every run's physical curve
(:mod:`labapp.records.curvefiles`), simulates every mesh's print release (:mod:`labapp.jobs.printrelease`), fits
the print physics, both calibration models and their leave-one-out predictions (:mod:`analysis.physics_fit`,
:mod:`analysis.simcal_fit`) and writes ``simcal.json`` (:mod:`labapp.records.simcal`), ``loo.csv`` and ``simcal.png``
(:mod:`labapp.figures.loo_plot`).
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import logging
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis import AnalysisError, BenchCalibration, LooShape, ShapeRun, fit_simcal, leave_one_out
from analysis.bands import band_block
from analysis.physics_fit import (
    DISCRETISATION_FACTOR,
    MIN_RUNS_TO_CHOOSE,
    PhysicsFit,
    choose_physics,
    fit_physics,
    refit_physics,
    with_discretisation,
)
from analysis.physics_grid import (
    DEFAULT_PHYSICS,
    FIT_IDENTITY,
    FIT_PARAMETERS,
    LAG,
    PHYSICS_CHOICES,
    PHYSICS_GRIDS,
    PHYSICS_IDENTITY,
    PHYSICS_PARAMETERS,
    PHYSICS_SETS,
)
from analysis.simcal import MODELS, check_weighed_run
from analysis.simcal_fit import DEFAULT_MAX_OFFSET_S
from design.geometry.voxelize import DEFAULT_RESOLUTION
from design.threads import thread_count
from labapp.figures.loo_plot import plot_loo
from labapp.jobs.calibrate_barrier import barrier_block, split_coated
from labapp.jobs.printrelease import mesh_release
from labapp.records import operators
from labapp.records.audit import Action
from labapp.records.audit import append as audit
from labapp.records.curvefiles import CurveFileError, read_physical_curve
from labapp.records.fileio import atomic_write, sha256_file
from labapp.records.lock import folder_lock
from labapp.records.outpaths import FolderKind, check_out
from labapp.records.simcal import FORMAT, FORWARD_MODEL, RELEASE_METHOD, SimCalError
from labapp.records.simcalset import SetRow, read_set, row_inputs

MIN_RESOLUTION, MAX_RESOLUTION = 8, 512
"""The resolutions a calibration accepts, voxels along each mesh's longest side."""
ROW_WORKERS = thread_count()
"""Meshes released at once when a print physics value is tried (:meth:`_Simulations.simulate_rows`)."""
Progress = Callable[[float, str], None]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SimCalRun:
    """What :func:`calibrate_sim` made.

    Attributes
    ----------
    doc : dict
        The content of ``simcal.json``.
    loo : tuple of analysis.LooShape
        The chosen model's leave-one-out predictions, in set order.
    path : Path
        ``simcal.json``.
    """

    doc: dict
    loo: tuple[LooShape, ...]
    path: Path


def _check_inputs(set_csv: Path, rows: list[SetRow], bench) -> dict:
    """Every mesh read and every run's calibration found before the first simulation: a bad row further down
    is refused at once, not after the rows above it were analysed and simulated. Returns the meshes."""
    from design.errors import DesignError
    from design.files.meshio import load_mesh

    meshes = {}
    for row in rows:
        where = f"{set_csv.name} row {row.row}"
        if bench is None and row.run.is_dir() and not (row.run / "calibration.json").is_file():
            raise SimCalError(f"{where}: the run folder {row.run} has no calibration.json of its own; give the bench "
                              "calibration with --calibration")
        if row.mesh not in meshes:
            try:
                meshes[row.mesh] = load_mesh(row.mesh)
            except DesignError as exc:
                raise SimCalError(f"{where}: {exc}") from exc
    return meshes


def _make_out(out_dir: Path) -> None:
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SimCalError(f"cannot create {out_dir}: {exc.strerror or exc}") from exc


def _loo_summary(loo: tuple[LooShape, ...], rows: list[SetRow]) -> list[dict]:
    return [{"run": str(r.run), "mesh": str(r.mesh), "rel_rmse": s.rel_rmse,
             "seconds_per_mm": s.cal.seconds_per_mm,
             "saturation_g_per_kg": s.cal.saturation_g_per_kg} for s, r in zip(loo, rows)]


def calibrate_sim(set_csv: str | Path, bench_calibration: str | Path | None, out_dir: str | Path, *,
                  model: str = "auto", resolution: int = DEFAULT_RESOLUTION,
                  max_offset_s: float = DEFAULT_MAX_OFFSET_S, physics: str = DEFAULT_PHYSICS,
                  second_resolution: int | None = None,
                  progress: Progress | None = None) -> SimCalRun:
    """Calibrate the simulator against measured runs and write ``simcal.json``, ``loo.csv``, ``simcal.png``.

    Parameters
    ----------
    set_csv : str or Path
        ``run,mesh,object_mass_g`` rows; ``run`` is a run folder or a curve CSV, paths relative to the file;
        an empty mass is taken from the run's ``run.json``.
    bench_calibration : str or Path or None
        Bench calibration JSON to analyse run folders with (None: each run's own ``calibration.json``).
    out_dir : str or Path
        Output folder; refused if it already holds a calibration.
    model : {'auto', 'constant', 'saturation'}
        The model used for prediction; ``auto`` fits both and takes the one with the lower mean
        leave-one-out error (both are reported); a named model is the only one fitted.
    resolution : int
        Voxels along each mesh's longest side.
    max_offset_s : float
        Bound on each run's drop-time offset, s.
    second_resolution : int, optional
        The fitted print physics is refitted at this resolution too (default 1.5 x ``resolution``, at most
        the largest; 0: not): its estimated discretisation bias (:func:`analysis.physics_fit.with_discretisation`) is
        added in quadrature to each parameter's standard error, and recorded in ``physics.discretisation``.
    physics : str
        A set of ``analysis.physics_grid.PHYSICS_SETS`` (``none``, ``anisotropy``, ``offset``, ``swelling``, ``lag``,
        their combinations joined by ``+``, ``all``) or ``auto``: print physics to fit with the scales
        (:func:`analysis.physics_fit.fit_physics`): the build-direction anisotropy, the surface offset, the swelling
        width below which channels are shut, the wetting lag after the drop (shared by all runs; the per-run
        drop offsets of ``max_offset_s`` are then its jitter around it);
        ``none`` keeps the isotropic model of the mesh as designed; ``auto`` (the default,
        ``analysis.physics_grid.DEFAULT_PHYSICS``) fits every subset and keeps the one leave-one-out prefers (a
        parameter must earn its place; the sets with the swelling width only when a shape has a channel the widest
        width searched would shut). The models of ``model`` are then fitted on the meshes simulated with the
        chosen physics.
    progress : callable, optional
        ``progress(fraction, message)`` before each run and each fit; it may raise ``KeyboardInterrupt`` to stop
        there (nothing is written into ``out_dir``).

    Returns
    -------
    SimCalRun

    Raises
    ------
    SimCalError
        Bad set file, run, mesh or calibration, with the file and row named; the same run listed twice.
    """
    say = progress or (lambda fraction, message: None)
    if model not in ("auto",) + MODELS:
        raise SimCalError(f"model {model!r} is not one of auto, {', '.join(MODELS)}")
    if physics not in PHYSICS_CHOICES:
        raise SimCalError(f"physics {physics!r} is not one of {', '.join(PHYSICS_CHOICES)}")
    if not MIN_RESOLUTION <= resolution <= MAX_RESOLUTION:
        raise SimCalError(f"resolution {resolution} is outside {MIN_RESOLUTION}..{MAX_RESOLUTION} voxels")
    second = (min(round(DISCRETISATION_FACTOR * resolution), MAX_RESOLUTION) if second_resolution is None
              else int(second_resolution))
    second = 0 if second == resolution and second_resolution is None else second   # at the largest resolution
    if second and not resolution < second <= MAX_RESOLUTION:
        raise SimCalError(f"second resolution {second} must be above the resolution {resolution} and at most "
                          f"{MAX_RESOLUTION} voxels (0: no discretisation term)")
    set_csv, out_dir = Path(set_csv), Path(out_dir)
    rows = read_set(set_csv)
    check_out(out_dir, FolderKind.SIMCAL, [set_csv, bench_calibration] + [p for r in rows for p in (r.run, *row_inputs(r))],
              replace=False)
    operator = operators.require(f"calibrating the simulator into {out_dir}")
    bench = None
    if bench_calibration is not None:
        try:
            bench = BenchCalibration.load(bench_calibration)
        except (AnalysisError, OSError, ValueError, KeyError) as exc:
            raise SimCalError(f"{bench_calibration}: not a bench calibration ({exc})") from exc
    meshes = _check_inputs(set_csv, rows, bench)
    rows, coated = split_coated(set_csv, rows)     # coated prints (a barrier_mesh) give the barrier's speed
    with folder_lock(out_dir):      # one writer (sfr calibrate-sim, the GUI's wizard); made here, after the checks
        _make_out(out_dir)
        return _fit_and_write(set_csv, rows, bench, bench_calibration, meshes, out_dir, model, resolution,
                              max_offset_s, say, operator, physics, second, coated)


def _has_channels(grid: tuple) -> bool:
    """Whether a calibration shape's voxel grid has a channel the widest swelling width searched would shut."""
    from design.forward.swelling import shut_channels

    rho, dx, mirror = grid
    return bool(shut_channels(rho, dx, max(PHYSICS_GRIDS["swelling_mm"]), mirror).any())


def _physics_doc(fits: dict[str, PhysicsFit], chosen: str, rows: list[SetRow], discretisation: dict | None = None
                 ) -> dict:
    fit = fits[chosen]
    return {"fitted": list(fit.fitted), "choice": chosen, **{p: fit.values[p] for p in FIT_PARAMETERS},
            "uncertainty": dict(fit.uncertainty), **({"discretisation": discretisation} if discretisation else {}),
            "candidates": {name: {"fitted": list(f.fitted), "values": f.values, "uncertainty": f.uncertainty,
                                  "loss": f.loss, "loo_rel_rmse_mean": f.loo_rel_rmse_mean,
                                  "loo": [{"run": str(r.run), "rel_rmse": s.rel_rmse, "values": v}
                                          for s, r, v in zip(f.loo, rows, f.loo_values)]}
                           for name, f in fits.items()}}


class _Simulations:
    """The set's runs and their meshes' releases with print physics, simulated once per mesh and physics.

    Attributes
    ----------
    measured : list of tuple
        Per row, ``(where, t_s, released_g, mass_g, water_g)`` of its measured run (:func:`_read_runs`).
    grids : dict
        Voxel grids per (mesh, offset).
    """

    def __init__(self, rows: list[SetRow], meshes: dict, resolution: int, measured: list | None = None,
                 name_errors: bool = True) -> None:
        self.rows, self.meshes, self.resolution = rows, meshes, resolution
        self.measured = [] if measured is None else measured
        self.name_errors = name_errors      # a shape the analysis refuses raised as a SimCalError
        self.simulated: dict[tuple, tuple] = {}   # (mesh, anisotropy, offset, swelling) -> (tau, volume, dx)
        self.grids: dict[tuple, tuple] = {}       # (mesh, offset) -> voxel grid

    def simulation(self, row: SetRow, values: dict) -> tuple:
        """``(tau_mm, released_mm3, dx_mm)`` of a row's mesh with print physics ``values``."""
        key = (row.mesh, *(round(values[p], 9) for p in PHYSICS_PARAMETERS))
        if key not in self.simulated:
            self.simulated[key] = mesh_release(self.meshes[row.mesh], row.mesh, self.resolution, values, self.grids,
                                               interpolated=True)
        return self.simulated[key]

    def simulate_rows(self, values: dict) -> None:
        """Every row's mesh not yet simulated at print physics ``values``, up to `ROW_WORKERS` meshes at a time
        (their kernels release the GIL; each release is the same whichever thread makes it)."""
        todo: dict[tuple, SetRow] = {}
        for row in self.rows:
            key = (row.mesh, *(round(values[p], 9) for p in PHYSICS_PARAMETERS))
            if key not in self.simulated:
                todo.setdefault(key, row)
        if len(todo) < 2 or ROW_WORKERS < 2:
            for row in todo.values():
                self.simulation(row, values)
            return
        with ThreadPoolExecutor(max_workers=min(len(todo), ROW_WORKERS)) as pool:
            list(pool.map(lambda row: self.simulation(row, values), todo.values()))

    def shapes_at(self, values: dict) -> list[ShapeRun]:
        """Every run with its mesh's release at print physics ``values``."""
        self.simulate_rows(values)
        out = []
        for row, (where, t, g, mass, water) in zip(self.rows, self.measured):
            tau, vol, _ = self.simulation(row, values)
            try:
                out.append(ShapeRun(f"{where} ({row.run.name}, {row.mesh.name})", tau, vol, t, g, mass, water))
            except AnalysisError as exc:
                if not self.name_errors:
                    raise
                raise SimCalError(str(exc)) from exc
        return out


def _read_runs(set_csv: Path, bench, sims: _Simulations, physics: str, say: Progress) -> None:
    """Every run's measured curve into ``sims.measured``, then every mesh simulated as designed."""
    n = len(sims.rows)
    for k, row in enumerate(sims.rows):
        where = f"{set_csv.name} row {row.row}"
        say(0.3 * k / n if physics == "none" else 0.05 * k / n, f"{where}: reading {row.run.name} ...")
        try:
            curve = read_physical_curve(row.run, calibration=bench)
        except CurveFileError as exc:
            raise SimCalError(f"{where}: {exc}") from exc
        mass = row.object_mass_g or curve.object_mass_g
        if mass is None:
            raise SimCalError(f"{where}: object_mass_g is empty and {row.run} records no weighed mass")
        water = row.water_g or curve.water_g or (bench.water_g if bench is not None else None)
        if water is None:
            raise SimCalError(f"{where}: {row.run} records no water mass; give it in a water_g column or give "
                              "the bench calibration")
        keep = curve.t_s >= 0
        t_s, released_g = curve.t_s[keep], curve.released_g[keep]
        mesh = sims.meshes[row.mesh]
        if mesh.is_volume:      # refused before any mesh is simulated; the simulated volume is checked again
            try:
                check_weighed_run(f"{where} ({row.run.name}, {row.mesh.name})", float(mass), float(mesh.volume),
                                  released_g, volume_of="the mesh's")
            except AnalysisError as exc:
                raise SimCalError(str(exc)) from exc
        sims.measured.append((where, t_s, released_g, float(mass), float(water)))
    say(0.3 if physics == "none" else 0.05, f"simulating the {len({r.mesh for r in sims.rows})} meshes as designed ...")
    sims.simulate_rows(PHYSICS_IDENTITY)


def _fit_print_physics(set_csv: Path, sims: _Simulations, physics: str, max_offset_s: float, say: Progress
                       ) -> tuple[dict[str, PhysicsFit], str]:
    """The print physics sets of ``physics`` fitted with their leave-one-out: ``(fits by set, the chosen set)``;
    none for ``physics`` ``none``."""
    physics_fits: dict[str, PhysicsFit] = {}
    if physics == "none":
        return physics_fits, "none"
    rows = sims.rows
    if physics == "auto" and len(rows) < MIN_RUNS_TO_CHOOSE:
        log.warning("%s: %d runs; print physics are chosen from at least %d (leave-one-out needs them): the isotropic "
                    "model is kept; name a set with --physics to fit one anyway", set_csv, len(rows), MIN_RUNS_TO_CHOOSE)
        return physics_fits, "none"
    names = [m for m in PHYSICS_SETS if physics == "auto" or m in ("none", physics)]
    losses: dict = {}   # shared by the sets: each candidate value's loss fitted once
    if physics == "auto" and not any(_has_channels(sims.grids[(row.mesh, 0.0)]) for row in rows):
        # no shape has a channel the widest swelling width would shut: its release cannot tell the width
        names = [m for m in names if "swelling_mm" not in PHYSICS_SETS[m]]
    offset_floor = 0.5 * float(np.median([sims.simulation(row, PHYSICS_IDENTITY)[2] for row in rows]))
    for j, name in enumerate(names):
        base, span = 0.1 + 0.5 * j / len(names), 0.5 / len(names)
        say(base, f"fitting print physics '{name}' and its leave-one-out ...")
        try:
            physics_fits[name] = fit_physics(
                sims.shapes_at, PHYSICS_SETS[name], max_offset_s=max_offset_s, offset_floor_mm=offset_floor,
                losses=losses,
                progress=lambda done, total, name=name, base=base, span=span: say(
                    base + span * done / total, f"print physics '{name}': {done} of {total} fits"))
        except AnalysisError as exc:
            raise SimCalError(f"{set_csv}: {exc}") from exc
    return physics_fits, (choose_physics(physics_fits) if physics == "auto" else physics)


def _refit_at_second_resolution(set_csv: Path, sims: _Simulations, fit: PhysicsFit, values: dict, chosen: str,
                                second_resolution: int, max_offset_s: float, say: Progress
                                ) -> tuple[PhysicsFit, dict]:
    """The chosen print physics refitted at ``second_resolution``: the fit with its discretisation bias added to
    each parameter's uncertainty, and ``physics.discretisation`` of ``simcal.json``."""
    say(0.6, f"print physics '{chosen}' refitted at resolution {second_resolution} (discretisation) ...")
    fine = _Simulations(sims.rows, sims.meshes, second_resolution, sims.measured, name_errors=False)
    try:
        refit = refit_physics(fine.shapes_at, fit.fitted, values, max_offset_s=max_offset_s)
    except AnalysisError as exc:
        raise SimCalError(f"{set_csv}: {exc}") from exc
    combined, bias = with_discretisation(fit.uncertainty, values, refit, second_resolution / sims.resolution)
    discretisation = {"resolution": second_resolution, "values": {p: refit[p] for p in fit.fitted},
                      "bias": bias, "uncertainty_refits": dict(fit.uncertainty)}
    return dataclasses.replace(fit, uncertainty=combined), discretisation


MODEL_TIE_REL = 0.01
"""Mean leave-one-out errors within this fraction of each other are a tie, which the simpler constant model wins: a
difference of 1 % of a few-percent error is far below what leaving one of a handful of runs out resolves."""
SATURATION_INERT = 0.01
"""A saturation fit whose c_sat lies so far beyond the data that the most loaded bath reaches less than this
fraction of it changes no curve by more than about 1 %: it is the constant model, and is not chosen as another."""


@dataclass(frozen=True)
class _ModelFits:
    """The calibration models fitted to every run, with their leave-one-out predictions, and the highest
    concentration the runs reach, g/kg."""

    models: tuple[str, ...]
    fits: dict
    loos: dict
    mean_loo: dict
    top_conc_g_per_kg: float = 0.0

    @property
    def chosen(self) -> str:
        """The model with the lowest mean leave-one-out error; the constant model on a tie (`MODEL_TIE_REL`) or
        when the saturation fit's c_sat lies far beyond the data (`SATURATION_INERT`)."""
        best = min(self.models, key=self.mean_loo.get)
        if best != "saturation" or "constant" not in self.models:
            return best
        c_sat = self.fits["saturation"].cal.saturation_g_per_kg
        tie = self.mean_loo["saturation"] >= (1.0 - MODEL_TIE_REL) * self.mean_loo["constant"]
        inert = c_sat is None or self.top_conc_g_per_kg < SATURATION_INERT * c_sat
        return "constant" if tie or inert else best


def _fit_models(shapes: list[ShapeRun], model: str, lag: bool, max_offset_s: float, say: Progress) -> _ModelFits:
    """The models of ``model`` (both for ``auto``) fitted to all runs and left out one at a time."""
    n = len(shapes)
    fits, loos = {}, {}
    models = MODELS if model == "auto" else (model,)
    for j, name in enumerate(models):
        base, span = 0.6 + 0.35 * j / len(models), 0.35 / len(models)
        say(base, f"fitting the {name} model to all {n} runs ...")
        fits[name] = fit_simcal(shapes, name, max_offset_s=max_offset_s, lag=lag)
        loos[name] = leave_one_out(shapes, name, max_offset_s=max_offset_s, lag=lag,
                                   progress=lambda done, total, name=name, base=base, span=span: say(
                                       base + span * done / total, f"{name} model: left {done} of {total} out"))
    mean_loo = {m: float(np.mean([s.rel_rmse for s in loos[m]])) for m in models}
    return _ModelFits(models, fits, loos, mean_loo, 1000.0 * max(s.mass_g / s.water_g for s in shapes))


def _simcal_doc(set_csv: Path, bench_calibration, rows: list[SetRow], shapes: list[ShapeRun], dxs: list[float],
                models: _ModelFits, physics_doc: dict, resolution: int, max_offset_s: float, operator) -> dict:
    """The content of ``simcal.json`` but its ``band``."""
    chosen, fits, loos, mean_loo = models.chosen, models.fits, models.loos, models.mean_loo
    fit = fits[chosen]
    doc = {
        "format": FORMAT,
        "forward_model": FORWARD_MODEL,
        "release_method": RELEASE_METHOD,
        "model": chosen,
        "seconds_per_mm": fit.cal.seconds_per_mm,
        "g_per_mm3": fit.cal.g_per_mm3,
        "density_g_per_cm3": fit.cal.g_per_mm3 * 1000.0,
        "saturation_g_per_kg": fit.cal.saturation_g_per_kg,
        "water_g": float(np.median([s.water_g for s in shapes])),
        "resolution": resolution,
        "voxel_size_mm": float(np.median(dxs)),
        "physics": physics_doc,
        "loss": fit.loss,
        "loo": _loo_summary(loos[chosen], rows),
        "loo_rel_rmse_mean": mean_loo[chosen],
        "models": {m: {"seconds_per_mm": fits[m].cal.seconds_per_mm,
                       "saturation_g_per_kg": fits[m].cal.saturation_g_per_kg, "loss": fits[m].loss,
                       "loo_rel_rmse_mean": mean_loo[m], "loo": _loo_summary(loos[m], rows)} for m in models.models},
        "shapes": [{"run": str(r.run), "mesh": str(r.mesh), "object_mass_g": s.mass_g, "water_g": s.water_g,
                    "volume_mm3": s.volume_mm3, "g_per_mm3": g, "offset_s": o, "loss": L,
                    "measured_until_s": float(s.t_s[-1]),
                    "measured_fraction": float(np.max(s.released_g) / s.mass_g)}
                   for r, s, g, o, L in zip(rows, shapes, fit.g_per_mm3_per_shape, fit.offsets_s,
                                            fit.loss_per_shape)],
        "max_offset_s": max_offset_s,
        "inputs_sha256": _input_hashes(set_csv, bench_calibration, rows),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "operator": operator,
    }
    doc["physics"][LAG] = fit.cal.lag_s   # the prediction model's own lag (the same fit for the constant model)
    return doc


def _write_outputs(out_dir: Path, doc: dict, rows: list[SetRow], models: _ModelFits) -> None:
    """``simcal.json``, ``loo.csv`` (every model's leave-one-out) and ``simcal.png`` (the chosen model's)."""
    chosen, loos = models.chosen, models.loos
    cal = models.fits[chosen].cal
    atomic_write(out_dir / "simcal.json", (json.dumps(doc, indent=2) + "\n").encode())
    lines = ["run,mesh,model,rel_rmse,seconds_per_mm_without_it"]
    for m in models.models:
        lines += [f"{r.run},{r.mesh},{m},{s.rel_rmse:.6f},{s.cal.seconds_per_mm:.3f}" for s, r in zip(loos[m], rows)]
    atomic_write(out_dir / "loo.csv", ("\n".join(lines) + "\n").encode())
    plot_loo(loos[chosen], [f"{r.run.name}\n{r.mesh.name}" for r in rows], out_dir / "simcal.png",
             f"leave-one-out predictions ({chosen} model, {cal.seconds_per_mm:.0f} s/mm, "
             f"{cal.g_per_mm3 * 1000:.3f} g/cm^3)")


def _fit_and_write(set_csv: Path, rows: list[SetRow], bench, bench_calibration, meshes: dict, out_dir: Path,
                   model: str, resolution: int, max_offset_s: float, say: Progress, operator,
                   physics: str = "none", second_resolution: int = 0, coated: list | None = None) -> SimCalRun:
    """The work of :func:`calibrate_sim` on checked inputs, into the locked ``out_dir``."""
    n = len(rows)
    sims = _Simulations(rows, meshes, resolution)
    _read_runs(set_csv, bench, sims, physics, say)
    physics_fits, chosen_physics = _fit_print_physics(set_csv, sims, physics, max_offset_s, say)
    values = physics_fits[chosen_physics].values if physics_fits else dict(FIT_IDENTITY)
    lag = bool(physics_fits) and LAG in physics_fits[chosen_physics].fitted
    discretisation = None
    if physics_fits and physics_fits[chosen_physics].fitted and second_resolution:
        physics_fits[chosen_physics], discretisation = _refit_at_second_resolution(
            set_csv, sims, physics_fits[chosen_physics], values, chosen_physics, second_resolution, max_offset_s, say)
    shapes = sims.shapes_at(values)
    dxs = [sims.simulation(row, values)[2] for row in rows]
    models = _fit_models(shapes, model, lag, max_offset_s, say)
    chosen = models.chosen
    physics_doc = (_physics_doc(physics_fits, chosen_physics, rows, discretisation) if physics_fits else
                   {"fitted": [], "choice": "none", **FIT_IDENTITY, "uncertainty": {}, "candidates": {}})
    doc = _simcal_doc(set_csv, bench_calibration, rows, shapes, dxs, models, physics_doc, resolution, max_offset_s,
                      operator)
    say(0.95, "error bands: each run's leave-one-out prediction against the band from the other runs ...")
    honest = physics_fits.get(chosen_physics)   # with print physics, the leave-one-out that refits it
    doc["band"] = band_block(honest.loo if honest else models.loos[chosen], shapes,
                             honest.loo_values if honest else None, doc["physics"]["uncertainty"],
                             lambda i, values: sims.simulation(rows[i], values)[:2])
    if coated:
        doc["barrier"] = barrier_block(set_csv, coated, lambda row: sims.simulation(row, values), models.fits[chosen].cal,
                                       doc["physics"], bench, say)
    say(0.96, f"writing {out_dir} ...")
    _write_outputs(out_dir, doc, rows, models)
    cal = models.fits[chosen].cal
    audit(out_dir, Action.CALIBRATE, f"simulation calibration simcal.json from {n} runs of {set_csv.name}: "
          f"{chosen} model, {cal.seconds_per_mm:.1f} s/mm", operator=operator)
    say(1.0, f"{chosen} model: {cal.seconds_per_mm:.1f} s/mm, mean leave-one-out error "
             f"{100 * models.mean_loo[chosen]:.2f}% of the weighed mass")
    return SimCalRun(doc, models.loos[chosen], out_dir / "simcal.json")


def _input_hashes(set_csv: Path, bench_calibration, rows: list[SetRow]) -> dict[str, str]:
    files = [set_csv] + ([Path(bench_calibration)] if bench_calibration is not None else [])
    return {str(p): sha256_file(p) for p in files + [p for r in rows for p in row_inputs(r)]}
