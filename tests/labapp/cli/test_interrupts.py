"""Ctrl-C and SIGTERM are recorded, never raised inside compiled code: a command stops at its next safe point,
prints one ``interrupted: ...`` line and exits with 130, leaving a folder that resumes or reruns."""
from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from labapp.cli import interrupt
from labapp.cli.main import main

ROOT = Path(__file__).resolve().parents[3]
BENCH = ROOT / "fixtures" / "bench"
SFR = [sys.executable, "-m", "labapp.cli.main"]
DESIGN = ["design", "--target", "sphere", "--resolution", "16", "--max-iter", "24", "--physical-correction", "none"]
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
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
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


def _sfr(args: list[str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(SFR + args, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _timed(commands: list[list[str]], cwd: Path) -> list[float]:
    """Run the commands side by side to the end; the seconds each took (a design may end without a solid: 1)."""
    t0 = time.monotonic()
    procs = [_sfr(args, cwd) for args in commands]
    took = []
    for proc in procs:
        _, err = proc.communicate(timeout=300)
        took.append(time.monotonic() - t0)
        assert proc.returncode in (0, 1) and not any(sign in err for sign in BAD_SIGNS), err
    return took


def _interrupt_at(commands: list[tuple[list[str], float]], cwd: Path) -> list[tuple[int | None, str]]:
    """Start the commands side by side, send each SIGINT after its delay; (exit code, stderr) of each, exit code
    None for one that had ended before its moment."""
    t0 = time.monotonic()
    procs = [(_sfr(args, cwd), delay) for args, delay in commands]
    missed = set()
    for i, (proc, delay) in sorted(enumerate(procs), key=lambda item: item[1][1]):
        time.sleep(max(0.0, t0 + delay - time.monotonic()))
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        else:
            missed.add(i)
    results = []
    for i, (proc, _) in enumerate(procs):
        _, err = proc.communicate(timeout=300)
        results.append((None, err) if i in missed else (proc.returncode, err))
    return results


@pytest.mark.timeout(600)
def test_ctrl_c_at_twenty_random_moments_of_a_design_an_analysis_and_a_calibration(tmp_path):
    """Each moment: exit code 130, a clean last line, nothing internal; then the design resumes to a finished
    run, the analysis reruns to the same curve and the calibration to the same fit. A design, an analysis and a
    calibration run side by side, each stopped at its own moment."""
    from labapp.jobs.analyse import analyse_run
    from labapp.jobs.calibrate_bench import calibrate_series
    from labapp.jobs.design import design

    cal = tmp_path / "cal.json"
    calibrate_series(BENCH / "calibration", cal)
    analyse_run(BENCH / "run", cal, tmp_path / "ref_analysis", plot=False)
    reference_curve = (tmp_path / "ref_analysis" / "curve.csv").read_text()
    reference_k = json.loads(cal.read_text())["cells"]["k"]

    def command(kind: str, out: Path) -> list[str]:
        return {"design": DESIGN + ["--out", str(out)],
                "analysis": ["analyze", str(BENCH / "run"), "--calibration", str(cal), "--out", str(out)],
                "calibration": ["calibrate-bench", str(BENCH / "calibration"), "--out", str(out) + ".json"]}[kind]
    kinds = ("design", "analysis", "calibration")
    durations = dict(zip(kinds, _timed([command(k, tmp_path / f"timed_{k}") for k in kinds], tmp_path)))
    rng = random.Random(32)
    # (kind, output, delay s, tries left): a moment that falls after the command's end (it ran faster than
    # when timed) is tried again earlier
    queue = [(kinds[i % 3], tmp_path / f"{kinds[i % 3]}_{i}", rng.uniform(0.05, 0.8) * durations[kinds[i % 3]], 2)
             for i in range(20)]
    caught = 0
    while queue:
        group, queue = queue[:3], queue[3:]
        for (kind, out, delay, tries), (code, err) in zip(group, _interrupt_at([(command(k, o), d) for k, o, d, _
                                                                                in group], tmp_path)):
            if code is None or (code in (0, 1) and "Ctrl-C" not in err):   # the moment fell after the command
                if tries:                                                   # had ended (a design may find no solid)
                    queue.append((kind, out.with_name(out.name + "_again"), delay / 2, tries - 1))
                continue
            caught += 1
            where = f"{kind} interrupted after {delay:.2f} s"
            assert code == 130, f"{where}: exit {code}\n{err}"
            assert err.strip().splitlines()[-1].startswith("interrupted: "), f"{where}\n{err}"
            assert not any(sign in err for sign in BAD_SIGNS), f"{where}\n{err}"
            finished = "finished its work" in err
            if kind == "design":
                if (out / "config.json").exists():      # started: it resumes to a finished run
                    result, _ = design(None, out, resume=True)
                    assert result.status.finished and (out / "summary.json").is_file(), where
                else:                                   # stopped before it began: nothing left behind
                    assert not out.exists() or not any(out.iterdir()), where
            elif kind == "analysis":
                assert finished or not (out / "curve.csv").exists(), where
                analyse_run(BENCH / "run", cal, out, plot=False)
                assert (out / "curve.csv").read_text() == reference_curve, where
            else:
                path = Path(str(out) + ".json")
                assert finished or not path.exists(), where
                if not path.exists():
                    calibrate_series(BENCH / "calibration", path)
                assert np.allclose(json.loads(path.read_text())["cells"]["k"], reference_k), where
    assert caught >= 18, f"only {caught} of 20 moments fell inside a command"
