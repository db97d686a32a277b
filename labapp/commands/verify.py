"""`sfr verify`: check a run folder against its manifest (SHA-256 per file, gaps, torn rows)."""
from __future__ import annotations

import argparse
import logging

log = logging.getLogger(__name__)

NAME = "verify"
HELP = "check every file of a run folder against frames.csv / run.json and report gaps and mismatches"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr verify`."""
    parser.add_argument("runs", nargs="+", help="run folder(s)")


def run(args: argparse.Namespace) -> int:
    """Print one report per folder; exit status 1 if any folder fails."""
    from labapp.storage import StorageError, verify_run

    failed = 0
    for folder in args.runs:
        try:
            report = verify_run(folder)
        except StorageError as exc:
            print(f"{folder}: {exc}")
            failed += 1
            continue
        print("\n".join(report.lines()))
        failed += not report.ok
    return 1 if failed else 0
