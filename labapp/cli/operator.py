"""The operator a recording `sfr` command acts as: ``--operator NAME``, else ``$SFR_OPERATOR``, else (only while
the lab has no users file) the login name, recorded unverified (:mod:`labapp.records.operators`).

A command module that records actions sets ``RECORDS = True`` (with a users file, refused without an operator:
no operator, no recorded action) or ``RECORDS = "optional"`` (the command decides: ``sfr demo`` acts as the
built-in demo operator); :func:`add_operator_option` gives it the ``--operator`` option and runs it as that
operator.
"""
from __future__ import annotations

import argparse
import getpass
import sys
from collections.abc import Callable

from labapp.records.operators import OPERATOR_ENV

__all__ = ["add_operator_option", "read_password"]


def add_operator_option(parser: argparse.ArgumentParser, run: Callable[[argparse.Namespace], int],
                        records: bool | str) -> None:
    """Add ``--operator`` to a command's parser and make it run as that operator (checked first)."""
    parser.add_argument("--operator", metavar="NAME",
                        help=f"the operator this command acts as, recorded in run.json and the audit trail "
                             f"(default ${OPERATOR_ENV}; without a users file, your login name, recorded as "
                             f"unverified; 'sfr users add NAME' creates the file and enforces operators)")

    def run_as_operator(args: argparse.Namespace) -> int:
        from labapp.records import operators

        if args.operator:
            with operators.acting_as(args.operator):
                return run(args)
        if records is True:
            operators.require(f"'sfr {args.command}'")
        return run(args)

    parser.set_defaults(_run=run_as_operator)


def read_password(prompt: str, from_stdin: bool, twice: bool = False) -> str:
    """A password: the first line of standard input (``--password-stdin``), else asked without echo
    (``twice``: asked again and compared).

    Raises
    ------
    labapp.records.operators.OperatorError
        When the two entries differ, or standard input is empty.
    """
    from labapp.records.operators import OperatorError

    if from_stdin:
        line = sys.stdin.readline().rstrip("\r\n")
        if not line:
            raise OperatorError("--password-stdin: standard input holds no password line")
        return line
    first = getpass.getpass(prompt)
    if twice and getpass.getpass("again: ") != first:
        raise OperatorError("the two passwords differ; nothing was changed")
    return first
