"""`sfr compare`: the JSON keys, the table, the picture, replicates with a bootstrap, and bad input."""
import json

import numpy as np
import pytest

from labapp.cli.main import main


def _csv(path, t, grams, header="t_s,released_g"):
    np.savetxt(path, np.column_stack([t, grams]), delimiter=",", header=header, comments="", fmt="%.9g")
    return str(path)


@pytest.fixture
def curves(tmp_path):
    t = np.arange(0, 3 * 3600, 11.0)
    a = _csv(tmp_path / "a.csv", t, 1.75 * (1 - np.exp(-t / 2400)))
    b = _csv(tmp_path / "b.csv", t, 1.70 * (1 - np.exp(-t / 2700)))
    return tmp_path, a, b


def test_json_has_the_metrics_of_both_curves(curves, capsys):
    tmp, a, b = curves
    assert main(["compare", a, b, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("f1", "f2", "mdt_a", "mdt_b", "de_a", "de_b", "points_used"):
        assert out[key] is not None, key
    assert out["points_used"] == len(out["times_s"]) >= 3
    assert out["mdt_a"] < out["mdt_b"]  # the faster curve has the shorter mean dissolution time
    assert out["best_fit_a"]["model"] in ("first-order", "Weibull")  # generated first-order
    assert 50 < out["f2"] < 100


def test_table_and_picture(curves, capsys):
    tmp, a, b = curves
    png = tmp / "cmp.png"
    assert main(["compare", a, b, "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    assert "f2 = " in text and "MDT (s)" in text and "best model fit A" in text
    assert png.stat().st_size > 10_000
    assert main(["compare", a, b, "--plot", str(png)]) == 2  # never overwritten
    assert "exists" in capsys.readouterr().err


def test_replicates_give_a_seeded_bootstrap_interval(curves, capsys):
    tmp, a, b = curves
    t = np.arange(0, 3 * 3600, 11.0)
    a2 = _csv(tmp / "a2.csv", t, 1.78 * (1 - np.exp(-t / 2300)))
    args = ["compare", f"{a},{a2}", b, "--bootstrap", "500", "--seed", "3", "--json"]
    assert main(args) == 0
    first = json.loads(capsys.readouterr().out)["f2_bootstrap"]
    assert main(args) == 0
    assert json.loads(capsys.readouterr().out)["f2_bootstrap"] == first
    assert first["lower"] <= first["upper"] and first["n_a"] == 2
    assert main(["compare", a, b, "--bootstrap", "500"]) == 2
    assert "replicate curves" in capsys.readouterr().err


def test_rules_that_cannot_be_met_are_reported_not_computed(tmp_path, capsys):
    t = np.array([0, 900, 1800, 2700, 3600.0])
    a = _csv(tmp_path / "a.csv", t, [0, 0.9, 1.8, 1.95, 2.0])  # passes 85 % at the second point
    b = _csv(tmp_path / "b.csv", t, [0, 0.8, 1.7, 1.9, 2.0])
    assert main(["compare", a, b, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["f2"] is None and "only 2 usable time point(s)" in out["reason"]
    assert out["mdt_a"] is not None


@pytest.mark.parametrize("make_b, message", [
    (lambda d: _csv(d / "release.csv", [0, 1, 2], [0, 1, 2], "tau_mm,released_mm3"), "no column t_s"),
    (lambda d: _csv(d / "late.csv", [2e5, 3e5], [0, 1]), "do not overlap in time"),
    (lambda d: _csv(d / "nan.csv", [0, 60, 120], [0, np.nan, 1]), "row 2: released_g = nan"),
    (lambda d: _csv(d / "down.csv", [0, 60, 120, 180], [0, 1.0, 0.2, 1.2]), "must not decrease"),
])
def test_bad_input_is_named(curves, capsys, make_b, message):
    tmp, a, _ = curves
    assert main(["compare", a, make_b(tmp)]) == 2
    assert message in capsys.readouterr().err


def test_a_reference_without_release_is_refused(tmp_path, capsys):
    a = _csv(tmp_path / "zero.csv", [0, 60, 120], [0, 0, 0])
    b = _csv(tmp_path / "b.csv", [0, 60, 120], [0, 1, 2])
    assert main(["compare", a, b]) == 2
    assert "releases 0 g in total" in capsys.readouterr().err


def test_a_designs_physical_prediction_carries_the_release_metrics(tmp_path):
    from pathlib import Path

    from analysis import SimCal
    from labapp.jobs.calibrate_sim import SimCalFile
    from labapp.jobs.physical import write_design_physical

    tau = np.linspace(0, 2.0, 201)
    target = 1000 * (1 - (1 - tau / 2.0) ** 3)       # a sphere-like target, mm^3
    binary = 1000 * np.minimum(tau / 1.8, 1.0) ** 0.9  # the design's printed solid
    np.savetxt(tmp_path / "curves.csv", np.column_stack([tau, target, binary]), delimiter=",",
               header="tau_mm,target_mm3,binary_mm3", comments="")
    (tmp_path / "summary.json").write_text("{}")
    simcal = SimCalFile(SimCal("constant", 1500.0, 1.3e-3), 64, 0.3, 500.0, Path("simcal.json"))
    summary = write_design_physical(tmp_path, simcal)
    metrics = json.loads((tmp_path / "summary.json").read_text())["release_metrics"]
    assert metrics == json.loads(json.dumps(summary["release_metrics"]))
    assert metrics["predicted"]["mdt_s"] > 0 and metrics["reference"]["best_fit"]["rank"] == 1
    assert metrics["f2_points"] >= 3 and 0 < metrics["f2"] < 100
