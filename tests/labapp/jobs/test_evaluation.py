"""`sfr evaluate` (Fig. 8 report) and `sfr simulate --model mc`'s job on a small synthetic calibration set."""
import json

import numpy as np
import pytest

from design.forward.reference import design_lattice, reference_release
from design.geometry.shapes import sample_shape
from design.montecarlo.erosion import MonteCarloParams
from labapp.cli.main import main
from labapp.jobs.simulate_mc import McCalibration, load_mc_calibration, simulate_mc_job
from labapp.records.curvefiles import read_physical_curve

SECONDS_PER_MM = 1500.0
G_PER_MM3 = 1.3e-3
RESOLUTION = 16


@pytest.fixture(scope="module")
def calibration_set(tmp_path_factory):
    """Three objects 'measured' as the release the calibration simulates (the reference evaluator's exact one,
    which the calibration's grid release is corrected to) at a known time and mass scale."""
    root = tmp_path_factory.mktemp("set")
    rows = ["run,mesh,object_mass_g,water_g"]
    for name in ("sphere", "pill", "spinner_top"):
        mesh = sample_shape(name)
        mesh.export(root / f"{name}.stl")
        tau = np.linspace(0.0, 0.5 * max(mesh.extents), 1025)
        release = reference_release(mesh, tau, cells=design_lattice(RESOLUTION))
        t = np.arange(0.0, release.total_time_mm * SECONDS_PER_MM * 1.1, 30.0)
        grams = np.interp(t / SECONDS_PER_MM, tau, release.released_mm3) * G_PER_MM3
        mass = float(release.volume_mm3 * G_PER_MM3)
        np.savetxt(root / f"{name}.csv", np.column_stack([t, grams]), delimiter=",", header="t_s,released_g",
                   comments="", fmt="%.6f")
        rows.append(f"{name}.csv,{name}.stl,{mass:.6f},500")
    (root / "set.csv").write_text("\n".join(rows) + "\n")
    return root


@pytest.mark.slow
def test_evaluate_writes_the_fig8_table_picture_and_a_monte_carlo_calibration(calibration_set, tmp_path, capsys):
    out = tmp_path / "eval"
    assert main(["evaluate", str(calibration_set / "set.csv"), "--out", str(out), "--resolution", str(RESOLUTION),
                 "--seeds", "2"]) == 0
    assert "| **mean** |" in capsys.readouterr().out
    doc = json.loads((out / "evaluation.json").read_text())
    assert len(doc["objects"]) == 3
    for row in doc["objects"]:
        # the data are the forward model's own release: its leave-one-out prediction is near exact
        assert row["rms_pct_forward"] < 1.0 and row["f2_forward"] > 85
        assert row["rms_pct_mc"] < 10.0 and row["f2_mc"] is not None
    assert len(doc["mc_calibration"]["grid"]) == 16
    for name in ("evaluation.csv", "evaluation.md", "evaluation.png", "simcal/simcal.json"):
        assert (out / name).stat().st_size > 0, name
    mc = load_mc_calibration(out / "mc.json")
    assert mc.params.dx_mm > 0 and mc.g_per_mm3 == pytest.approx(G_PER_MM3, rel=0.05)
    capsys.readouterr()
    assert main(["evaluate", str(calibration_set / "set.csv"), "--out", str(out)]) == 2  # never over its results
    assert "already holds a model evaluation folder" in capsys.readouterr().err


def test_simulate_mc_writes_the_forward_models_files(tmp_path):
    calibration = McCalibration(MonteCarloParams(0.05, 5000.0), g_per_mm3=1.3e-3, water_g=500.0)
    out = tmp_path / "mc"
    result = simulate_mc_job("sample:sphere", out, calibration, resolution=12, seeds=3)
    for name in ("release.csv", "release_physical.csv", "summary.json", "release.png"):
        assert (out / name).is_file(), name
    curve = read_physical_curve(out)  # sfr compare reads it like any physical curve
    assert curve.released_g[-1] == pytest.approx(result.release.volume_mm3 * 1.3e-3, rel=1e-5)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["model"] == "mc" and summary["seeds"] == [0, 1, 2]
    assert summary["physical"]["release"]["mdt_s"] > 0


def test_sfr_simulate_model_mc_takes_a_calibration_and_refuses_the_forward_ones(tmp_path, capsys):
    mc_json = tmp_path / "mc.json"
    mc_json.write_text(json.dumps({"format": "sfr-mc-calibration/1", "a_per_s": 0.05, "ea_j_per_mol": 5000.0,
                                   "temp_k": 343.15, "dx_mm": 1.0, "g_per_mm3": 1.3e-3, "water_g": 500.0,
                                   "resolution": 12}))
    out = tmp_path / "sim"
    assert main(["simulate", "sample:sphere", "--model", "mc", "--mc-calibration", str(mc_json), "--seeds", "2",
                 "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["grid_shape"] == [12, 12, 12] and summary["params"]["a_per_s"] != 0.05  # rescaled to its dx
    assert "Monte Carlo:" in capsys.readouterr().out
    assert main(["simulate", "sample:sphere", "--model", "mc", "--simcal", str(mc_json), "--out",
                 str(tmp_path / "x")]) == 2
    assert "--mc-calibration" in capsys.readouterr().err
    mc_json.write_text(json.dumps({"format": "sfr-simcal/1"}))
    assert main(["simulate", "sample:sphere", "--model", "mc", "--mc-calibration", str(mc_json), "--out",
                 str(tmp_path / "y")]) == 2
    assert "is not 'sfr-mc-calibration/1'" in capsys.readouterr().err


def test_sfr_simulate_simcal_summary_carries_the_release_metrics(tmp_path):
    from labapp.records.simcal import FORMAT, FORWARD_MODEL

    simcal = tmp_path / "simcal.json"
    simcal.write_text(json.dumps({"format": FORMAT, "forward_model": FORWARD_MODEL,
        "physics": {"anisotropy": 1.0, "offset_mm": 0.0}, "model": "constant",
                                  "seconds_per_mm": SECONDS_PER_MM, "g_per_mm3": G_PER_MM3, "resolution": 12,
                                  "voxel_size_mm": 1.0, "water_g": 500.0}))
    out = tmp_path / "sim"
    assert main(["simulate", "sample:sphere", "--simcal", str(simcal), "--out", str(out)]) == 0
    release = json.loads((out / "summary.json").read_text())["physical"]["release"]
    assert release["mdt_s"] > 0 and release["best_fit"]["rank"] == 1
