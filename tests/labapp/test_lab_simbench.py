"""The simulated bench: nominal unit mapping, the forward-simulated sample, and device faults during a run."""
import numpy as np
import pytest

from labapp.clock import SteppedClock
from labapp.engine import Engine
from labapp.procedures import RunConfig, RunProcedure
from labapp.simbench import DENSITY_G_PER_MM3, SECONDS_PER_MM, SampleRelease, SimulatedBench, sample_release
from labapp.storage import read_run, verify_run


def _sphere(radius_mm=6.82):
    tau = np.linspace(0.0, radius_mm, 400)
    return SampleRelease.from_simulation("sphere", tau, 4 / 3 * np.pi * (radius_mm ** 3 - (radius_mm - tau) ** 3))


def test_nominal_constants_map_a_sphere_to_grams_and_hours():
    release = _sphere()
    assert release.mass_g == pytest.approx(4 / 3 * np.pi * 6.82 ** 3 * 1.32e-3)   # 1.32 g/cm^3
    assert release.duration_s == pytest.approx(6.82 * SECONDS_PER_MM)
    assert release.conc_g_per_kg(-5.0) == 0.0
    assert release.conc_g_per_kg(1e9) == pytest.approx(release.mass_g / 0.5)       # 500 g of water
    assert DENSITY_G_PER_MM3 == 1.32e-3


def test_the_shipped_sample_dissolves_in_about_three_hours():
    release = sample_release("sphere", resolution=32)
    assert release.mass_g == pytest.approx(1.75, rel=0.03)
    assert 2.5 * 3600 < release.duration_s < 3.5 * 3600
    assert np.all(np.diff(release.released_g) >= -1e-9)


def test_faults_during_a_simulated_run_are_logged_and_the_run_goes_on(tmp_path, sim_calibration):
    calibration, _ = sim_calibration
    clock = SteppedClock()
    sim = SimulatedBench(clock, release=_sphere())
    try:
        config = RunConfig(interval_s=11, max_duration_s=800, stop_on_steady=False, auto_drop=True,
                           stable_step_s=120, keepalive_s=0.2, frame_bytes_estimate=100_000)
        proc = RunProcedure(config, sim.bench(), tmp_path, calibration)
        engine = Engine(clock)

        def inject(event):
            if event.kind == "frame":
                {5: lambda: sim.camera_busy(1), 10: lambda: sim.corrupt_frames(1),
                 15: lambda: sim.drop_hotplate_link(300.0)}.get(event.data["index"], lambda: None)()
        engine.subscribe(inject)
        assert engine.run(proc) == "complete"
    finally:
        sim.close()
    log = (proc.run.path / "events.log").read_text()
    assert "camera busy" in log                                         # camera busy: that slot is skipped
    assert "frame_000011.jpg: could not analyse" in log                 # corrupt frame: kept, not analysed
    assert "hotplate link" in log                                       # link dropped (and restored)
    snap = read_run(proc.run.path)
    assert snap.status == "complete" and snap.frames[-1].t_s >= 800
    assert verify_run(proc.run.path).ok
    slots = round(snap.frames[-1].t_s / 11) + 1
    assert len(snap.frames) == slots - 1                                # every slot but the busy one
