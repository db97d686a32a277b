"""sfr calibrate-sim / simulate --simcal / design --simcal: hidden scales recovered, the loop closed, bad input named.

Measured curves here are the simulated bench's objects (forward model at resolution 48, hidden seeded
material, each print its own few-percent deviation) sampled every 30 s with 0.2%-of-mass noise; the
calibration simulates the meshes at resolution 32, so the discretisation differs as it does on a real
bench. Tolerances are the acceptance figures: scales within 2%, leave-one-out within 3% RMS of the
weighed mass, a design's predicted release within 3% RMS of its measured target. The material has no print
physics, so these calibrations fit the scales of the isotropic model alone (``physics="none"``); that the default
(``auto``) keeps no print physics on such a bench is test_simcal_physics.py's identity case.
"""
import json

import numpy as np
import pytest

from design.geometry.shapes import sample_shape
from labapp.acquisition.simbench import Material, sample_release
from labapp.cli.main import main
from labapp.errors import UsageError
from labapp.jobs.calibrate_sim import calibrate_sim
from labapp.records.simcal import SimCalError, load_simcal
from tests.session_once import once_per_session

SHAPES = ("sphere", "pill", "spinner_top", "csg")
MATERIAL = Material(1850.0, 1.24)


def _curve(release, index, *, stop_fraction=None, shift_s=0.0, water_g=500.0):
    rng = np.random.default_rng(index)
    t = np.arange(30.0, 1.15 * release.duration_s, 30.0)
    grams = np.interp(t - shift_s, release.t_s, release.released_g, left=0.0)
    grams = grams + 0.002 * release.mass_g * rng.standard_normal(t.size)
    if stop_fraction is not None:
        keep = grams < stop_fraction * release.mass_g
        t, grams = t[keep], grams[keep]
    return t, grams, grams / water_g * 1000.0


@pytest.fixture(scope="module")
def releases(tmp_path_factory):
    """The four shapes' releases on the simulated bench (computed once per test session)."""
    return once_per_session(tmp_path_factory, "simcal-job-releases", lambda _: {
        s: sample_release(s, index=i, resolution=48, material=MATERIAL) for i, s in enumerate(SHAPES)})[1]


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory, releases):
    """The complete set calibrated with the constant model and no print physics: its folder (holding ``set/`` and
    ``cal/``, to be read only) and the calibration's document."""
    def calibrate(folder):
        return calibrate_sim(_write_set(folder / "set", releases), None, folder / "cal", resolution=32,
                             model="constant", physics="none").doc
    return once_per_session(tmp_path_factory, "simcal-job-calibrated", calibrate)


def _write_set(folder, releases, *, stop=None, shift=None, water=None, mass=None):
    """curve CSVs, meshes and SET.csv; ``stop``/``shift``/``water``/``mass``: {shape: value} overrides."""
    folder.mkdir(parents=True, exist_ok=True)
    rows = ["run,mesh,object_mass_g"]
    for i, (shape, release) in enumerate(releases.items()):
        w = (water or {}).get(shape, 500.0)
        t, grams, conc = _curve(release, i, stop_fraction=(stop or {}).get(shape),
                                shift_s=(shift or {}).get(shape, 0.0), water_g=w)
        np.savetxt(folder / f"{shape}.csv", np.column_stack([t, conc, conc, grams]), delimiter=",", comments="",
                   header="t_s,conc_g_per_kg,conc_smooth_g_per_kg,released_g", fmt="%.6f")
        sample_shape(shape).export(folder / f"{shape}.stl")
        rows.append(f"{shape}.csv,{shape}.stl,{(mass or {}).get(shape, round(release.mass_g, 4))}")
    (folder / "set.csv").write_text("\n".join(rows) + "\n")
    return folder / "set.csv"


def _true_scales(releases):
    return (np.mean([r.truth["seconds_per_mm"] for r in releases.values()]),
            np.mean([r.truth["g_per_mm3"] for r in releases.values()]))


@pytest.mark.parametrize("case", ["complete", "stopped_at_80_percent_and_30_s_drop_error"])
def test_hidden_scales_are_recovered_and_left_out_shapes_predicted(tmp_path, releases, case, request):
    if case == "complete":
        folder, doc = request.getfixturevalue("calibrated")
    else:
        folder = tmp_path
        doc = calibrate_sim(_write_set(tmp_path / "set", releases, stop={"pill": 0.8}, shift={"csg": 30.0}), None,
                            tmp_path / "cal", resolution=32, model="constant", physics="none").doc
    rate, g_per_mm3 = _true_scales(releases)
    assert doc["seconds_per_mm"] == pytest.approx(rate, rel=0.02)
    assert doc["g_per_mm3"] == pytest.approx(g_per_mm3, rel=0.02)
    assert [row["rel_rmse"] < 0.03 for row in doc["loo"]] == [True] * 4
    assert {"water_g", "model", "resolution", "loss", "inputs_sha256"} <= set(doc)
    assert len(doc["inputs_sha256"]) == 1 + 2 * 4 and doc["resolution"] == 32
    assert set(doc["models"]) == {"constant"}
    if case != "complete":
        pill, csg = doc["shapes"][1], doc["shapes"][3]
        assert pill["measured_fraction"] < 0.8
        assert csg["offset_s"] > 10.0       # the late drop is seen (with the print's own rate spread folded in)
    loo_csv = (folder / "cal" / "loo.csv").read_text().splitlines()
    assert loo_csv[0] == "run,mesh,model,rel_rmse,seconds_per_mm_without_it" and len(loo_csv) == 1 + 4
    assert (folder / "cal" / "simcal.png").stat().st_size > 10_000
    with pytest.raises(UsageError, match="already holds a simulation calibration"):
        calibrate_sim(folder / "set" / "set.csv", None, folder / "cal", resolution=32)


def test_different_water_masses_share_one_calibration(tmp_path, releases):
    run = calibrate_sim(_write_set(tmp_path / "set", releases, water={"sphere": 300.0, "csg": 800.0}), None,
                        tmp_path / "cal", resolution=32, physics="none")   # model auto: both, the better one used
    assert set(run.doc["models"]) == {"constant", "saturation"}
    assert len((tmp_path / "cal" / "loo.csv").read_text().splitlines()) == 1 + 2 * 4
    waters = [s["water_g"] for s in run.doc["shapes"]]
    assert waters == pytest.approx([300.0, 500.0, 500.0, 800.0], rel=1e-4)      # read back from released/conc
    assert run.doc["seconds_per_mm"] == pytest.approx(_true_scales(releases)[0], rel=0.02)
    assert run.doc["water_g"] == pytest.approx(500.0, rel=1e-4)


@pytest.mark.slow
def test_the_loop_measured_curve_to_design_within_3_percent(tmp_path, releases):
    set_csv = _write_set(tmp_path / "set", dict(list(releases.items())[:3]))
    calibrate_sim(set_csv, None, tmp_path / "cal", resolution=32, model="constant", physics="none")
    simcal = tmp_path / "cal" / "simcal.json"
    further = sample_release("polyhedron", index=7, resolution=48, material=MATERIAL)
    t, grams, conc = _curve(further, 7)
    target = tmp_path / "measured.csv"
    np.savetxt(target, np.column_stack([t, grams, conc]), delimiter=",", comments="",
               header="t_s,released_g,conc_smooth_g_per_kg", fmt="%.6f")
    assert main(["design", "--target", str(target), "--out", str(tmp_path / "none"), "--max-iter", "2"]) == 2
    assert not (tmp_path / "none" / "config.json").exists()
    out = tmp_path / "design"
    assert main(["design", "--target", str(target), "--simcal", str(simcal), "--resolution", "36",
                 "--max-iter", "100", "--allow-infeasible", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["rel_rmse_physical"] < 0.03
    assert summary["print_mass_g"] == pytest.approx(further.mass_g, rel=0.05)
    rows = np.genfromtxt(out / "curves_physical.csv", delimiter=",", names=True)
    assert rows.dtype.names == ("t_s", "target_released_g", "design_released_g", "design_released_g_q05",
                                "design_released_g_q95")
    np.testing.assert_allclose(rows["t_s"], t)
    assert np.all(rows["design_released_g_q05"] <= rows["design_released_g"])
    assert np.all(rows["design_released_g"] <= rows["design_released_g_q95"])
    assert (out / "report.png").is_file() and (out / "report_simulation.png").is_file()


def test_simulate_with_simcal_writes_the_physical_curve_and_refuses_another_resolution(tmp_path, releases,
                                                                                      calibrated):
    simcal = calibrated[0] / "cal" / "simcal.json"
    assert main(["simulate", "sample:pill", "--simcal", str(simcal), "--out", str(tmp_path / "sim")]) == 0
    rows = np.genfromtxt(tmp_path / "sim" / "release_physical.csv", delimiter=",", names=True)
    assert rows.dtype.names == ("t_s", "released_g", "conc_g_per_kg", "released_g_q05", "released_g_q95")
    truth = releases["pill"]
    assert rows["released_g"][-1] == pytest.approx(truth.mass_g, rel=0.03)
    half = [np.interp(0.5 * c["released_g"][-1], c["released_g"], c["t_s"]) for c in (rows, truth.__dict__)]
    assert half[0] == pytest.approx(half[1], rel=0.03)                  # half released at the true time
    np.testing.assert_allclose(rows["conc_g_per_kg"], rows["released_g"] * 2.0, atol=1e-5)
    with pytest.raises(SimCalError, match="calibrated at resolution 32, not 48"):    # the grid model's voxels
        _raise_through(["simulate", "sample:pill", "--simcal", str(simcal), "--model", "grid", "--resolution", "48",
                        "--out", str(tmp_path / "s2")])


def _raise_through(argv):
    """Run a command's ``run`` directly so that its error is seen, not just its exit code."""
    from labapp.cli.main import build_parser

    args = build_parser().parse_args(argv)
    args._run(args)


def test_bad_calibration_files_are_refused(tmp_path, calibrated):
    doc = json.loads((calibrated[0] / "cal" / "simcal.json").read_text())
    for change, message in ((dict(model="cubic"), "model 'cubic' is not one of"),
                            (dict(format="sfr-bench-calibration/1"), "format 'sfr-bench-calibration/1' is not"),
                            (dict(forward_model="other"), "calibrated for the simulator 'other'"),
                            (dict(seconds_per_mm=-1), "seconds_per_mm = -1.0 must be positive")):
        bad = tmp_path / f"bad_{len(change)}_{list(change)[0]}.json"
        bad.write_text(json.dumps({**doc, **change}))
        with pytest.raises(SimCalError, match=message):
            load_simcal(bad)


@pytest.mark.parametrize("edit, message", [
    (lambda s: s.replace("pill.stl", "gone.stl"), r"set.csv: row 2: mesh 'gone.stl' does not exist"),
    (lambda s: s.replace("csg.csv", "missing/curve.csv"), r"set.csv: row 4: run 'missing/curve.csv' does not exist"),
    (lambda s: s.replace("run,mesh", "folder,mesh"), r"no column run"),
    (lambda s: s.replace("sphere.stl,", "sphere.stl,-1"), r"row 1: object_mass_g '-1.*' is not a positive"),
])
def test_bad_set_files_name_the_row(tmp_path, releases, edit, message):
    set_csv = _write_set(tmp_path / "set", releases)
    set_csv.write_text(edit(set_csv.read_text()))
    with pytest.raises(SimCalError, match=message):
        calibrate_sim(set_csv, None, tmp_path / "cal", resolution=32, model="constant")
    assert not (tmp_path / "cal").exists()


def test_impossible_density_and_a_run_without_release_are_named(tmp_path, releases, monkeypatch):
    def simulated(*args, **kwargs):
        raise AssertionError("a mesh was simulated before the set was refused")

    monkeypatch.setattr("labapp.jobs.calibrate_sim.mesh_release", simulated)      # refused before any simulation
    set_csv = _write_set(tmp_path / "set", releases, mass={"spinner_top": 0.5})
    with pytest.raises(SimCalError, match=r"set.csv row 3 \(spinner_top.csv, spinner_top.stl\): weighed 0.5 g "
                                          r"over the mesh's .* mm\^3 means 0.3.. g/cm\^3, outside 0.8-2 g/cm\^3"):
        calibrate_sim(set_csv, None, tmp_path / "cal", resolution=32)
    set_csv = _write_set(tmp_path / "set2", releases)
    flat = tmp_path / "set2" / "pill.csv"
    flat.write_text("t_s,released_g,conc_g_per_kg\n" + "".join(f"{t},0.001,0.002\n" for t in range(0, 3000, 30)))
    with pytest.raises(SimCalError, match=r"set.csv row 2 \(pill.csv, pill.stl\): the run shows no release"):
        calibrate_sim(set_csv, None, tmp_path / "cal2", resolution=32)
