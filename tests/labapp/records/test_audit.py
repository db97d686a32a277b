"""Operators, the audit trail's hash chain and electronic signatures: every tampering is detected or refused."""
import json

import pytest

from labapp.jobs.verify import verify
from labapp.records import operators
from labapp.records.audit import AUDIT_FILE, Action, append, check_trail
from labapp.records.manifests import read_record
from labapp.records.operators import OperatorError
from labapp.records.runrecord import RecordStatus
from labapp.records.signatures import SignatureError, check_signatures, sign
from labapp.records.storage import create_run, finalise_run, open_run

PASSWORD = "correct horse battery"


@pytest.fixture
def users(tmp_path, monkeypatch):
    """A users file of its own with 'A. Jones' and 'B. Smith' (same password), acting as A. Jones."""
    path = tmp_path / "users.json"
    monkeypatch.setenv(operators.USERS_ENV, str(path))
    monkeypatch.setenv(operators.OPERATOR_ENV, "A. Jones")
    operators.add_user("A. Jones", PASSWORD)
    operators.add_user("B. Smith", PASSWORD)
    return path


def _finished_run(tmp_path, n=2):
    run = create_run(tmp_path / "data", "pill", {"water_g": 500.0, "simulated": True})
    for k in range(n):
        run.add_frame(f"frame_{k:06d}.jpg", bytes([k]) * 50, t_s=11.0 * k, t_unix_s=1e9 + 11 * k)
    run.finish(RecordStatus.STOPPED)
    run.close()
    return run.path


def _lines(folder):
    return (folder / AUDIT_FILE).read_bytes().splitlines(keepends=True)


# ------------------------------------------------------------------------------------------------- operators
def test_passwords_are_salted_hashed_and_checked(users):
    stored = json.loads(users.read_text())["users"]
    assert stored[0]["salt"] != stored[1]["salt"] and stored[0]["hash"] != stored[1]["hash"]
    assert PASSWORD not in users.read_text()
    assert operators.check_password("A. Jones", PASSWORD)
    assert not operators.check_password("A. Jones", PASSWORD + "!")
    assert not operators.check_password("nobody", PASSWORD)
    with pytest.raises(OperatorError, match="at least 8"):
        operators.add_user("C. Short", "short")
    with pytest.raises(OperatorError, match="exists"):
        operators.add_user("A. Jones", PASSWORD)


def test_no_operator_no_recorded_action(users, tmp_path, monkeypatch):
    monkeypatch.delenv(operators.OPERATOR_ENV)
    with pytest.raises(OperatorError, match="no operator"):
        create_run(tmp_path / "data", "pill", {"simulated": True})
    assert not (tmp_path / "data").exists()
    monkeypatch.setenv(operators.OPERATOR_ENV, "Mallory")
    with pytest.raises(OperatorError, match="not in the users file"):
        create_run(tmp_path / "data", "pill", {"simulated": True})
    operators.set_enabled("B. Smith", False)
    with pytest.raises(OperatorError, match="disabled"), operators.acting_as("B. Smith"):
        pass
    assert not operators.check_password("B. Smith", PASSWORD)


def test_the_demo_operator_records_only_on_the_simulated_bench(users, tmp_path):
    with operators.acting_as(operators.DEMO_OPERATOR):
        with pytest.raises(OperatorError, match="simulated bench"):
            create_run(tmp_path / "data", "pill", {"simulated": False})
        run = create_run(tmp_path / "data", "pill", {"simulated": True})
    assert read_record(run.path).operator == operators.DEMO_OPERATOR
    run.close()


def test_the_cli_refuses_a_recording_command_without_operator(users, tmp_path, monkeypatch, capsys):
    from labapp.cli.main import main

    monkeypatch.delenv(operators.OPERATOR_ENV)
    assert main(["run", "--simulate", "--out", str(tmp_path / "runs")]) == 2
    assert "no operator" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()
    assert main(["run", "--simulate", "--out", str(tmp_path / "runs"), "--operator", "Mallory"]) == 2
    assert "not in the users file" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------------- audit trail
def test_a_run_audits_who_did_what_and_its_chain_holds(users, tmp_path):
    folder = _finished_run(tmp_path)
    with operators.acting_as("B. Smith"):
        run = open_run(folder)
        run.finish(RecordStatus.STOPPED)
        run.close()
    trail = check_trail(folder, expect_last=Action.STOP)
    assert trail.ok, trail.problems
    assert [(e["operator"], e["action"]) for e in trail.entries] == [
        ("A. Jones", "start"), ("A. Jones", "stop"), ("B. Smith", "resume"), ("B. Smith", "stop")]
    assert trail.entries[0]["record"] == folder.name and read_record(folder).operator == "A. Jones"
    assert verify(folder).ok


def test_an_edited_entry_is_detected(users, tmp_path):
    folder = _finished_run(tmp_path)
    lines = _lines(folder)
    lines[0] = lines[0].replace(b"A. Jones", b"B. Smith")
    (folder / AUDIT_FILE).write_bytes(b"".join(lines))
    trail = check_trail(folder)
    assert not trail.ok and "line 1 (seq 1, start): EDITED" in trail.problems[0]
    report = verify(folder)
    assert not report.ok and "EDITED" in report.reason


def test_a_deleted_entry_is_detected(users, tmp_path):
    folder = _finished_run(tmp_path)
    append(folder, Action.REANALYSE, "analysed")
    lines = _lines(folder)
    (folder / AUDIT_FILE).write_bytes(lines[0] + lines[2])
    problems = check_trail(folder).problems
    assert any("seq 2 DELETED" in p for p in problems), problems
    (folder / AUDIT_FILE).write_bytes(lines[1] + lines[2])
    assert any("entries before it were DELETED" in p for p in check_trail(folder).problems)


def test_reordered_entries_are_detected(users, tmp_path):
    folder = _finished_run(tmp_path)
    append(folder, Action.REANALYSE, "analysed")
    lines = _lines(folder)
    (folder / AUDIT_FILE).write_bytes(lines[0] + lines[2] + lines[1])
    problems = check_trail(folder).problems
    assert problems and all("REORDERED" in p for p in problems), problems


def test_a_truncated_trail_is_detected(users, tmp_path):
    folder = _finished_run(tmp_path)
    lines = _lines(folder)
    (folder / AUDIT_FILE).write_bytes(lines[0] + lines[1][:20])          # torn last line
    assert any("torn" in p for p in check_trail(folder).problems)
    (folder / AUDIT_FILE).write_bytes(lines[0])                            # the 'stop' entry cut off
    assert check_trail(folder).ok                                          # the chain alone cannot tell ...
    report = verify(folder)                                                # ... the record's status can
    assert not report.ok and "TRUNCATED" in report.reason
    (folder / AUDIT_FILE).unlink()
    assert "audit trail audit.jsonl is missing" in verify(folder).reason


def test_finalising_is_audited_with_its_reason(users, tmp_path):
    run = create_run(tmp_path / "data", "pill", {"simulated": True})
    run.close()                                                            # left running: an interrupted run
    finalise_run(run.path, reason="power cut; run abandoned")
    actions = [(e["action"], e["reason"]) for e in check_trail(run.path).entries]
    assert actions[-2:] == [("finalise", "power cut; run abandoned"), ("stop", None)]


# ------------------------------------------------------------------------------------------------- signatures
def test_a_signature_holds_until_the_record_changes(users, tmp_path):
    folder = _finished_run(tmp_path)
    signature = sign(folder, "approved", PASSWORD, reason="batch release")
    assert signature["signer"] == "A. Jones" and signature["meaning"] == "approved"
    [state] = check_signatures(folder)
    assert state.intact and verify(folder).ok
    assert check_trail(folder).entries[-1]["action"] == "sign"
    (folder / "frame_000001.jpg").write_bytes(b"changed")
    [state] = check_signatures(folder)
    assert not state.intact and "changed after it was signed" in state.why
    assert any("BROKEN" in p for p in verify(folder).problems)


def test_an_added_file_or_an_edited_signature_breaks_it(users, tmp_path):
    folder = _finished_run(tmp_path)
    sign(folder, "reviewed", PASSWORD)
    (folder / "analysis").mkdir()
    (folder / "analysis" / "curve.csv").write_text("t_s,released_g\n")
    assert not check_signatures(folder)[0].intact
    (folder / "analysis" / "curve.csv").unlink()
    (folder / "analysis").rmdir()
    assert check_signatures(folder)[0].intact
    text = (folder / "signatures.jsonl").read_text().replace("reviewed", "approved")
    (folder / "signatures.jsonl").write_text(text)
    assert "edited" in check_signatures(folder)[0].why


def test_a_wrong_password_is_refused_and_audited(users, tmp_path):
    folder = _finished_run(tmp_path)
    with pytest.raises(SignatureError, match="wrong password"):
        sign(folder, "approved", "not the password")
    assert not (folder / "signatures.jsonl").exists()
    last = check_trail(folder).entries[-1]
    assert (last["action"], last["operator"]) == ("sign-refused", "A. Jones")
    with pytest.raises(SignatureError, match="meaning"):
        sign(folder, "liked", PASSWORD)
    with operators.acting_as(operators.DEMO_OPERATOR), pytest.raises(SignatureError, match="cannot sign"):
        sign(folder, "approved", PASSWORD)


def test_a_record_that_fails_verification_is_not_signed(users, tmp_path):
    folder = _finished_run(tmp_path)
    (folder / "frame_000000.jpg").write_bytes(b"tampered")
    with pytest.raises(SignatureError, match="fails verification"):
        sign(folder, "approved", PASSWORD)


def test_sign_and_audit_from_the_command_line(users, tmp_path, monkeypatch, capsys):
    import io

    from labapp.cli.main import main

    folder = _finished_run(tmp_path)
    monkeypatch.setattr("sys.stdin", io.StringIO("wrong password\n"))
    assert main(["sign", str(folder), "--meaning", "approved", "--password-stdin"]) == 2
    assert "wrong password" in capsys.readouterr().err
    monkeypatch.setattr("sys.stdin", io.StringIO(PASSWORD + "\n"))
    assert main(["sign", str(folder), "--meaning", "approved", "--password-stdin", "--operator", "B. Smith"]) == 0
    assert main(["audit", str(folder)]) == 0
    out = capsys.readouterr().out
    assert "sign-refused" in out and "B. Smith" in out and "chain OK" in out
    assert main(["verify", str(folder)]) == 0
    assert "SIGNATURE approved by B. Smith" in capsys.readouterr().out


def test_a_setting_changes_during_a_run_only_audited_with_a_reason(users, tmp_path):
    from labapp.acquisition.procedures import RunConfig, RunProcedure
    from labapp.errors import UsageError
    from labapp.records.manifests import read_run

    proc = RunProcedure(RunConfig(max_duration_s=3600.0), bench=None, data_dir=tmp_path / "data")
    with pytest.raises(UsageError, match="no run is recording"):
        proc.change_setting("max_duration_s", 7200.0, "slow sample")
    proc.run = create_run(tmp_path / "data", "pill", {"simulated": True, "config": proc.config.to_dict()})
    with pytest.raises(UsageError, match="interval_s cannot change while a run records"):
        proc.change_setting("interval_s", 5.0, "faster")
    with pytest.raises(UsageError, match="needs a reason"):
        proc.change_setting("max_duration_s", 7200.0, " ")
    with pytest.raises(UsageError, match="must be > 0"):
        proc.change_setting("max_duration_s", -1.0, "oops")
    proc.change_setting("max_duration_s", 7200.0, "the sample dissolves slower than expected")
    assert proc.config.max_duration_s == 7200.0
    assert read_run(proc.run.path).record.config["max_duration_s"] == 7200.0     # a resume keeps it
    last = check_trail(proc.run.path).entries[-1]
    assert (last["action"], last["detail"], last["reason"], last["operator"]) == (
        "change-setting", "max_duration_s: 1 -> 2 h", "the sample dissolves slower than expected", "A. Jones")
    proc.run.close()


def test_a_reanalysis_into_the_record_is_audited_with_its_reason(users, tmp_path):
    import shutil
    from pathlib import Path

    from labapp.jobs.analyse import analyse_run
    from labapp.jobs.calibrate_bench import calibrate_series

    bench = Path(__file__).resolve().parents[3] / "fixtures" / "bench"
    run = tmp_path / "run"
    shutil.copytree(bench / "run", run)
    calibrate_series(bench / "calibration", tmp_path / "cal.json", reduce=4)
    assert not (bench / "calibration" / AUDIT_FILE).exists()       # a series without a trail is not written
    analyse_run(run, tmp_path / "cal.json", reduce=4, plot=False, reason="smoothing window corrected")
    [entry] = check_trail(run).entries
    assert (entry["action"], entry["operator"], entry["reason"]) == ("reanalyse", "A. Jones",
                                                                      "smoothing window corrected")


def test_the_operator_reaches_the_processes_a_session_starts(users):
    import os
    import subprocess
    import sys

    with operators.acting_as("B. Smith"):
        assert os.environ[operators.OPERATOR_ENV] == "B. Smith"
        out = subprocess.run([sys.executable, "-c", "from labapp.records import operators; print(operators.current())"],
                             capture_output=True, text=True, check=True).stdout
        assert out.strip() == "B. Smith"
    assert os.environ[operators.OPERATOR_ENV] == "A. Jones" == operators.current()
