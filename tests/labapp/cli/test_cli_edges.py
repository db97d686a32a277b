"""The command line at its edges: options after the command, full or unwritable outputs, one writer per folder,
inputs checked before any work, a run's own calibration, duplicate runs, masses in the wrong unit, Latin-1 STL."""
from __future__ import annotations

import errno
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from labapp.cli.main import main
from labapp.records.lock import LOCK_NAME, FolderLocked, folder_lock, holder

ROOT = Path(__file__).resolve().parents[3]
BENCH = ROOT / "fixtures" / "bench"


def _last_err(capsys) -> str:
    return capsys.readouterr().err.strip().splitlines()[-1]


def test_debug_is_accepted_after_the_command(tmp_path, capsys):
    code = main(["simulate", str(tmp_path / "missing.stl"), "--debug", "--out", str(tmp_path / "sim")])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" in err and "unrecognized arguments" not in err
    assert main(["verify", "-v", str(BENCH / "run")]) == 0     # -v after the command too


@pytest.mark.parametrize("number", [errno.ENOSPC, errno.EROFS, errno.EACCES])
def test_a_full_or_read_only_out_is_exit_2_with_the_file_named(monkeypatch, capsys, tmp_path, number):
    import labapp.cli.commands.simulate as simulate_command

    def run(args):
        raise OSError(number, os.strerror(number), str(Path(args.out) / "release.csv"))
    monkeypatch.setattr(simulate_command, "run", run)
    assert main(["simulate", "sample:sphere", "--out", str(tmp_path / "sim")]) == 2
    assert _last_err(capsys) == f"sfr simulate: cannot write {tmp_path / 'sim' / 'release.csv'}: {os.strerror(number)}"

    def run_unnamed(args):      # a write() that fills the disk names no file: the --out is named instead
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr(simulate_command, "run", run_unnamed)
    assert main(["simulate", "sample:sphere", "--out", str(tmp_path / "sim")]) == 2
    assert f"cannot write {tmp_path / 'sim'}: No space left on device" in _last_err(capsys)


def test_an_out_that_cannot_be_created_is_refused_before_any_work(capsys):
    assert main(["simulate", "sample:sphere", "--resolution", "12", "--out", "/sys/sfr-test-out"]) == 2
    assert "/sys/sfr-test-out" in _last_err(capsys)


# -- the lock ---------------------------------------------------------------------------------------------------

HOLD = ("import sys, time\nfrom labapp.records.lock import folder_lock\n"
        "with folder_lock(sys.argv[1], 'sfr analyze RUN --out X'):\n    print('held', flush=True)\n    time.sleep(60)\n")


def _holding(folder: Path) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(folder)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "held"
    return proc


def test_a_second_writer_is_refused_with_who_holds_the_folder(tmp_path):
    folder = tmp_path / "out"
    proc = _holding(folder)
    try:
        with pytest.raises(FolderLocked, match=rf"{folder} is being written by process {proc.pid} on "
                                               rf"{socket.gethostname()}, `sfr analyze RUN --out X`, since 20"):
            with folder_lock(folder):
                pass
        assert holder(folder)["pid"] == proc.pid
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert (folder / LOCK_NAME).exists() and holder(folder) is None     # a dead holder's file: harmless
    with folder_lock(folder):
        assert holder(folder)["pid"] == os.getpid()
    assert folder.is_dir() and not any(folder.iterdir())    # released: the lock file goes
    with folder_lock(tmp_path / "new"):
        pass
    assert not (tmp_path / "new").exists()      # a folder the lock made, with nothing else written: removed again


def test_the_lock_is_reentrant_in_a_thread_and_refuses_another_thread(tmp_path):
    folder = tmp_path / "out"
    errors = []
    with folder_lock(folder):
        with folder_lock(folder):                       # the command and its job
            pass
        (folder / "result.txt").write_text("kept")
        thread = threading.Thread(target=lambda: errors.append(pytest.raises(FolderLocked, folder_lock(folder)
                                                                             .__enter__)))
        thread.start()
        thread.join()
    assert errors and folder.is_dir() and not (folder / LOCK_NAME).exists()


def test_two_analyses_resumes_or_designs_into_one_folder_second_refused(tmp_path, capsys):
    from labapp.jobs.calibrate_bench import calibrate_series

    cal, out = tmp_path / "cal.json", tmp_path / "analysis"
    calibrate_series(BENCH / "calibration", cal)
    proc = _holding(out)
    try:
        for argv in (["analyze", str(BENCH / "run"), "--calibration", str(cal), "--out", str(out)],
                     ["design", "--resume", "--out", str(out)],
                     ["design", "--target", "sphere", "--resolution", "16", "--out", str(out)],
                     ["simulate", "sample:sphere", "--out", str(out)]):
            assert main(argv) == 2, argv
            assert f"is being written by process {proc.pid}" in _last_err(capsys), argv
    finally:
        proc.kill()
        proc.wait()


# -- inputs checked before any work ------------------------------------------------------------------------------

def test_demo_refuses_a_bad_sample_at_once_leaving_no_folder(tmp_path, capsys):
    t0 = time.monotonic()
    assert main(["demo", "--sample", "nosuch", "--out", str(tmp_path / "demo")]) == 2
    assert time.monotonic() - t0 < 10
    assert "--sample 'nosuch' is not a sample shape" in _last_err(capsys)
    assert main(["demo", "--sample", "sphere", "--out", str(tmp_path / "demo")]) == 2
    assert "one of the calibration set" in _last_err(capsys)
    assert not (tmp_path / "demo").exists()


def _set_file(tmp_path: Path, runs: list[str]) -> Path:
    mesh = tmp_path / "sphere.stl"
    if not mesh.exists():
        from design.geometry.shapes import sample_shape
        sample_shape("sphere").export(mesh)
    path = tmp_path / "set.csv"
    path.write_text("run,mesh,object_mass_g\n" + "".join(f"{r},sphere.stl,1.5\n" for r in runs))
    return path


def test_calibrate_sim_refuses_a_run_listed_twice(tmp_path):
    from labapp.records.simcal import SimCalError
    from labapp.records.simcalset import read_set

    (tmp_path / "a.csv").write_text("t_s,released_g\n0,0\n100,1\n")
    shutil.copyfile(tmp_path / "a.csv", tmp_path / "copy_of_a.csv")
    (tmp_path / "b.csv").write_text("t_s,released_g\n0,0\n100,1.2\n")
    with pytest.raises(SimCalError, match=r"rows 1 and 3 list the same run .*a\.csv"):
        read_set(_set_file(tmp_path, ["a.csv", "b.csv", "./a.csv"]))
    with pytest.raises(SimCalError, match=r"rows 1 and 2 list the same run twice: .*a\.csv and .*copy_of_a\.csv "
                                          r"have an identical content"):
        read_set(_set_file(tmp_path, ["a.csv", "copy_of_a.csv", "b.csv"]))
    shutil.copytree(BENCH / "run", tmp_path / "run_copy", ignore=shutil.ignore_patterns("*.jpg"))
    with pytest.raises(SimCalError, match=r"rows 2 and 3 .* identical manifest \(frames\.csv\)"):
        read_set(_set_file(tmp_path, ["b.csv", str(BENCH / "run"), "run_copy"]))
    assert len(read_set(_set_file(tmp_path, ["a.csv", "b.csv"]))) == 2


def test_calibrate_bench_warns_on_masses_typed_in_mg(tmp_path, capsys):
    from labapp.jobs.calibrate_bench import PLAUSIBLE_MAX_G_PER_KG, implausible_levels

    assert implausible_levels(np.array([0.0, 0.35, 2.1]), 500.0) == []
    (message,) = implausible_levels(np.array([0.0, 350.0, 2100.0]), 500.0)
    assert "reach 4200 g/kg" in message and f"0-{PLAUSIBLE_MAX_G_PER_KG:g} g/kg" in message
    assert "grams" in message and "milligrams" in message and "4.2 g/kg" in message
    series = tmp_path / "series"
    shutil.copytree(BENCH / "calibration", series)
    lines = (series / "masses.csv").read_text().splitlines()
    rows = [line.split(",") for line in lines[1:]]
    (series / "masses.csv").write_text(lines[0] + "\n" + "".join(f"{f},{float(m) * 1000:g}\n" for f, m in rows))
    (series / "run.json").unlink(missing_ok=True)
    assert main(["calibrate-bench", str(series), "--out", str(tmp_path / "cal.json")]) == 0
    err = capsys.readouterr().err
    assert "warning: " in err and "typed in milligrams" in err and "(--water-g)" in err


def test_analyze_uses_the_runs_own_calibration(tmp_path, capsys, monkeypatch):
    from labapp.jobs.calibrate_bench import calibrate_series

    run = tmp_path / "run"
    shutil.copytree(BENCH / "run", run)
    assert main(["analyze", str(run)]) == 2
    assert "holds no calibration.json of its own; give the bench calibration with --calibration" in _last_err(capsys)
    assert not (run / "analysis").exists()
    calibrate_series(BENCH / "calibration", tmp_path / "cal.json")
    shutil.copyfile(tmp_path / "cal.json", run / "calibration.json")      # as a recorded run holds it
    assert main(["analyze", str(run), "--no-plot"]) == 0
    assert (run / "analysis" / "curve.csv").is_file() and not (run / "analysis" / LOCK_NAME).exists()
    monkeypatch.chdir(tmp_path)                 # the README's way: a relative run folder
    assert main(["analyze", "run", "--no-plot"]) == 0


def test_analyze_out_analysis_from_the_repository_root_says_why(monkeypatch, capsys, tmp_path):
    from labapp.jobs.calibrate_bench import calibrate_series

    cal = tmp_path / "cal.json"
    calibrate_series(BENCH / "calibration", cal)
    monkeypatch.chdir(ROOT)
    before = sorted(p.name for p in (ROOT / "analysis").iterdir())
    assert main(["analyze", str(BENCH / "run"), "--calibration", str(cal), "--out", "analysis"]) == 2
    assert "is a Python package of the software" in _last_err(capsys)
    assert sorted(p.name for p in (ROOT / "analysis").iterdir()) == before


def test_an_ascii_stl_named_in_latin_1_is_read(tmp_path):
    import tomllib

    from design.files.meshio import load_mesh
    from design.geometry.shapes import sample_shape

    text = sample_shape("sphere").export(file_type="stl_ascii")
    path = tmp_path / "pièce.stl"
    path.write_bytes(text.replace("solid", "solid pièce d'essai é", 1).encode("latin-1"))
    assert len(load_mesh(path).faces) > 100
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    assert any(d.startswith("charset-normalizer") for d in deps)     # a fresh install has what trimesh needs


def test_a_calibration_file_written_meanwhile_is_not_overwritten(tmp_path):
    from analysis import BenchCalibration
    from labapp.jobs.calibrate_bench import _save_new, calibrate_series
    from labapp.records.outpaths import OutPathError

    cal = calibrate_series(BENCH / "calibration", tmp_path / "cal.json")
    assert isinstance(BenchCalibration.load(tmp_path / "cal.json"), BenchCalibration)
    before = (tmp_path / "cal.json").read_bytes()
    with pytest.raises(OutPathError, match="written by another command meanwhile"):
        _save_new(cal, tmp_path / "cal.json")
    assert (tmp_path / "cal.json").read_bytes() == before and [p.name for p in tmp_path.iterdir()] == ["cal.json"]


def test_calibrate_sim_checks_every_mesh_before_the_first_simulation(tmp_path):
    from labapp.jobs.calibrate_sim import calibrate_sim
    from labapp.records.simcal import SimCalError

    for name, top in (("a.csv", 1.0), ("b.csv", 1.2), ("c.csv", 0.9)):
        (tmp_path / name).write_text(f"t_s,released_g\n0,0\n100,{top}\n")
    set_csv = _set_file(tmp_path, ["a.csv", "b.csv", "c.csv"])
    (tmp_path / "broken.stl").write_text("solid broken\nendsolid broken\n")
    set_csv.write_text(set_csv.read_text().replace("c.csv,sphere.stl", "c.csv,broken.stl"))
    steps = []
    with pytest.raises(SimCalError, match=r"set\.csv row 3: .*broken\.stl"):
        calibrate_sim(set_csv, None, tmp_path / "simcal", progress=lambda f, m: steps.append(m))
    assert steps == [] and not (tmp_path / "simcal").exists()


def test_the_design_job_refuses_a_second_resume_of_one_folder(tmp_path):
    """The job takes the lock itself, so the GUI's launcher and sfr design never resume one run together."""
    from design.inverse.config import DesignConfig
    from labapp.jobs.design import design

    out = tmp_path / "design"
    design(DesignConfig(target="sphere", resolution=16, max_iter=3, physical_correction="none"), out)
    proc = _holding(out)
    try:
        with pytest.raises(FolderLocked, match=f"is being written by process {proc.pid}"):
            design(None, out, resume=True)
    finally:
        proc.kill()
        proc.wait()


def test_the_calibrate_sim_job_takes_the_lock_after_its_checks(tmp_path):
    from labapp.jobs.calibrate_sim import calibrate_sim

    for name, top in (("a.csv", 1.0), ("b.csv", 1.2)):
        (tmp_path / name).write_text(f"t_s,released_g\n0,0\n100,{top}\n")
    out = tmp_path / "simcal"
    proc = _holding(out)
    try:
        with pytest.raises(FolderLocked, match=f"is being written by process {proc.pid}"):
            calibrate_sim(_set_file(tmp_path, ["a.csv", "b.csv"]), None, out)
    finally:
        proc.kill()
        proc.wait()
