"""Recording a calibration series: the job the GUI and `sfr calibrate-bench --record` share, walked headless on the
simulated bench with an instant clock."""
import csv
import io
import json

import numpy as np
import pytest

from analysis import BenchCalibration
from labapp.acquisition.bench import Bench
from labapp.acquisition.clock import SteppedClock
from labapp.acquisition.settings import INSTANT_STABLE_STEP_S, SERIES_REDUCE, SETTLE, BathSettings
from labapp.cli.main import main
from labapp.errors import UsageError
from labapp.jobs.series import new_series, simulated_series_bench
from labapp.records.manifests import read_run
from labapp.records.verification import verify_run
from tests.labapp.lab_fakes import SCENE, ModelHotplate, RenderCamera

QUICK_BATH = ("--setpoint", "25", "--tolerance", "1", "--hold", "30")
"""A bath the emulated plate holds within a few simulated minutes (every poll of it takes real time)."""


def _levels(folder):
    with open(folder / "masses.csv") as fh:
        return [float(r["added_mass_g"]) for r in csv.DictReader(fh)]


def test_sfr_records_a_series_on_the_simulated_bench_and_fits_it(tmp_path, capsys):
    data = tmp_path / "data"
    assert main(["calibrate-bench", "--record", str(data), "--simulate", "--speed", "0", "--masses", "0.25,0.5,1,1.5",
                 *QUICK_BATH, "--water-g", "400"]) == 0
    out = capsys.readouterr().out
    (folder,) = data.iterdir()
    assert folder.name.endswith("_calibration") and f"calibration {folder / 'bench_calibration.json'}" in out
    assert _levels(folder) == [0.0, 0.25, 0.5, 1.0, 1.5] and "level 4: cal_004.jpg, 1.5 g added" in out
    assert verify_run(folder).ok
    snap = read_run(folder)
    assert snap.status == "complete" and snap.meta["kind"] == "calibration-series" and snap.meta["simulated"]
    config = snap.meta["config"]                 # the settings, in the flat layout of every run.json
    assert (config["setpoint_c"], config["tolerance_c"], config["hold_s"]) == (25.0, 1.0, 30.0)
    assert (config["water_g"], config["settle_s"]) == (400.0, SETTLE.default)
    assert (config["stable_step_s"], config["reduce"]) == (INSTANT_STABLE_STEP_S, SERIES_REDUCE.default)
    cal = BenchCalibration.load(folder / "bench_calibration.json")
    assert cal.water_g == 400.0 and cal.reduce == SERIES_REDUCE.default
    assert np.unique(np.round(cal.conc_levels_g_per_kg, 6)).tolist() == [0.0, 0.625, 1.25, 2.5, 3.75]
    assert cal.good.mean() > 0.9


def test_the_operator_enters_each_mass_at_the_prompt(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("sys.stdin", io.StringIO("0.25\nabc\n0.5\n1\n\n"))
    data = tmp_path / "data"
    assert main(["calibrate-bench", "--record", str(data), "--simulate", "--speed", "0", "--settle", "0", *QUICK_BATH]) == 0
    out = capsys.readouterr().out
    (folder,) = data.iterdir()
    assert _levels(folder) == [0.0, 0.25, 0.5, 1.0]
    assert ">>> Add filament" in out and "'abc': expected the cumulative mass in g, >= 0 g" in out
    assert json.loads((folder / "run.json").read_text())["config"]["settle_s"] == 0.0


@pytest.mark.parametrize("argv, says", [
    (["calibrate-bench", "--record", "D", "--simulate", "FOLDER"], "a FOLDER to fit does not go with it"),
    (["calibrate-bench", "--record", "D", "--simulate", "--no-mirror"], "--no-mirror does not go with it"),
    (["calibrate-bench", "--record", "D", "--camera-spec", "folder:/nowhere"], "needs --crop"),
    (["calibrate-bench"], "give the calibration-series FOLDER to fit, or --record DATA_DIR"),
])
def test_what_does_not_go_with_record(argv, says, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    assert says in capsys.readouterr().err
    assert not (tmp_path / "D").exists()


def test_a_real_bench_cannot_add_masses_by_itself(tmp_path):
    clock = SteppedClock()
    bench = Bench(RenderCamera(clock, lambda t: 0.0), ModelHotplate(clock))
    with pytest.raises(UsageError, match=r"only the simulated bench adds filament by itself"):
        new_series(bench, tmp_path, SCENE.default_crop(), masses_g=(0.25, 0.5))
    proc = new_series(bench, tmp_path, SCENE.default_crop(), bath=BathSettings(setpoint_c=50.0))
    assert proc.config.settle_s == 0.0 and proc.config.bath.setpoint_c == 50.0 and proc.config.bath.stable_step_s == 5.0
    assert not any(tmp_path.iterdir())                     # built and checked, nothing written
    simulated = Bench(bench.camera, bench.hotplate, simulated=True, on_add_mass=lambda m: None)
    proc = new_series(simulated, tmp_path, SCENE.default_crop(), masses_g=(0.25, 0.5), clock_speed=float("inf"))
    assert proc.config.settle_s == SETTLE.default and proc.config.bath.stable_step_s == INSTANT_STABLE_STEP_S


def test_the_simulated_series_bench_holds_the_baths_water():
    sim = simulated_series_bench(SteppedClock(), water_g=400.0)
    try:
        assert sim.scene.water_g == 400.0 and sim.scene.intrusion_probability == 0.0
        sim.add_mass(1.0)
        assert sim.conc_at(sim.clock.now()) == pytest.approx(2.5)      # g/kg
    finally:
        sim.close()
