"""`sfr change`: change a setting of a run while it records (from another terminal), with a reason."""
from __future__ import annotations

import argparse

from labapp.acquisition.settings import CHANGEABLE_DURING_RUN

NAME = "change"
HELP = "change a setting of a run while it records (maximum or minimum duration), with a reason for the audit trail"
RECORDS = True
"""Acts as a named operator (``--operator``, ``$SFR_OPERATOR``): see :mod:`labapp.cli.operator`."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr change`: the run folder, one or more settings, the reason."""
    from labapp.cli.argtypes import setting_type

    parser.add_argument("run", help="the run folder being recorded (by `sfr run` or `sfr lab`)")
    for setting in CHANGEABLE_DURING_RUN:
        parser.add_argument(setting.flag, dest=setting.name, type=setting_type(setting), default=None,
                            metavar=setting.display_unit.upper(),
                            help=f"new {setting.label}, {setting.display_unit} ({setting.range_text(shown=True)})")
    parser.add_argument("--reason", required=True, help="why (recorded in the run's audit trail)")


def run(args: argparse.Namespace) -> int:
    """Ask the recording process to make each change at its next frame; print what changed."""
    from labapp.cli import interrupt
    from labapp.errors import UsageError
    from labapp.jobs.run import change_setting

    changes = [(s, getattr(args, s.name)) for s in CHANGEABLE_DURING_RUN if getattr(args, s.name) is not None]
    if not changes:
        raise UsageError("nothing to change: give " + " or ".join(s.flag for s in CHANGEABLE_DURING_RUN))
    for setting, value in changes:
        print(f"waiting for {args.run}'s next frame to change {setting.label} ...", flush=True)
        print(f"changed {change_setting(args.run, setting.name, value, args.reason, interrupt.requested)}")
    return 0
