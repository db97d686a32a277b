"""No command writes over its inputs, a record or another command's files; --out is checked before any work."""
import hashlib
import json
import shutil
import time
from pathlib import Path

import pytest

from labapp.cli.main import main
from labapp.records.outpaths import FolderKind, OutPathError, check_data_dir, check_out, folder_kind
from labapp.records.runrecord import RecordKind, RecordStatus
from labapp.records.storage import create_run

FIXTURES = Path(__file__).resolve().parents[3] / "fixtures"


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def series(tmp_path):
    folder = tmp_path / "series"
    shutil.copytree(FIXTURES / "bench" / "calibration", folder)
    return folder


def test_calibrate_bench_never_replaces_the_series_masses(series, capsys):
    before = digest(series / "masses.csv")
    assert main(["calibrate-bench", str(series), "--out", str(series / "masses.csv")]) == 2
    assert "is an input of this command" in capsys.readouterr().err
    assert digest(series / "masses.csv") == before


def test_calibrate_bench_refuses_an_existing_file_and_a_record(series, tmp_path, capsys):
    existing = tmp_path / "cal.json"
    existing.write_text("keep me")
    assert main(["calibrate-bench", str(series), "--out", str(existing)]) == 2
    assert "exists; it is never overwritten" in capsys.readouterr().err and existing.read_text() == "keep me"
    assert main(["calibrate-bench", str(series), "--out", str(series / "cal.json")]) == 2
    assert "which no command adds files to" in capsys.readouterr().err and not (series / "cal.json").exists()


def test_simulate_refuses_a_design_folder_before_any_work(tmp_path, capsys):
    design = tmp_path / "design"
    design.mkdir()
    for name, text in (("config.json", "{}"), ("feasibility.txt", "ok"), ("summary.json", '{"space": "nfc"}')):
        (design / name).write_text(text)
    start = time.perf_counter()
    assert main(["simulate", "sample:sphere", "--resolution", "160", "--out", str(design)]) == 2
    assert time.perf_counter() - start < 5.0                      # refused before voxelising 160^3
    assert "is a design run folder (sfr design)" in capsys.readouterr().err
    assert json.loads((design / "summary.json").read_text()) == {"space": "nfc"}


def test_simulate_never_overwrites_an_earlier_simulation_and_refuses_its_input(tmp_path, capsys):
    out = tmp_path / "sim"
    assert main(["simulate", "sample:sphere", "--model", "grid", "--resolution", "12", "--out", str(out)]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert main(["simulate", "sample:sphere", "--model", "grid", "--resolution", "14", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "already holds a simulation folder" in err and f"e.g. {out}-2" in err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    mesh = tmp_path / "m" / "sphere.stl"
    mesh.parent.mkdir()
    shutil.copyfile(FIXTURES / "shapes" / "sphere.stl", mesh)
    assert main(["simulate", str(mesh), "--resolution", "12", "--out", str(mesh.parent)]) == 2
    assert "contains the input" in capsys.readouterr().err


def test_analyze_writes_only_into_the_runs_analysis_folder(tmp_path, capsys):
    run = create_run(tmp_path / "data", "r", {"kind": "run"})
    run.finish(RecordStatus.COMPLETE)
    run.close()
    for out, says in ((run.path, "is an input of this command"), (run.path / "x", "lies inside the input folder")):
        assert main(["analyze", str(run.path), "--calibration", str(tmp_path / "c.json"), "--out", str(out)]) == 2
        assert says in capsys.readouterr().err
    assert sorted(p.name for p in run.path.iterdir()) == ["audit.jsonl", "events.log", "frames.csv", "run.json"]
    check_out(run.path / "analysis", FolderKind.ANALYSIS, [tmp_path / "c.json"], analysed=run.path)  # its own place


def test_one_runs_analysis_is_never_written_into_another_run(tmp_path, capsys):
    runs = []
    for name in ("a", "b"):
        run = create_run(tmp_path / "data", name, {"kind": "run"})
        run.finish(RecordStatus.COMPLETE)
        run.close()
        runs.append(run.path)
    a, b = runs
    before = sorted(p.name for p in b.iterdir())
    (tmp_path / "c.json").write_text("{}")
    assert main(["analyze", str(a), "--calibration", str(tmp_path / "c.json"), "--out", str(b / "analysis")]) == 2
    err = capsys.readouterr().err
    assert f"is the analysis folder of {b}, another record" in err and f"{a / 'analysis'} is its own" in err
    assert sorted(p.name for p in b.iterdir()) == before
    with pytest.raises(OutPathError, match="another record"):
        check_out(b / "analysis", FolderKind.ANALYSIS, [], analysed=a)
    with pytest.raises(OutPathError, match="another record"):
        check_out(b / "analysis", FolderKind.ANALYSIS, [])              # no record named: no record's folder


def test_run_refuses_a_data_directory_inside_a_record(tmp_path, capsys):
    run = create_run(tmp_path / "data", "r", {"kind": "run"})
    run.finish(RecordStatus.COMPLETE)
    run.close()
    before = sorted(p.name for p in run.path.iterdir())
    assert main(["run", "--simulate", "--out", str(run.path)]) == 2
    assert "is or lies inside" in capsys.readouterr().err
    assert sorted(p.name for p in run.path.iterdir()) == before
    with pytest.raises(OutPathError, match="is or lies inside"):
        check_data_dir(run.path / "sub")
    assert check_data_dir(tmp_path / "data") == (tmp_path / "data").resolve()


def test_folder_kinds(tmp_path):
    assert folder_kind(tmp_path / "absent") is None and folder_kind(tmp_path) is None
    (tmp_path / "release.csv").write_text("tau_mm,released_mm3\n")
    assert folder_kind(tmp_path) == FolderKind.SIMULATION
    assert folder_kind(FIXTURES / "bench" / "run") == RecordKind.RUN and folder_kind(FIXTURES / "shapes") == FolderKind.OTHER
    with pytest.raises(OutPathError, match="not a analysis folder|is a simulation folder"):
        check_out(tmp_path, FolderKind.ANALYSIS)


def test_analyze_never_writes_over_another_runs_analysis(tmp_path, capsys):
    run = create_run(tmp_path / "data", "r", {"kind": "run"})
    run.finish(RecordStatus.COMPLETE)
    run.close()
    out = tmp_path / "analysis-of-another"
    out.mkdir()
    (out / "curve.csv").write_text("t_s,released_g\n")
    (out / "summary.json").write_text(json.dumps({"run": str(tmp_path / "other-run")}))
    assert main(["analyze", str(run.path), "--calibration", str(tmp_path / "c.json"), "--out", str(out)]) == 2
    assert f"holds the analysis of {tmp_path / 'other-run'}, another run" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["curve.csv", "summary.json"]
