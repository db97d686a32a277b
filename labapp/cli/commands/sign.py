"""`sfr sign`: an electronic signature of a record, after the operator re-enters their password."""
from __future__ import annotations

import argparse

NAME = "sign"
HELP = "sign a record (reviewed or approved) after re-entering your password; bound to the record's hash"
MEANINGS = ("reviewed", "approved")
"""The values of ``labapp.records.signatures.Meaning`` (kept here so that ``sfr --help`` loads no records)."""
RECORDS = True
"""Acts as a named operator (``--operator``, ``$SFR_OPERATOR``): see :mod:`labapp.cli.operator`."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr sign`."""
    parser.add_argument("record", help="run, calibration-series, calibration or design folder")
    parser.add_argument("--meaning", required=True, choices=MEANINGS,
                        help="what the signature means")
    parser.add_argument("--reason", help="why (stored with the signature and in the audit trail)")
    parser.add_argument("--password-stdin", action="store_true",
                        help="read the password from the first line of standard input (scripts)")


def run(args: argparse.Namespace) -> int:
    """Ask the password, sign, print the signature line."""
    from labapp.cli.operator import read_password
    from labapp.records import operators
    from labapp.records.signatures import check_signer, sign

    signer = check_signer(operators.require(f"signing {args.record}"))     # refused before a password is asked
    password = read_password(f"password of {signer!r} (signing {args.record} as {args.meaning}): ",
                             args.password_stdin)
    signature = sign(args.record, args.meaning, password, reason=args.reason)
    print(f"signed {args.record}: {signature['meaning']} by {signature['signer']} at {signature['utc']} "
          f"(record SHA-256 {signature['record_hash']})")
    return 0
