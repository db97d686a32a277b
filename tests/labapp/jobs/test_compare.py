"""`sfr compare`: the JSON keys, the table, the picture, the 100 % rule, replicate units (curves or a units
CSV) with the regulators' rules, bootf2's bootstrap and the multivariate tests, and bad input."""
import json
import shutil

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
    # generated first-order to 1.75 g; with no weighed mass 100 % is the final value, so first-order is not
    # exact and a two-parameter model may rank first: every ranked fit is close
    assert out["best_fit_a"]["r2"] > 0.999 and {f["model"] for f in out["fits_a"]} >= {"first-order", "Hopfenberg"}
    assert 50 < out["f2"] < 100
    assert out["percent_basis"] == "final value" and out["rule"] == "ema"


def test_table_and_picture(curves, capsys):
    tmp, a, b = curves
    png = tmp / "cmp.png"
    assert main(["compare", a, b, "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    assert "f2 = " in text and "MDT (s)" in text and "best model fit A" in text
    assert png.stat().st_size > 10_000
    assert main(["compare", a, b, "--plot", str(png)]) == 2  # never overwritten
    assert "exists" in capsys.readouterr().err


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
    (lambda d: _csv(d / "down.csv", [0, 600, 1200, 1800], [0, 1.0, 0.2, 1.2]), "must not decrease"),
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
    from labapp.jobs.physical import write_design_physical
    from labapp.records.simcal import SimCalFile

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


def _run_curve(folder, t, grams, mass=None):
    """RUN/analysis/curve.csv, with RUN/run.json giving the weighed mass when ``mass`` is given."""
    (folder / "analysis").mkdir(parents=True)
    if mass is not None:
        (folder / "run.json").write_text(json.dumps({"object_mass_g": mass, "water_g": 400.0}))
    return _csv(folder / "analysis" / "curve.csv", t, grams)


def test_one_rule_for_100_percent_whether_a_run_is_given_as_its_folder_or_its_curve(tmp_path, capsys):
    t = np.arange(0, 3 * 3600, 60.0)
    run_a = tmp_path / "runA"
    curve_a = _run_curve(run_a, t, 1.5 * (1 - np.exp(-t / 2400)), mass=1.6)  # 100 % = 1.6 g when both are known
    loose = str(shutil.copy(curve_a, tmp_path / "copied_curve.csv"))                # the same curve, no run.json
    b_mass = _run_curve(tmp_path / "runB", t, 1.4 * (1 - np.exp(-t / 2700)), mass=1.5)
    b_none = _csv(tmp_path / "b.csv", t, 1.4 * (1 - np.exp(-t / 2700)))

    def compare(a, b):
        assert main(["compare", str(a), str(b), "--json"]) == 0
        return json.loads(capsys.readouterr().out)

    folder, curve, copy = (compare(x, b_none) for x in (run_a / "analysis", curve_a, loose))
    for key in ("f2", "mdt_a", "de_a", "de_b", "total_g_a"):
        assert folder[key] == curve[key] == copy[key], key
    assert folder["percent_basis"] == "final value" and folder["total_g_a"] == pytest.approx(1.5 * (1 - np.exp(-t[-1] / 2400)))
    both = compare(run_a / "analysis", b_mass)
    assert both["percent_basis"] == "weighed mass" and both["total_g_a"] == 1.6 and both["total_g_b"] == 1.5
    assert both["de_a"] == pytest.approx(folder["de_a"] * both["total_g_a"] ** -1 * folder["total_g_a"])
    assert main(["compare", str(run_a / "analysis"), b_mass]) == 0
    assert "100 % = each curve's weighed mass" in capsys.readouterr().out
    assert main(["compare", loose, b_mass]) == 0
    assert "100 % = each curve's final value (the weighed mass is not recorded for every curve)" in \
        capsys.readouterr().out


def _units_csv(path, times_min, units, header="t_min"):
    cols = ",".join(f"unit{i + 1:02d}" for i in range(len(units)))
    np.savetxt(path, np.column_stack([times_min, np.asarray(units).T]), delimiter=",", header=f"{header},{cols}",
               comments="", fmt="%.10g")
    return str(path)


def _shah(tmp_path, batch):
    from tests.analysis.published import shah1998

    s = shah1998(batch)
    return _units_csv(tmp_path / f"{batch}.csv", s.times, s.units)


def test_units_files_give_bootf2s_published_bootstrap(tmp_path, capsys):
    ref, test = _shah(tmp_path, "ref"), _shah(tmp_path, "test1")
    assert main(["compare", "--reference", ref, "--test", test, "--bootstrap", "1000", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    exp = out["bootstrap"]["estimators"]["exp.f2"]
    # bootf2 tests/testthat/test_bootf2.R (seed 306, the default of both)
    assert round(exp["estimate"], 2) == 56.83 and round(exp["boot_mean"], 2) == 57.40
    assert [round(x, 2) for x in exp["intervals"]["percentile"]] == [50.03, 67.04]
    assert [round(x, 2) for x in exp["intervals"]["normal"]] == [47.74, 64.79]
    assert out["percent_basis"] == "units file" and out["n_test"] == out["n_reference"] == 12
    # the EMA's CV rule is not met (10.61 % at 30 min, above 10 %: no point is early): the bootstrap is the way
    assert out["points_used"] == 3 and "test CV 10.61 % at 30 min exceeds 10 %" in out["refused"]
    assert out["msd"]["df1"] == 3 and out["msd"]["F"] > 0
    assert main(["compare", "--reference", ref, "--test", test, "--bootstrap", "200"]) == 0
    table = capsys.readouterr().out
    assert "rule: EMA" in table and "bca.boot" in table and "MSD (Tsong, MIMCR)" in table and "Hoffelder" in table


def test_a_25_percent_cv_at_the_first_point_refuses_under_ema_and_warns_under_fda(tmp_path, capsys):
    z = np.linspace(-1.5, 1.5, 12)
    z = (z - z.mean()) / z.std(ddof=1)
    times, mean = [5, 10, 15, 20, 30, 45], np.array([20, 40, 60, 75, 88, 95.0])
    cv = np.array([25, 5, 5, 5, 5, 5]) / 100
    ref = _units_csv(tmp_path / "r.csv", times, (mean + 2) * (1 + cv * z[:, None]))
    test = _units_csv(tmp_path / "t.csv", times, mean * (1 + cv * z[:, None]))
    assert main(["compare", "--reference", ref, "--test", test]) == 0
    out = capsys.readouterr().out
    assert "f2 refused: CV rule of the EMA not met (test CV 25.00 % at 5 min exceeds 20 %" in out
    assert main(["compare", "--reference", ref, "--test", test, "--rule", "fda", "--json"]) == 0
    fda = json.loads(capsys.readouterr().out)
    assert fda["f2"] == pytest.approx(100 - 25 * np.log10(1 + 4)) and "not strictly met" in fda["warnings"][0]


def test_replicate_curves_are_set_on_common_points_with_a_seeded_bootstrap(tmp_path, capsys):
    t = np.arange(0, 4 * 3600 + 1, 30.0)
    rng = np.random.default_rng(4)
    ref = [_csv(tmp_path / f"r{i}.csv", t, 1.6 * (1 - np.exp(-t / rng.uniform(2300, 2600)))) for i in range(6)]
    test = [_csv(tmp_path / f"t{i}.csv", t, 1.6 * (1 - np.exp(-t / rng.uniform(2500, 2800)))) for i in range(6)]
    args = ["compare", "--reference", *ref[:3], "--reference", *ref[3:], "--test", *test, "--bootstrap", "300",
            "--seed", "3", "--json"]
    assert main(args) == 0
    first = json.loads(capsys.readouterr().out)
    assert main(args) == 0
    assert json.loads(capsys.readouterr().out)["bootstrap"] == first["bootstrap"]
    assert first["n_reference"] == 6 and first["time_unit"] == "s" and "regular grid" in first["notes"][0]
    assert "test: 6 units; the guidelines ask for 12" in first["warnings"]
    assert first["mean_reference"]["mdt"] < first["mean_test"]["mdt"]
    png = tmp_path / "sets.png"
    assert main(["compare", "--reference", *ref, "--test", *test, "--times", "600,1200,1800,2400",
                 "--plot", str(png)]) == 0
    assert "f2 = " in capsys.readouterr().out and png.stat().st_size > 10_000


@pytest.mark.parametrize("args, message", [
    (lambda d, a, b: ["compare", a, b, "--bootstrap", "500"], "--bootstrap needs replicate units"),
    (lambda d, a, b: ["compare", "--reference", a], "need both --reference UNIT... and --test UNIT..."),
    (lambda d, a, b: ["compare", a, "--test", b], "either two curves A B, or replicate units"),
    (lambda d, a, b: ["compare", "--reference", a, "--test", b, "--bootstrap", "50"], "expected a number of samples >= 100"),
    (lambda d, a, b: ["compare", "--reference", _units_csv(d / "u.csv", [5, 10], [[1, 2], [2, 3]]), "--test", b],
     "give both products as units files, or both as curves"),
    (lambda d, a, b: ["compare", "--reference", _units_csv(d / "v.csv", [5, 10], [[1, 2]], "time"), "--test", b],
     "no column t_s"),
    (lambda d, a, b: ["compare", f"{a},{a}", b], "not separated by commas"),
])
def test_bad_replicate_input_is_named(curves, capsys, args, message):
    tmp, a, b = curves
    assert main(args(tmp, a, b)) == 2
    assert message in capsys.readouterr().err


def test_the_commands_rule_names_are_the_analysis_ones():
    from analysis.regulatory import RULE_NAMES
    from labapp.cli.commands.compare import RULES

    assert RULES == RULE_NAMES


def test_the_who_rule_cuts_two_curves_where_the_reference_passes_85_percent(tmp_path, capsys):
    t = np.array([0, 600, 1200, 1800, 2400, 3000.0])
    ref = _csv(tmp_path / "r.csv", t, [0, 0.30, 0.55, 0.75, 0.90, 0.98])   # above 85 % (of 0.98) at 2400 s
    test = _csv(tmp_path / "t.csv", t, [0, 0.50, 0.88, 0.95, 0.97, 0.98])  # at 1200 s
    got = {}
    for rule in ("ema", "who"):
        assert main(["compare", ref, test, "--rule", rule, "--json"]) == 0
        got[rule] = json.loads(capsys.readouterr().out)
    assert got["ema"]["times_s"] == [600, 1200] and got["ema"]["f2"] is None  # 2 points: refused
    assert got["who"]["times_s"] == [600, 1200, 1800, 2400] and got["who"]["rule"] == "who"
    r, s = np.array([0.30, 0.55, 0.75, 0.90]) / 0.98 * 100, np.array([0.50, 0.88, 0.95, 0.97]) / 0.98 * 100
    assert got["who"]["f2"] == pytest.approx(100 - 25 * np.log10(1 + np.mean((r - s) ** 2)))


@pytest.mark.parametrize("batch, f2", [("test1", 60.03), ("test2", 51.08), ("test3", 51.19),
                                       ("test4", 50.07), ("test5", 48.05)])
def test_shah_1998_published_f2_from_the_command_line(tmp_path, capsys, batch, f2):
    # Shah et al. 1998 (Pharm. Res. 15:889), as bootf2 computes them: calcf2(..., "FDA", both.TR.85 = TRUE)
    ref, test = _shah(tmp_path, "ref"), _shah(tmp_path, batch)
    assert main(["compare", "--reference", ref, "--test", test, "--rule", "fda", "--both-tr-85", "--json"]) == 0
    assert round(json.loads(capsys.readouterr().out)["f2"], 2) == f2


def test_disprofas_profile_portion_from_the_command_line(tmp_path, capsys):
    from tests.analysis.published import dip

    cols = ["t.5", "t.10", "t.15", "t.20", "t.30", "t.60", "t.90", "t.120"]
    r, t = dip("dip1", "type", "R", cols), dip("dip1", "type", "T", cols)
    ref = _units_csv(tmp_path / "r.csv", r.times, r.units)
    test = _units_csv(tmp_path / "t.csv", t.times, t.units)
    assert main(["compare", "--reference", ref, "--test", test, "--bounds", "1,95", "--signif", "0.1", "--json"]) == 0
    msd = json.loads(capsys.readouterr().out)["msd"]
    # disprofas examples_mimcr.R, res4: mimcr(dip1, tcol = 3:10, grouping = "type", bounds = c(1, 95), signif = 0.1)
    assert len(msd["times"]) == 8 and round(msd["p_hoffelder"], 7) == 0.1449045
    assert round(msd["sim_limit"], 7) == 19.4271898 and round(msd["obs_upper"], 7) == 33.3180044


def test_options_of_replicate_units_are_refused_for_two_curves_and_other_rules(tmp_path, capsys):
    ref, test = _shah(tmp_path, "ref"), _shah(tmp_path, "test1")
    assert main(["compare", "--reference", ref, "--test", test, "--both-tr-85"]) == 2
    assert "needs --rule fda" in capsys.readouterr().err
    a = _csv(tmp_path / "a.csv", [0, 600, 1200], [0, 1, 2])
    assert main(["compare", a, a, "--bounds", "1,95"]) == 2
    assert "--bounds applies to replicate units" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["compare", "--reference", ref, "--test", test, "--bounds", "90,10"])
    assert exc.value.code == 2 and "LOW <= HIGH" in capsys.readouterr().err
