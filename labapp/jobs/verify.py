"""Verify a folder against its manifests (`sfr verify`)."""
from __future__ import annotations

from pathlib import Path

from labapp.records.storage import VerifyReport, verify_run


def verify(folder: str | Path) -> VerifyReport:
    """Check a folder against its manifests; returns a :class:`labapp.records.storage.VerifyReport` (never raises
    for a bad folder: what is wrong is in the report)."""
    return verify_run(Path(folder))
