"""The barrier's speed in `calibrate-sim` (coated rows of the set file) and a two-material design from a measured
curve through the calibration (`labapp.jobs.calibrate_barrier`, `labapp.jobs.design_barrier_measured`)."""
from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from design.files import twomaterial_outputs
from design.forward.reference import reference_release
from design.inverse.twomaterial_problem import TwoMaterialSettings
from labapp.cli.main import main
from labapp.jobs.calibrate_barrier import coat_thickness_mm, split_coated
from labapp.jobs.calibrate_sim import calibrate_sim
from labapp.jobs.design_barrier_measured import design_barrier_measured, write_barrier_target
from labapp.records.curvefiles import PhysicalCurve
from labapp.records.simcal import SimCalError, load_simcal
from labapp.records.simcalset import read_set
from tests.labapp.jobs.simcal_sets import write_run

K, RHO, S, COAT = 1500.0, 1.3e-3, 0.35, 0.5
"""The synthetic bench: seconds per mm, g per mm^3, the barrier's speed, the coat, mm."""


@pytest.fixture(autouse=True)
def _no_reference(monkeypatch):
    # the design's reference evaluator takes minutes; these tests check the jobs, not the evaluator
    monkeypatch.setattr(twomaterial_outputs, "REFERENCE_MODULE", "design.forward.no_such_module")


def _box_and_coat(coat=COAT):
    drug = trimesh.creation.box((4.0, 4.0, 2.0))
    return drug, trimesh.creation.box((4.0 + 2 * coat, 4.0 + 2 * coat, 2.0 + 2 * coat))


@pytest.mark.parametrize("kind", ["block", "shell"])
def test_the_coat_is_measured_from_a_coated_block_or_the_coats_own_solid(kind):
    drug, block = _box_and_coat()
    barrier = block if kind == "block" else trimesh.boolean.difference([block, drug], engine="manifold")
    # every point of the box's faces is exactly 0.5 mm from the block's faces (float32 point-triangle distances)
    assert coat_thickness_mm(drug, barrier, "set.csv row 3") == pytest.approx(COAT, abs=1e-6)


@pytest.mark.parametrize("barrier,message", [
    (trimesh.creation.box((5.0, 5.0, 4.0)), "0.500 to 1.000 mm thick"),             # thicker on the z faces
    (trimesh.creation.box((5.0, 5.0, 2.0)), "lie on the print's surface"),           # z faces open
])
def test_a_coat_that_is_uneven_or_open_is_refused_naming_the_row(barrier, message):
    drug, _ = _box_and_coat()
    with pytest.raises(SimCalError, match=message) as exc:
        coat_thickness_mm(drug, barrier, "set.csv row 3")
    assert "set.csv row 3" in str(exc.value)


def _coated_curve(drug_tau, drug_vol, index: int, rng) -> tuple[np.ndarray, np.ndarray, float]:
    """A coated print's measured curve as the bench makes it: the drug's release delayed by c / s, with the print's
    own rate and density (1.5 % and 2 % spread) and 0.2 % noise."""
    k, rho = K * (1 + 0.015 * rng.standard_normal()), RHO * (1 + 0.02 * rng.standard_normal())
    t = np.arange(0.0, k * (COAT / S + drug_tau[-1]) * 1.1, 30.0)
    g = rho * np.interp(t / k - COAT / S, drug_tau, drug_vol, left=0.0)
    return t, g + rng.normal(0.0, 0.002 * g.max(), t.size), rho * drug_vol[-1]


def _set(tmp_path, coated: int = 3, uncoated: int = 2) -> tuple:
    rng = np.random.default_rng(5)
    drug, coat = _box_and_coat()
    coat.export(tmp_path / "coat.stl")
    ref = reference_release(drug, np.linspace(0.0, 1.0, 201))
    rows = []
    for i, mesh in enumerate([trimesh.creation.box((3.0, 3.0, 3.0)), trimesh.creation.box((4.0, 2.0, 2.0))][:uncoated]):
        r = reference_release(mesh, np.linspace(0.0, 1.5, 301))
        t = np.arange(0.0, K * r.tau_mm[-1] * 1.1, 30.0)
        g = RHO * np.interp(t / K, r.tau_mm, r.released_mm3)
        rows.append(write_run(tmp_path, f"plain{i}", mesh, t, g, RHO * r.released_mm3[-1]) + ",")
    for i in range(coated):
        t, g, mass = _coated_curve(ref.tau_mm, ref.released_mm3, i, rng)
        rows.append(write_run(tmp_path, f"coated{i}", drug, t, g, mass) + ",coat.stl")
    (tmp_path / "set.csv").write_text("\n".join(["run,mesh,object_mass_g,water_g,barrier_mesh", *rows]) + "\n")
    return tmp_path / "set.csv"


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """The synthetic set calibrated once (resolution 16, no print physics, the constant model): its folder and run."""
    folder = tmp_path_factory.mktemp("barrier-set")
    return folder, calibrate_sim(_set(folder), None, folder / "simcal", resolution=16, physics="none", model="constant")


def test_calibrate_sim_fits_the_barrier_speed_from_the_coated_rows(calibrated):
    tmp_path, run = calibrated
    b = run.doc["barrier"]
    # the drug is calibrated on the two uncoated rows only (a coated row's delay is not the drug's rate)
    assert len(run.doc["loo"]) == 2 and run.doc["seconds_per_mm"] == pytest.approx(K, rel=0.02)
    # s from the three coated prints within 3 standard errors (the prints' own scatter and the noise), SE < 2 %
    assert abs(b["speed"] - S) <= 3 * b["error"] and 0 < b["error"] < 0.02 * S
    assert [r["coat_mm"] for r in b["runs"]] == pytest.approx([COAT] * 3, abs=1e-6)
    assert all(str(tmp_path / "coat.stl") in p for p in b["inputs_sha256"] if p.endswith("coat.stl"))
    simcal = load_simcal(run.path)
    assert simcal.barrier["speed"] == b["speed"] and simcal.barrier["error"] == b["error"]


def test_the_command_prints_the_barrier_speed(calibrated, capsys):
    from labapp.cli.commands.calibrate_sim import print_summary

    print_summary(calibrated[1].doc)
    b = calibrated[1].doc["barrier"]
    assert f"barrier speed {b['speed']:.4f} +- {b['error']:.4f} from 3 coated prints" in capsys.readouterr().out


def test_a_set_with_coated_rows_needs_two_uncoated_and_existing_barrier_meshes(tmp_path):
    set_csv = _set(tmp_path, coated=2, uncoated=1)
    with pytest.raises(SimCalError, match="1 rows without a barrier_mesh"):
        split_coated(set_csv, read_set(set_csv))
    set_csv.write_text(set_csv.read_text().replace("coat.stl", "nowhere.stl"))
    with pytest.raises(SimCalError, match="row 2: barrier_mesh 'nowhere.stl' does not exist"):
        read_set(set_csv)


def test_an_evaluation_refuses_coated_rows_before_any_work(calibrated, tmp_path):
    from labapp.jobs.evaluate import evaluate_models

    with pytest.raises(SimCalError, match="rows 3, 4, 5 name a barrier_mesh"):
        evaluate_models(calibrated[0] / "set.csv", None, tmp_path / "evaluation")
    assert not (tmp_path / "evaluation").exists()


def _delayed_curve(tmp_path) -> PhysicalCurve:
    """A measured delay-then-constant-rate curve: nothing for 1.5 mm of drug, then 20 mm^3/mm for 1 mm."""
    rng = np.random.default_rng(2)
    t = np.arange(0.0, K * 3.5, 30.0)
    g = RHO * 20.0 * np.clip(t / K - 1.5, 0.0, 1.0) + rng.normal(0.0, 2e-4, t.size)
    np.savetxt(tmp_path / "measured.csv", np.column_stack([t, g]), delimiter=",", header="t_s,released_g", comments="")
    return PhysicalCurve(t, g, None, None, str(tmp_path / "measured.csv"))


def test_a_measured_delayed_curve_becomes_a_target_with_its_delay(tmp_path, calibrated):
    simcal = load_simcal(calibrated[1].path)
    notes = write_barrier_target(_delayed_curve(tmp_path), simcal, tmp_path / "target.csv")
    data = np.genfromtxt(tmp_path / "target.csv", delimiter=",", names=True)
    k = simcal.cal.seconds_per_mm
    # nothing before the release exceeds 5 % of its final level (0.05 mm of drug after the delay of 1.5 mm), then the
    # rate; all of it within 5 % of the end (the measured curve's level errors at both ends are not pulses or pauses)
    first = data["tau_mm"][np.argmax(data["released_mm3"] > 0)]
    assert 1.5 * K / k <= first <= (1.5 + 0.05) * K / k + 30.0 / k and notes["zeroed_until_s"] >= 1.5 * K - 30.0
    full = data["tau_mm"][np.argmax(data["released_mm3"] >= data["released_mm3"][-1])]
    assert full <= 2.5 * K / k + 30.0 / k
    assert data["released_mm3"][-1] == pytest.approx(20.0 * RHO / simcal.cal.g_per_mm3, rel=0.01)


def test_a_design_from_a_measured_curve_takes_the_calibrated_speed_and_maps_back(tmp_path, capsys, calibrated):
    simcal = load_simcal(calibrated[1].path)
    _delayed_curve(tmp_path)
    out = tmp_path / "design"
    argv = ["design", "--target", str(tmp_path / "measured.csv"), "--barrier-speed", "--resolution", "16",
            "--max-iter", "4", "--out", str(out)]
    assert main(argv) == 2                                  # no calibration: refused, nothing written
    assert "give --simcal" in capsys.readouterr().err and not out.exists()
    assert main(argv + ["--simcal", str(simcal.path)]) == 0
    text = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    physical = json.loads((out / "physical.json").read_text())
    assert summary["barrier_speed"] == simcal.barrier["speed"] and physical["speed_source"] == "calibrated"
    assert "measured target" in text and physical["rel_rmse_physical"] >= 0
    header = (out / "curves_physical.csv").read_text().splitlines()[0]
    assert header == "t_s,measured_g,target_g,design_released_g"


def test_the_calibrated_speed_needs_a_calibration_that_has_one(tmp_path, capsys, calibrated):
    simcal = load_simcal(calibrated[1].path)
    doc = json.loads(simcal.path.read_text())
    del doc["barrier"]
    (tmp_path / "plain.json").write_text(json.dumps(doc))
    _delayed_curve(tmp_path)
    out = tmp_path / "design"
    assert main(["design", "--target", str(tmp_path / "measured.csv"), "--simcal", str(tmp_path / "plain.json"),
                 "--barrier-speed", "--resolution", "16", "--out", str(out)]) == 2
    assert "has none: calibrate with coated prints" in capsys.readouterr().err and not out.exists()


def test_the_job_refuses_an_out_that_is_its_input(tmp_path, calibrated):
    simcal = load_simcal(calibrated[1].path)
    _delayed_curve(tmp_path)
    settings = TwoMaterialSettings(str(tmp_path / "measured.csv"), 0.35, resolution=16, max_iter=2)
    with pytest.raises(Exception, match="measured.csv"):
        design_barrier_measured(settings, tmp_path / "measured.csv", simcal)
