"""`sfr verify`: check folders as what they are: a run record against its manifests (SHA-256 per file,
unlisted files, damaged manifests, gaps), a frames folder or a calibration series without checksums, or a
plain image folder."""
from __future__ import annotations

import argparse

NAME = "verify"
HELP = "check a run folder against its manifests (missing, altered, unlisted files, damaged manifests)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr verify`."""
    parser.add_argument("runs", nargs="+", help="run folder(s), calibration series or image folders")


def run(args: argparse.Namespace) -> int:
    """Print one report per folder, its last line ``OK`` or ``FAILED: <reason>``; exit 1 if any fails."""
    from labapp.jobs.verify import verify  # here, not at the top: `sfr --help` does not load the records layer

    failed = 0
    for folder in args.runs:
        report = verify(folder)
        print("\n".join(report.lines()), flush=True)
        failed += not report.ok
    return 1 if failed else 0
