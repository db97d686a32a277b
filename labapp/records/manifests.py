"""A run folder's layout and manifests, read from disk without changing anything.

A run folder (format in ``docs/formats.md``, written by :mod:`labapp.records.storage`) holds the frames,
``frames.csv`` (one row per frame with the SHA-256 of the file, :class:`FrameRecord`), ``events.log`` and
``run.json`` (read through :func:`read_record` as a :class:`labapp.records.runrecord.RunRecord`).
:func:`read_run` reads the folder as a :class:`RunSnapshot`, also while it is written or after a crash: a
half-written last row of ``frames.csv`` (a torn write) is measured, not parsed, and :func:`unrecorded_frames`
names the frames written but never recorded.
"""
from __future__ import annotations

import csv
import io
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import psutil

from labapp.records.fileio import StorageError
from labapp.records.runrecord import RecordFormatError, RecordStatus, RunRecord

FRAMES_CSV = "frames.csv"
EVENTS_LOG = "events.log"
RUN_JSON = "run.json"
MASSES_CSV = "masses.csv"
ANALYSIS_DIR = "analysis"
FRAME_COLUMNS = ("file", "t_s", "t_unix_s", "plate_c", "probe_c", "speed_rpm", "sha256", "bytes")


class RecordReadError(StorageError):
    """A folder's ``run.json`` cannot be read as a record; :attr:`reason` says why, without the path."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


@dataclass(frozen=True)
class FrameRecord:
    """One row of ``frames.csv``. Temperatures in degrees C, speed in rpm, ``t_s`` from the drop."""

    file: str
    t_s: float
    t_unix_s: float
    plate_c: float | None
    probe_c: float | None
    speed_rpm: float | None
    sha256: str
    bytes: int

    def row(self) -> list[str]:
        """The CSV cells of this record (empty for unknown readings)."""
        def fmt(v: float | None, spec: str) -> str:
            return "" if v is None else format(v, spec)
        return [self.file, f"{self.t_s:.3f}", f"{self.t_unix_s:.3f}", fmt(self.plate_c, ".2f"),
                fmt(self.probe_c, ".2f"), fmt(self.speed_rpm, ".1f"), self.sha256, str(self.bytes)]

    @classmethod
    def from_row(cls, row: dict[str, str]) -> FrameRecord:
        """Parse a ``frames.csv`` row (as from ``csv.DictReader``)."""
        def num(key: str) -> float | None:
            return float(row[key]) if row.get(key) else None
        return cls(row["file"], float(row["t_s"]), float(row["t_unix_s"]), num("plate_c"), num("probe_c"),
                   num("speed_rpm"), row["sha256"], int(row["bytes"]))


def _read_frames(path: Path) -> tuple[list[FrameRecord], int]:
    """Parse frames.csv; returns the records and the byte length of the complete lines.

    Raises
    ------
    StorageError
        For a header that is not :data:`FRAME_COLUMNS` or a complete row that cannot be parsed (a manifest
        torn or edited anywhere but at its last row); the message names the line.
    """
    raw = path.read_bytes() if path.exists() else b""
    good = raw[: raw.rfind(b"\n") + 1]
    try:
        text = good.decode()
    except UnicodeDecodeError as exc:
        raise StorageError(f"{path}: not text (byte {exc.start}); the manifest is damaged") from None
    reader = csv.DictReader(io.StringIO(text))
    if good and tuple(reader.fieldnames or ()) != FRAME_COLUMNS:
        raise StorageError(f"{path}: header {','.join(reader.fieldnames or [])!r} is not {','.join(FRAME_COLUMNS)!r}")
    records = []
    for row in reader:
        try:
            if None in row or None in row.values():
                raise ValueError(f"{len(row) - (None in row)} fields, expected {len(FRAME_COLUMNS)}")
            records.append(FrameRecord.from_row(row))
        except (KeyError, TypeError, ValueError) as exc:
            raise StorageError(f"{path} line {reader.line_num}: damaged row ({exc})") from None
    return records, len(good)


@dataclass(frozen=True)
class RunSnapshot:
    """A run folder as read from disk, without opening it for writing."""

    path: Path
    record: RunRecord
    frames: list[FrameRecord]
    torn_bytes: int

    @property
    def meta(self) -> dict[str, Any]:
        """``run.json`` exactly as stored (what a writer extends); read its fields through :attr:`record`."""
        return dict(self.record.stored)

    @property
    def live(self) -> bool:
        """True while the process that writes the run is still alive."""
        record = self.record
        if record.status != RecordStatus.RUNNING or record.writer_pid is None:
            return False
        try:
            return abs(psutil.Process(record.writer_pid).create_time() - (record.writer_started or 0.0)) < 1.0
        except psutil.Error:
            return False

    @property
    def status(self) -> RecordStatus | str:
        """The stored status, except ``interrupted`` for a ``running`` run whose writer is gone."""
        status = self.record.status
        return RecordStatus.INTERRUPTED if status == RecordStatus.RUNNING and not self.live else status

    def events(self) -> list[str]:
        """The lines of ``events.log``."""
        log_path = self.path / EVENTS_LOG
        return log_path.read_text().splitlines() if log_path.exists() else []


def read_record(path: Path) -> RunRecord:
    """The typed ``run.json`` of the folder ``path``, migrated in memory to the current layout; the file is
    never written (see :func:`labapp.records.runrecord.migrate`).

    Raises
    ------
    RecordReadError
        If ``run.json`` is absent or unreadable, not a JSON object, or of a format this version cannot read.
    """
    path = Path(path)
    try:
        stored = json.loads((path / RUN_JSON).read_text())
    except (OSError, ValueError) as exc:
        raise RecordReadError(f"{path} is not a readable run folder ({RUN_JSON}: {exc})", str(exc)) from exc
    if not isinstance(stored, dict):
        raise RecordReadError(f"{path}: {RUN_JSON} is not a JSON object", "not a JSON object")
    try:
        return RunRecord.from_stored(stored)
    except RecordFormatError as exc:
        raise RecordReadError(f"{path}: {RUN_JSON} {exc}", str(exc)) from exc


def read_run(path: Path) -> RunSnapshot:
    """Read a run folder (also one being written or left by a crash) without changing it.

    Raises
    ------
    StorageError
        If ``path`` has no readable ``run.json`` (:class:`RecordReadError`) or a damaged ``frames.csv``.
    """
    path = Path(path)
    record = read_record(path)
    csv_path = path / FRAMES_CSV
    frames, good_len = _read_frames(csv_path)
    torn = csv_path.stat().st_size - good_len if csv_path.exists() else 0
    return RunSnapshot(path, record, frames, torn)


UNRECORDED_DIR = ".unrecorded"
"""Hidden subfolder where reopening a run keeps frames written but not recorded before a crash."""
_FRAME_NAME = re.compile(r"frame_\d{6}\.[A-Za-z0-9]+")


def unrecorded_frames(snapshot: RunSnapshot) -> list[str]:
    """Frame files of an unfinished run that its manifests do not list: a crash between a frame's atomic
    write and its ``frames.csv`` row (or its ``run.json`` entry) leaves at most one such frame and its
    companion files."""
    if snapshot.status not in (RecordStatus.INTERRUPTED, RecordStatus.RUNNING):
        return []
    listed = {f.file for f in snapshot.frames} | set(snapshot.record.files)
    return sorted(p.name for p in snapshot.path.iterdir()
                  if p.is_file() and _FRAME_NAME.fullmatch(p.name) and p.name not in listed)

