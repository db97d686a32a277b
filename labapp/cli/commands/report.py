"""`sfr report`: the PDF report of a run (method, settings, devices, calibration, curve, metrics, f2, criteria,
warnings, audit trail, signatures)."""
from __future__ import annotations

import argparse

NAME = "report"
HELP = "write a run's report as a PDF: settings, curve in g and percent, MDT/DE/model fits, f2, audit trail, signatures"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr report`."""
    from labapp.cli.commands.compare import RULES

    parser.add_argument("record", help="the run folder")
    parser.add_argument("--out", required=True, help="the PDF to write (a new file)")
    parser.add_argument("--reference", action="append", default=[], metavar="RUN",
                        help="a reference run or curve CSV for f2 (repeatable)")
    parser.add_argument("--rule", choices=RULES, default=None,
                        help="the regulator whose f2 time-point rule applies (default: sfr compare's, ema)")
    parser.add_argument("--curve", help="the run's curve.csv from sfr analyze (default: RUN/analysis/curve.csv "
                        "if recorded, else the run is analysed in memory with its calibration.json)")


def run(args: argparse.Namespace) -> int:
    """Write the PDF; print its path, page count and SHA-256."""
    from labapp.jobs.report import report_digest, write_report

    rule = {} if args.rule is None else {"rule": args.rule}
    path = write_report(args.record, args.out, references=tuple(args.reference), curve=args.curve, **rule)
    print(f"report written: {path} (3 pages, SHA-256 {report_digest(path)})")
    return 0
