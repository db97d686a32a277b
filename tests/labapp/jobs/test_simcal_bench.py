"""End to end through the simulated bench: images of two dissolving prints -> sfr calibrate-sim -> the bench's
hidden material recovered. Smallest settings that still test it: a frame every 3 minutes, the bath already
hot, the meshes simulated at resolution 32 (the bench's own truth is simulated at 48)."""
import json

import pytest

from design.geometry.shapes import sample_shape
from labapp.acquisition.clock import SteppedClock
from labapp.acquisition.simbench import Material, sample_release
from labapp.cli.main import main
from labapp.jobs.demo import simulated_run


@pytest.mark.slow
def test_images_to_simcal_recover_the_hidden_material(tmp_path, sim_calibration):
    calibration, cal_path = sim_calibration
    material = Material(1300.0, 1.21)
    clock = SteppedClock()
    rows, truths = ["run,mesh,object_mass_g"], []
    for index, (shape, water) in enumerate((("sphere", 500.0), ("csg", 350.0))):
        release = sample_release(shape, index=index, resolution=48, material=material)
        run = simulated_run(clock, calibration, release, tmp_path / "runs", interval_s=180.0, water_g=water,
                            hotplate=False)
        sample_shape(shape).export(tmp_path / f"{shape}.stl")
        rows.append(f"runs/{run.name},{shape}.stl,")             # the weighed mass comes from run.json
        truths.append(release.truth)
    (tmp_path / "set.csv").write_text("\n".join(rows) + "\n")
    assert main(["calibrate-sim", str(tmp_path / "set.csv"), "--calibration", str(cal_path), "--out",
                 str(tmp_path / "cal"), "--resolution", "32", "--model", "constant"]) == 0
    doc = json.loads((tmp_path / "cal" / "simcal.json").read_text())
    mean_rate = sum(t["seconds_per_mm"] for t in truths) / 2
    mean_density = sum(t["g_per_mm3"] for t in truths) / 2
    assert doc["seconds_per_mm"] == pytest.approx(mean_rate, rel=0.02)
    assert doc["g_per_mm3"] == pytest.approx(mean_density, rel=0.02)
    assert [s["water_g"] for s in doc["shapes"]] == [500.0, 350.0]
    assert [s["object_mass_g"] for s in doc["shapes"]] == [round(t["mass_g"], 4) for t in truths]
    assert max(row["rel_rmse"] for row in doc["loo"]) < 0.03
