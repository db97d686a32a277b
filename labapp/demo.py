"""The headless demo: a complete simulated bench session on an instant clock.

calibration series -> release run of a shipped sample object (with injected device faults) -> offline
analysis -> plots and a summary. Simulated time is driven, never slept: a 3-hour run takes as long as its
frames take to render, write and analyse.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis import BenchCalibration, analyze_run, write_cells_csv, write_curve_csv
from drivers.sim import BenchScene
from labapp.calseries import CalibrationProcedure, SeriesConfig
from labapp.clock import SteppedClock
from labapp.engine import Engine, Event
from labapp.procedures import RunConfig, RunProcedure
from labapp.simbench import SCENE, WATER_G, SampleRelease, SimulatedBench, sample_release
from labapp.storage import read_run, verify_run

log = logging.getLogger(__name__)

CAL_MASSES_G = (0.25, 0.5, 0.875, 1.25, 1.75, 2.25)
"""Cumulative filament masses of the simulated calibration series, g (up to above the sample's 1.75 g)."""


@dataclass(frozen=True)
class DemoResult:
    """Where the demo put things, and how well the measured curve matches the truth."""

    out_dir: Path
    calibration_path: Path
    run_dir: Path
    curve_csv: Path
    figure: Path
    summary_path: Path
    n_frames: int
    duration_s: float
    final_conc_g_per_kg: float
    true_final_conc_g_per_kg: float
    rms_error_g_per_kg: float
    faults_logged: int
    wall_s: float


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
        config = SeriesConfig(crop=sim.scene.default_crop(), water_g=WATER_G, masses_g=CAL_MASSES_G,
                              settle_s=600.0, stable_step_s=60.0, reduce=2)
        proc = CalibrationProcedure(config, sim.bench(), out_dir)
        outcome = Engine(clock).run(proc)
    finally:
        sim.close()
    if proc.calibration_path is None:
        raise RuntimeError(f"the simulated calibration series ended '{outcome}' without a calibration; "
                           f"see {proc.run.path / 'events.log'}")
    return BenchCalibration.load(proc.calibration_path), proc.calibration_path


def _inject_faults(sim: SimulatedBench) -> Callable[[Event], None]:
    """A subscriber that injects one fault of each kind during the run (the event log must show them)."""
    def on_event(event: Event) -> None:
        if event.kind != "frame":
            return
        index = event.data["index"]
        if index == 60:
            sim.camera_busy(1)
        elif index == 120:
            sim.corrupt_frames(1)
        elif index == 180:
            sim.drop_hotplate_link(900.0)
    return on_event


def run_demo(out_dir: Path, sample: str = "pill", interval_s: float = 11.0, resolution: int = 48,
             progress: Callable[[str], None] = lambda text: None) -> DemoResult:
    """The whole simulated session; ``progress(text)`` gets one line per step and a status line per frame."""
    start = time.monotonic()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    progress(f"simulating the release of the sample object '{sample}' (forward model, {resolution} voxels) ...")
    release = sample_release(sample, resolution=resolution)
    progress(f"  {release.mass_g:.3f} g, dissolves completely in {release.duration_s / 3600:.2f} h (nominal)")
    clock = SteppedClock()
    progress("calibration series: clear water + 6 filament additions at 70 C ...")
    calibration, cal_path = simulated_calibration(out_dir / "calibration", clock)
    progress(f"  {cal_path}")
    sim = SimulatedBench(clock, release=release, scene=SCENE)
    try:
        config = RunConfig(name=f"demo-{sample}", interval_s=interval_s, max_duration_s=release.duration_s + 3600.0,
                           stop_on_steady=True, min_duration_s=0.5 * release.duration_s, water_g=WATER_G,
                           object_mass_g=round(release.mass_g, 4), object_name=sample, auto_drop=True,
                           stable_step_s=60.0, notes="sfr demo: simulated bench, nominal constants")
        proc = RunProcedure(config, sim.bench(), out_dir / "runs", calibration)
        engine = Engine(clock)
        engine.subscribe(_inject_faults(sim))
        engine.subscribe(lambda e: progress(f"  frame {e.data['index']:4d}  t={e.data['t_s'] / 60:6.1f} min  "
                                            f"{e.data['conc_g_per_kg']:.3f} g/kg")
                         if e.kind == "frame" and e.data["index"] % 100 == 0 else None)
        progress(f"release run at {interval_s:g} s per frame (3 faults injected: camera busy, corrupt frame, "
                 "hotplate link drop) ...")
        outcome = engine.run(proc)
    finally:
        sim.close()
    if outcome not in ("complete", "stopped"):
        raise RuntimeError(f"the simulated run ended '{outcome}': {engine.error}; see {proc.run.path / 'events.log'}")
    run_dir = proc.run.path
    progress(f"  {outcome}: {len(proc.run.frames)} frames in {run_dir}")
    progress("offline analysis of the run folder ...")
    curve = analyze_run(run_dir, calibration, cache_dir=run_dir / "analysis")
    analysis_dir = out_dir / "analysis"
    analysis_dir.mkdir(exist_ok=True)
    write_curve_csv(curve, analysis_dir / "curve.csv")
    write_cells_csv(curve, analysis_dir / "cells.csv")
    truth = np.array([release.conc_g_per_kg(t) for t in curve.t_s])
    rms = float(np.sqrt(np.mean((curve.conc_smooth_g_per_kg - truth) ** 2)))
    snap = read_run(run_dir)
    faults = sum(1 for line in snap.events() if "\tWARNING\t" in line)
    figure = analysis_dir / "demo.png"
    _plot(curve, release, snap, figure)
    result = DemoResult(out_dir, cal_path, run_dir, analysis_dir / "curve.csv", figure, analysis_dir / "summary.json",
                        len(curve.t_s), float(curve.t_s[-1]), float(curve.conc_smooth_g_per_kg[-1]),
                        release.conc_g_per_kg(float(curve.t_s[-1])), rms, faults, time.monotonic() - start)
    summary = {k: str(v) if isinstance(v, Path) else v for k, v in result.__dict__.items()}
    summary["verify_ok"] = verify_run(run_dir).ok
    result.summary_path.write_text(json.dumps(summary, indent=2))
    return result


def _plot(curve, release: SampleRelease, snap, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from labapp.release_plot import draw_release

    fig, (ax, bath) = plt.subplots(2, 1, figsize=(8, 7), dpi=110, sharex=True,
                                   gridspec_kw={"height_ratios": [3, 1.3]})
    draw_release(ax, curve)
    truth_t = np.linspace(0.0, curve.t_s[-1], 400)
    ax.plot(truth_t / 60.0, [release.conc_g_per_kg(t) for t in truth_t], "--", color="C3",
            label=f"truth: forward simulation of '{release.name}'")
    ax.legend(loc="lower right")
    ax.set_title("sfr demo: simulated bench, measured vs simulated release")
    t = np.array([f.t_s for f in snap.frames]) / 60.0
    bath.plot(t, [np.nan if f.probe_c is None else f.probe_c for f in snap.frames], color="C2", label="probe (C)")
    bath.plot(t, [np.nan if f.plate_c is None else f.plate_c for f in snap.frames], color="C1", label="plate (C)")
    bath.set_ylabel("temperature (C)")
    bath.set_xlabel("time since drop (min)")
    bath.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
