"""`sfr lab` stops on SIGTERM and Ctrl-C (SIGINT) as closing the window mid-run does: heating off, the run folder
left interrupted and resumable, exit status 128 + the signal (143 for SIGTERM, 130 for SIGINT). A real process,
offscreen, on the simulated bench."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("pytestqt")

from labapp.jobs.run import resumable
from labapp.records.manifests import read_run
from labapp.records.verification import verify_run

ROOT = Path(__file__).resolve().parents[3]


def _frames(data: Path) -> tuple[Path | None, int]:
    for folder in sorted(data.glob("*_run")):
        csv = folder / "frames.csv"
        if csv.is_file():
            return folder, max(len(csv.read_text().splitlines()) - 1, 0)
    return None, 0


@pytest.mark.slow
@pytest.mark.parametrize("signum, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_interrupts_the_run_resumably_with_the_heating_off(tmp_path, sim_calibration, signum, code):
    _, cal_path = sim_calibration
    data = tmp_path / "runs"
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", SFR_LAB_SETTINGS=str(tmp_path / "lab.ini"))
    proc = subprocess.Popen([sys.executable, "-m", "labapp.cli.main", "lab", "--simulate", "--speed", "0",
                             "--sample", "sphere", "--autostart", "--calibration", str(cal_path), "--data", str(data)],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        folder, n = None, 0
        while time.monotonic() < deadline and proc.poll() is None:
            folder, n = _frames(data)
            if n >= 3:
                break
            time.sleep(0.2)
        assert n >= 3, (proc.poll(), proc.stderr.read() if proc.poll() is not None else "")
        proc.send_signal(signum)
        out, err = proc.communicate(timeout=300)
    finally:
        proc.kill()
    assert proc.returncode == code, (out, err)
    assert f"sfr lab: {signal.Signals(signum).name}: interrupting" in err
    snap = read_run(folder)
    assert snap.status == "interrupted" and len(snap.frames) >= 3 and verify_run(folder).ok
    assert resumable(folder).path == folder                        # the Runs tab (or sfr run --resume) continues it
    events = (folder / "events.log").read_text()
    assert "heating and stirring switched off" in events and "the run can be resumed" in events
