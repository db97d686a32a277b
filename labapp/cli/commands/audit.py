"""`sfr audit`: the audit trail of a record as a table, with whether its hash chain holds."""
from __future__ import annotations

import argparse

NAME = "audit"
HELP = "print the audit trail of a run, calibration or design folder (who, when, what, why) and check its chain"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr audit`."""
    parser.add_argument("records", nargs="+", help="run, calibration-series, calibration or design folder(s)")


def run(args: argparse.Namespace) -> int:
    """One table per record; the last line ``chain OK`` or ``chain BROKEN: ...``, checked as ``sfr verify``
    checks the trail; exit 1 (``sfr verify``'s code for a failed record) if any is broken or absent."""
    from pathlib import Path

    from labapp.errors import EXIT_FAILED, EXIT_OK, UsageError
    from labapp.records.signatures import trail_check

    broken = 0
    for folder in map(Path, args.records):
        if not folder.is_dir():
            raise UsageError(f"{folder} is not a folder; give a run, calibration or design folder")
        check = trail_check(folder)
        if not check.exists:
            print(f"{folder}: no audit trail ({check.path.name} absent)")
            broken += 1
            continue
        print(f"{folder}: {len(check.entries)} entries")
        for line in table(check.entries):
            print(line)
        print("chain OK" if check.ok else "chain BROKEN: " + "; ".join(check.problems))
        broken += not check.ok
    return EXIT_FAILED if broken else EXIT_OK


def table(entries: list[dict]) -> list[str]:
    """The entries as aligned text rows: seq, UTC time, operator, action, detail (and reason)."""
    rows = [("seq", "utc", "operator", "action", "detail / reason")]
    rows += [(str(e.get("seq")), str(e.get("utc")), str(e.get("operator")), str(e.get("action")),
              str(e.get("detail")) + (f"  [reason: {e['reason']}]" if e.get("reason") else "")) for e in entries]
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    return ["  ".join(r[i].ljust(widths[i]) for i in range(4)) + "  " + r[4] for r in rows]
