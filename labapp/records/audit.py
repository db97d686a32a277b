"""The audit trail of a record: ``audit.jsonl``, one JSON object per line, append-only and hash-chained.

Each run folder, calibration series, calibration and design folder keeps one. An entry says who
(``operator``), when (``utc``, ISO 8601), what (``action``, one of :class:`Action`, and ``detail``), why
(``reason``: the reason an operator gives for a change after the fact) and carries ``seq`` (1, 2, ...),
``prev`` (the ``hash`` of the entry before it; the first entry's ``prev`` is the hash of the record's
identity, ``record``, which it names) and its own ``hash`` (SHA-256 of the entry's canonical JSON without
``hash``). An entry is written with ``O_APPEND`` and ``fsync`` as one line.

:func:`check_trail` names an edited entry (its hash no longer matches), a deleted one (a ``seq`` missing or a
broken link), reordered ones (``seq`` out of order), a torn last line, and a trail that ends before what the
record itself says happened (a finished run without its last entry: the tail was cut off). A consistent
rewrite of the whole file by someone with write access is not detectable from the file alone; signatures
(:mod:`labapp.records.signatures`) bind the trail's head at signing, and the lab's access control and backups
(``docs/records.md``) cover the rest.
"""
from __future__ import annotations

import enum
import fcntl
import hashlib
import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from labapp.records import operators

__all__ = ["AUDIT_FILE", "SIGNATURES_FILE", "Action", "AuditCheck", "append", "check_trail", "entry_hash", "genesis",
           "read_trail"]

AUDIT_FILE = "audit.jsonl"
SIGNATURES_FILE = "signatures.jsonl"
"""The signatures of a record (:mod:`labapp.records.signatures`); like the audit trail, not part of the
record's hash."""
_FIELDS = ("seq", "utc", "operator", "action", "detail", "reason", "prev")


class Action(enum.StrEnum):
    """What an audit entry records."""

    START = "start"
    """A run or calibration series folder created (recording starts)."""
    DROP = "drop"
    CHANGE_SETTING = "change-setting"
    COMPLETE = "complete"
    STOP = "stop"
    ABORT = "abort"
    FAIL = "fail"
    RESUME = "resume"
    FINALISE = "finalise"
    REANALYSE = "reanalyse"
    CALIBRATE = "calibrate"
    DESIGN = "design"
    DESIGN_END = "design-end"
    SIGN = "sign"
    SIGN_REFUSED = "sign-refused"


FINISH_ACTIONS = {"complete": Action.COMPLETE, "stopped": Action.STOP, "aborted": Action.ABORT, "failed": Action.FAIL}
"""The entry that closes a run, by the run's final status."""


def genesis(identity: str) -> str:
    """The ``prev`` of a trail's first entry: SHA-256 of the record's identity (hex)."""
    return hashlib.sha256(f"sfr-audit\n{identity}".encode()).hexdigest()


def _canonical(entry: Mapping[str, Any]) -> bytes:
    return json.dumps({k: v for k, v in entry.items() if k != "hash"}, sort_keys=True, separators=(",", ":"),
                      ensure_ascii=False).encode()


def entry_hash(entry: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of an entry's canonical JSON (sorted keys, no spaces) without its ``hash``."""
    return hashlib.sha256(_canonical(entry)).hexdigest()


def append(folder: str | Path, action: Action | str, detail: str, *, operator: str | None = None,
           reason: str | None = None, identity: str | None = None) -> dict[str, Any]:
    """Append one entry to ``folder/audit.jsonl`` (created with its first entry) and return it.

    Parameters
    ----------
    folder : path
        The record's folder (it must exist).
    action : Action
    detail : str
        What was done, one line (settings, files, values).
    operator : str, optional
        Who; default the operator this process acts as (:func:`labapp.records.operators.require`).
    reason : str, optional
        Why (required by the callers of after-the-fact changes).
    identity : str, optional
        The record's identity for a new trail (default the folder's name).

    Raises
    ------
    labapp.records.operators.OperatorError
        When no operator is given and the process acts as nobody.
    """
    folder = Path(folder)
    action = Action(action)
    operator = operator or operators.require(f"'{action}' in {folder}")
    path = folder / AUDIT_FILE
    fd = os.open(path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        raw = path.read_bytes()
        lines = [line for line in raw.split(b"\n") if line.strip()]
        entry: dict[str, Any] = {"seq": len(lines) + 1, "utc": operators.utc_now(), "operator": operator,
                                 "action": str(action), "detail": " ".join(detail.split()),
                                 "reason": " ".join(reason.split()) if reason else None}
        if lines:
            try:
                last = json.loads(lines[-1])
                entry["prev"] = last["hash"]
                entry["seq"] = int(last["seq"]) + 1
            except (ValueError, KeyError, TypeError):
                entry["prev"] = hashlib.sha256(lines[-1]).hexdigest()
        else:
            entry["record"] = identity or folder.resolve().name
            entry["prev"] = genesis(entry["record"])
        entry["hash"] = entry_hash(entry)
        prefix = b"\n" if raw and not raw.endswith(b"\n") else b""
        os.write(fd, prefix + json.dumps(entry, sort_keys=True, ensure_ascii=False).encode() + b"\n")
        os.fsync(fd)
    finally:
        os.close(fd)
    return entry


@dataclass(frozen=True)
class AuditCheck:
    """What :func:`check_trail` found: the entries it could read and the problems, each one line naming the
    entry (``seq`` and line)."""

    path: Path
    entries: list[dict[str, Any]]
    problems: list[str] = field(default_factory=list)
    exists: bool = True

    @property
    def ok(self) -> bool:
        return self.exists and not self.problems

    @property
    def head(self) -> tuple[int, str] | None:
        """``(seq, hash)`` of the last entry, None for an empty trail."""
        return (int(self.entries[-1]["seq"]), str(self.entries[-1]["hash"])) if self.entries else None


def read_trail(folder: str | Path) -> list[dict[str, Any]]:
    """The entries of ``folder/audit.jsonl`` that parse as JSON objects, in file order (no checks)."""
    return check_trail(folder).entries


def check_trail(folder: str | Path, *, expect_last: Action | None = None,
                pinned: Mapping[int, str] | None = None) -> AuditCheck:
    """Check the hash chain of ``folder/audit.jsonl``.

    Parameters
    ----------
    expect_last : Action, optional
        The action the record's own state says came last (a stopped run: ``stop``); its absence after the
        last ``start``/``resume`` means the trail was cut off.
    pinned : mapping, optional
        ``seq -> hash`` the trail must contain (the heads recorded by signatures): a missing or different
        entry there means the trail was truncated or rewritten.
    """
    folder = Path(folder)
    path = folder / AUDIT_FILE
    if not path.is_file():
        return AuditCheck(path, [], [], exists=False)
    raw = path.read_bytes()
    problems: list[str] = []
    if raw and not raw.endswith(b"\n"):
        problems.append(f"{AUDIT_FILE}: the last line is torn (no line end): the trail was truncated or cut "
                        "off while it was written")
    all_seqs = set()
    for line in raw.split(b"\n"):
        try:
            all_seqs.add(int(json.loads(line)["seq"]))
        except (ValueError, TypeError, KeyError):
            pass
    entries: list[dict[str, Any]] = []
    prev_hash: str | None = None
    prev_seq = 0
    for number, line in enumerate(raw.split(b"\n"), start=1):
        if not line.strip():
            continue
        try:
            entry = json.loads(line)
            if not isinstance(entry, dict) or any(k not in entry for k in _FIELDS + ("hash",)):
                raise ValueError("not an entry with " + ", ".join(_FIELDS + ("hash",)))
            seq = int(entry["seq"])
        except (ValueError, TypeError) as exc:
            problems.append(f"{AUDIT_FILE} line {number}: unreadable entry ({exc})")
            prev_hash = None
            continue
        where = f"{AUDIT_FILE} line {number} (seq {seq}, {entry.get('action')})"
        if entry_hash(entry) != entry["hash"]:
            problems.append(f"{where}: EDITED, its content no longer matches its hash")
        if not entries:
            identity = entry.get("record")
            if seq != 1 and 1 in all_seqs:
                problems.append(f"{where}: REORDERED, it comes before seq 1")
            elif seq != 1 or identity is None:
                problems.append(f"{where}: the trail does not start at entry 1; entries before it were DELETED")
            elif entry["prev"] != genesis(str(identity)):
                problems.append(f"{where}: the first entry is not chained to the record's identity {identity!r}")
        elif seq < prev_seq + 1:
            problems.append(f"{where}: REORDERED or repeated, it follows seq {prev_seq}")
        elif seq > prev_seq + 1 and prev_seq + 1 in all_seqs:
            problems.append(f"{where}: REORDERED, it comes before seq {prev_seq + 1}")
        elif seq > prev_seq + 1:
            missing = f"seq {prev_seq + 1}" if seq == prev_seq + 2 else f"seq {prev_seq + 1}..{seq - 1}"
            problems.append(f"{where}: {missing} DELETED (the sequence jumps from {prev_seq})")
        elif prev_hash is not None and entry["prev"] != prev_hash:
            problems.append(f"{where}: not chained to the entry before it (that entry was edited or replaced)")
        entries.append(entry)
        prev_hash, prev_seq = entry["hash"], max(prev_seq, seq)
    by_seq = {int(e["seq"]): e for e in entries}
    for seq, digest in sorted((pinned or {}).items()):
        if seq not in by_seq:
            problems.append(f"{AUDIT_FILE}: entry seq {seq}, recorded by a signature, is gone: the trail was "
                            "TRUNCATED or rewritten")
        elif by_seq[seq]["hash"] != digest:
            problems.append(f"{AUDIT_FILE}: entry seq {seq} differs from the one a signature recorded: the trail "
                            "was rewritten")
    if expect_last is not None and entries:
        lifecycle = [e["action"] for e in entries if e["action"] in {a.value for a in FINISH_ACTIONS.values()}
                     | {Action.START, Action.RESUME, Action.FINALISE}]
        if not lifecycle or lifecycle[-1] != expect_last:
            problems.append(f"{AUDIT_FILE}: the record says it ended '{expect_last}' but the trail has no such "
                            f"entry after its last start or resume: entries at its end were TRUNCATED")
    return AuditCheck(path, entries, problems)
