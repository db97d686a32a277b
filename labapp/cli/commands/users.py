"""`sfr users`: the operators of this machine (add, list, disable, enable), in the users file."""
from __future__ import annotations

import argparse

NAME = "users"
HELP = "the operators who may record and sign: add NAME, list, disable NAME, enable NAME"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr users`."""
    sub = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    add = sub.add_parser("add", help="add an operator (the password is asked twice, never echoed)")
    add.add_argument("name", help="the operator's name as it appears in records (e.g. 'A. Jones')")
    add.add_argument("--password-stdin", action="store_true", help="read the password from the first line of "
                     "standard input (scripts)")
    sub.add_parser("list", help="the operators, enabled or not, and the users file")
    for action, what in (("disable", "may no longer record or sign (kept: old records name them)"),
                         ("enable", "may record and sign again")):
        p = sub.add_parser(action, help=f"the operator {what}")
        p.add_argument("name")


def run(args: argparse.Namespace) -> int:
    """Do the action; print one line per operator or change."""
    from labapp.cli.operator import read_password
    from labapp.records import operators

    path = operators.users_path()
    if args.action == "add":
        first = not operators.enforced()
        password = read_password(f"password for {args.name!r}: ", args.password_stdin, twice=True)
        operators.add_user(args.name, password)
        print(f"operator {args.name!r} added to {path}")
        if first:
            print("operators are now enforced: every recorded action needs an enabled operator of this file "
                  "(--operator NAME or $SFR_OPERATOR), and may be signed")
    elif args.action == "list":
        users = operators.load_users()
        print(f"{path}: {len(users)} operator(s)" + ("" if operators.enforced() else
              " (no users file: operators are not enforced; actions name the login name, unverified)"))
        for user in users.values():
            print(f"  {user.name:<24} {'enabled ' if user.enabled else 'DISABLED'}  since {user.created_utc}")
    else:
        user = operators.set_enabled(args.name, args.action == "enable")
        print(f"operator {user.name!r} {'enabled' if user.enabled else 'disabled'} in {path}")
    return 0
