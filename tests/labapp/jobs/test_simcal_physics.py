"""calibrate-sim --physics: print physics of the forward model fitted from runs on a bench whose truth is not the model.

The runs are the simulated bench's prints (labapp.acquisition.printworld: its own fast marching by scikit-fmm
on a grid of 64 voxels, anisotropy as a metric) of shapes that tell the build direction apart (a flat slab, a
tall column, a sphere, a bar lying down), sampled every 30 s with 0.2%-of-mass noise; the calibration simulates
the meshes at resolution 32. The anisotropy and the identity cases fit three of the shapes (slab, column, bar)
at resolution 16: the uncertainty they are checked against carries the discretisation term (the refit at 24).
"""
import json

import numpy as np
import pytest
import trimesh

from analysis.physics_grid import FIT_IDENTITY, LAG, PHYSICS_SETS
from labapp.acquisition.printworld import PrintPhysics, world_release
from labapp.acquisition.simbench import Material, SampleRelease
from labapp.cli.main import main
from labapp.jobs.calibrate_sim import calibrate_sim
from labapp.jobs.printrelease import print_volume_mm3
from labapp.records.simcal import load_simcal
from tests.labapp.jobs.simcal_sets import write_run, write_set

MESHES = {"slab": lambda: trimesh.creation.box((16, 16, 5)),
          "column": lambda: trimesh.creation.cylinder(radius=3.5, height=18, sections=48),
          "sphere": lambda: trimesh.creation.icosphere(4, radius=6.0),
          "bar": lambda: trimesh.creation.box((22, 6, 6))}
BUILD_DIRECTION = ("slab", "column", "bar")
"""The shapes that tell the build direction apart at a coarse resolution: flat, tall, lying down."""
WORLD_RESOLUTION, RESOLUTION, COARSE = 64, 32, 16


def _bench_set(folder, physics, shapes=None):
    """The bench's runs of ``shapes`` (names of `MESHES`; all of them by default) and their set file."""
    folder.mkdir(parents=True, exist_ok=True)
    material = Material(1500.0, 1.25, physics=physics)
    rows = []
    for i, (name, make) in enumerate(MESHES.items()):
        if shapes is not None and name not in shapes:
            continue
        mesh = make()
        seconds_per_mm, g_per_mm3 = material.printed(i)
        world = world_release(mesh, physics, resolution=WORLD_RESOLUTION)
        release = SampleRelease.from_simulation(name, world.tau_mm, world.released_mm3, seconds_per_mm, g_per_mm3,
                                                lag_s=physics.wetting_lag_s)
        t = np.arange(30.0, 1.15 * release.duration_s, 30.0)
        grams = np.interp(t, release.t_s, release.released_g)
        grams += 0.002 * release.mass_g * np.random.default_rng(i).standard_normal(t.size)
        rows.append(write_run(folder, name, mesh, t, grams, release.mass_g, fmt="%.6f"))
    return write_set(folder, rows)


@pytest.mark.slow
def test_hidden_anisotropy_is_recovered_and_earns_its_place(tmp_path):
    set_csv = _bench_set(tmp_path / "set", PrintPhysics(anisotropy=1.4), BUILD_DIRECTION)
    run = calibrate_sim(set_csv, None, tmp_path / "cal", resolution=COARSE, model="constant", physics="anisotropy")
    physics = run.doc["physics"]
    # observed: 1.400 +/- 0.051 (the jackknife over the leave-one-out refits and the discretisation term)
    assert physics["choice"] == "anisotropy" and physics["fitted"] == ["anisotropy"]
    assert abs(physics["anisotropy"] - 1.4) < physics["uncertainty"]["anisotropy"]
    assert physics["uncertainty"]["anisotropy"] < 0.15
    # the discretisation term: the physics refitted at 1.5 x the resolution, its extrapolated difference added in
    # quadrature to the spread of the leave-one-out refits
    disc = physics["discretisation"]
    assert disc["resolution"] == 24 and set(disc["values"]) == {"anisotropy"}
    assert disc["bias"]["anisotropy"] == pytest.approx(3.0 * abs(disc["values"]["anisotropy"] - physics["anisotropy"]))
    assert physics["uncertainty"]["anisotropy"] == pytest.approx(
        np.hypot(disc["uncertainty_refits"]["anisotropy"], disc["bias"]["anisotropy"]))
    iso, aniso = (physics["candidates"][m]["loo_rel_rmse_mean"] for m in ("none", "anisotropy"))
    # observed: isotropic 6.05 %, calibrated anisotropy 1.05 % of the weighed mass
    assert aniso < 0.5 * iso
    # the models' own leave-one-out keeps the physics fitted to all shapes: lower than the honest one above
    assert run.doc["loo_rel_rmse_mean"] < iso
    # predictions use it: the file round-trips and names it
    simcal = load_simcal(run.path)
    assert simcal.physics["anisotropy"] == pytest.approx(physics["anisotropy"])
    assert f"anisotropy {physics['anisotropy']:.3g}" in simcal.describe()
    assert json.loads(run.path.read_text())["format"] == "sfr-simcal/2"


def test_the_default_keeps_the_hidden_anisotropy_it_earns(tmp_path):
    """calibrate-sim without --physics fits every set and keeps the one leave-one-out shows earns its place."""
    set_csv = _bench_set(tmp_path / "set", PrintPhysics(anisotropy=1.4), BUILD_DIRECTION)
    physics = calibrate_sim(set_csv, None, tmp_path / "cal", resolution=COARSE, model="constant").doc["physics"]
    assert set(physics["candidates"]) == {m for m, p in PHYSICS_SETS.items() if "swelling_mm" not in p}
    # observed: anisotropy 1.400 +/- 0.051, leave-one-out 6.05 % isotropic against 1.05 % with it
    assert physics["choice"] == "anisotropy" and physics["fitted"] == ["anisotropy"]
    assert abs(physics["anisotropy"] - 1.4) < 2 * physics["uncertainty"]["anisotropy"]
    iso, kept = (physics["candidates"][m]["loo_rel_rmse_mean"] for m in ("none", "anisotropy"))
    assert kept < 0.5 * iso


@pytest.mark.slow
def test_identity_physics_keeps_the_isotropic_model(tmp_path, capsys):
    set_csv = _bench_set(tmp_path / "set", PrintPhysics(), BUILD_DIRECTION)
    assert main(["calibrate-sim", str(set_csv), "--out", str(tmp_path / "cal"), "--resolution", str(COARSE),
                 "--model", "constant"]) == 0       # the default --physics: auto
    doc = json.loads((tmp_path / "cal" / "simcal.json").read_text())
    physics = doc["physics"]
    assert physics["choice"] == "none" and physics["anisotropy"] == 1.0 and physics["offset_mm"] == 0.0
    # no shape has a channel: the sets with the swelling width are not tried (the release cannot tell it)
    assert set(physics["candidates"]) == {m for m, p in PHYSICS_SETS.items() if "swelling_mm" not in p}
    # every fitted value is within its uncertainty's reach of the identity (observed: anisotropy 1.018 +/- 0.022,
    # offset -0.03 +/- 0.56 mm, the two together 1.007 +/- 0.044 and -0.03 +/- 0.56 mm, the lag 0 +/- 1.5 s)
    for c in physics["candidates"].values():
        for p in c["fitted"]:
            assert abs(c["values"][p] - FIT_IDENTITY[p]) < 2 * c["uncertainty"][p]
    assert "print physics 'none'" in capsys.readouterr().out


def test_version_1_file_loads_as_isotropic(tmp_path):
    doc = {"format": "sfr-simcal/1", "forward_model": "design.forward.simulator: fast marching, eqs. 2-10",
           "model": "constant", "seconds_per_mm": 1500.0, "g_per_mm3": 0.00125, "saturation_g_per_kg": None,
           "water_g": 500.0, "resolution": 32, "voxel_size_mm": 0.5}
    (tmp_path / "simcal.json").write_text(json.dumps(doc))
    simcal = load_simcal(tmp_path / "simcal.json")
    assert simcal.physics == {"anisotropy": 1.0, "offset_mm": 0.0, "swelling_mm": 0.0}
    doc.update(format="sfr-simcal/2", physics={"anisotropy": -1.0, "offset_mm": 0.0})
    (tmp_path / "simcal.json").write_text(json.dumps(doc))
    with pytest.raises(Exception, match="physics.anisotropy"):
        load_simcal(tmp_path / "simcal.json")


def test_predictions_simulate_with_the_calibrated_physics(tmp_path):
    from design.files.pipeline import simulate_mesh
    from design.geometry.shapes import sample_shape
    from labapp.jobs.physical import predict_mesh

    doc = {"format": "sfr-simcal/2", "forward_model": "design.forward.simulator: fast marching, eqs. 2-10",
           "model": "constant", "seconds_per_mm": 1500.0, "g_per_mm3": 0.00125, "saturation_g_per_kg": None,
           "water_g": 500.0, "resolution": 24, "voxel_size_mm": 0.5,
           "physics": {"anisotropy": 1.5, "offset_mm": 0.1, "fitted": ["anisotropy", "offset_mm"]}}
    (tmp_path / "simcal.json").write_text(json.dumps(doc))
    simcal = load_simcal(tmp_path / "simcal.json")
    t, grams = predict_mesh("sample:pill", simcal)
    truth = simulate_mesh(sample_shape("pill"), resolution=24, anisotropy=1.5, offset_mm=0.1)
    assert t[-1] == pytest.approx(truth.tau_mm[-1] * 1500.0, rel=1e-9)
    # the grams are the print's exact volume (the pill's mesh grown by 0.1 mm), the curve's shape the voxels'
    exact = print_volume_mm3(sample_shape("pill"), 0.1)
    assert grams[-1] == pytest.approx(exact * 0.00125, rel=1e-9)
    np.testing.assert_allclose(np.interp(truth.tau_mm * 1500.0, t, grams / grams[-1]),
                               truth.released_mm3 / truth.released_mm3[-1], atol=1e-3)
    iso = simulate_mesh(sample_shape("pill"), resolution=24)
    assert truth.released_mm3[-1] > 1.02 * iso.released_mm3[-1]   # the offset grows the print
    assert main(["simulate", "sample:pill", "--simcal", str(tmp_path / "simcal.json"), "--out", str(tmp_path / "sim")]) == 0
    summary = json.loads((tmp_path / "sim" / "summary.json").read_text())
    assert summary["physics"] == {"anisotropy": 1.5, "offset_mm": 0.1, "swelling_mm": 0.0}
    assert summary["physical"]["mass_g"] == pytest.approx(exact * 0.00125, rel=1e-6)   # the CSV's digits
    # release.csv is the exact model's release of the print (the pill grown by 0.1 mm, at anisotropy 1.5): its volume
    # the quadrature's, Steiner's for the convex pill within the stated error
    assert summary["model"] == "exact" and summary["method"] == "exact-distance, anisotropy 1.5, surface offset +0.1 mm"
    assert summary["volume_mm3"] == pytest.approx(exact, abs=summary["error"]["error_mm3"]) and summary["warnings"] == []


def test_a_parameter_is_kept_only_where_it_earns_it():
    from analysis.physics_fit import PhysicsFit, choose_physics
    from analysis.simcal import LooShape

    def fit(fitted, values, sigma, loo):
        shapes = tuple(LooShape("s", None, np.zeros(1), np.zeros(1), np.zeros(1), loo) for _ in range(3))
        full = {"anisotropy": 1.0, "offset_mm": 0.0, **values}
        return PhysicsFit(tuple(fitted), full, {p: sigma for p in fitted}, 0.0, shapes, ())

    none = fit((), {}, 0.0, 0.040)
    resolved = fit(("anisotropy",), {"anisotropy": 1.5}, 0.2, 0.030)
    assert choose_physics({"none": none, "anisotropy": resolved}) == "anisotropy"
    # better leave-one-out, but 1.3 is within 2 standard errors of 1: not kept
    assert choose_physics({"none": none, "anisotropy": fit(("anisotropy",), {"anisotropy": 1.3}, 0.2, 0.030)}) == "none"
    # resolved, but less than 5 % better: not kept
    assert choose_physics({"none": none, "anisotropy": fit(("anisotropy",), {"anisotropy": 1.5}, 0.2, 0.039)}) == "none"
    # both parameters must beat the one-parameter set they contain
    both = fit(("anisotropy", "offset_mm"), {"anisotropy": 1.5, "offset_mm": 0.3}, 0.1, 0.0295)
    assert choose_physics({"none": none, "anisotropy": resolved, "all": both}) == "anisotropy"
    both = fit(("anisotropy", "offset_mm"), {"anisotropy": 1.5, "offset_mm": 0.3}, 0.1, 0.020)
    assert choose_physics({"none": none, "anisotropy": resolved, "all": both}) == "all"


def _slotted(width):
    slab = trimesh.creation.box((8.0, 8.0, 3.0))
    return trimesh.boolean.difference([slab, trimesh.creation.box((width, 5.0, 4.0))], engine="manifold")


SLOTTED = {"slot05": lambda: _slotted(0.5), "slot10": lambda: _slotted(1.0),
           "sphere": lambda: trimesh.creation.icosphere(3, radius=4.0),
           "bar": lambda: trimesh.creation.box((10, 3, 3))}


@pytest.mark.slow
def test_hidden_swelling_is_bracketed_by_the_slots_it_shuts_and_opens(tmp_path, monkeypatch):
    """The bench's 0.75 mm swelling shuts the 0.5 mm slot and leaves the 1.0 mm one open: every width in
    (0.5, 1.0] mm fits alike at 0.25 mm voxels, so the fit is the middle of that flat minimum on the search grid,
    0.8 mm, with the flat run's spread (or half a voxel) as its uncertainty."""
    monkeypatch.setitem(globals(), "MESHES", SLOTTED)
    set_csv = _bench_set(tmp_path / "set", PrintPhysics(swelling_mm=0.75))
    run = calibrate_sim(set_csv, None, tmp_path / "cal", resolution=RESOLUTION, model="constant", physics="swelling")
    physics = run.doc["physics"]
    assert physics["choice"] == "swelling" and physics["fitted"] == ["swelling_mm"]
    # observed: 0.80 +/- 0.125 mm (the flat minimum 0.6-1.0 mm; the floor of half a 0.25 mm voxel)
    assert abs(physics["swelling_mm"] - 0.75) < physics["uncertainty"]["swelling_mm"] < 0.2, physics
    none, swelling = (physics["candidates"][m]["loo_rel_rmse_mean"] for m in ("none", "swelling"))
    assert swelling < 0.85 * none  # observed: 1.96% without, 1.54% with the swelling width
    assert load_simcal(run.path).simulate_options()["swelling_mm"] == pytest.approx(physics["swelling_mm"])


@pytest.mark.slow
def test_a_physics_block_without_the_swelling_width_reads_as_none(tmp_path):
    set_csv = _bench_set(tmp_path / "set", PrintPhysics())
    run = calibrate_sim(set_csv, None, tmp_path / "cal", resolution=16, model="constant")
    doc = json.loads(run.path.read_text())
    del doc["physics"]["swelling_mm"]
    run.path.write_text(json.dumps(doc))
    assert load_simcal(run.path).physics["swelling_mm"] == 0.0
    doc["physics"]["swelling_mm"] = -0.1
    run.path.write_text(json.dumps(doc))
    with pytest.raises(Exception, match="physics.swelling_mm must be a number >= 0"):
        load_simcal(run.path)
    # nor without the wetting lag: none
    doc["physics"]["swelling_mm"] = 0.0
    del doc["physics"][LAG]
    run.path.write_text(json.dumps(doc))
    assert load_simcal(run.path).cal.lag_s == 0.0
    doc["physics"][LAG] = -5.0
    run.path.write_text(json.dumps(doc))
    with pytest.raises(Exception, match="physics.wetting_lag_s must be a number of seconds >= 0"):
        load_simcal(run.path)


@pytest.mark.slow
def test_hidden_wetting_lag_is_recovered_and_delays_predictions_and_targets(tmp_path):
    """A 400 s wetting lag on the bench (isotropic otherwise): ``--physics lag`` recovers it within one 30 s frame
    and within 3 of its stated standard errors, leave-one-out falls, and every use of the calibration carries it:
    a prediction releases nothing before it, a measured target's clock starts at its end."""
    from labapp.jobs.physical import predict_mesh, write_target_csv
    from labapp.records.curvefiles import read_physical_curve

    set_csv = _bench_set(tmp_path / "set", PrintPhysics(wetting_lag_s=400.0))
    run = calibrate_sim(set_csv, None, tmp_path / "cal", resolution=RESOLUTION, model="constant", physics="lag")
    physics = run.doc["physics"]
    assert physics["choice"] == "lag" and physics["fitted"] == [LAG]
    assert physics[LAG] == pytest.approx(400.0, abs=30.0)
    assert abs(physics[LAG] - 400.0) < 3 * physics["uncertainty"][LAG] < 120.0, physics["uncertainty"]
    none, lag = (physics["candidates"][m]["loo_rel_rmse_mean"] for m in ("none", "lag"))
    assert lag < 0.8 * none
    assert all(abs(r["values"][LAG] - 400.0) < 60.0 for r in physics["candidates"]["lag"]["loo"])
    simcal = load_simcal(run.path)
    assert simcal.cal.lag_s == physics[LAG] and "wetting lag" in simcal.describe()
    t, grams = predict_mesh(tmp_path / "set" / "sphere.stl", simcal)
    assert np.all(grams[t <= simcal.cal.lag_s] == 0.0) and grams[-1] > 0
    curve = read_physical_curve(tmp_path / "set" / "sphere.csv")
    write_target_csv(curve, simcal, tmp_path / "target.csv")
    target = np.genfromtxt(tmp_path / "target.csv", delimiter=",", names=True)
    assert target["tau_mm"][0] == 0.0 and target["t_s"][0] == pytest.approx(simcal.cal.lag_s, abs=1e-3)
    assert target["tau_mm"][-1] == pytest.approx((target["t_s"][-1] - simcal.cal.lag_s) / simcal.cal.seconds_per_mm,
                                                 rel=1e-6)
