"""A full disk: every output is written whole or not at all, nothing partial is left beside it, and the
command ends with exit code 2 naming the file (a test double for the write calls: a file that takes 4 KiB
and then raises ENOSPC, as a full file system does)."""
import errno
import io

import numpy as np
import pytest

from analysis import AnalysisError
from labapp.cli.main import main
from labapp.errors import EXIT_USAGE
from labapp.records import fileio
from labapp.records.fileio import WriteError, atomic_write

FREE_BYTES = 4096


class _FullDisk(io.FileIO):
    """A file on a disk with ``FREE_BYTES`` free."""

    def write(self, data):
        if self.tell() + len(data) > FREE_BYTES:
            raise OSError(errno.ENOSPC, "No space left on device")
        return super().write(data)


@pytest.fixture
def full_disk(monkeypatch):
    """``open`` of :mod:`labapp.records.fileio` (every atomic write) opens files on a full disk."""
    def full_open(path, mode="r", **kwargs):
        return _FullDisk(path, "w", opener=kwargs.get("opener")) if mode == "wb" else open(path, mode, **kwargs)

    monkeypatch.setattr(fileio, "open", full_open, raising=False)


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir())


def test_an_atomic_write_on_a_full_disk_leaves_the_old_file_and_no_part(full_disk, tmp_path):
    target = tmp_path / "summary.json"
    target.write_bytes(b"old")
    with pytest.raises(WriteError, match=f"cannot write {target}: No space left on device") as exc:
        atomic_write(target, b"x" * (2 * FREE_BYTES))
    assert exc.value.exit_code == EXIT_USAGE
    assert _leftovers(tmp_path) == ["summary.json"] and target.read_bytes() == b"old"
    atomic_write(target, b"new")                     # what fits is written
    assert target.read_bytes() == b"new"


def test_a_report_on_a_full_disk_exits_2_and_leaves_no_torn_pdf(full_disk, tmp_path, capsys):
    from labapp.records.runrecord import RecordStatus
    from labapp.records.storage import create_run

    run = create_run(tmp_path / "data", "pill", {"simulated": True, "object_mass_g": 2.0, "water_g": 500.0})
    run.finish(RecordStatus.COMPLETE)
    run.close()
    t = np.arange(0.0, 4 * 3600.0 + 1, 300.0)
    curve = tmp_path / "curve.csv"
    curve.write_text("t_s,released_g\n" + "".join(f"{a:.1f},{2 * (1 - np.exp(-3e-4 * a)):.6f}\n" for a in t))
    out = tmp_path / "full"
    out.mkdir()
    assert main(["report", str(run.path), "--curve", str(curve), "--out", str(out / "r.pdf")]) == EXIT_USAGE
    err = capsys.readouterr().err
    assert f"cannot write {out / 'r.pdf'}: No space left on device" in err and "internal error" not in err
    assert _leftovers(out) == []


def test_a_cell_cache_that_does_not_fit_leaves_no_part_file(monkeypatch, tmp_path):
    from analysis import runfolder

    def savez(path, **arrays):
        open(path, "wb").close()
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(runfolder.np, "savez", savez)
    with pytest.raises(OSError):
        runfolder._save_cache(tmp_path, "key", {"a": np.zeros((2, 2))})
    assert _leftovers(tmp_path) == []


def test_a_bench_calibration_that_does_not_fit_leaves_no_part_file(monkeypatch, tmp_path):
    from labapp.jobs.calibrate_bench import _save_new

    class Calibration:
        def save(self, path):           # as analysis.BenchCalibration.save fails on a full disk
            path.write_bytes(b"")
            try:
                raise OSError(errno.ENOSPC, "No space left on device")
            except OSError as exc:
                raise AnalysisError(f"cannot write calibration {path}: {exc.strerror}") from exc

    with pytest.raises(WriteError, match="cannot write .*c.json: No space left on device"):
        _save_new(Calibration(), tmp_path / "c.json")
    assert _leftovers(tmp_path) == []
