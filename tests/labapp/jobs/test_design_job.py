"""`sfr design` through its job: a resume keeps the calibration and the settings the run started with, and bad
density or checkpoint files are one line with exit code 2."""
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from labapp.cli.main import main
from labapp.records.simcal import FORMAT, FORWARD_MODEL

TINY = ["--space", "extruded", "--resolution", "16", "--radius", "2"]
G_PER_MM3 = 2.0e-3


def _simcal(path: Path, g_per_mm3: float = G_PER_MM3) -> Path:
    path.write_text(json.dumps({"format": FORMAT, "forward_model": FORWARD_MODEL,
        "physics": {"anisotropy": 1.0, "offset_mm": 0.0}, "model": "constant",
                                "seconds_per_mm": 1500.0, "g_per_mm3": g_per_mm3, "resolution": 16,
                                "voxel_size_mm": 1.0, "water_g": 500.0}))
    return path


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory) -> tuple[Path, Path]:
    """A finished design started with --simcal (the file is then changed: the run keeps its own copy)."""
    root = tmp_path_factory.mktemp("calibrated")
    simcal = _simcal(root / "simcal.json")
    out = root / "design"
    assert main(["design", "--target", "sphere", *TINY, "--max-iter", "40", "--simcal", str(simcal),
                 "--out", str(out)]) == 0
    return out, simcal


def test_the_calibration_is_copied_with_its_sha256(calibrated):
    out, simcal = calibrated
    record = json.loads((out / "simcal_source.json").read_text())
    assert (out / "simcal_input.json").read_bytes() == simcal.read_bytes()
    assert record["source"] == str(simcal.resolve()) and len(record["sha256"]) == 64
    summary = json.loads((out / "summary.json").read_text())
    assert summary["print_mass_g"] == pytest.approx(summary["volume_mm3"] * G_PER_MM3)


def test_a_resume_without_simcal_writes_the_physical_outputs_with_the_runs_calibration(calibrated, tmp_path, capsys):
    out, simcal = calibrated
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    for name in ("summary.json", "curves_physical.csv"):  # Ctrl-C while the outputs were written
        (copy / name).unlink()
    assert main(["design", "--resume", "--out", str(copy)]) == 0
    summary = json.loads((copy / "summary.json").read_text())
    assert (copy / "curves_physical.csv").is_file() and "rel_rmse_physical" in summary
    assert summary["print_mass_g"] == pytest.approx(summary["volume_mm3"] * G_PER_MM3)  # not at 1.32 g/cm^3
    assert summary["simcal"]["g_per_mm3"] == G_PER_MM3
    # a finished run is then left as it is, with or without the same --simcal
    before = {p.name: p.read_bytes() for p in copy.iterdir() if p.is_file()}
    capsys.readouterr()
    assert main(["design", "--resume", "--simcal", str(simcal), "--out", str(copy)]) == 0
    assert "already finished: nothing to do" in capsys.readouterr().out
    assert {p.name: p.read_bytes() for p in copy.iterdir() if p.is_file()} == before


def test_a_resume_refuses_another_calibration_and_an_altered_copy(calibrated, tmp_path, capsys):
    out, _ = calibrated
    other = _simcal(tmp_path / "other.json", g_per_mm3=1.0e-3)
    assert main(["design", "--resume", "--simcal", str(other), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--simcal {other} differs from the run's stored calibration {out / 'simcal_input.json'}" in err
    assert "drop it to resume" in err and "internal error" not in err
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    _simcal(copy / "simcal_input.json", g_per_mm3=3.0e-3)
    assert main(["design", "--resume", "--out", str(copy)]) == 2
    assert "copy of its simulation calibration is missing or altered" in capsys.readouterr().err
    plain = tmp_path / "plain"
    assert main(["design", "--target", "sphere", *TINY, "--max-iter", "2", "--out", str(plain)]) == 1  # no solid yet
    assert main(["design", "--resume", "--simcal", str(other), "--out", str(plain)]) == 2
    assert "started without a simulation calibration" in capsys.readouterr().err


@pytest.mark.parametrize("option, stored", [
    (["--space", "nfc"], "--space nfc differs from the run's stored extruded"),
    (["--radius", "3"], "--radius 3.0 differs from the run's stored 2.0"),
    (["--max-iter", "10"], "--max-iter 10 differs from the run's stored 40"),
    (["--w-binary", "7"], "--w-binary 7.0 differs from the run's stored"),
    (["--allow-pieces"], "--allow-pieces True differs from the run's stored False"),
    (["--units", "cm"], "--units cm differs from the run's stored mm"),
    (["--calibration", "cal.json"], "--calibration is used when a run starts"),
])
def test_options_given_with_a_resume_must_be_the_stored_ones(calibrated, capsys, option, stored):
    out, _ = calibrated
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert main(["design", "--resume", *option, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert stored in err and "internal error" not in err
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before


def test_a_file_target_is_compared_with_the_source_the_run_recorded(tmp_path, capsys):
    target = tmp_path / "target.csv"
    target.write_text("tau_mm,released_mm3\n0,0\n1,40\n2,70\n3,90\n4,100\n")
    out = tmp_path / "d"
    assert main(["design", "--target", str(target), *TINY, "--max-iter", "2", "--out", str(out)]) == 1  # no solid yet
    same = tmp_path / "same.csv"  # another path with the same bytes is the same target
    same.write_bytes(target.read_bytes())
    capsys.readouterr()
    assert main(["design", "--resume", "--target", str(same), "--out", str(out)]) == 1
    assert "already finished: nothing to do" in capsys.readouterr().out
    other = tmp_path / "other.csv"
    other.write_text("tau_mm,released_mm3\n0,0\n1,50\n2,100\n")
    assert main(["design", "--resume", "--target", str(other), "--out", str(out)]) == 2
    assert (f"--target {other} differs from the run's stored {target.resolve()} in {out / 'target_source.json'}; "
            "drop it to resume") in capsys.readouterr().err


def test_the_same_options_resume(calibrated, capsys):
    out, _ = calibrated
    assert main(["design", "--resume", "--target", "sphere", *TINY, "--max-iter", "40", "--units", "mm",
                 "--out", str(out)]) == 0
    assert "already finished: nothing to do" in capsys.readouterr().out


def _bad_files(folder: Path) -> dict[str, Path]:
    folder.mkdir()
    valid = folder / "valid.npz"
    np.savez(valid, rho=np.ones((8, 8, 8)), dx_mm=0.5)
    files = {"empty": folder / "empty.npz", "truncated": folder / "truncated.npz", "text": folder / "text.npz"}
    files["empty"].write_bytes(b"")
    files["truncated"].write_bytes(valid.read_bytes()[: valid.stat().st_size // 2])
    files["text"].write_text("rho,dx_mm\n1,0.5\n")
    return files


@pytest.mark.parametrize("kind", ["empty", "truncated", "text"])
def test_a_bad_density_file_is_one_line_and_exit_2(tmp_path, capsys, kind):
    bad = _bad_files(tmp_path / "in")[kind]
    for command in (["simulate", str(bad), "--out", str(tmp_path / "sim")],
                    ["design", "--target", str(bad), *TINY, "--max-iter", "2", "--out", str(tmp_path / "des")]):
        assert main(command) == 2, command
        err = capsys.readouterr().err
        errors = [line for line in err.splitlines() if line.startswith("sfr") and str(bad) in line]
        assert len(errors) == 1 and "internal error" not in err and "Traceback" not in err, err


def test_a_truncated_checkpoint_and_a_full_disk_are_one_line_and_exit_2(calibrated, tmp_path, capsys, monkeypatch):
    out, _ = calibrated
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    data = (copy / "checkpoint.npz").read_bytes()
    (copy / "checkpoint.npz").write_bytes(data[: len(data) // 3])
    assert main(["design", "--resume", "--out", str(copy)]) == 2
    err = capsys.readouterr().err.strip()
    assert f"{copy / 'checkpoint.npz'}: not a readable design checkpoint" in err and "internal error" not in err

    monkeypatch.setattr("design.files.records.os", _FullDisk())  # the checkpoint's own writes only
    run = tmp_path / "full"
    assert main(["design", "--target", "sphere", *TINY, "--max-iter", "12", "--out", str(run)]) == 2
    err = capsys.readouterr().err
    assert "cannot write the checkpoint" in err and "checkpoint.npz: No space left on device" in err
    assert not list(tmp_path.rglob("checkpoint.tmp.npz"))


class _FullDisk:
    """``os`` for the checkpoint writer of a full disk: flushing to the disk fails."""

    def __getattr__(self, name):
        return getattr(os, name)

    @staticmethod
    def fsync(fd):
        raise OSError(28, "No space left on device")
