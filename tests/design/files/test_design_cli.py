"""`sfr design` end to end on a tiny grid, `--resume`, and the ico space with a preset."""
import json

from labapp.cli.main import main


def test_sfr_design_writes_a_run_and_resumes(tmp_path, capsys):
    out = tmp_path / "run"
    base = ["design", "--target", "sphere", "--space", "extruded", "--resolution", "16", "--radius", "2"]
    # cut short by its limit, no solid yet: a failed job that says it did not converge and what to raise
    assert main(base + ["--max-iter", "8", "--out", str(out)]) == 1
    captured = capsys.readouterr()
    assert "rel. RMSE" in captured.out and "it    8/8" in captured.err  # final progress line
    assert "did not converge: the evaluation limit (8)" in captured.out and "--max-iter 16" in captured.out
    assert "error: the design produced no solid" in captured.err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["space"] == "extruded" and summary["iterations"] == 8 and summary["pieces"] == 0
    # the same command line with --resume and a higher limit continues the run to it
    assert main(base + ["--max-iter", "40", "--resume", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["iterations"] == 40 and summary["config"]["max_iter"] == 40
    assert json.loads((out / "config.json").read_text())["max_iter"] == 40
    capsys.readouterr()
    # resuming a finished run changes nothing and says so
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert main(["design", "--resume", "--out", str(out)]) == 0
    assert "already finished: nothing to do" in capsys.readouterr().out
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before
    # a setting that differs from the stored run is refused with the stored value
    assert main(["design", "--resume", "--resolution", "32", "--out", str(out)]) == 2
    assert (f"--resolution 32 differs from the run's stored 16 in {out / 'config.json'}; drop it to resume"
            in capsys.readouterr().err)
    assert main(["design", "--resume", "--target", "pill", "--out", str(out)]) == 2
    assert "--target pill differs from the run's stored sphere" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before


def test_sfr_design_ico_with_a_preset_reports_ico_and_overhangs(tmp_path, capsys):
    out = tmp_path / "ico"
    code = main(["design", "--target", "sphere", "--space", "ico", "--preset", "paper:sphere", "--resolution", "16",
                 "--radius", "2", "--layers", "4", "--max-iter", "4", "--out", str(out)])
    assert code == 1  # 4 evaluations leave no solid: a failed job, whose report is written all the same
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
                 "--out", str(tmp_path / "bad")]) == 2
    assert "unknown preset 'paper:teapot'" in capsys.readouterr().err


def test_sfr_design_needs_a_target(tmp_path, capsys):
    assert main(["design", "--out", str(tmp_path / "x")]) == 2
    assert "--target is required" in capsys.readouterr().err
