"""`sfr design --barrier-speed S`: routed to the two-material design, its options and inputs checked before any work,
its outputs and its resume."""
from __future__ import annotations

import json

import pytest

from design.files import twomaterial_outputs
from labapp.cli.main import main

DELAY = "delay-zero:delay=2,rate=10,volume=20"


@pytest.fixture(autouse=True)
def _no_reference(monkeypatch):
    # the reference evaluator takes minutes at any grid; these tests check the command, not the evaluator
    monkeypatch.setattr(twomaterial_outputs, "REFERENCE_MODULE", "design.forward.no_such_module")


@pytest.mark.parametrize("argv,message", [
    (["--target", DELAY, "--barrier-speed", "0"], "mm with an insoluble barrier (--barrier-speed 0)"),
    (["--target", "pulses:volume=8,width=1.25,gap=2", "--barrier-speed", "0"], "pause"),
    (["--target", DELAY, "--barrier-speed", "0.25", "--space", "ico"], "--space ico with --barrier-speed"),
    (["--target", DELAY, "--barrier-speed", "0.25", "--starts", "2"], "does not take starts"),
    (["--target", DELAY, "--barrier-speed", "0.25", "--domain-mm", "10", "10", "12"], "cubic for nfc"),
    (["--target", "missing.csv", "--barrier-speed", "0.25"], "missing.csv: no such file"),
    (["--target", "delay-zero:delay=2,rate=10", "--barrier-speed", "0.25"], "needs volume"),
])
def test_bad_input_is_exit_2_naming_it_and_writes_nothing(tmp_path, capsys, argv, message):
    out = tmp_path / "run"
    assert main(["design", *argv, "--resolution", "16", "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_a_negative_speed_is_refused_by_the_parser(tmp_path):
    with pytest.raises(SystemExit) as exc:
        main(["design", "--target", DELAY, "--barrier-speed", "-1", "--out", str(tmp_path / "run")])
    assert exc.value.code == 2


def test_design_writes_both_materials_then_refuses_the_same_out_and_resumes_as_finished(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["design", "--target", DELAY, "--barrier-speed", "0.25", "--resolution", "16", "--max-iter", "8",
            "--out", str(out)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "two-material design (nfc, barrier speed 0.25)" in text and "barrier.stl" in text
    summary = json.loads((out / "summary.json").read_text())
    assert summary["barrier_speed"] == 0.25 and summary["barrier"]["mesh"] == "barrier.stl"
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    assert main(argv) == 2                              # a record is not written over
    assert "design run" in capsys.readouterr().err
    assert main(["design", "--resume", "--barrier-speed", "0.25", "--out", str(out)]) == 0
    assert "already finished" in capsys.readouterr().out
    assert main(["design", "--resume", "--out", str(out)]) == 0      # the folder says it is a two-material run
    assert "already finished" in capsys.readouterr().out
    assert main(["design", "--resume", "--barrier-speed", "0.5", "--out", str(out)]) == 2
    assert "barrier_speed = 0.5 differs" in capsys.readouterr().err
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == before
