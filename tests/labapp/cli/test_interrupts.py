"""Ctrl-C and SIGTERM are recorded, never raised inside compiled code: a command stops at its next safe point,
prints one ``interrupted: ...`` line and exits with 130, leaving a folder that resumes or reruns."""
from __future__ import annotations

import contextlib
import json
import os
import random
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from design.inverse.status import FINISHED
from labapp.cli import interrupt
from labapp.cli.main import main

ROOT = Path(__file__).resolve().parents[3]
BENCH = ROOT / "fixtures" / "bench"
SFR = [sys.executable, "-m", "labapp.cli.main"]
DESIGN = ["design", "--target", "sphere", "--resolution", "16", "--max-iter", "24", "--physical-correction", "none"]
#: Commands running at once: the moments' commands and the resumes and reruns that follow them.
PARALLEL = 4
BAD_SIGNS = ("Traceback", "internal error", "SystemError", "Fatal Python error", "GIL")


def test_the_handler_records_and_check_raises_at_the_safe_points():
    interrupt.reset()
    with interrupt.handling():
        os.kill(os.getpid(), signal.SIGINT)        # no KeyboardInterrupt here, whatever runs
        total = sum(range(10_000))
        assert total and interrupt.requested()
        for _ in range(2):                          # at every safe point after the request
            with pytest.raises(KeyboardInterrupt):
                interrupt.check()
    interrupt.reset()
    assert not interrupt.requested()


def test_a_second_ctrl_c_quits_at_once_with_130():
    code = ("import os, signal, time\n"
            "from labapp.cli import interrupt\n"
            "with interrupt.handling():\n"
            "    os.kill(os.getpid(), signal.SIGINT); time.sleep(0.05)\n"
            "    os.kill(os.getpid(), signal.SIGINT); time.sleep(5)\n"
            "print('not reached')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 130 and "not reached" not in out.stdout
    assert "Ctrl-C again quits at once" in out.stderr and "quitting at once" in out.stderr


def test_exit_code_130_even_when_the_command_had_finished(monkeypatch, capsys):
    """A signal that comes while a command writes its last output: the outputs are complete, the exit code 130."""
    import labapp.cli.commands.verify as verify_command

    def run(args):
        os.kill(os.getpid(), signal.SIGTERM)
        sum(range(1000))
        return 0
    monkeypatch.setattr(verify_command, "run", run)
    assert main(["verify", str(BENCH / "run")]) == 130
    assert capsys.readouterr().err.strip().splitlines()[-1] == \
        "interrupted: the command had finished its work when the signal came; its outputs are complete"


class WarmSfr:
    """`sfr` commands forked from one warmed process (`warm_cli.py`): each is a real process with its own signal
    handling, started without paying the imports."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.errors = folder / "warm_cli.err"
        with open(self.errors, "w") as err:
            self.server = subprocess.Popen([sys.executable, str(Path(__file__).with_name("warm_cli.py"))], cwd=ROOT,
                                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=err, text=True)
        self.started = 0
        self.running: set[int] = set()

    def __enter__(self) -> WarmSfr:
        return self

    def __exit__(self, *exc) -> None:
        """Children still running (a failed test) are killed; the server ends."""
        for pid in self.running:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        self.server.stdin.close()
        try:
            self.server.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.server.kill()

    def ask(self, request: dict) -> dict:
        self.server.stdin.write(json.dumps(request) + "\n")
        self.server.stdin.flush()
        line = self.server.stdout.readline()
        assert line, f"the warmed sfr ended: {self.errors.read_text()[-3000:]}"
        return json.loads(line)

    def warm(self, commands: list[list[str]]) -> None:
        """Run the commands once in the server (imports and compiled code stay for every child)."""
        self.ask({"warm": commands, "cwd": str(self.folder)})

    def start(self, args: list[str]) -> tuple[int, Path]:
        """The child's pid and its standard error's file."""
        self.started += 1
        log = self.folder / f"command_{self.started}"
        pid = self.ask({"run": args, "cwd": str(self.folder), "log": str(log)})["pid"]
        self.running.add(pid)
        return pid, log.with_suffix(".err")

    def poll(self, pid: int) -> int | None:
        """The child's exit code, None while it runs."""
        code = self.ask({"poll": pid})["code"]
        if code is not None:
            self.running.discard(pid)
        return code


@dataclass
class Moment:
    """A command stopped at one moment, then resumed or run again; ``pid`` is the running one's."""

    kind: str
    out: Path
    delay: float
    tries: int
    pid: int = 0
    err: Path = Path()
    started: float = 0.0
    signalled: bool = False
    following_up: bool = False

    @property
    def where(self) -> str:
        return f"{self.kind} interrupted after {self.delay:.2f} s ({self.out.name})"


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_ctrl_c_at_twenty_random_moments_of_a_design_an_analysis_and_a_calibration(tmp_path):
    """Each moment: exit code 130, a clean last line, nothing internal; then the design resumes to a finished
    run, the analysis reruns to the same curve and the calibration to the same fit. Designs, analyses and
    calibrations run side by side, PARALLEL at a time, each stopped at its own moment."""
    cal = tmp_path / "cal.json"

    def command(kind: str, out: Path) -> list[str]:
        return {"design": DESIGN + ["--out", str(out)],
                "analysis": ["analyze", str(BENCH / "run"), "--calibration", str(cal), "--out", str(out)],
                "calibration": ["calibrate-bench", str(BENCH / "calibration"), "--out", str(out) + ".json"]}[kind]
    with WarmSfr(tmp_path) as sfr:
        caught = _twenty_moments(sfr, command, tmp_path)
    assert caught >= 18, f"only {caught} of 20 moments fell inside a command"


def _twenty_moments(sfr: WarmSfr, command, tmp_path: Path) -> int:
    """Warm up, then stop 20 commands at random moments and complete each; how many moments fell inside."""
    cal = tmp_path / "cal.json"
    kinds = ("calibration", "analysis", "design")
    sfr.warm([command("calibration", cal.with_suffix("")), command("analysis", tmp_path / "reference"),
              command("design", tmp_path / "reference_design")])
    durations = _timed(sfr, {kind: command(kind, tmp_path / f"timed_{kind}") for kind in kinds})
    reference_curve = (tmp_path / "reference" / "curve.csv").read_text()
    reference_k = json.loads(cal.read_text())["cells"]["k"]
    rng = random.Random(32)
    pending = [Moment(kinds[i % 3], tmp_path / f"{kinds[i % 3]}_{i}", rng.uniform(0.05, 0.8) * durations[kinds[i % 3]], 2)
               for i in range(20)]
    running: list[Moment] = []
    caught = 0
    while pending or running:
        while pending and len(running) < PARALLEL:
            moment = pending.pop(0)
            moment.pid, moment.err = sfr.start(command(moment.kind, moment.out))
            moment.started = time.monotonic()
            running.append(moment)
        for moment in list(running):
            code = sfr.poll(moment.pid)
            if code is None:
                if not moment.signalled and time.monotonic() >= moment.started + moment.delay:
                    os.kill(moment.pid, signal.SIGINT)
                    moment.signalled = True
                continue
            err = moment.err.read_text()
            if moment.following_up:
                assert code == 0 and not any(sign in err for sign in BAD_SIGNS), f"{moment.where}, then:\n{err}"
                _assert_completed(moment, reference_curve, reference_k)
                running.remove(moment)
            elif not moment.signalled or (code == 0 and "Ctrl-C" not in err):   # the moment fell after the end
                assert code == 0, f"{moment.where}: exit {code}\n{err}"
                running.remove(moment)
                if moment.tries:
                    pending.append(Moment(moment.kind, moment.out.with_name(moment.out.name + "_again"),
                                          moment.delay / 2, moment.tries - 1))
            else:
                caught += 1
                follow_up = _assert_interrupted(moment, code, err, command)
                if follow_up is None:
                    running.remove(moment)
                    if moment.kind != "design":         # its outputs were complete when the signal came
                        _assert_completed(moment, reference_curve, reference_k)
                else:
                    moment.pid, moment.err = sfr.start(follow_up)
                    moment.following_up = True
        time.sleep(0.02)
    return caught


def _timed(sfr: WarmSfr, commands: dict[str, list[str]]) -> dict[str, float]:
    """The seconds each command takes when they run side by side from the warmed server (as the moments do)."""
    t0 = time.monotonic()
    running = {kind: sfr.start(args)[0] for kind, args in commands.items()}
    took = {}
    while running:
        for kind, pid in list(running.items()):
            if sfr.poll(pid) is not None:
                took[kind] = time.monotonic() - t0
                del running[kind]
        time.sleep(0.02)
    return took


def _assert_interrupted(moment: Moment, code: int, err: str, command) -> list[str] | None:
    """The checks of an interrupted command; the command that completes its work, or None when there is none
    to run: a design stopped before it began (nothing left behind) or a calibration whose file is complete."""
    assert code == 130, f"{moment.where}: exit {code}\n{err}"
    assert err.strip().splitlines()[-1].startswith("interrupted: "), f"{moment.where}\n{err}"
    assert not any(sign in err for sign in BAD_SIGNS), f"{moment.where}\n{err}"
    finished = "finished its work" in err
    out = moment.out
    if moment.kind == "design":
        if not (out / "config.json").exists():     # stopped before it began: nothing left behind
            assert not out.exists() or not any(out.iterdir()), f"{moment.where}: left {list(out.iterdir())}"
            return None
        return DESIGN + ["--resume", "--out", str(out)]
    if moment.kind == "analysis":                   # an analysis reruns into its own folder
        assert finished or not (out / "curve.csv").exists(), moment.where
        return command(moment.kind, out)
    written = Path(str(out) + ".json").exists()     # a calibration file is never overwritten
    assert finished or not written, moment.where
    return None if written else command(moment.kind, out)


def _assert_completed(moment: Moment, reference_curve: str, reference_k: list) -> None:
    """The design resumed to a finished run, the analysis to the uninterrupted curve, the calibration to its fit."""
    if moment.kind == "design":
        status = json.loads((moment.out / "summary.json").read_text())["status"]
        assert status in FINISHED, f"{moment.where}: resumed to {status}"
    elif moment.kind == "analysis":
        assert (moment.out / "curve.csv").read_text() == reference_curve, moment.where
    else:
        assert np.allclose(json.loads(Path(str(moment.out) + ".json").read_text())["cells"]["k"], reference_k), \
            moment.where
