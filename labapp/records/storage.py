"""Crash-safe run folders: atomic frame writes, append-only manifests, atomic run.json.

A run folder (format in ``docs/formats.md``) holds

- the frames, each written to ``.<name>.part``, flushed, fsync'ed and renamed before it is recorded;
- ``frames.csv``: one row per frame, appended and fsync'ed row by row, with the SHA-256 of the file;
- ``events.log``: the event log, appended and flushed line by line (tab-separated);
- ``run.json``: the run's settings and state, rewritten atomically (temp file + rename); read through
  :func:`labapp.records.manifests.read_record` as a :class:`labapp.records.runrecord.RunRecord`. It holds a seal
  (:mod:`labapp.records.seal`) of its own fields, of each ``frames.csv`` row and of ``masses.csv``,
  rewritten with it, so that verification names any of them edited afterwards.

After a crash or power cut the folder is still a valid run: every row of ``frames.csv`` names a complete
file, a half-written last row (a torn write) is dropped when the folder is reopened, and stray ``.part``
files are ignored. A folder is never reused: :func:`create_run` always makes a new one.

This module writes run folders (:class:`RunFolder`); :mod:`labapp.records.manifests` reads them and
:mod:`labapp.records.verification` checks them against their manifests.
"""
from __future__ import annotations

import csv
import dataclasses
import hashlib
import json
import logging
import os
import time
from pathlib import Path
from typing import Any

import psutil

from labapp.records import operators
from labapp.records.audit import FINISH_ACTIONS, Action
from labapp.records.audit import append as audit
from labapp.records.fileio import StorageError, atomic_write, sanitize_name, timestamp_name
from labapp.records.manifests import (
    EVENTS_LOG,
    FRAME_COLUMNS,
    FRAMES_CSV,
    MASSES_CSV,
    RUN_JSON,
    UNRECORDED_DIR,
    FrameRecord,
    RunSnapshot,
    read_run,
    unrecorded_frames,
)
from labapp.records.runrecord import FORMAT, RecordStatus, RunRecord
from labapp.records.seal import SEAL_KEY, make_seal

log = logging.getLogger(__name__)


def _inside(root: Path, path: Path) -> Path:
    root, path = root.resolve(), path.resolve()
    if root != path and root not in path.parents:
        raise StorageError(f"{path} is outside the data directory {root}")
    return path


class RunFolder:
    """A run folder open for writing by this process. Make with :func:`create_run` or :func:`open_run`."""

    def __init__(self, snapshot: RunSnapshot) -> None:
        self.path = snapshot.path
        self.meta: dict[str, Any] = snapshot.meta
        """``run.json`` as stored, extended by :meth:`update`; read its fields through :attr:`record`."""
        self.frames: list[FrameRecord] = list(snapshot.frames)
        csv_path = self.path / FRAMES_CSV
        if snapshot.torn_bytes:
            log.warning("%s: dropping a torn last row of %s (%d bytes)", self.path, FRAMES_CSV, snapshot.torn_bytes)
            with open(csv_path, "r+b") as fh:
                fh.truncate(csv_path.stat().st_size - snapshot.torn_bytes)
        if not csv_path.exists() or csv_path.stat().st_size == 0:
            with open(csv_path, "w", newline="") as fh:
                csv.writer(fh).writerow(FRAME_COLUMNS)
        self._csv = open(csv_path, "a", newline="")
        self._writer = csv.writer(self._csv)
        self._events = open(self.path / EVENTS_LOG, "a")
        if snapshot.torn_bytes:
            self.event("warning", "torn-row", f"dropped {snapshot.torn_bytes} bytes of a half-written row")
        for name in unrecorded_frames(snapshot):
            aside = self.path / UNRECORDED_DIR
            aside.mkdir(exist_ok=True)
            os.replace(self.path / name, aside / name)
            self.event("warning", "unrecorded-frame", f"{name} was written but not recorded before the process "
                       f"stopped; kept aside as {UNRECORDED_DIR}/{name}")

    @property
    def record(self) -> RunRecord:
        """The typed ``run.json`` as it is now."""
        return RunRecord.from_stored(self.meta)

    @property
    def status(self) -> RecordStatus | str:
        """The run's status as stored in ``run.json``."""
        return self.record.status

    def update(self, **fields: Any) -> None:
        """Merge ``fields`` into ``run.json`` and rewrite it atomically, sealed with the folder's manifests as
        they are now (call it with no fields after writing ``masses.csv``)."""
        self.meta.update(fields)
        _write_sealed(self.path, self.meta)

    def event(self, level: str, kind: str, message: str, t_s: float | None = None) -> None:
        """Append ``time<TAB>t_s<TAB>LEVEL<TAB>kind<TAB>message`` to ``events.log``, flushed and fsync'ed."""
        stamp = time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime())
        t_txt = "" if t_s is None else f"{t_s:.1f}"
        self._events.write(f"{stamp}\t{t_txt}\t{level.upper()}\t{kind}\t{' '.join(message.split())}\n")
        self._events.flush()
        os.fsync(self._events.fileno())

    def write_file(self, name: str, data: bytes) -> tuple[str, int]:
        """Atomically write a new file into the run folder; returns its SHA-256 (hex) and size (bytes).

        Raises
        ------
        StorageError
            If the file exists already (a run folder never overwrites a frame).
        """
        target = _inside(self.path, self.path / sanitize_name(name))
        if target.exists():
            raise StorageError(f"{target} exists; a run folder never overwrites a frame")
        atomic_write(target, data)
        return hashlib.sha256(data).hexdigest(), len(data)

    def add_file(self, name: str, data: bytes) -> str:
        """Atomically write an auxiliary file (reference frame, calibration copy, companion raw file) and
        list it with its SHA-256 under ``files`` in ``run.json``; returns the stored name."""
        digest, _ = self.write_file(name, data)
        stored = sanitize_name(name)
        self.update(files=dict(self.record.files, **{stored: digest}))
        return stored

    def add_frame(self, name: str, data: bytes, t_s: float, t_unix_s: float, plate_c: float | None = None,
                  probe_c: float | None = None, speed_rpm: float | None = None) -> FrameRecord:
        """Write a frame atomically, then append and fsync its ``frames.csv`` row.

        ``t_s`` is seconds from the drop, temperatures in degrees C, speed in rpm.
        """
        digest, size = self.write_file(name, data)
        record = FrameRecord(sanitize_name(name), t_s, t_unix_s, plate_c, probe_c, speed_rpm, digest, size)
        self._writer.writerow(record.row())
        self._csv.flush()
        os.fsync(self._csv.fileno())
        self.frames.append(record)
        self.update()
        return record

    def add_gap(self, after_t_s: float, before_t_s: float, reason: str) -> None:
        """Record that no frames exist between two times (s from the drop), e.g. across a crash."""
        gaps = [dataclasses.asdict(g) for g in self.record.gaps]
        gaps.append({"after_t_s": round(after_t_s, 3), "before_t_s": round(before_t_s, 3), "reason": reason})
        self.update(gaps=gaps)
        self.event("warning", "gap", f"no frames between t={after_t_s:.1f} s and t={before_t_s:.1f} s: {reason}")

    def finish(self, status: RecordStatus | str) -> None:
        """Set the final status (``complete``, ``stopped``, ``aborted``, ``failed``) and release the run."""
        try:
            status = RecordStatus(status)
        except ValueError:
            raise StorageError(f"status {status!r} is not one of {tuple(s.value for s in RecordStatus)}") from None
        self.update(status=status, writer_pid=None, writer_started=None, finished_unix_s=time.time())
        self.event("info", "finished", f"run {status} with {len(self.frames)} frames")
        if status in FINISH_ACTIONS:
            audit(self.path, FINISH_ACTIONS[status], f"{self.record.kind} {status} with {len(self.frames)} frames")

    def close(self) -> None:
        """Close the manifests (``run.json`` is always complete on disk already)."""
        self._csv.close()
        self._events.close()

    def __enter__(self) -> RunFolder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _write_sealed(path: Path, meta: dict[str, Any]) -> None:
    """Write ``meta`` as the ``run.json`` of the folder ``path``, with the seal of it and of the folder's
    ``frames.csv`` and ``masses.csv`` as they are on disk."""
    frames = path / FRAMES_CSV
    masses = path / MASSES_CSV
    meta[SEAL_KEY] = make_seal(meta, frames.read_bytes() if frames.exists() else b"",
                               masses.read_bytes() if masses.exists() else None)
    atomic_write(path / RUN_JSON, json.dumps(meta, indent=2, sort_keys=True).encode())


def _writer() -> dict[str, Any]:
    """Who writes the run: pid and process start time (so a reused pid is not mistaken for the writer)."""
    return {"writer_pid": os.getpid(), "writer_started": psutil.Process().create_time()}


def create_run(data_dir: Path, name: str, meta: dict[str, Any]) -> RunFolder:
    """Create a new run folder ``data_dir/<YYYYmmdd-HHMMSS>_<name>`` (suffixed ``-2``, ``-3`` if taken).

    Parameters
    ----------
    data_dir : Path
        The data directory; nothing is written outside it.
    name : str
        User text naming the run; sanitised.
    meta : dict
        Initial ``run.json`` content (settings); ``name``, ``status``, ``format``, ``writer_pid`` and
        ``created_unix_s`` are added.
    """
    data_dir = Path(data_dir)
    operator = operators.require(f"recording {meta.get('kind', 'a run')}")
    if operator == operators.DEMO_OPERATOR and not meta.get("simulated", True):
        raise operators.OperatorError(f"the demo operator {operator!r} records only on the simulated bench")
    data_dir.mkdir(parents=True, exist_ok=True)
    base = timestamp_name(name)
    for k in range(1, 1000):
        path = _inside(data_dir, data_dir / (base if k == 1 else f"{base}-{k}"))
        try:
            path.mkdir()
            break
        except FileExistsError:
            continue
    else:
        raise StorageError(f"could not find a free run folder name for {base!r} in {data_dir}")
    full = dict(meta, name=name, status=RecordStatus.RUNNING, created_unix_s=time.time(), gaps=[], format=FORMAT,
                operator=operator, **_writer())
    _write_sealed(path, full)
    run = RunFolder(read_run(path))
    run.event("info", "created", f"run folder {path.name} created")
    audit(path, Action.START, f"{meta.get('kind', 'run')} {path.name} created", operator=operator)
    log.info("created run folder %s", path)
    return run


def open_run(path: Path, action: Action = Action.RESUME, reason: str | None = None) -> RunFolder:
    """Reopen an interrupted or finished run for writing (resume); marks it ``running`` by this process.

    The audit trail gets an ``action`` entry (``resume``, or ``finalise``) by the current operator.

    Raises
    ------
    StorageError
        If ``path`` is not a run folder or another live process is writing it.
    """
    snapshot = read_run(path)
    if snapshot.live and snapshot.record.writer_pid != os.getpid():
        raise StorageError(f"{path} is being written by process {snapshot.record.writer_pid}; not reopening it")
    audit(path, action, f"{snapshot.record.kind} reopened ({snapshot.status}, {len(snapshot.frames)} frames)",
          reason=reason)
    run = RunFolder(snapshot)
    if snapshot.status == RecordStatus.INTERRUPTED:
        run.event("warning", "interrupted", "the process writing this run stopped without finishing it")
    run.update(status=RecordStatus.RUNNING, resumed=snapshot.record.resumed + 1, **_writer())
    return run


def finalise_run(path: Path, reason: str | None = None) -> None:
    """Close an interrupted run without resuming it: its status becomes ``stopped``; nothing else changes."""
    run = open_run(path, Action.FINALISE, reason)
    run.event("info", "finalised", "finalised by the operator without resuming")
    run.finish(RecordStatus.STOPPED)
    run.close()

