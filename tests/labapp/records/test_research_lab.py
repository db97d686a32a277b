"""Operators in a research lab and in a regulated one: without a users file every recorded action names the login
name (or the name given), marked unverified, and nobody can sign; once a users file exists operators are
enforced as before (tests/conftest.py's session is the regulated lab; `no_users_file` the research lab)."""
import getpass
import io
import shutil
from pathlib import Path

import pytest

from labapp.cli.main import main
from labapp.errors import EXIT_USAGE
from labapp.records import operators
from labapp.records.audit import read_trail
from labapp.records.manifests import read_record
from labapp.records.operators import OperatorError
from labapp.records.runrecord import RecordStatus
from labapp.records.signatures import SignatureError, sign
from labapp.records.storage import create_run

FIXTURES = Path(__file__).resolve().parents[3] / "fixtures"
PASSWORD = "correct horse battery"


def _run(tmp_path):
    run = create_run(tmp_path / "data", "pill", {"simulated": True, "water_g": 500.0})
    run.finish(RecordStatus.COMPLETE)
    run.close()
    return run.path


def test_without_a_users_file_the_login_name_is_recorded_unverified(no_users_file, tmp_path, monkeypatch):
    login = f"{getpass.getuser()} (unverified)"
    assert not operators.enforced() and operators.current() == login
    assert operators.given() is None            # nobody named: sfr demo acts as its own operator, not the login
    folder = _run(tmp_path)
    assert read_record(folder).operator == login
    assert {e["operator"] for e in read_trail(folder)} == {login}
    monkeypatch.setenv(operators.OPERATOR_ENV, "A. Jones")          # a name given is recorded, unverified too
    assert operators.current() == "A. Jones (unverified)"
    with operators.acting_as("B. Smith"):
        assert operators.current() == "B. Smith (unverified)"
    with pytest.raises(SignatureError, match="acts without a users file and cannot sign"):
        sign(folder, "approved", PASSWORD)
    assert not no_users_file.exists()


def test_a_recording_command_works_without_a_users_file_and_sign_is_refused(no_users_file, tmp_path, capsys):
    series = tmp_path / "series"
    shutil.copytree(FIXTURES / "bench" / "calibration", series)
    assert main(["calibrate-bench", str(series), "--water-g", "500", "--out", str(tmp_path / "cal.json")]) == 0
    capsys.readouterr()
    folder = _run(tmp_path)
    assert main(["sign", str(folder), "--meaning", "approved"]) == EXIT_USAGE      # refused before a password
    assert "cannot sign" in capsys.readouterr().err


def test_a_users_file_enforces_operators(no_users_file, tmp_path, monkeypatch, capsys):
    assert main(["users", "list"]) == 0
    assert "operators are not enforced" in capsys.readouterr().out
    monkeypatch.setattr("sys.stdin", io.StringIO(PASSWORD + "\n"))
    assert main(["users", "add", "A. Jones", "--password-stdin"]) == 0
    assert "operators are now enforced" in capsys.readouterr().out and operators.enforced()
    with pytest.raises(OperatorError, match="no operator"):
        create_run(tmp_path / "data", "pill", {"simulated": True})
    monkeypatch.setenv(operators.OPERATOR_ENV, "Mallory")
    with pytest.raises(OperatorError, match="not in the users file"):
        operators.current()
    monkeypatch.setenv(operators.OPERATOR_ENV, "A. Jones (unverified)")   # a marked name is no way around it
    with pytest.raises(OperatorError, match="not in the users file"):
        operators.current()
    monkeypatch.setenv(operators.OPERATOR_ENV, "A. Jones")
    folder = _run(tmp_path)
    assert read_record(folder).operator == "A. Jones"
    assert sign(folder, "approved", PASSWORD)["signer"] == "A. Jones"
