"""Start or resume an acquisition run: the procedure the engine walks (`sfr run`, `sfr run --resume`)."""
from __future__ import annotations

import math
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

from analysis import BenchCalibration
from labapp.acquisition.bench import Bench
from labapp.acquisition.methods import Method
from labapp.acquisition.procedures import RunConfig, RunProcedure, check_change
from labapp.acquisition.settings import INTERVAL
from labapp.errors import UsageError
from labapp.records import operators, requests
from labapp.records.fileio import StorageError, WriteError, check_disk_space
from labapp.records.manifests import RunSnapshot, read_run
from labapp.records.outpaths import FolderKind, check_data_dir, folder_kind
from labapp.records.runrecord import RecordKind, RecordStatus
from labapp.records.storage import finalise_run


def new_run(config: RunConfig, bench: Bench, data_dir: str | Path,
            calibration: BenchCalibration | None = None, method: Method | None = None) -> RunProcedure:
    """A :class:`labapp.acquisition.procedures.RunProcedure` for a new run in ``data_dir`` (checked, nothing written).

    ``method``: the method file the run follows (``config`` made by :meth:`Method.apply`); ``run.json`` cites it.

    Raises
    ------
    UsageError
        If ``data_dir`` is a file or lies inside a record or another command's folder.
    labapp.records.fileio.WriteError
        If no run folder can be written there, or the run's frames would not fit (:func:`check_run_data_dir`).
    """
    data_dir = check_run_data_dir(data_dir)
    n_frames = math.ceil(config.max_duration_s / config.interval_s)
    try:
        check_disk_space(data_dir if data_dir.exists() else _existing_parent(data_dir),
                         config.frame_bytes_estimate or bench.frame_bytes, n_frames)
    except StorageError as exc:
        raise WriteError(f"--out {data_dir}: {exc}; no run was started: free space or choose another --out") from None
    proc = RunProcedure(config, bench, data_dir, calibration)
    if method is not None:
        proc.record_extra["method"] = method.citation()
    return proc


def check_run_data_dir(data_dir: str | Path, option: str = "--out") -> Path:
    """The data directory of a new run, resolved, once it is known that a run folder can be written there: checked
    by `labapp.records.outpaths.check_data_dir`, then by writing and removing a small probe folder in it (or in its
    nearest existing parent), so that a read-only, forbidden or full disk is refused before the bench heats.

    Raises
    ------
    UsageError
        As `check_data_dir`.
    labapp.records.fileio.WriteError
        Naming the folder and the operating system's reason (exit code 2); nothing is left behind.
    """
    data_dir = check_data_dir(data_dir, option)
    where = _existing_parent(data_dir)
    try:
        probe = Path(tempfile.mkdtemp(prefix=".sfr-write-check-", dir=where))
        try:
            with open(probe / "probe", "wb") as fh:
                fh.write(bytes(PROBE_BYTES))
                fh.flush()
                os.fsync(fh.fileno())
        finally:
            shutil.rmtree(probe, ignore_errors=True)
    except OSError as exc:
        raise WriteError(f"{option} {data_dir}: no run folder can be written in {where} ({exc.strerror or exc}); "
                         f"no run was started: choose a writable data directory or free space") from None
    return data_dir


PROBE_BYTES = 65536
"""Size of the probe file :func:`check_run_data_dir` writes, bytes: about one JPEG frame's first blocks."""


def _existing_parent(path: Path) -> Path:
    """``path`` or its nearest ancestor that exists."""
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def resumable(folder: str | Path) -> RunSnapshot:
    """The snapshot of an interrupted acquisition run; anything else is refused without writing a byte.

    Raises
    ------
    UsageError
        Naming what ``folder`` is instead: not a run folder, a calibration series or other kind, a run
        that finished (complete, stopped, aborted, failed), or one still being written.
    """
    folder = Path(folder)
    try:
        snap = read_run(folder)
    except StorageError:
        kind = folder_kind(folder)
        what = "does not exist" if not folder.exists() else \
            f"is not a run folder ({'no run.json' if kind in (None, FolderKind.OTHER, FolderKind.IMAGES) else kind})"
        raise UsageError(f"{folder} {what}; only an interrupted acquisition run can be resumed") from None
    kind = snap.record.kind
    if kind != RecordKind.RUN:
        raise UsageError(f"{folder} is a {kind or 'folder of unknown kind'}, not an acquisition run; only an "
                         "interrupted acquisition run can be resumed")
    if snap.live:
        raise UsageError(f"{folder} is being written by process {snap.record.writer_pid}; it is not "
                         "interrupted")
    if snap.status != RecordStatus.INTERRUPTED:
        raise UsageError(f"{folder} finished ({snap.status}); only an interrupted run can be resumed. "
                         "A finished run is a record: start a new run instead")
    if snap.record.config is None:
        raise UsageError(f"{folder}/run.json has no run settings (config); it cannot be resumed")
    return snap


def resume_run(folder: str | Path, bench: Bench, calibration: BenchCalibration | None = None) -> RunProcedure:
    """A :class:`labapp.acquisition.procedures.RunProcedure` continuing the interrupted run in ``folder``.

    Call :func:`resumable` first to learn from ``run.json`` whether the run was simulated (and build the
    matching bench); this checks again and refuses a bench of the other kind.

    Raises
    ------
    UsageError
        As :func:`resumable`, or when the bench is simulated and the run was not (or the reverse).
    """
    snap = resumable(folder)
    if snap.record.simulated != bool(bench.simulated):
        raise UsageError(f"{folder} was recorded on a {'simulated' if snap.record.simulated else 'real'} "
                         f"bench; it cannot be resumed on a {'simulated' if bench.simulated else 'real'} one")
    return RunProcedure.resume(Path(folder), bench, calibration)


def finalise(folder: str | Path, reason: str) -> None:
    """Close an interrupted run or calibration series without resuming it, as the current operator, with
    ``reason``: its status becomes ``stopped`` and the audit trail's ``finalise`` entry says who, when and why.

    Raises
    ------
    UsageError
        For no reason, or a folder that is not an interrupted record (finished, still being written, not a run).
    labapp.records.operators.OperatorError
        When the process acts as nobody.
    """
    folder = Path(folder)
    if not reason or not reason.strip():
        raise UsageError(f"finalising {folder.name} needs a reason (it is recorded in the audit trail)")
    try:
        snap = read_run(folder)
    except StorageError as exc:
        raise UsageError(f"{folder} is not a run folder ({exc}); nothing to finalise") from None
    if snap.live or snap.status != RecordStatus.INTERRUPTED:
        raise UsageError(f"{folder} is {'being written' if snap.live else snap.status}; only an interrupted run "
                         "can be finalised")
    finalise_run(folder, reason.strip())


REQUEST_WAIT_S = 30.0
"""How long a change waits for the recording process beyond one frame interval, s."""


def change_setting(folder: str | Path, name: str, value: float, reason: str,
                   should_stop: Callable[[], bool] = lambda: False) -> str:
    """Change a setting of the run recording into ``folder`` (stored units, e.g. ``max_duration_s`` in s), as the
    current operator, with ``reason``: the recording process (`sfr run`, the GUI) carries it out at its next
    frame and writes the audit entry. Returns what changed, one line (old and new value).

    Raises
    ------
    UsageError
        For a folder that is not a run being recorded, a setting that cannot change during a run, no reason, a
        value out of range, or a recording process that did not answer within a frame interval and
        :data:`REQUEST_WAIT_S` (the request is then withdrawn: nothing changed).
    labapp.records.operators.OperatorError
        When the process acts as nobody.
    """
    folder = Path(folder)
    check_change(name, value, reason)       # refused at once, not after waiting for the next frame
    operator = operators.require(f"changing {name} of {folder.name}")
    try:
        snap = read_run(folder)
    except StorageError as exc:
        raise UsageError(f"{folder} is not a run folder ({exc})") from None
    if not snap.live:
        raise UsageError(f"{folder} is not being recorded ({snap.status}); a setting changes only during a run")
    request = requests.post(folder, {"action": "change", "name": name, "value": value, "reason": reason.strip(),
                                     "operator": operator})
    interval_s = float((snap.record.config or {}).get("interval_s") or INTERVAL.default)
    outcome = requests.wait_answer(request, interval_s + REQUEST_WAIT_S, should_stop)
    if outcome is None:
        raise UsageError(f"the process recording {folder.name} did not take the change within "
                         f"{interval_s + REQUEST_WAIT_S:.0f} s; nothing changed")
    if not outcome.get("done"):
        raise UsageError(f"the run refused the change: {outcome.get('why')}")
    return str(outcome.get("detail"))
