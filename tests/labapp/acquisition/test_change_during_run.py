"""A setting changed while a run records, from another process (`sfr change`): carried out by the recording
process at its next frame, audited with who and why, kept in run.json; refused with the reason otherwise."""
import os
import subprocess
import sys

import pytest

from labapp.records.audit import check_trail
from labapp.records.manifests import read_run
from labapp.records.requests import REQUESTS_DIR
from labapp.records.verification import verify_run
from tests.labapp.acquisition.runwait import wait_frames


def _sfr(*args, **kwargs):
    return subprocess.Popen([sys.executable, "-m", "labapp.cli.main", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, env=dict(os.environ, PYTHONUNBUFFERED="1"), text=True, **kwargs)


@pytest.mark.slow
def test_sfr_change_extends_a_recording_run_audited_and_kept(tmp_path, sim_calibration, capsys):
    from labapp.cli.main import main
    from labapp.jobs.run import change_setting  # noqa: F401  (imported before the clock starts)

    _, cal_path = sim_calibration
    runs = tmp_path / "runs"
    recording = _sfr("run", "--simulate", "--speed", "300", "--sample", "sphere", "--out", str(runs), "--calibration",
                     str(cal_path), "--max-hours", "0.5", "--no-steady-stop", "--interval", "60")
    folder = wait_frames(runs, 3, recording)
    with pytest.raises(SystemExit) as refused:          # a change without a reason: refused by argparse
        main(["change", str(folder), "--max-hours", "0.75"])
    assert refused.value.code == 2
    assert "--reason" in capsys.readouterr().err
    assert main(["change", str(folder), "--max-hours", "0.75", "--reason", "the sample dissolves slower than planned"]) == 0
    assert "changed max_duration_s: 0.5 -> 0.75 h" in capsys.readouterr().out
    out, _ = recording.communicate(timeout=300)
    assert recording.returncode == 0, out

    snap = read_run(folder)
    assert snap.record.config["max_duration_s"] == 2700.0
    # well past the old limit (1800 s), to the new: the run stops after the first frame at whose end the run
    # clock has reached 2700 s; that frame may have been captured just before, when a loaded machine is late
    assert 2400.0 < snap.frames[-1].t_s and snap.frames[-2].t_s < 2700.0 and len(snap.frames) < 2700 / 60 + 2
    entry = [e for e in check_trail(folder).entries if e["action"] == "change-setting"][-1]
    assert (entry["operator"], entry["detail"], entry["reason"]) == (
        "tester", "max_duration_s: 0.5 -> 0.75 h", "the sample dissolves slower than planned")
    assert "maximum duration 2700 s reached" in (folder / "events.log").read_text()
    assert verify_run(folder).ok and not list((folder / REQUESTS_DIR).iterdir())

    after = subprocess.run([sys.executable, "-m", "labapp.cli.main", "change", str(folder), "--min-minutes", "10",
                            "--reason", "too late"], capture_output=True, text=True, timeout=300)
    assert after.returncode == 2 and "is not being recorded" in after.stderr, after.stderr


def test_a_request_the_run_cannot_carry_out_is_answered_with_why(tmp_path):
    from labapp.acquisition.procedures import RunConfig, RunProcedure
    from labapp.records import requests
    from labapp.records.storage import create_run

    class Session:
        notes = []

        def note(self, *args):
            self.notes.append(args)

    proc = RunProcedure(RunConfig(), bench=None, data_dir=tmp_path)
    proc.run = create_run(tmp_path, "pill", {"simulated": True, "config": proc.config.to_dict()})
    proc.session = Session()
    asked = [requests.post(proc.run.path, body) for body in (
        {"action": "change", "name": "interval_s", "value": 5.0, "reason": "faster", "operator": "tester"},
        {"action": "reboot"},
        {"action": "change", "name": "min_duration_s", "value": 600.0, "reason": "fast sample", "operator": "tester"})]
    (proc.run.path / REQUESTS_DIR / "0-garbage.json").write_text("{not json")
    proc._serve_requests()
    answers = [requests.wait_answer(path, 1.0) for path in asked]
    assert [a["done"] for a in answers] == [False, False, True]
    assert "interval_s cannot change while a run records" in answers[0]["why"]
    assert "not a request this run understands" in answers[1]["why"]
    assert proc.config.min_duration_s == 600.0 and proc.config.interval_s == RunConfig().interval_s
    assert requests.wait_answer(proc.run.path / REQUESTS_DIR / "0-garbage.json", 1.0)["done"] is False
    proc.run.close()


def test_an_unanswered_request_is_withdrawn_so_it_never_applies_later(tmp_path):
    from labapp.records import requests

    path = requests.post(tmp_path, {"action": "change"})
    assert requests.wait_answer(path, 0.3, poll_s=0.05) is None
    assert list(requests.claim(tmp_path)) == []         # withdrawn: a later frame does not find it
