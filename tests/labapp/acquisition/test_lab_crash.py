"""Crash safety: SIGKILL the acquisition process mid-run, reopen the folder, resume into it; Ctrl-C stops cleanly."""
import os
import signal
import subprocess
import sys

import pytest

from labapp.records.manifests import read_run, unrecorded_frames
from labapp.records.runrecord import RecordStatus
from labapp.records.verification import verify_run
from tests.labapp.acquisition.runwait import wait_frames


def _sfr_run(*args):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "labapp.cli.main", "run", "--simulate", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env, text=True)


@pytest.mark.slow
def test_sigkill_mid_run_then_resume_into_the_same_folder(tmp_path, sim_calibration):
    _, cal_path = sim_calibration
    runs = tmp_path / "runs"
    first = _sfr_run("--speed", "200", "--sample", "sphere", "--out", str(runs), "--calibration", str(cal_path),
                     "--max-hours", "3", "--no-steady-stop")
    folder = wait_frames(runs, 15, first)
    first.send_signal(signal.SIGKILL)
    first.wait(120)

    before = read_run(folder)
    assert before.status == RecordStatus.INTERRUPTED and not before.live
    assert len(before.frames) >= 15
    assert all((folder / f.file).is_file() for f in before.frames)
    report = verify_run(folder)                        # every frame listed exactly once and intact, except
    assert report.ok or report.unlisted == unrecorded_frames(read_run(folder)) != []   # one killed mid-record

    second = _sfr_run("--speed", "200", "--resume", str(folder))
    wait_frames(runs, len(before.frames) + 10, second)
    second.send_signal(signal.SIGINT)                  # Ctrl-C: a clean stop
    out, _ = second.communicate(timeout=300)
    assert second.returncode == 130, out
    assert "stopping cleanly" in out and "run stopped" in out

    after = read_run(folder)
    assert after.status == RecordStatus.STOPPED and after.meta["resumed"] == 1
    assert after.frames[: len(before.frames)] == before.frames
    names = [f.file for f in after.frames]
    assert len(names) == len(set(names)) and len(names) >= len(before.frames) + 10
    t = [f.t_s for f in after.frames]
    assert all(b > a for a, b in zip(t, t[1:]))
    gap = after.meta["gaps"][0]
    assert gap["after_t_s"] == before.frames[-1].t_s and gap["before_t_s"] < after.frames[len(before.frames)].t_s
    assert verify_run(folder).ok
    log = (folder / "events.log").read_text()
    assert "stopped without finishing" in log and "resumed into the same folder" in log
    assert list(tmp_path.glob("runs/*")) == [folder]   # no second folder
