"""Crash-safe run folders: atomic frame writes, append-only manifests, atomic run.json.

A run folder (format in ``docs/formats.md``) holds

- the frames, each written to ``.<name>.part``, flushed, fsync'ed and renamed before it is recorded;
- ``frames.csv``: one row per frame, appended and fsync'ed row by row, with the SHA-256 of the file;
- ``events.log``: the event log, appended and flushed line by line (tab-separated);
- ``run.json``: the run's settings and state, rewritten atomically (temp file + rename); read through
  :func:`read_record` as a :class:`labapp.records.runrecord.RunRecord`. It holds a seal
  (:mod:`labapp.records.seal`) of its own fields, of each ``frames.csv`` row and of ``masses.csv``,
  rewritten with it, so that verification names any of them edited afterwards.

After a crash or power cut the folder is still a valid run: every row of ``frames.csv`` names a complete
file, a half-written last row (a torn write) is dropped when the folder is reopened, and stray ``.part``
files are ignored. A folder is never reused: :func:`create_run` always makes a new one.
"""
from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
import json
import logging
import math
import os
import re
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import psutil

from analysis.decode import IMAGE_SUFFIXES
from labapp.errors import LabError
from labapp.records import operators
from labapp.records.audit import AUDIT_FILE, FINISH_ACTIONS, SIGNATURES_FILE, Action
from labapp.records.audit import append as audit
from labapp.records.runrecord import FORMAT, Gap, RecordFormatError, RecordKind, RecordStatus, RunRecord
from labapp.records.seal import SEAL_KEY, make_seal, seal_findings

log = logging.getLogger(__name__)

FRAMES_CSV = "frames.csv"
EVENTS_LOG = "events.log"
RUN_JSON = "run.json"
MASSES_CSV = "masses.csv"
ANALYSIS_DIR = "analysis"
FRAME_COLUMNS = ("file", "t_s", "t_unix_s", "plate_c", "probe_c", "speed_rpm", "sha256", "bytes")
_SAFE = re.compile(r"[^A-Za-z0-9._-]+")


class StorageError(LabError):
    """A run folder could not be created, written or read; the message names the path."""


class RecordReadError(StorageError):
    """A folder's ``run.json`` cannot be read as a record; :attr:`reason` says why, without the path."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


def sanitize_name(text: str, max_len: int = 64) -> str:
    """A file-system-safe single path component made from user text.

    Keeps letters, digits, ``.``, ``_`` and ``-``; everything else becomes ``_``; leading dots are removed
    so the result is never hidden, ``.`` or ``..``.

    Raises
    ------
    StorageError
        If nothing usable is left of ``text``.
    """
    name = _SAFE.sub("_", text.strip()).lstrip("._")[:max_len].rstrip("._")
    if not name:
        raise StorageError(f"name {text!r} has no usable characters (allowed: letters, digits, . _ -)")
    return name


def timestamp_name(name: str | None = None) -> str:
    """The name of a new folder: ``<YYYYmmdd-HHMMSS>_<sanitised name>`` in local time now (the stamp alone
    without ``name``); run folders, series, designs, sweeps and demos are named so."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    return stamp if name is None else f"{stamp}_{sanitize_name(name)}"


def _inside(root: Path, path: Path) -> Path:
    root, path = root.resolve(), path.resolve()
    if root != path and root not in path.parents:
        raise StorageError(f"{path} is outside the data directory {root}")
    return path


def _fsync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so that ``path`` is either absent or complete, never partial."""
    tmp = path.with_name(f".{path.name}.part")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    _fsync_dir(path.parent)


def sha256_file(path: Path) -> str:
    """Hex SHA-256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def free_bytes(folder: Path) -> int:
    """Free space, in bytes, on the file system holding ``folder``."""
    return shutil.disk_usage(folder).free


def check_disk_space(folder: Path, frame_bytes: int, n_frames: int, margin: float = 1.5) -> int:
    """Refuse a run that would not fit: returns the free bytes when ``frame_bytes * n_frames * margin`` fit.

    Raises
    ------
    StorageError
        When the estimate exceeds the free space on ``folder``'s file system.
    """
    need = int(frame_bytes * n_frames * margin)
    have = free_bytes(folder)
    if need > have:
        raise StorageError(f"not enough disk space in {folder}: a run of {n_frames} frames of ~{frame_bytes} bytes "
                           f"needs ~{need / 1e9:.2f} GB (x{margin} margin), {have / 1e9:.2f} GB free")
    return have


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


@dataclass(frozen=True)
class VerifyReport:
    """What :func:`verify_run` found. ``ok`` is True when nothing is missing, altered, listed twice, unlisted,
    torn or wrong; :attr:`reason` is the first failure in one line."""

    path: Path
    kind: str
    status: str
    n_frames: int
    missing: list[str]
    mismatched: list[str]
    duplicates: list[str]
    unlisted: list[str]
    gaps: list[Gap]
    torn_bytes: int
    problems: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not (self.problems or self.missing or self.mismatched or self.duplicates or self.unlisted
                    or self.torn_bytes)

    @property
    def reason(self) -> str:
        """The first failure, one line ("" when ok)."""
        def some(names: list[str]) -> str:
            return ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
        if self.problems:
            return self.problems[0]
        if self.missing:
            return f"{len(self.missing)} listed file(s) absent: {some(self.missing)}"
        if self.mismatched:
            return f"{len(self.mismatched)} file(s) altered (SHA-256 differs): {some(self.mismatched)}"
        if self.duplicates:
            return f"{len(self.duplicates)} file(s) listed twice: {some(self.duplicates)}"
        if self.unlisted:
            return f"{len(self.unlisted)} file(s) present but not listed: {some(self.unlisted)}"
        if self.torn_bytes:
            return f"torn last row of {FRAMES_CSV} ({self.torn_bytes} bytes)"
        return ""

    def lines(self) -> list[str]:
        """A human-readable report, one finding per line; the last is ``OK`` or ``FAILED: <reason>``."""
        out = [f"{self.path}: {self.kind}, status {self.status}, {self.n_frames} frames listed"]
        out += [f"PROBLEM {p}" for p in self.problems]
        out += [f"MISSING {name}" for name in self.missing]
        out += [f"MISMATCH {name} (SHA-256 differs from the manifest)" for name in self.mismatched]
        out += [f"DUPLICATE {name} (listed more than once)" for name in self.duplicates]
        out += [f"UNLISTED {name} (in the folder, not in the manifest)" for name in self.unlisted]
        out += [f"GAP {g.after_t_s:.1f} s .. {g.before_t_s:.1f} s: {g.reason}" for g in self.gaps]
        if self.torn_bytes:
            out.append(f"TORN last row of {FRAMES_CSV} ({self.torn_bytes} bytes; dropped when the run is reopened)")
        out += [f"NOTE {n}" for n in self.notes]
        out.append("OK" if self.ok else f"FAILED: {self.reason}")
        return out




def _entries(path: Path) -> list[Path]:
    """Files and folders of ``path``, hidden ones (``.part`` leftovers) excluded."""
    return sorted(p for p in path.iterdir() if not p.name.startswith("."))


def _bad_event_lines(path: Path) -> list[int]:
    """Line numbers of complete ``events.log`` lines without the five tab-separated fields."""
    if not path.exists():
        return []
    lines = path.read_bytes().split(b"\n")[:-1]
    return [i for i, line in enumerate(lines, start=1) if len(line.split(b"\t")) < 5]


def _verify_record(path: Path) -> VerifyReport:
    """A folder written by :mod:`labapp.records.storage` (``run.json`` + ``frames.csv`` with SHA-256)."""
    problems: list[str] = []
    try:
        snap = read_run(path)
    except StorageError as exc:
        torn = f"{RUN_JSON} is torn or unreadable" if (path / RUN_JSON).exists() else f"no {RUN_JSON}"
        return VerifyReport(path, "run folder", "unknown", 0, [], [], [], [], [], 0,
                            [str(exc) if FRAMES_CSV in str(exc) else f"{torn}: {exc}"])
    kind = snap.record.kind
    if kind not in tuple(RecordKind):
        problems.append(f"{RUN_JSON} names kind {kind!r}; a run folder is a 'run' or a 'calibration-series'")
    if not (path / FRAMES_CSV).is_file():
        problems.append(f"the manifest {FRAMES_CSV} is missing")
    if not (path / EVENTS_LOG).is_file():
        problems.append(f"the event log {EVENTS_LOG} is missing")
    bad = _bad_event_lines(path / EVENTS_LOG)
    if bad:
        problems.append(f"{EVENTS_LOG} line {bad[0]} is damaged (not time, t_s, level, kind, message)")
    listed = [(f.file, f.sha256) for f in snap.frames] + list(snap.record.files.items())
    seen: set[str] = set()
    missing, mismatched, duplicates = [], [], []
    for name, digest in listed:
        if name in seen:
            duplicates.append(name)
            continue
        seen.add(name)
        target = snap.path / name
        if not target.is_file():
            missing.append(name)
        elif sha256_file(target) != digest:
            mismatched.append(name)
    own = {FRAMES_CSV, EVENTS_LOG, RUN_JSON, ANALYSIS_DIR, AUDIT_FILE, SIGNATURES_FILE}
    if kind == RecordKind.CALIBRATION_SERIES:
        own.add(MASSES_CSV)
        problems += _check_masses(path, seen, required=True)
    unlisted = [p.name for p in _entries(snap.path) if p.name not in seen and p.name not in own]
    pending = unrecorded_frames(snap)
    notes = [f"{name} was written just before the process stopped and never recorded; resuming or finalising "
             f"the run keeps it aside in {UNRECORDED_DIR}/" for name in pending]
    masses = path / MASSES_CSV
    frames = path / FRAMES_CSV
    altered, seal_notes = seal_findings(snap.record.stored, frames.read_bytes() if frames.is_file() else b"",
                                        masses.read_bytes() if masses.is_file() else None,
                                        unfinished=snap.status in (RecordStatus.RUNNING, RecordStatus.INTERRUPTED))
    problems += altered
    notes += seal_notes
    label = "calibration-series record" if kind == RecordKind.CALIBRATION_SERIES else "acquisition run record"
    return VerifyReport(snap.path, label, snap.status, len(snap.frames), missing, mismatched, duplicates, unlisted,
                        list(snap.record.gaps), snap.torn_bytes, problems, notes)


def _check_masses(path: Path, listed: set[str] | None, required: bool) -> list[str]:
    """Problems of ``masses.csv``: unreadable, non-finite or decreasing masses, an image listed twice or
    (when ``listed`` is given) an image not in the frame manifest."""
    csv_path = path / MASSES_CSV
    if not csv_path.is_file():
        return [f"{MASSES_CSV} is missing"] if required else []
    try:
        with open(csv_path, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        return [f"{MASSES_CSV} cannot be read: {exc}"]
    names: set[str] = set()
    last = 0.0
    for line, row in enumerate(rows, start=2):
        name = row.get("file") or ""
        try:
            mass = float(row.get("added_mass_g") or "")
        except ValueError:
            return [f"{MASSES_CSV} line {line}: added_mass_g {row.get('added_mass_g')!r} is not a number"]
        if not math.isfinite(mass) or mass < last:
            return [f"{MASSES_CSV} line {line}: added_mass_g {mass} is not a finite cumulative mass"]
        if name in names:
            return [f"{MASSES_CSV} line {line}: {name} is listed twice"]
        if listed is not None and name not in listed:
            return [f"{MASSES_CSV} line {line}: {name} is not in {FRAMES_CSV}"]
        if not (path / name).is_file():
            return [f"{MASSES_CSV} line {line}: {name} is absent"]
        names.add(name)
        last = mass
    return []


def _verify_unrecorded(path: Path) -> VerifyReport:
    """A folder not written by :mod:`labapp.records.storage`: a frames folder without checksums (a rendered fixture),
    a calibration series with ``masses.csv`` only, or a plain image folder. Every image must be listed
    where there is a manifest; nothing can be checked byte for byte."""
    entries = _entries(path)
    images = [p.name for p in entries if p.suffix.lower() in IMAGE_SUFFIXES]
    problems, missing, duplicates = [], [], []
    listed: set[str] = set()
    record: RunRecord | None = None
    if (path / RUN_JSON).exists():
        try:
            record = read_record(path)
        except RecordReadError as exc:
            problems.append(f"{RUN_JSON} is torn or unreadable: {exc.reason}")
    n_frames = 0
    if (path / FRAMES_CSV).is_file():
        kind = "frames folder without checksums (not an acquisition record)"
        raw = (path / FRAMES_CSV).read_bytes()
        if raw and not raw.endswith(b"\n"):
            problems.append(f"{FRAMES_CSV}: the last row is torn (no line end)")
        reader = csv.DictReader(io.StringIO(raw.decode(errors="replace")))
        if not {"file", "t_s"} <= set(reader.fieldnames or ()):
            problems.append(f"{FRAMES_CSV}: no file,t_s header")
        else:
            for row in reader:
                n_frames += 1
                try:
                    if None in row or float(row["t_s"]) != float(row["t_s"]):
                        raise ValueError
                except (TypeError, ValueError):
                    problems.append(f"{FRAMES_CSV} line {reader.line_num}: damaged row")
                    break
                name = row["file"]
                if name in listed:
                    duplicates.append(name)
                listed.add(name)
                if not (path / name).is_file():
                    missing.append(name)
        stored = record.stored if record is not None else {}
        listed |= {v for k, v in stored.items() if k.endswith("_file") and isinstance(v, str)}
        problems += _check_masses(path, None, required=False)
        listed |= _masses_names(path)
    elif (path / MASSES_CSV).is_file():
        kind = "calibration-series folder without checksums (not an acquisition record)"
        problems += _check_masses(path, None, required=True)
        listed = _masses_names(path)
        n_frames = len(listed)
    elif images:
        kind = "plain image folder (no manifest)"
        listed = set(images)
        n_frames = len(images)
    else:
        return VerifyReport(path, "not a run folder", "unknown", 0, [], [], [], [], [], 0,
                            [f"{path} holds no run.json, {FRAMES_CSV}, {MASSES_CSV} or images: not a run, "
                             "calibration series or image folder"])
    unlisted = [name for name in images if name not in listed]
    others = [p.name for p in entries if p.name not in listed and p.name not in unlisted
              and p.name not in (FRAMES_CSV, RUN_JSON, MASSES_CSV, EVENTS_LOG, ANALYSIS_DIR, AUDIT_FILE,
                                 SIGNATURES_FILE)]
    notes = ["no checksums: files are checked for presence only"] if kind != "plain image folder (no manifest)" \
        else [f"{len(images)} images; no manifest, so nothing can be missing or altered"]
    if others:
        notes.append(f"other files (not frames): {', '.join(others)}")
    status = record.status if record is not None and "status" in record.stored else "not recorded"
    return VerifyReport(path, kind, str(status), n_frames, missing, [], duplicates, unlisted, [], 0, problems, notes)


def _masses_names(path: Path) -> set[str]:
    try:
        with open(path / MASSES_CSV, newline="") as fh:
            return {row.get("file") or "" for row in csv.DictReader(fh)}
    except (OSError, UnicodeDecodeError, csv.Error):
        return set()


def verify_run(path: Path) -> VerifyReport:
    """Check a folder as what it is; never raises for a bad folder (what is wrong is in the report).

    A record written by this module (``run.json`` with ``writer_pid``/``created_unix_s`` and a checksummed
    ``frames.csv``): every listed frame and file against its SHA-256, a manifest (``run.json``,
    ``frames.csv``, ``events.log``, ``masses.csv``) missing or damaged anywhere, a ``run.json`` field, a
    ``frames.csv`` row or ``masses.csv`` changed since the writer sealed them, files present but
    unlisted (only the ``analysis`` subfolder may be added), a kind other than ``run`` or
    ``calibration-series``. Any other folder is verified as a frames folder without checksums, a
    calibration series, or a plain image folder (see :func:`_verify_unrecorded`).
    """
    path = Path(path)
    if not path.is_dir():
        what = "does not exist" if not path.exists() else "is a file, not a folder"
        return VerifyReport(path, "not a folder", "unknown", 0, [], [], [], [], [], 0, [f"{path} {what}"])
    header = (path / FRAMES_CSV).read_bytes()[:200] if (path / FRAMES_CSV).is_file() else b""
    recorded = b"sha256" in header.split(b"\n")[0] or (
        (path / RUN_JSON).is_file() and b"created_unix_s" in (path / RUN_JSON).read_bytes())
    return _verify_record(path) if recorded else _verify_unrecorded(path)
