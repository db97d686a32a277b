"""`sfr demo` on a full disk: refused before anything is written, naming the folder; a disk that fills during the loop
ends with a storage error naming the folder, not an internal error."""
import errno
import os

import pytest

from labapp.cli.main import main
from labapp.errors import EXIT_FAILED
from labapp.jobs import demo
from labapp.records.fileio import StorageError


def test_a_demo_on_a_full_disk_is_refused_before_it_writes(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(demo, "free_bytes", lambda folder: 10_000_000)     # 10 MB free
    out = tmp_path / "full" / "demo"
    assert main(["demo", "--out", str(out)]) == EXIT_FAILED
    err = capsys.readouterr().err
    assert "not enough disk space for the demo" in err and str(out) in err and "10 MB free" in err
    assert "internal error" not in err
    assert not out.exists()                 # no partial session folder


def test_a_disk_that_fills_during_the_loop_names_the_folder(tmp_path, monkeypatch):
    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr("labapp.acquisition.calseries.create_run", full)
    with pytest.raises(StorageError, match="calibration series could not write its run folder in .*cal.*No space"):
        demo.simulated_calibration(tmp_path / "cal")
