"""`sfr sweep` on real Dask processes: a scheduler and two workers on loopback with one worker killed
mid-sweep, and Ctrl-C on the local cluster."""
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from design.inverse.status import FINISHED

NAMES = [f"radius_vox={r},w_binary={w}" for w in (10, 20) for r in (2, 3)]
WAIT_S = 300
"""The ceiling of each wait: it fails a hung sweep only (the events come in seconds on a quiet machine)."""


def _spec(resolution: int, max_iter: int) -> str:
    """A sweep of four sphere designs (two binarisation weights by two radii), checkpointed every 3 evaluations."""
    return f"""target = "sphere"
space = "nfc"
resolution = {resolution}
max_iter = {max_iter}
checkpoint_every = 3
physical_correction = "none"
[grid]
w_binary = [10, 20]
radius_vox = [2.0, 3.0]
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_for(predicate, timeout_s: float, what: str):
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def _started(log: Path) -> list[str]:
    return [line for line in log.read_text().splitlines() if " start " in line] if log.exists() else []


def _check_every_combination_once(out: Path) -> None:
    """Every combination finished once, with a valid run folder and an unbroken evaluation history."""
    log = (out / "sweep.log").read_text()
    rows = (out / "sweep.csv").read_text().splitlines()
    assert len(rows) == 1 + len(NAMES)
    for name in NAMES:
        folder = out / "runs" / name
        assert log.count(f"finish {name} ") == 1, log
        summary = json.loads((folder / "summary.json").read_text())
        assert summary["status"] in FINISHED  # L-BFGS may stall before the limit
        history = np.loadtxt(folder / "history.csv", delimiter=",", skiprows=1)
        assert history[:, 0].tolist() == list(range(1, summary["iterations"] + 1)), name
        for file in ("config.json", "density.npz", "curves.csv", "report.png"):
            assert (folder / file).is_file(), (name, file)
        assert any(row.startswith(f'"{name}",') and f",{summary['status']}," in row for row in rows)


def _spawn(args, **kw):
    return subprocess.Popen([sys.executable, *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, **kw)


@pytest.mark.slow
def test_sweep_survives_a_killed_worker(tmp_path):
    spec, out = tmp_path / "spec.toml", tmp_path / "sweep"
    spec.write_text(_spec(16, 60))     # 60 evaluations: the killed design is still running after its first checkpoint
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = [_spawn(["-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", str(port),
                     "--no-dashboard"])]
    workers = {}
    try:
        for i in range(2):
            worker_port = _free_port()
            workers[f"tcp://127.0.0.1:{worker_port}"] = proc = _spawn(
                ["-m", "distributed.cli.dask_worker", address, "--nthreads", "1", "--no-nanny", "--host",
                 "127.0.0.1", "--worker-port", str(worker_port), "--no-dashboard", "--name", f"w{i}"])
            procs.append(proc)
        sweep = _spawn(["-m", "labapp.cli.main", "sweep", str(spec), "--out", str(out), "--scheduler", address,
                        "--workers", "2"])
        procs.append(sweep)
        # kill the worker of the first design to start, once that design has checkpointed
        first = _wait_for(lambda: _started(out / "sweep.log"), WAIT_S, "a design to start")[0]
        name, victim = first.split(" start ")[1].split(" on ")[0], first.split(" on ")[1].split(" ")[0]
        _wait_for(lambda: (out / "runs" / name / "checkpoint.npz").exists(), WAIT_S, "a checkpoint")
        assert folder_not_done(out / "runs" / name), "the design finished before the kill; make it longer"
        workers[victim].kill()
        _, err = sweep.communicate(timeout=WAIT_S)
        assert sweep.returncode == 0, err.decode()[-2000:]
        starts = _started(out / "sweep.log")
        assert sum(f"start {name} " in s for s in starts) == 2  # the killed attempt, then the resume
        assert any(f"start {name} " in s and "(resume)" in s and victim not in s for s in starts)
        assert f"{len(NAMES)} done (0 failed), 0 running, 0 left" in err.decode()
        _check_every_combination_once(out)
        assert (out / "contact_sheet.png").stat().st_size > 10_000
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
            proc.wait(WAIT_S)


def folder_not_done(folder: Path) -> bool:
    return not (folder / "summary.json").exists()


@pytest.mark.slow
def test_ctrl_c_checkpoints_running_designs(tmp_path):
    spec, out = tmp_path / "spec.toml", tmp_path / "sweep"
    spec.write_text(_spec(48, 2000))
    cmd = ["-m", "labapp.cli.main", "sweep", str(spec), "--out", str(out), "--workers", "2"]
    # a terminal's Ctrl-C: SIGINT to the whole process group (the command and its local workers)
    sweep = _spawn(cmd, start_new_session=True)
    try:
        _wait_for(lambda: len(list(out.glob("runs/*/checkpoint.npz"))) == 2, WAIT_S, "two running designs")
        os.killpg(sweep.pid, signal.SIGINT)
        _, err = sweep.communicate(timeout=WAIT_S)
    finally:
        if sweep.poll() is None:
            os.killpg(sweep.pid, signal.SIGKILL)
    assert sweep.returncode == 130, err.decode()[-2000:]
    assert "rerun the same command to resume" in err.decode()
    statuses = {p.parent.name: json.loads(p.read_text())["status"] for p in out.glob("runs/*/summary.json")}
    assert len(statuses) == 2, statuses  # the queued two never started
    # the running two stop with a checkpoint (one may have ended on its own just before: L-BFGS can stall)
    assert "stopped" in statuses.values() and set(statuses.values()) <= {"stopped", *FINISHED}, statuses
    for name, status in statuses.items():
        with np.load(out / "runs" / name / "checkpoint.npz") as ckpt:
            assert 0 < len(ckpt["history"]) < 2000
    rows = (out / "sweep.csv").read_text()
    assert rows.count(",stopped,") == list(statuses.values()).count("stopped") and rows.count(",not started,") == 2
