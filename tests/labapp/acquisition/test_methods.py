"""Method files: saved from options or a run, loaded with each setting checked, applied to a run without
silent changes, cited in run.json."""
import json

import pytest

from labapp.acquisition.methods import Criterion, MethodError, load_method, make_method, method_from_run, save_method
from labapp.acquisition.procedures import RunConfig, RunProcedure
from labapp.acquisition.settings import BathSettings
from labapp.records.manifests import read_record
from labapp.records.storage import create_run

SETTINGS = {"water_g": 500.0, "setpoint_c": 37.0, "speed_rpm": 100.0, "tolerance_c": 0.5, "hold_s": 120.0,
            "heat_timeout_s": 7200.0, "interval_s": 30.0, "max_duration_s": 7200.0, "min_duration_s": 1800.0}


def test_a_method_round_trips_and_is_cited_by_its_hash(tmp_path):
    cal = tmp_path / "cal.json"
    cal.write_text("{}")
    criteria = (Criterion("released_percent", 20.0, 40.0, 1.0), Criterion("f2", 50.0))
    path = save_method(make_method("IR tablet", SETTINGS, True, cal, criteria), tmp_path / "ir.json")
    method = load_method(path)
    assert method.settings == SETTINGS and method.acceptance == criteria and method.created_by == "tester"
    assert method.citation()["sha256"] == __import__("hashlib").sha256(path.read_bytes()).hexdigest()
    assert method.check_calibration(None) == cal.resolve()
    with pytest.raises(MethodError, match="never overwritten"):
        save_method(method, path)
    other = tmp_path / "other.json"
    other.write_text("{ }")
    with pytest.raises(MethodError, match="not the one method 'IR tablet' names"):
        method.check_calibration(other)


def test_a_method_fixes_the_run_settings(tmp_path):
    method = make_method("m", SETTINGS)
    config = method.apply(RunConfig(name="pill", object_mass_g=1.2))
    assert (config.interval_s, config.bath.setpoint_c, config.bath.speed_rpm) == (30.0, 37.0, 100.0)
    assert config.object_mass_g == 1.2 and config.name == "pill"
    with pytest.raises(MethodError, match="--interval 20 s contradicts method 'm' \\(30 s\\)"):
        method.apply(RunConfig(interval_s=20.0))
    with pytest.raises(MethodError, match="--setpoint 60 C contradicts"):
        method.apply(RunConfig(bath=BathSettings(setpoint_c=60.0)))
    assert method.apply(RunConfig(interval_s=30.0)).interval_s == 30.0      # the method's own value: fine


def test_bad_method_files_are_refused_naming_the_field(tmp_path):
    path = save_method(make_method("m", SETTINGS), tmp_path / "m.json")
    data = json.loads(path.read_text())
    data["settings"]["interval_s"] = -1
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match="settings.interval_s must be > 0 s, got -1"):
        load_method(path)
    del data["settings"]["setpoint_c"]
    path.write_text(json.dumps(data))
    with pytest.raises(MethodError, match="settings.setpoint_c is missing"):
        load_method(path)
    path.write_text(json.dumps({"kind": "something"}))
    with pytest.raises(MethodError, match="not a method file"):
        load_method(path)
    with pytest.raises(MethodError, match="at_h"):
        Criterion("released_percent", 10.0)


def test_a_method_from_a_run_and_a_run_citing_it(tmp_path):
    config = RunConfig(interval_s=15.0, bath=BathSettings(setpoint_c=40.0))
    run = create_run(tmp_path / "data", "r", {"config": config.to_dict(), "simulated": True})
    run.close()
    method = method_from_run(run.path, "from run")
    assert method.settings["interval_s"] == 15.0 and method.settings["setpoint_c"] == 40.0
    method = load_method(save_method(method, tmp_path / "m.json"))
    proc = RunProcedure(method.apply(RunConfig()), bench=None, data_dir=tmp_path / "data")
    proc.record_extra["method"] = method.citation()
    cited = create_run(tmp_path / "data", "cited", {"simulated": True, **proc.record_extra})
    cited.close()
    assert read_record(cited.path).method == method.citation()


def test_sfr_method_save_and_show(tmp_path, capsys):
    from labapp.cli.main import main

    out = tmp_path / "m.json"
    assert main(["method", "save", str(out), "--interval", "20", "--setpoint", "37", "--accept-released", "1:20:40",
                 "--accept-f2", "50"]) == 0
    assert main(["method", "show", str(out)]) == 0
    text = capsys.readouterr().out
    assert "frame interval" in text and "20 s" in text and "released at 1 h in [20, 40] %" in text
    assert "f2 >= 50" in text


def test_sfr_run_refuses_an_option_that_contradicts_its_method(tmp_path, capsys):
    from labapp.cli.main import main

    path = save_method(make_method("m", SETTINGS), tmp_path / "m.json")
    assert main(["run", "--simulate", "--out", str(tmp_path / "runs"), "--method", str(path), "--interval", "20"]) == 2
    assert "--interval 20 s contradicts method 'm' (30 s)" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()
