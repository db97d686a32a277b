"""`sfr design` end to end on a tiny grid, `--resume`, and the reserved ico space."""
import json

from labapp.cli import main


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


def test_sfr_design_ico_is_not_available_yet(tmp_path, capsys):
    code = main(["design", "--target", "sphere", "--space", "ico", "--out", str(tmp_path / "ico")])
    assert code == 1
    assert "not available yet" in capsys.readouterr().err


def test_sfr_design_needs_a_target(tmp_path, capsys):
    assert main(["design", "--out", str(tmp_path / "x")]) == 2
    assert "--target is required" in capsys.readouterr().err
