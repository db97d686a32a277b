"""`sfr design` end to end on a tiny grid, `--resume`, and the ico space with a preset."""
import json

from labapp.cli.main import main


def test_sfr_design_writes_a_run_and_resumes(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["design", "--target", "sphere", "--space", "extruded", "--resolution", "16", "--radius", "2",
                 "--max-iter", "8", "--out", str(out)])
    assert code == 0
    captured = capsys.readouterr()
    assert "rel. RMSE" in captured.out and "it    8/8" in captured.err  # final progress line
    summary = json.loads((out / "summary.json").read_text())
    assert summary["space"] == "extruded" and summary["iterations"] == 8
    # resuming a finished run re-writes its outputs without further evaluations
    assert main(["design", "--resume", "--out", str(out)]) == 0
    assert json.loads((out / "summary.json").read_text())["iterations"] == 8


def test_sfr_design_ico_with_a_preset_reports_ico_and_overhangs(tmp_path, capsys):
    out = tmp_path / "ico"
    code = main(["design", "--target", "sphere", "--space", "ico", "--preset", "paper:sphere", "--resolution", "16",
                 "--radius", "2", "--layers", "4", "--max-iter", "4", "--out", str(out)])
    assert code == 0
    printed = capsys.readouterr().out
    assert "ICO J_fab" in printed and "overhangs along +z" in printed and "preset paper:sphere" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert summary["preset"] == "paper:sphere" and summary["config"]["w_fab"] == 50.0
    assert summary["ico"]["layers"] == 4 and 0 < summary["ico"]["fab_time_share"] < 1
    assert 0.0 <= summary["overhang_fraction"] <= 1.0 and summary["max_overhang_run_mm"] >= 0.0
    header = (out / "history.csv").read_text().splitlines()[0]
    assert header.split(",")[4:6] == ["J_fab", "fab_seconds"]
    assert "support_material = 0" in (out / "design.ini").read_text()
    assert main(["design", "--target", "sphere", "--space", "ico", "--preset", "paper:teapot",
                 "--out", str(tmp_path / "bad")]) != 0
    assert "unknown preset 'paper:teapot'" in capsys.readouterr().err


def test_sfr_design_needs_a_target(tmp_path, capsys):
    assert main(["design", "--out", str(tmp_path / "x")]) == 2
    assert "--target is required" in capsys.readouterr().err
