"""Verification of a folder against its manifests: :func:`verify_run` and its :class:`VerifyReport`.

A record written by :mod:`labapp.records.storage` is checked byte for byte (every listed file against its
SHA-256, the seal of ``run.json``, ``frames.csv`` and ``masses.csv``); any other folder as a frames folder
without checksums, a calibration series or a plain image folder, for presence only.
"""
from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

from analysis.decode import IMAGE_SUFFIXES
from labapp.records.audit import AUDIT_FILE, SIGNATURES_FILE
from labapp.records.fileio import StorageError, sha256_file
from labapp.records.manifests import (
    ANALYSIS_DIR,
    EVENTS_LOG,
    FRAMES_CSV,
    MASSES_CSV,
    RUN_JSON,
    UNRECORDED_DIR,
    RecordReadError,
    read_record,
    read_run,
    unrecorded_frames,
)
from labapp.records.runrecord import Gap, RecordKind, RecordStatus, RunRecord
from labapp.records.seal import seal_findings


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

    A record written by :mod:`labapp.records.storage` (``run.json`` with ``writer_pid``/``created_unix_s`` and a
    checksummed ``frames.csv``): every listed frame and file against its SHA-256, a manifest (``run.json``,
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
