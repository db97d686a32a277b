"""Verify a folder against its manifests (`sfr verify`)."""
from __future__ import annotations

import dataclasses
from pathlib import Path

from labapp.records.audit import AUDIT_FILE
from labapp.records.signatures import record_checks
from labapp.records.verification import VerifyReport, verify_run


def verify(folder: str | Path) -> VerifyReport:
    """Check a folder against its manifests; returns a :class:`labapp.records.verification.VerifyReport` (never raises
    for a bad folder: what is wrong is in the report), with its audit trail and signatures
    (:func:`labapp.records.signatures.record_checks`)."""
    folder = Path(folder)
    report = verify_run(folder)
    problems, notes = record_checks(folder) if folder.is_dir() else ([], [])
    if report.kind == "not a run folder" and (folder / AUDIT_FILE).is_file():   # a design or calibration folder
        return VerifyReport(folder, "record with an audit trail (design or calibration folder)", "n/a", 0, [], [], [],
                            [], [], 0, problems, notes)
    return dataclasses.replace(report, problems=report.problems + problems, notes=report.notes + notes)
