"""The simulated bench: its hidden material, the forward-simulated sample, and device faults during a run."""
import numpy as np
import pytest

from labapp.acquisition.clock import SteppedClock
from labapp.acquisition.engine import Engine
from labapp.acquisition.events import FrameStored
from labapp.acquisition.procedures import RunConfig, RunProcedure
from labapp.acquisition.settings import BathSettings
from labapp.acquisition.simbench import Material, SampleRelease, SimulatedBench, sample_release
from labapp.records.manifests import read_run
from labapp.records.verification import verify_run


def _sphere(radius_mm=6.82):
    tau = np.linspace(0.0, radius_mm, 400)
    return SampleRelease.from_simulation("sphere", tau, 4 / 3 * np.pi * (radius_mm ** 3 - (radius_mm - tau) ** 3),
                                         1600.0, 1.32e-3)


def test_an_object_maps_to_grams_and_hours_with_its_own_scales():
    release = _sphere()
    assert release.mass_g == pytest.approx(4 / 3 * np.pi * 6.82 ** 3 * 1.32e-3)
    assert release.duration_s == pytest.approx(6.82 * 1600.0)
    assert release.truth["mass_g"] == pytest.approx(release.mass_g)
    assert release.conc_g_per_kg(-5.0) == 0.0
    assert release.conc_g_per_kg(1e9) == pytest.approx(release.mass_g / 0.5)       # 500 g of water


def test_the_hidden_material_and_each_print_differ_by_seeded_draws():
    material = Material.draw()
    assert 1000 <= material.seconds_per_mm <= 2400 and 1.15 <= material.density_g_per_cm3 <= 1.45
    assert Material.draw(1) != material and Material.draw() == material
    prints = np.array([material.printed(i) for i in range(40)])
    rate = prints[:, 0] / material.seconds_per_mm - 1
    dens = prints[:, 1] / (material.density_g_per_cm3 * 1e-3) - 1
    assert 0.007 < rate.std() < 0.03 and 0.01 < dens.std() < 0.04        # a few percent, every print its own
    assert material.printed(3) == material.printed(3) != material.printed(4)


def test_the_shipped_sample_dissolves_in_hours():
    material = Material(1500.0, 1.3)
    release = sample_release("sphere", index=0, resolution=32, material=material)
    seconds_per_mm, g_per_mm3 = material.printed(0)
    assert release.truth["seconds_per_mm"] == seconds_per_mm and release.truth["g_per_mm3"] == g_per_mm3
    assert release.mass_g == pytest.approx(1326 * g_per_mm3, rel=0.03)
    assert 2.0 * 3600 < release.duration_s < 3.5 * 3600
    assert np.all(np.diff(release.released_g) >= -1e-9)


@pytest.mark.slow
def test_faults_during_a_simulated_run_are_logged_and_the_run_goes_on(tmp_path, sim_calibration):
    calibration, _ = sim_calibration
    clock = SteppedClock()
    sim = SimulatedBench(clock, release=_sphere())
    try:
        config = RunConfig(interval_s=11, max_duration_s=800, stop_on_steady=False, auto_drop=True,
                           frame_bytes_estimate=100_000, bath=BathSettings(stable_step_s=120, keepalive_s=0.2))
        proc = RunProcedure(config, sim.bench(), tmp_path, calibration)
        engine = Engine(clock)

        def inject(event):
            if isinstance(event, FrameStored):
                {5: lambda: sim.camera_busy(1), 10: lambda: sim.corrupt_frames(1),
                 15: lambda: sim.drop_hotplate_link(300.0)}.get(event.index, lambda: None)()
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


def test_the_simulated_beaker_holds_the_water_it_is_given():
    release = SampleRelease("step", np.array([0.0, 100.0]), np.array([0.0, 1.0]))
    sim = SimulatedBench(SteppedClock(start_s=0.0), release=release, with_hotplate=False, water_g=400.0)
    assert sim.scene.water_g == 400.0 and SimulatedBench.default_crop() == sim.scene.default_crop()
    sim.drop(0.0)
    assert sim.conc_at(200.0) == pytest.approx(2.5)          # 1 g in 400 g of water
