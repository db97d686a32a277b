"""Edges of the commands' inputs: implausible units refused with the plausible range, and messages that name the
file, the option and what was expected (not an internal field or a parser's raw text)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from analysis import AnalysisError, BenchCalibration
from labapp.cli.main import main

ROOT = Path(__file__).resolve().parents[3]
BENCH = ROOT / "fixtures" / "bench"


@pytest.mark.parametrize("water", ["0.5", "1e9"])
def test_implausible_water_is_refused_with_the_range(water, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["calibrate-bench", str(BENCH / "calibration"), "--water-g", water, "--out", str(tmp_path / "c.json")])
    assert exc.value.code == 2
    assert f"--water-g: '{water}': expected a number in [100, 5000] g" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_analyze_refuses_implausible_water_too(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["analyze", str(BENCH / "run"), "--water-g", "1e9", "--out", str(tmp_path / "a")])
    assert exc.value.code == 2
    assert "--water-g: '1e9': expected a number in [100, 5000] g" in capsys.readouterr().err


def test_the_milligram_warning_names_the_water_too():
    from labapp.jobs.calibrate_bench import implausible_levels

    (message,) = implausible_levels(np.array([0.0, 350.0, 2100.0]), 500.0)
    assert "Check the water, 500 g (--water-g), and the masses" in message and "milligrams" in message


def test_a_calibration_with_implausible_water_is_refused(tmp_path):
    from analysis import CropGeometry

    g = 2
    cells = {name: np.full((g, g), 0.1) for name in ("t0", "t0_sigma", "k", "k_sigma", "cov_t0_k", "rms_rel")}
    cal = BenchCalibration(CropGeometry(0, 0, 20, g), 500.0, good=np.ones((g, g), bool), conc_levels_g_per_kg=(0.0, 1.0), **cells)
    cal.save(tmp_path / "c.json")
    text = (tmp_path / "c.json").read_text()
    assert '"water_g": 500.0' in text
    (tmp_path / "c.json").write_text(text.replace('"water_g": 500.0', '"water_g": 1e9'))
    with pytest.raises(AnalysisError, match=r"water_g is 1e\+?0?9|water_g is 1000000000"):
        BenchCalibration.load(tmp_path / "c.json")
    with pytest.raises(AnalysisError, match=r"expected a water mass in \[100, 5000\] g"):
        BenchCalibration(CropGeometry(0, 0, 20, g), 0.5, good=np.ones((g, g), bool), conc_levels_g_per_kg=(0.0, 1.0), **cells)


def test_a_text_file_given_as_a_calibration_is_named_as_such(tmp_path, capsys):
    text = tmp_path / "notes.txt"
    text.write_text("calibrated on Monday, see lab book\n")
    with pytest.raises(AnalysisError) as exc:
        BenchCalibration.load(text)
    assert str(exc.value).startswith(f"{text} is not a bench calibration JSON") and "Expecting value" not in str(exc.value)
    assert main(["analyze", str(BENCH / "run"), "--calibration", str(text), "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert "is not a bench calibration JSON" in err and "Expecting value" not in err


def _units(path: Path, scale: float = 1.0, nan_at: tuple[int, int] | None = None) -> str:
    """A units CSV of three units over 0-120 min, percent times ``scale``; NaN in data row and column ``nan_at``."""
    rows = ["t_min,u1,u2,u3"]
    for r, t in enumerate(range(0, 121, 10), start=1):
        cells = [f"{scale * 100 * (1 - np.exp(-t / 30)) * (1 + 0.02 * k):.3f}" for k in range(3)]
        if nan_at and nan_at[0] == r:
            cells[nan_at[1] - 2] = "nan"
        rows.append(f"{t}," + ",".join(cells))
    path.write_text("\n".join(rows) + "\n")
    return str(path)


def _curve(path: Path, start_s: float) -> str:
    t = np.arange(0.0, 7201.0, 600.0)
    path.write_text("t_s,released_g\n" + "".join(f"{a + start_s:g},{1.5 * (1 - np.exp(-a / 2000)):.5f}\n" for a in t))
    return str(path)


@pytest.mark.parametrize("make, says", [
    (lambda d: [_curve(d / "good.csv", 0), _curve(d / "early.csv", -600)],
     "early.csv: row 1: t_s = -600 s; times count from the drop (t = 0), never negative"),
    (lambda d: ["--reference", _units(d / "r.csv"), "--test", _units(d / "neg.csv", -0.4)],
     "neg.csv: row 2 (line 3), column 2 (u1): -11.339 % released; a unit releases -10 to 150 %"),
    (lambda d: ["--reference", _units(d / "r.csv"), "--test", _units(d / "big.csv", 40)],
     "big.csv: row 2 (line 3), column 2 (u1): 1133.88 % released"),
    (lambda d: ["--reference", _units(d / "r.csv"), "--test", _units(d / "nan.csv", nan_at=(11, 3))],
     "nan.csv: row 11 (line 12), column 3 (u2): 'nan' is not a finite number"),
])
def test_compare_refuses_negative_times_implausible_percents_and_names_nan_cells(make, says, tmp_path, capsys):
    assert main(["compare", *make(tmp_path)]) == 2
    assert says in capsys.readouterr().err


def test_masses_out_of_order_name_the_option(tmp_path, capsys):
    assert main(["calibrate-bench", "--record", str(tmp_path / "rec"), "--simulate", "--masses", "0.5,0.3"]) == 2
    err = capsys.readouterr().err
    assert "masses 0.5, 0.3 g (--masses): each must be above the one before" in err and "SeriesConfig" not in err
    assert not (tmp_path / "rec").exists()


@pytest.mark.parametrize("spec, says", [
    ("accel:q=-1", "target 'accel:q=-1': q = -1; expected a number >= 0: the final over the initial release rate"),
    ("accel:q=2,final=1.5", "final = 1.5; expected in (0, 1]"),
    ("zero-order:duration=0", "duration = 0; expected in (0, 1]"),
])
def test_analytic_target_parameters_are_named_in_the_users_terms(spec, says, tmp_path, capsys):
    assert main(["design", "--target", spec, "--out", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err
    assert says in err and "T = " not in err
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize("content, says", [
    ("this is a shopping list, not a mesh\n", "fake.stl: not an STL mesh (no triangles could be read from it)"),
    ("", "fake.stl: empty file; expected an STL triangle mesh in mm"),
])
def test_a_text_file_renamed_stl_is_named_not_a_mesh(content, says, tmp_path, capsys):
    (tmp_path / "fake.stl").write_text(content)
    assert main(["simulate", str(tmp_path / "fake.stl"), "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert says in err and "contains no triangles" not in err


def test_a_folder_that_does_not_exist_is_named_so(tmp_path, capsys):
    from analysis import read_frame_list

    with pytest.raises(AnalysisError, match=r"gone does not exist; give a run folder or a folder of images"):
        read_frame_list(tmp_path / "gone")
    (tmp_path / "file").write_text("x")
    with pytest.raises(AnalysisError, match=r"file is not a folder"):
        read_frame_list(tmp_path / "file")


def test_a_batch_with_a_missing_run_folder_is_refused_before_any_work(tmp_path, capsys):
    from labapp.jobs.calibrate_bench import calibrate_series

    calibrate_series(BENCH / "calibration", tmp_path / "cal.json")
    code = main(["analyze", str(BENCH / "run"), str(tmp_path / "gone"), "--calibration", str(tmp_path / "cal.json"),
                 "--out", str(tmp_path / "batch")])
    assert code == 2
    err = capsys.readouterr().err
    assert f"1 of the 2 run folders do not exist or are not folders: {tmp_path / 'gone'}" in err
    assert "cluster" not in err                                     # refused before Dask starts
    assert not (tmp_path / "batch").exists()


def test_a_read_only_data_directory_is_refused_before_the_run_starts(tmp_path, capsys, monkeypatch):
    import errno

    import labapp.jobs.run as run_job

    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(run_job.tempfile, "mkdtemp", read_only)
    assert main(["run", "--simulate", "--speed", "0", "--out", str(tmp_path / "runs")]) == 2
    captured = capsys.readouterr()
    assert f"--out {tmp_path / 'runs'}: no run folder can be written in {tmp_path} (Read-only file system)" in captured.err
    assert "Errno" not in captured.err and "simulated calibration" not in captured.out + captured.err
    assert not any(tmp_path.iterdir())


def test_a_data_directory_without_room_for_the_run_is_refused_before_it_starts(tmp_path, capsys, monkeypatch):
    import labapp.records.fileio as fileio

    monkeypatch.setattr(fileio, "free_bytes", lambda folder: 10_000_000)
    cal = tmp_path / "cal.json"
    from labapp.jobs.calibrate_bench import calibrate_series

    calibrate_series(BENCH / "calibration", cal)
    assert main(["run", "--simulate", "--speed", "0", "--calibration", str(cal), "--out", str(tmp_path / "runs")]) == 2
    err = capsys.readouterr().err
    assert f"--out {tmp_path / 'runs'}: not enough disk space" in err and "no run was started" in err
    assert not (tmp_path / "runs").exists()


def test_a_sweep_of_a_missing_target_is_refused_before_any_work(tmp_path, capsys):
    spec = tmp_path / "sweep.toml"
    spec.write_text('target = "gone.stl"\nmax_iter = 2\nresolution = 16\n[grid]\nw_binary = [10, 20]\n')
    assert main(["sweep", str(spec), "--out", str(tmp_path / "sw")]) == 2
    err = capsys.readouterr().err
    assert f"target 'gone.stl' does not exist (looked for {tmp_path / 'gone.stl'}" in err
    assert not (tmp_path / "sw").exists()


@pytest.mark.parametrize("loo, c_sat, chosen", [
    ({"constant": 0.0500, "saturation": 0.0500}, 5.7e6, "constant"),    # a tie, c_sat far beyond the data
    ({"constant": 0.0500, "saturation": 0.0498}, 50.0, "constant"),     # within 1 %: a tie
    ({"constant": 0.0500, "saturation": 0.0400}, 5.7e6, "constant"),    # better, but c_sat 1e5 x the data's
    ({"constant": 0.0500, "saturation": 0.0400}, 50.0, "saturation"),   # better and reached: saturation
])
def test_the_simpler_model_wins_a_tie_and_an_inert_saturation(loo, c_sat, chosen):
    from types import SimpleNamespace

    from labapp.jobs.calibrate_sim import _ModelFits

    fits = {"constant": SimpleNamespace(cal=SimpleNamespace(saturation_g_per_kg=None)),
            "saturation": SimpleNamespace(cal=SimpleNamespace(saturation_g_per_kg=c_sat))}
    assert _ModelFits(("constant", "saturation"), fits, {}, loo, top_conc_g_per_kg=4.0).chosen == chosen


@pytest.mark.parametrize("noise_g, says", [(1e-6, "noise is below 0.01 %"), (0.0037, "noise is about 0.25 %")])
def test_the_noise_of_a_measured_target_is_never_about_zero(noise_g, says):
    from labapp.jobs.physical import MeasuredTarget

    target = MeasuredTarget(Path("t.csv"), 1.5, "weighed", noise_g, 0.01, 0.0, 0)
    assert says in target.text() and "0.00 %)" not in target.text().split("noise")[1]


def test_a_design_whose_line_search_stalls_is_reported_as_converged(tmp_path):
    from design.files.summary_text import summary_lines

    summary = {"status": "stalled", "iterations": 73, "seconds": 40.0, "seconds_per_iteration": 0.55,
               "rel_rmse_print": 0.0056, "rel_rmse_density": 0.005, "rel_rmse_design_grid_binary": 0.006,
               "rate_dev_mid80": {"print": 0.02, "density": 0.02, "design_grid_binary": 0.02}, "pieces": 1,
               "print_mass_g": 1.2, "min_channel_mm": None, "enclosed_voids": 0, "enclosed_void_mm3": 0.0,
               "overhang_fraction": 0.1, "max_overhang_run_mm": 1.0, "warnings": []}
    first = summary_lines(summary, tmp_path)[0]
    assert first.startswith("converged (no step lowers J further) after 73 evaluations") and "stalled" not in first


@pytest.mark.slow
def test_an_extruded_multistart_design_warns_once(tmp_path, capsys, caplog):
    import logging

    caplog.set_level(logging.DEBUG)
    assert main(["design", "--target", "zero-order", "--space", "extruded", "--resolution", "16", "--max-iter", "4",
                 "--out", str(tmp_path / "d")]) == 0
    warned = [r for r in caplog.records if r.levelno >= logging.WARNING and "middle 80%" in r.getMessage()]
    assert len(warned) == 1                                          # at the start, not once per start and again
    assert capsys.readouterr().out.count("warning: the target's middle 80%") == 1    # and in the summary


def test_the_guide_names_everything_analyze_adds_to_a_run_folder(tmp_path):
    import re
    import shutil

    from labapp.jobs.calibrate_bench import calibrate_series

    run = tmp_path / "myrun"
    shutil.copytree(BENCH / "run", run)
    before = {p.name for p in run.iterdir()}
    calibrate_series(BENCH / "calibration", tmp_path / "cal.json")
    assert main(["analyze", str(run), "--calibration", str(tmp_path / "cal.json")]) == 0
    added = {p.name for p in run.iterdir()} - before
    assert added == {"analysis", "audit.jsonl"}
    guide = (ROOT / "docs" / "guide.md").read_text()
    record_rule = re.search(r"A run folder is a record: no command changes it except (.*?)(?:\n\n|\Z)", guide, re.S).group(1)
    assert all(f"`RUN/{name}" in record_rule for name in added)


def test_a_run_whose_camera_cannot_be_reached_leaves_no_data_directory(tmp_path, capsys):
    code = main(["run", "--camera", f"folder:{tmp_path / 'no-camera'}", "--out", str(tmp_path / "runs")])
    assert code == 1 and "no run folder written" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()
