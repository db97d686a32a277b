"""`sfr` as an operator meets it: the command list, --version, one error line with the documented exit
codes, --debug for the traceback, output piped into head, `sfr lab` without a display."""
import subprocess
import sys

import pytest

from labapp.cli import main as cli
from labapp.cli.main import WORKFLOW, main

SFR = [sys.executable, "-m", "labapp.cli.main"]


def test_no_arguments_lists_the_commands_in_workflow_order(capsys):
    assert main([]) == 0
    out = capsys.readouterr().out.splitlines()
    names = [line.split()[0] for line in out if line.startswith("  ")]
    assert names[:3] == ["devices", "calibrate-bench", "run"]
    ranked = [n for n in WORKFLOW if n in names]
    assert names[:len(ranked)] == ranked and {"verify", "analyze", "simulate", "design"} <= set(names)
    assert all(len(line.split(None, 1)) == 2 for line in out if line.startswith("  "))   # one line each


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.startswith("sfr ")


def test_exit_codes_and_one_error_line(tmp_path, capsys):
    assert main(["verify", str(tmp_path / "nothing")]) == 1                      # the job failed
    capsys.readouterr()
    assert main(["simulate", str(tmp_path / "nothing.stl"), "--out", str(tmp_path / "o")]) == 2   # bad input
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("sfr simulate: ") and "no such file" in err[-1]


def test_an_unexpected_error_is_one_line_and_debug_shows_the_traceback(monkeypatch, capsys):
    def broken(args):
        raise KeyError("boom")
    monkeypatch.setattr("labapp.cli.commands.verify.run", broken)
    assert main(["verify", "x"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "internal error (KeyError: 'boom')" in err and "--debug" in err
    assert main(["--debug", "verify", "x"]) == 1
    assert "Traceback (most recent call last)" in capsys.readouterr().err


def test_piping_into_head_does_not_crash():
    out = subprocess.run(" ".join(SFR) + " | head -1", shell=True, capture_output=True, text=True, timeout=300)
    assert out.stdout.startswith("sfr ") and out.stderr == ""
    many = subprocess.run(" ".join(SFR) + " verify " + " ".join(["/nonexistent"] * 3000) + " | head -2",
                          shell=True, capture_output=True, text=True, timeout=300)
    assert "Traceback" not in many.stderr and "BrokenPipe" not in many.stderr and many.stderr == ""


def test_lab_without_a_display_says_what_to_do(capsys, monkeypatch):
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    assert main(["lab"]) == 2
    err = capsys.readouterr().err
    assert "QT_QPA_PLATFORM=offscreen" in err and "sfr run" in err and err.count("\n") == 1


def test_exit_code_mapping():
    from analysis import AnalysisError
    from design.errors import DesignError
    from drivers.errors import DriverError
    from labapp.errors import JobFailed, UsageError

    assert [cli.exit_code(e) for e in (UsageError("u"), DesignError("d"), AnalysisError("a"), ValueError("v"),
                                       JobFailed("j"), DriverError("c"), RuntimeError("r"))] == [2, 2, 2, 2, 1, 1, 1]
