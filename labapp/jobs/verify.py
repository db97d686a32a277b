"""Verify a folder against its manifests (`sfr verify`)."""
from __future__ import annotations

from pathlib import Path


def verify(folder: str | Path):
    """Check a folder against its manifests; returns a :class:`labapp.records.storage.VerifyReport` (never raises
    for a bad folder: what is wrong is in the report)."""
    from labapp.records.storage import verify_run

    return verify_run(Path(folder))
