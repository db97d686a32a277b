"""The calibration series and the release run, walked by the engine on fake devices and a stepped clock."""
import csv
import dataclasses
import math

import numpy as np
import pytest

from analysis import BenchCalibration, analyze_run
from drivers.camera.base import DSLR_FRAME_BYTES, CameraError, CaptureMissed
from labapp.acquisition.bench import Bench
from labapp.acquisition.calseries import CalibrationProcedure, SeriesConfig
from labapp.acquisition.clock import SteppedClock
from labapp.acquisition.engine import Engine
from labapp.acquisition.events import FrameStored, Prompt, StateChanged
from labapp.acquisition.procedures import RunConfig, RunProcedure
from labapp.acquisition.settings import WATER, BathSettings
from labapp.acquisition.simbench import SimulatedBench
from labapp.records.manifests import read_run
from labapp.records.verification import verify_run
from tests.labapp.lab_fakes import SCENE, ModelHotplate, RenderCamera

WATER_G = WATER.default
FAST_BATH = BathSettings(stable_step_s=30, keepalive_s=0.02)


def _bench(clock, conc_of_t, faults=None):
    return Bench(RenderCamera(clock, conc_of_t, faults), ModelHotplate(clock), simulated=True)


@pytest.fixture(scope="module")
def calibration(tmp_path_factory):
    clock = SteppedClock(start_s=1e9)
    state = {"mass": 0.0}
    bench = _bench(clock, lambda t: state["mass"] / (WATER_G / 1000))
    bench.on_add_mass = lambda m: state.update(mass=m)
    config = SeriesConfig(crop=SCENE.default_crop(), masses_g=(0.25, 0.5, 1.0, 1.5, 2.0), settle_s=300, reduce=1,
                          bath=BathSettings(water_g=WATER_G, stable_step_s=30, keepalive_s=0.02))
    proc = CalibrationProcedure(config, bench, tmp_path_factory.mktemp("cal"))
    assert Engine(clock).run(proc) == "complete"
    with open(proc.run.path / "masses.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r["added_mass_g"]) for r in rows] == [0.0, 0.25, 0.5, 1.0, 1.5, 2.0]
    assert verify_run(proc.run.path).ok
    return BenchCalibration.load(proc.calibration_path)


def _truth(t0):
    return lambda t: 0.0 if t0[0] is None or t < t0[0] else 3.5 * (1 - math.exp(-(t - t0[0]) / 1500.0))


def test_a_simulated_run_heats_drops_acquires_and_reads_the_concentration(tmp_path, calibration):
    clock = SteppedClock(start_s=2e9)
    t0 = [None]
    bench = _bench(clock, _truth(t0))
    bench.on_drop = lambda t: t0.__setitem__(0, t)
    config = RunConfig(name="pill", interval_s=60, max_duration_s=3000, stop_on_steady=False, auto_drop=True,
                       frame_bytes_estimate=100_000, low_space_bytes=0, bath=FAST_BATH)
    engine = Engine(clock)
    frames, phases = [], []
    engine.subscribe(lambda e: frames.append(e) if isinstance(e, FrameStored) else
                     phases.append(e.phase) if isinstance(e, StateChanged) else None)
    proc = RunProcedure(config, bench, tmp_path, calibration)
    assert engine.run(proc) == "complete"
    assert phases[:3] == ["starting", "connecting", "opened"] and "heating" in phases and "acquiring" in phases
    snap = read_run(proc.run.path)
    assert snap.status == "complete" and snap.meta["reference_file"] == "reference.jpg"
    assert len(snap.frames) == 51 and snap.frames[0].t_s == 0.0 and snap.frames[-1].t_s == 3000.0
    assert all(f.probe_c is not None and abs(f.probe_c - 70) < 0.6 for f in snap.frames)
    assert snap.frames[-1].speed_rpm == 150.0
    assert bench.hotplate.log[-2:] == ["heating off", "close"] and not bench.hotplate.heating
    truth = np.array([_truth(t0)(t0[0] + f.t_s) for f in frames])
    conc = np.array([f.conc_g_per_kg for f in frames])
    assert np.sqrt(np.mean((conc - truth) ** 2)) < 0.02 * 3.5
    assert verify_run(proc.run.path).ok
    curve = analyze_run(proc.run.path, calibration)      # the offline analysis reads the same folder
    assert len(curve.t_s) == 51 and abs(curve.conc_g_per_kg[-1] - conc[-1]) < 1e-6


def test_faults_are_logged_and_the_run_goes_on(tmp_path, calibration):
    clock = SteppedClock(start_s=3e9)
    t0 = [None]
    faults = {4: CameraError, 6: CaptureMissed, 8: "corrupt", 9: CameraError, 10: CameraError, 11: CameraError}
    bench = _bench(clock, _truth(t0), faults)
    bench.on_drop = lambda t: (t0.__setitem__(0, t), setattr(bench.hotplate, "fail_reads", 3))
    config = RunConfig(interval_s=60, max_duration_s=1800, stop_on_steady=False, auto_drop=True,
                       frame_bytes_estimate=100_000, low_space_bytes=0,
                       bath=BathSettings(stable_step_s=30, keepalive_s=0.01))
    proc = RunProcedure(config, bench, tmp_path, calibration)
    assert Engine(clock).run(proc) == "complete"
    log_text = (proc.run.path / "events.log").read_text()
    for expected in ("camera-error", "camera-missed", "could not analyse", "re-initialised",
                     "hotplate link lost", "hotplate link restored"):
        assert expected in log_text, expected
    snap = read_run(proc.run.path)
    assert len(snap.frames) == 31 - 5 and verify_run(proc.run.path).ok


def test_operator_stop_while_waiting_for_the_drop(tmp_path, calibration):
    clock = SteppedClock(start_s=4e9)
    engine = Engine(clock)
    engine.subscribe(lambda e: engine.stop() if isinstance(e, Prompt) and e.prompt == "drop" else None)
    proc = RunProcedure(RunConfig(frame_bytes_estimate=1000, bath=FAST_BATH), _bench(clock, _truth([None])),
                        tmp_path, calibration)
    assert engine.run(proc) == "stopped"
    snap = read_run(proc.run.path)
    assert snap.status == "stopped" and snap.frames == [] and "t0_unix_s" not in snap.meta


def test_config_guards():
    with pytest.raises(ValueError, match=r"RunConfig.interval_s must be > 0 s, got 0"):
        RunConfig(interval_s=0)
    with pytest.raises(ValueError, match=r"BathSettings.setpoint_c must be in \[25, 100\] C, got 400"):
        RunConfig(bath=BathSettings(setpoint_c=400))
    with pytest.raises(ValueError, match=r"masses 0.5, 0.25 g \(--masses\): each must be above the one before"):
        SeriesConfig(crop=(0, 0, 100), masses_g=(0.5, 0.25))
    with pytest.raises(ValueError, match=r"SeriesConfig.reduce must be one of 1, 2, 4, 8, got 3"):
        SeriesConfig(crop=(0, 0, 100), reduce=3)


def test_the_disk_check_before_a_run_uses_the_benchs_frame_size(tmp_path, calibration, monkeypatch):
    monkeypatch.setattr("labapp.records.fileio.free_bytes", lambda folder: 10**9)  # 1 GB free
    config = RunConfig(max_duration_s=3600, bath=FAST_BATH)  # 328 frames at 11 s
    clock = SteppedClock(start_s=4e9)
    dslr = _bench(clock, _truth([None]))  # 15 MB a frame: 328 x 15 MB x 1.5 = 7.4 GB do not fit
    assert dslr.frame_bytes == DSLR_FRAME_BYTES
    engine = Engine(clock)
    assert engine.run(RunProcedure(config, dslr, tmp_path / "dslr", calibration)) == "failed"
    assert not (tmp_path / "dslr").exists()  # refused before any folder is made
    # 200 kB frames (a simulated camera's JPEGs): 98 MB fit, and the run starts
    small = dataclasses.replace(dslr, frame_bytes=200_000)
    engine = Engine(clock)
    engine.subscribe(lambda e: engine.stop() if isinstance(e, Prompt) and e.prompt == "drop" else None)
    proc = RunProcedure(config, small, tmp_path / "small", calibration)
    assert engine.run(proc) == "stopped" and proc.run.path.is_dir()


def test_a_simulated_bench_estimates_its_frames_from_its_image_size():
    sim = SimulatedBench(SteppedClock(start_s=4e9), sample="sphere")
    # its JPEGs are below their raw RGB size, far below a DSLR's raw capture
    assert sim.bench().frame_bytes == 3 * sim.scene.width * sim.scene.height < DSLR_FRAME_BYTES
