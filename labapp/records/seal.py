"""The seal a run folder keeps in its ``run.json``: a digest of every metadata field, of each frame's
manifest row, and of the calibration masses, so that ``sfr verify`` names any of them edited afterwards.

The frames' SHA-256 in ``frames.csv`` proves the images are unchanged; the seal proves the numbers that
turn them into grams are too: ``water_g``, ``object_mass_g``, the crop, each frame's time and
temperatures, the masses of a calibration series. It is rewritten (inside ``run.json``, atomically)
whenever the writer changes any of them, so it always describes the folder as its writer left it; a
crash can leave at most the last ``frames.csv`` row written but not yet sealed.

It detects changes made by hand or by other software, not a forger who recomputes it: that is what
the audit trail and signatures are for.
"""
from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from typing import Any

SEAL_KEY = "seal"
"""The ``run.json`` key that holds the seal."""
_DIGEST_HEX = 16
"""Hex digits kept of each SHA-256: 64 bits, ample against accidental collisions, and a 4-hour run's
seal stays a few kB."""


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:_DIGEST_HEX]


def _value_digest(value: Any) -> str:
    return _digest(json.dumps(value, sort_keys=True, separators=(",", ":")).encode())


def _lines(csv_bytes: bytes) -> list[bytes]:
    """The complete lines of a CSV file (a torn last line is not one)."""
    return csv_bytes[: csv_bytes.rfind(b"\n") + 1].splitlines()


def make_seal(meta: Mapping[str, Any], frames_csv: bytes, masses_csv: bytes | None) -> dict[str, Any]:
    """The seal of ``run.json``'s fields (``meta`` without the seal), the complete lines of ``frames.csv``
    (header first) and ``masses.csv`` (None when the folder has none)."""
    return {"fields": {key: _value_digest(value) for key, value in meta.items() if key != SEAL_KEY},
            "frames_csv": [_digest(line) for line in _lines(frames_csv)],
            "masses_csv": None if masses_csv is None else _digest(masses_csv)}


def seal_findings(meta: Mapping[str, Any], frames_csv: bytes, masses_csv: bytes | None, *,
                  unfinished: bool) -> tuple[list[str], list[str]]:
    """What differs from the seal stored in ``meta``: (problems, notes).

    Parameters
    ----------
    meta : mapping
        ``run.json`` as stored.
    frames_csv, masses_csv : bytes
        The files as they are now (``masses_csv`` None when absent).
    unfinished : bool
        The run is running or interrupted: one complete ``frames.csv`` row after the sealed ones is then
        the row a crash left unsealed (a note), not an addition.
    """
    seal = meta.get(SEAL_KEY)
    if not isinstance(seal, Mapping):
        return [], ["run.json holds no seal (a folder written by hand or by a version of sfr without seals): "
                    "its settings and frame times cannot be checked"]
    problems: list[str] = []
    sealed = dict(seal.get("fields") or {})
    current = {key: _value_digest(value) for key, value in meta.items() if key != SEAL_KEY}
    for key in sorted(set(sealed) | set(current)):
        if key not in current:
            problems.append(f"run.json field {key!r} was removed after it was recorded")
        elif key not in sealed:
            problems.append(f"run.json field {key!r} was added after the run was recorded")
        elif sealed[key] != current[key]:
            problems.append(f"run.json field {key!r} was changed after it was recorded (now {meta[key]!r})")
    rows = list(seal.get("frames_csv") or [])
    lines = _lines(frames_csv)
    notes: list[str] = []
    for number, (line, digest) in enumerate(zip(lines, rows), start=1):
        if _digest(line) != digest:
            what = "the header" if number == 1 else f"row {number} ({line.split(b',')[0].decode(errors='replace')})"
            problems.append(f"frames.csv line {number}, {what}, was changed after it was recorded: "
                            f"{line.decode(errors='replace')}")
    if len(lines) < len(rows):
        problems.append(f"frames.csv lost {len(rows) - len(lines)} recorded row(s) after line {len(lines)}")
    extra = len(lines) - len(rows)
    if extra == 1 and unfinished:
        notes.append(f"frames.csv line {len(lines)} was written just before the process stopped and is not sealed "
                     "yet; resuming or finalising the run seals it")
    elif extra > 0:
        problems.append(f"frames.csv lines {len(rows) + 1}..{len(lines)} were added after the run was recorded")
    sealed_masses = seal.get("masses_csv")
    if sealed_masses is not None or masses_csv is not None:
        if masses_csv is None:
            problems.append("masses.csv was removed after it was recorded")
        elif sealed_masses is None:
            problems.append("masses.csv was added after the run was recorded")
        elif _digest(masses_csv) != sealed_masses:
            problems.append("masses.csv was changed after it was recorded (the calibration's added masses)")
    return problems, notes
