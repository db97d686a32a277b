"""The headless demo: the whole measure -> calibrate -> design loop on the simulated bench, on an instant clock.

1. a calibration series (bench calibration, paper section 4.2);
2. short release runs of the calibration prints (:data:`CALIBRATION_SHAPES`: three sample objects and a flat, a
   tall and a lying print that ``calibrate-sim --plan`` proposes; a frame a minute, bath already hot; one in 400 g of
   water);
3. ``calibrate-sim`` on them: seconds per mm, grams per mm^3 and the leave-one-out table (section 4.3);
4. a release run of a further object at the paper's 11 s per frame, with a camera-busy error, a corrupt
   frame and a hotplate link drop injected on purpose, and its offline analysis (beside step 3, on another thread:
   neither needs the other; its progress lines follow step 3's);
5. an inverse design whose target is that object's measured curve, predicted in grams over hours (the object's
   prediction from its mesh is made beside it);
6. one picture: the leave-one-out predictions, and the further object measured, predicted from its mesh
   and designed, each prediction with its error band (:mod:`labapp.jobs.bands`).

The bench's material is hidden (:class:`labapp.acquisition.simbench.Material`); ``truth.json`` beside the results
records it for comparison and nothing in the loop reads it. Simulated time is driven, never slept.
"""
from __future__ import annotations

import dataclasses
import json
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis import BenchCalibration, RunCurve, analyze_run, write_cells_csv, write_curve_csv
from analysis.physics_grid import LAG
from design.errors import DesignError
from design.geometry.shapes import SAMPLE_SHAPES, sample_shape
from design.inverse.config import DesignConfig
from design.inverse.settings import MAX_ITER
from drivers.sim import BenchScene
from labapp.acquisition.calseries import CalibrationProcedure, SeriesConfig
from labapp.acquisition.clock import SteppedClock
from labapp.acquisition.engine import Engine
from labapp.acquisition.events import EngineEvent, FrameStored, Outcome
from labapp.acquisition.procedures import RunConfig, RunProcedure
from labapp.acquisition.settings import INTERVAL, BathSettings
from labapp.acquisition.simbench import SCENE, WATER_G, Material, SampleRelease, SimulatedBench, sample_release
from labapp.errors import JobFailed, LabError, UsageError
from labapp.jobs.bands import prediction_band, quantile_columns, source_simulator
from labapp.jobs.calibrate_sim import MAX_RESOLUTION as MAX_SIMCAL_RESOLUTION
from labapp.jobs.calibrate_sim import MIN_RESOLUTION as MIN_SIMCAL_RESOLUTION
from labapp.jobs.calibrate_sim import SimCalRun, calibrate_sim
from labapp.jobs.physical import design_from_target
from labapp.jobs.plan import GENERATED
from labapp.records.curvefiles import PhysicalCurve, read_physical_curve
from labapp.records.fileio import StorageError, free_bytes
from labapp.records.lock import folder_lock
from labapp.records.manifests import read_run
from labapp.records.simcal import SimCalFile, load_simcal
from labapp.records.verification import verify_run

CAL_MASSES_G = (0.25, 0.5, 0.875, 1.25, 1.75, 2.25)
"""Cumulative filament masses of the simulated calibration series, g (up to above a sample's ~1.8 g)."""
CALIBRATION_SHAPES = ("sphere", "spinner_top", "csg", "flat", "tall", "bar")
"""The simulation calibration set: three sample objects and three generated prints of ``calibrate-sim --plan``
(:data:`labapp.jobs.plan.GENERATED`): the flat slab and the tall column it proposes first and a bar lying down.
Round prints erode at a mix of the in-plane and build-direction rates and confound the anisotropy with the time
scale; the flat and the tall print separate them, and the bar keeps them separated in each leave-one-out refit
that lacks one of the two. The further object is any other sample."""
CALIBRATION_WATER_G = (WATER_G, 400.0, WATER_G, WATER_G, WATER_G, WATER_G)
"""Water of each calibration run, g: one run in less water shows that water masses may differ."""
PRINT_INDEX = {"sphere": 0, "spinner_top": 1, "csg": 2, "flat": 3, "tall": 4, "bar": 6}
"""Each calibration print's index of the bench's per-print draws (:meth:`Material.printed`)."""
FURTHER_INDEX = 5
"""The further object's index of the bench's per-print draws."""
TRUTH_RESOLUTION = 80
"""Voxels along the longest side of the simulated bench's own (hidden) forward simulations."""
CALIBRATION_INTERVAL_S = 60.0
"""Frame interval of the calibration set's short runs, s."""
SIMCAL_RESOLUTION, DESIGN_RESOLUTION = 48, 40
"""The demo's simulation-calibration resolution and design grid."""
DESIGN_ITERATIONS = MAX_ITER.default
"""The demo design's evaluation budget: `sfr design`'s own default (at 40 voxels its evaluations take seconds)."""
LINK_DROP_S = 120.0
"""How long the further object's run loses its hotplate link, simulated s: a few frames, so that the driver's
reconnects, which back off in wall seconds, find the link back however fast the frames render."""
DEMO_DESIGN_PLACEHOLDER = "zero-order"
"""The target the design settings are checked with before the measured curve that replaces it exists."""
DEMO_FREE_BYTES = 200_000_000
"""Free disk space a demo needs before it starts, bytes: a session's folder holds about 95 MB (the frames of its
seven runs), with a margin for the file system's blocks and the analysis caches."""


@dataclass(frozen=True)
class DemoResult:
    """Where the demo put things and its headline numbers."""

    out_dir: Path
    calibration_path: Path
    simcal_path: Path
    run_dir: Path
    curve_csv: Path
    design_dir: Path
    figure: Path
    summary_path: Path
    loo: tuple[tuple[str, float], ...]
    seconds_per_mm: float
    true_seconds_per_mm: float
    """The calibration prints' own hidden rates, mean, s/mm: what the calibration can learn."""
    density_g_per_cm3: float
    """The calibrated effective density: weighed grams per mm^3 of the modelled print (the mesh with the fitted
    surface offset, none when the offset is not kept)."""
    true_density_g_per_cm3: float
    """The hidden prints' grams per mm^3 of the same modelled print: the like-for-like truth of
    ``density_g_per_cm3``."""
    rel_rmse_prediction: float
    rel_rmse_design: float
    n_frames: int
    duration_s: float
    faults_logged: int
    wall_s: float
    physics: str
    """The print physics the calibration kept, with their values."""
    material_density_g_per_cm3: float
    """The hidden prints' own density over their true volume (the bench's prints may be larger than their
    meshes), mean, g/cm^3."""
    material_seconds_per_mm: float
    """The hidden material's rate, s/mm (each print draws its own around it)."""


def simulated_calibration(out_dir: Path, clock: SteppedClock | None = None,
                          scene: BenchScene = SCENE) -> tuple[BenchCalibration, Path]:
    """Run a simulated calibration series into ``out_dir`` on an instant clock; returns the calibration and its file.

    Every piece of filament has dissolved before its frame is taken, so the calibration scene has no
    intrusions (objects or bubbles in the crop); the run's scene keeps them.
    """
    clock = clock or SteppedClock()
    no_object = SampleRelease("none", np.array([0.0, 1.0]), np.zeros(2))
    sim = SimulatedBench(clock, release=no_object, scene=dataclasses.replace(scene, intrusion_probability=0.0))
    try:
        config = SeriesConfig(crop=sim.scene.default_crop(), masses_g=CAL_MASSES_G, settle_s=600.0, reduce=2,
                              bath=BathSettings(water_g=WATER_G, stable_step_s=60.0))
        proc = CalibrationProcedure(config, sim.bench(), out_dir)
        engine = Engine(clock)
        outcome = engine.run(proc)
    finally:
        sim.close()
    if proc.run is None:
        raise _not_started("the simulated calibration series", out_dir, engine.error)
    if proc.calibration_path is None:
        raise RuntimeError(f"the simulated calibration series ended '{outcome}' without a calibration; "
                           f"see {proc.run.path / 'events.log'}")
    return BenchCalibration.load(proc.calibration_path), proc.calibration_path


def _not_started(what: str, folder: Path, error: BaseException | None) -> LabError:
    """The error of a simulated procedure that could not create its run folder in ``folder`` (a full or read-only
    disk): a :class:`StorageError` naming the folder, or the procedure's own :class:`LabError`."""
    if isinstance(error, LabError):
        return error
    if isinstance(error, OSError):
        return StorageError(f"{what} could not write its run folder in {folder}: "
                            f"{error.strerror or error}; free space or choose another --out")
    return JobFailed(f"{what} did not start in {folder}: {error}")


def check_demo_space(out_dir: Path, need_bytes: int = DEMO_FREE_BYTES) -> None:
    """Refuse a demo whose folder's disk has less than ``need_bytes`` free, before anything is written.

    Raises
    ------
    StorageError
        Naming the folder, the space needed and the space free.
    """
    folder = Path(out_dir).expanduser().resolve()
    existing = next(p for p in (folder, *folder.parents) if p.exists())
    have = free_bytes(existing)
    if have < need_bytes:
        raise StorageError(f"not enough disk space for the demo in {folder}: it needs about {need_bytes / 1e6:.0f} MB, "
                           f"{have / 1e6:.0f} MB free; free space or choose another --out")


def _inject_faults(sim: SimulatedBench) -> Callable[[EngineEvent], None]:
    """A subscriber that injects one fault of each kind during the run (the event log must show them)."""
    def on_event(event: EngineEvent) -> None:
        if not isinstance(event, FrameStored):
            return
        index = event.index
        if index == 60:
            sim.camera_busy(1)
        elif index == 120:
            sim.corrupt_frames(1)
        elif index == 180:
            sim.drop_hotplate_link(LINK_DROP_S)
    return on_event


def simulated_run(clock: SteppedClock, calibration: BenchCalibration, release: SampleRelease, data_dir: Path,
                  *, interval_s: float, water_g: float = WATER_G, faults: bool = False, hotplate: bool = True,
                  progress: Callable[[str], None] = lambda text: None, min_duration_s: float | None = None,
                  seed: int = 0) -> Path:
    """One release run of a simulated object until steady state; returns its run folder.

    The run is not stopped as steady before ``min_duration_s`` (default: half the object's dissolution; a print
    that releases nothing for longer, behind a barrier, needs more). ``seed`` seeds the bench's image noise and
    intrusions (runs meant to be independent measurements take different seeds).

    The run records the object's weighed mass (its true mass to 0.1 mg) and the water, as an operator would.
    Without ``hotplate`` the bath is taken as already at temperature (no emulator, no heating phase).
    """
    sim = SimulatedBench(clock, release=release, scene=dataclasses.replace(SCENE, water_g=water_g),
                         with_hotplate=hotplate, seed=seed)
    try:
        config = RunConfig(name=f"demo-{release.name}", interval_s=interval_s,
                           max_duration_s=release.duration_s + 3600.0, stop_on_steady=True,
                           min_duration_s=0.5 * release.duration_s if min_duration_s is None else min_duration_s,
                           object_mass_g=round(release.mass_g, 4), object_name=release.name, auto_drop=True,
                           notes="sfr demo: simulated bench", bath=BathSettings(water_g=water_g, stable_step_s=60.0))
        proc = RunProcedure(config, sim.bench(), data_dir, calibration)
        engine = Engine(clock)
        if faults:
            engine.subscribe(_inject_faults(sim))
        engine.subscribe(lambda e: progress(f"  frame {e.index:4d}  t={e.t_s / 60:6.1f} min  "
                                            f"{e.conc_g_per_kg:.3f} g/kg")
                         if isinstance(e, FrameStored) and e.index % 100 == 0 else None)
        outcome = engine.run(proc)
    finally:
        sim.close()
    if proc.run is None:
        raise _not_started(f"the simulated run of {release.name}", data_dir, engine.error)
    if outcome not in (Outcome.COMPLETE, Outcome.STOPPED):
        raise RuntimeError(f"the simulated run ended '{outcome}': {engine.error}; see {proc.run.path / 'events.log'}")
    return proc.run.path


def run_demo(out_dir: Path, sample: str = "pill", interval_s: float = 11.0,
             calibration_interval_s: float = CALIBRATION_INTERVAL_S, resolution: int = SIMCAL_RESOLUTION,
             design_resolution: int = DESIGN_RESOLUTION, design_iterations: int = DESIGN_ITERATIONS,
             material: Material | None = None, progress: Callable[[str], None] = lambda text: None) -> DemoResult:
    """The whole loop; ``progress(text)`` gets one line per step.

    Parameters
    ----------
    out_dir : Path
    sample : str
        The further object whose measured curve is the design target (not one of
        :data:`CALIBRATION_SHAPES`).
    interval_s, calibration_interval_s : float
        Frame interval of the further object's run and of the calibration runs, s.
    resolution : int
        Voxels along each mesh's longest side for the simulation calibration.
    design_resolution, design_iterations : int
        Inverse design grid and evaluation budget.
    material : Material, optional
        The bench's hidden material (default: :meth:`Material.draw`).

    Raises
    ------
    UsageError
        Before anything is written, for any input the loop would refuse later (:func:`check_demo`), or an
        ``out_dir`` another command is writing.
    StorageError
        Before anything is written, when ``out_dir``'s disk has too little free space (:func:`check_demo_space`);
        during the loop, when a run folder cannot be written.
    """
    config = check_demo(sample, interval_s, calibration_interval_s, resolution, design_resolution, design_iterations)
    check_demo_space(out_dir)
    with folder_lock(out_dir):
        return _run_demo(Path(out_dir), sample, interval_s, calibration_interval_s, resolution, config,
                         material or Material.draw(), progress)


def check_demo(sample: str, interval_s: float, calibration_interval_s: float = CALIBRATION_INTERVAL_S,
               resolution: int = SIMCAL_RESOLUTION, design_resolution: int = DESIGN_RESOLUTION,
               design_iterations: int = DESIGN_ITERATIONS) -> DesignConfig:
    """Check every input of :func:`run_demo` before any work; returns the design's settings (its target, the
    measured curve, is set once it exists).

    Raises
    ------
    UsageError
        Naming the input, the value and what is allowed.
    """
    further = [s for s in SAMPLE_SHAPES if s not in CALIBRATION_SHAPES]
    if sample not in further:
        what = "is one of the calibration set" if sample in CALIBRATION_SHAPES else "is not a sample shape"
        raise UsageError(f"--sample {sample!r} {what}; the further object is one of {', '.join(further)} "
                         f"({', '.join(CALIBRATION_SHAPES)} are the calibration set)")
    INTERVAL.check(interval_s, "demo")
    INTERVAL.check(calibration_interval_s, "demo.calibration")
    if not MIN_SIMCAL_RESOLUTION <= resolution <= MAX_SIMCAL_RESOLUTION:
        raise UsageError(f"demo.resolution must be in {MIN_SIMCAL_RESOLUTION}..{MAX_SIMCAL_RESOLUTION} voxels, "
                         f"got {resolution!r}")
    try:
        return DesignConfig(target=DEMO_DESIGN_PLACEHOLDER, space="nfc", resolution=design_resolution,
                            max_iter=design_iterations, allow_infeasible=True)
    except (DesignError, ValueError) as exc:
        raise UsageError(f"demo design settings: {exc}") from exc


def _run_demo(out_dir: Path, sample: str, interval_s: float, calibration_interval_s: float, resolution: int,
              design: DesignConfig, material: Material, progress: Callable[[str], None]) -> DemoResult:
    """The loop of :func:`run_demo` on checked inputs, in a locked ``out_dir``: the steps of the module's list."""
    start = time.monotonic()
    clock = SteppedClock()
    progress("1. calibration series: clear water + 6 filament additions at 70 C ...")
    calibration, cal_path = simulated_calibration(out_dir / "calibration", clock)
    progress(f"   {cal_path}")
    truths: dict[str, dict] = {}
    set_csv = _calibration_runs(out_dir, clock, calibration, calibration_interval_s, material, truths, progress)
    held = _HeldProgress(progress)
    with ThreadPoolExecutor(max_workers=1) as pool:   # the further object's run goes on while calibrate-sim fits
        further = pool.submit(_further_run, out_dir, clock, calibration, sample, interval_s, material, truths, held)
        cal_run, simcal, loo = _calibrate_simulation(set_csv, cal_path, out_dir / "simcal", resolution, progress)
        held.release()
        run_dir, curve, faults = further.result()
    curve_csv = out_dir / "analysis" / "curve.csv"

    progress(f"5. design from the measured curve (nfc, {design.resolution}^3, {design.max_iter} evaluations) ...")
    design_dir = out_dir / "design"
    held = _HeldProgress(progress)
    with ThreadPoolExecutor(max_workers=1) as pool:   # the further object predicted from its mesh beside the design
        predicted = pool.submit(_predict_further, curve_csv, sample, simcal, cal_run, held)
        result, physical = design_from_target(dataclasses.replace(design, target=str(curve_csv)), design_dir,
                                              simcal=simcal)
        held.release()
        prediction = predicted.result()
    figure = out_dir / "demo.png"
    designed = np.genfromtxt(design_dir / "curves_physical.csv", delimiter=",", names=True)
    _plot(cal_run, prediction.measured, prediction.predicted, designed, sample, figure, prediction.band)

    _write_truth(out_dir / "truth.json", material, truths)
    truth = _truth_like_the_model(truths, simcal)
    result_ = DemoResult(out_dir, cal_path, simcal.path, run_dir, curve_csv, design_dir, figure,
                         out_dir / "summary.json", loo, simcal.cal.seconds_per_mm, truth["seconds_per_mm"],
                         simcal.cal.g_per_mm3 * 1000.0, truth["effective_density_g_per_cm3"], prediction.rel_rmse,
                         physical["rel_rmse_physical"], len(curve.t_s), float(curve.t_s[-1]), faults,
                         time.monotonic() - start, _physics_line(cal_run.doc["physics"]), truth["density_g_per_cm3"],
                         material.seconds_per_mm)
    _write_summary(result_, result.status, physical, cal_run, prediction)
    return result_


class _HeldProgress:
    """Progress lines of a step that runs beside another: held back until :meth:`release`, then passed on in order
    and as they come."""

    def __init__(self, progress: Callable[[str], None]) -> None:
        self.progress, self.lines, self.held, self.lock = progress, [], True, threading.Lock()

    def __call__(self, text: str) -> None:
        with self.lock:
            if self.held:
                self.lines.append(text)
            else:
                self.progress(text)

    def release(self) -> None:
        """Pass on the lines held so far, and every later line as it comes."""
        with self.lock:
            for text in self.lines:
                self.progress(text)
            self.lines, self.held = [], False


def _truth_like_the_model(truths: dict[str, dict], simcal: SimCalFile) -> dict:
    """The hidden truth of the calibration prints in the calibration's own terms: their mean rate, s/mm; their
    weighed grams per cm^3 of the print the model simulates (each mesh with the fitted surface offset: the effective
    density, which absorbs the volume of an offset the model does not fit); their own mean density over their
    true volume."""
    from labapp.jobs.printrelease import print_volume_mm3

    cal = {name: t for name, t in truths.items() if name in CALIBRATION_SHAPES}
    modelled = sum(print_volume_mm3(calibration_mesh(name), simcal.physics["offset_mm"]) for name in cal)
    return {"seconds_per_mm": float(np.mean([t["seconds_per_mm"] for t in cal.values()])),
            "effective_density_g_per_cm3": 1000.0 * sum(t["mass_g"] for t in cal.values()) / modelled,
            "density_g_per_cm3": 1000.0 * float(np.mean([t["g_per_mm3"] for t in cal.values()]))}


def calibration_mesh(name: str):
    """The mesh of a print of `CALIBRATION_SHAPES`: a generated shape of ``calibrate-sim --plan`` or a sample's."""
    return GENERATED[name][0]() if name in GENERATED else sample_shape(name)


def _physics_line(physics: dict) -> str:
    """The print physics ``simcal.json``'s block ``physics`` kept, in a few words, e.g. ``anisotropy 0.731, wetting lag
    551 s``."""
    units = {"anisotropy": "", "offset_mm": " mm", "swelling_mm": " mm", LAG: " s"}
    names = {"anisotropy": "anisotropy", "offset_mm": "surface offset", "swelling_mm": "swelling width",
             LAG: "wetting lag"}
    return ", ".join(f"{names[p]} {physics[p]:.3g}{units[p]}" for p in physics.get("fitted") or []) or "none (isotropic)"


def _calibration_runs(out_dir: Path, clock: SteppedClock, calibration: BenchCalibration, interval_s: float,
                      material: Material, truths: dict[str, dict], progress: Callable[[str], None]) -> Path:
    """Step 2: a short run of each of `CALIBRATION_SHAPES`, its mesh in ``meshes/`` and its truth in ``truths``;
    returns the calibration set's CSV (run, mesh, object mass) that lists them."""
    meshes = out_dir / "meshes"
    meshes.mkdir(exist_ok=True)
    set_rows = ["run,mesh,object_mass_g"]
    progress(f"2. short runs of {len(CALIBRATION_SHAPES)} calibration prints ({', '.join(CALIBRATION_SHAPES)}; "
             f"{interval_s:g} s per frame) ...")
    for shape, water in zip(CALIBRATION_SHAPES, CALIBRATION_WATER_G):
        mesh = calibration_mesh(shape)
        release = sample_release(shape, index=PRINT_INDEX[shape], resolution=TRUTH_RESOLUTION, material=material,
                                 mesh=mesh)
        mesh.export(meshes / f"{shape}.stl")
        run_dir = simulated_run(clock, calibration, release, out_dir / "runs", interval_s=interval_s,
                                water_g=water, hotplate=False)
        truths[shape] = release.truth
        set_rows.append(f"{run_dir.relative_to(out_dir)},meshes/{shape}.stl,")
        progress(f"   {shape}: {len(read_run(run_dir).frames)} frames, {release.mass_g:.3f} g in {water:g} g water "
                 f"-> {run_dir.name}")
    set_csv = out_dir / "calibration_set.csv"
    set_csv.write_text("\n".join(set_rows) + "\n")
    return set_csv


def _calibrate_simulation(set_csv: Path, cal_path: Path, simcal_dir: Path, resolution: int,
                   progress: Callable[[str], None]) -> tuple[SimCalRun, SimCalFile, tuple[tuple[str, float], ...]]:
    """Step 3: ``calibrate-sim`` on the calibration set; returns its run, its file and the leave-one-out errors
    (mesh name, rel. RMSE of the weighed mass)."""
    progress(f"3. calibrate-sim {set_csv.name} (resolution {resolution}, leave-one-out) ...")
    cal_run = calibrate_sim(set_csv, cal_path, simcal_dir, resolution=resolution,
                            progress=lambda f, m: progress(f"   {m}"))
    simcal = load_simcal(cal_run.path)
    loo = tuple((Path(row["mesh"]).stem, row["rel_rmse"]) for row in cal_run.doc["loo"])
    for name, error in loo:
        progress(f"   leave-one-out {name:12s} rel. RMSE {100 * error:.2f}% of the weighed mass")
    return cal_run, simcal, loo


def _further_run(out_dir: Path, clock: SteppedClock, calibration: BenchCalibration, sample: str, interval_s: float,
                 material: Material, truths: dict[str, dict], progress: Callable[[str], None]
                 ) -> tuple[Path, RunCurve, int]:
    """Step 4: the further object's run with faults injected and its analysis (``analysis/curve.csv`` and
    ``cells.csv``); returns the run folder, the measured curve and the warnings in its event log."""
    progress(f"4. release run of a further object, '{sample}' ({interval_s:g} s per frame; faults injected: "
             "camera busy, corrupt frame, hotplate link drop) ...")
    release = sample_release(sample, index=FURTHER_INDEX, resolution=TRUTH_RESOLUTION, material=material)
    truths[sample] = release.truth
    sample_shape(sample).export(out_dir / "meshes" / f"{sample}.stl")
    run_dir = simulated_run(clock, calibration, release, out_dir / "runs", interval_s=interval_s, faults=True,
                            progress=progress)
    curve = analyze_run(run_dir, calibration, cache_dir=run_dir / "analysis")
    analysis_dir = out_dir / "analysis"
    analysis_dir.mkdir(exist_ok=True)
    write_curve_csv(curve, analysis_dir / "curve.csv")
    write_cells_csv(curve, analysis_dir / "cells.csv")
    snap = read_run(run_dir)
    faults = sum(1 for line in snap.events() if "\tWARNING\t" in line)
    progress(f"   {len(curve.t_s)} frames over {curve.t_s[-1] / 3600:.2f} h, {faults} warnings in the event log")
    return run_dir, curve, faults


@dataclass(frozen=True)
class _Prediction:
    """The further object's measured curve, its release predicted from its mesh and its error band."""

    measured: PhysicalCurve
    predicted: np.ndarray
    """Predicted release at the measured times, g."""
    rel_rmse: float
    """RMSE of the prediction as a fraction of the measured final grams."""
    band: tuple[np.ndarray, np.ndarray] | None
    """The prediction's band (low, high), g; None without a band in the calibration."""
    inside: float | None
    """Fraction of the measured points inside the band."""


def _predict_further(curve_csv: Path, sample: str, simcal: SimCalFile, cal_run: SimCalRun,
                     progress: Callable[[str], None]) -> _Prediction:
    """The further object's release predicted from its mesh by the simulation calibration, against its measured
    curve: from its weighed mass, which its run records (the calibration's pooled density only without one; the
    pooled density's error is then the print's own density draw, which no calibration can know)."""
    measured = read_physical_curve(curve_csv)
    simulate_at = source_simulator(f"sample:{sample}", simcal.resolution, method=simcal.release_method)
    tau, vol = simulate_at(simcal.physics)
    water, mass = measured.water_g or WATER_G, measured.object_mass_g
    predicted = simcal.cal.to_physical(tau, vol, measured.t_s, water, mass_g=mass)
    rel_pred = float(np.sqrt(np.mean((predicted - measured.released_g) ** 2)) / measured.released_g.max())
    band = prediction_band(simcal, tau, vol, measured.t_s, water, simulate_at, mass_g=mass)
    inside = None if band is None else float(np.mean((measured.released_g >= band[0]) & (measured.released_g <= band[1])))
    if band is not None:
        progress(f"   {100 * inside:.0f}% of the further object's measured points lie inside its predicted "
                 f"{100 * cal_run.doc['band']['level']:.0f}% band")
    return _Prediction(measured, predicted, rel_pred, band, inside)


def _write_truth(path: Path, material: Material, truths: dict[str, dict]) -> None:
    """Write ``truth.json``: the bench's hidden material and each object's own rate and density."""
    truth = {"material": dataclasses.asdict(material), "objects": truths,
             "note": "hidden ground truth of the simulated bench; no step of the loop reads this file"}
    path.write_text(json.dumps(truth, indent=2) + "\n")


def _write_summary(result: DemoResult, design_status: str, physical: dict, cal_run: SimCalRun,
                   prediction: _Prediction) -> None:
    """Write the demo's ``summary.json``: the `DemoResult`, the run's verification, the design's status, print
    mass and narrowest channel, and the band's coverage."""
    summary = {k: str(v) if isinstance(v, Path) else v for k, v in dataclasses.asdict(result).items()}
    summary["verify_ok"] = verify_run(result.run_dir).ok
    summary["design_status"] = design_status
    summary["print_mass_g"] = physical["print_mass_g"]
    summary["min_channel_mm"] = physical["min_channel_mm"]
    if prediction.band is not None:
        summary["band"] = {"level": cal_run.doc["band"]["level"], "loo_coverage": cal_run.doc["band"]["loo_coverage"],
                           "prediction_points_inside": prediction.inside}
    result.summary_path.write_text(json.dumps(summary, indent=2) + "\n")


def _plot(run, measured, predicted: np.ndarray, designed, sample: str, path: Path,
          band: tuple[np.ndarray, np.ndarray] | None = None) -> None:
    """Left: the calibration set measured vs leave-one-out predicted; right: the further object measured,
    predicted from its mesh with its band, and the design's predicted release with its band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    doc = run.doc
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.6), dpi=110)
    for i, (shape, row) in enumerate(zip(run.loo, doc["loo"])):
        name = Path(row["mesh"]).stem
        left.plot(shape.t_s / 3600, shape.measured_g, color=f"C{i}", lw=2, label=f"{name}: measured")
        left.plot(shape.t_s / 3600, shape.predicted_g, "--", color="k", lw=1,
                  label=f"{name}: left-out prediction ({100 * shape.rel_rmse:.1f}%)")
    left.set_title(f"calibration: {doc['seconds_per_mm']:.0f} s/mm, {doc['g_per_mm3'] * 1000:.3f} g/cm$^3$ effective "
                   f"({doc['model']} model)\nprint physics kept: {_physics_line(doc['physics'])}", fontsize=10)
    level = (doc.get("band") or {}).get("level")
    if band is not None:
        right.fill_between(measured.t_s / 3600, band[0], band[1], color="C3", alpha=0.15, lw=0,
                           label=f"{100 * level:.0f}% band of the prediction")
    low, high = (f"design_released_g_{q}" for q in quantile_columns())
    if high in (designed.dtype.names or ()):
        right.fill_between(designed["t_s"] / 3600, designed[low], designed[high], color="C2", alpha=0.15, lw=0,
                           label=f"{100 * level:.0f}% band of the design")
    right.plot(measured.t_s / 3600, measured.released_g, color="C0", lw=2.5, label=f"{sample}: measured")
    right.plot(measured.t_s / 3600, predicted, "--", color="C3", lw=1.5, label=f"{sample}: predicted from its mesh")
    right.plot(designed["t_s"] / 3600, designed["design_released_g"], "-", color="C2", lw=1.5,
               label="design for the measured curve (predicted)")
    coverage = (doc.get("band") or {}).get("loo_coverage")
    right.set_title("a further object, and a design from its measured curve" + (
        "" if coverage is None else f"\nleave-one-out: {100 * coverage['fraction']:.0f}% of held-out points inside "
                                    f"their {100 * level:.0f}% bands"), fontsize=10)
    for ax in (left, right):
        ax.set_xlabel("time since drop (h)")
        ax.set_ylabel("released (g)")
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right", fontsize=7)
    fig.suptitle("sfr demo: measure -> calibrate -> design on the simulated bench (hidden material)", fontsize=11)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
