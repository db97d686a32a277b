"""`sfr method`: save a method file (from a run's settings or from options) and show one."""
from __future__ import annotations

import argparse

from labapp.cli.argtypes import add_setting, finite_float

NAME = "method"
HELP = "save a method (bath, interval, stop rule, calibration, acceptance criteria) from a run or options; show one"
RECORDS = "optional"
"""``save`` records who made the method (``--operator``, ``$SFR_OPERATOR``); ``show`` needs no operator."""


def _released(text: str) -> tuple[float, float | None, float | None]:
    """``H:LOW:HIGH`` (either bound may be empty) -> (hours, low %, high %)."""
    parts = text.split(":")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"{text!r}: expected HOURS:LOW:HIGH in % (e.g. 1:20:40, 4:80:)")
    hours = finite_float(parts[0])
    low = finite_float(parts[1]) if parts[1] else None
    high = finite_float(parts[2]) if parts[2] else None
    if hours <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: HOURS = {hours:g}; expected a time after the drop, > 0 h")
    if low is not None and high is not None and low > high:
        raise argparse.ArgumentTypeError(f"{text!r}: LOW {low:g} % is above HIGH {high:g} %; expected HOURS:LOW:HIGH "
                                         f"with LOW <= HIGH (e.g. {parts[0]}:{parts[2]}:{parts[1]})")
    return hours, low, high


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr method save` and `sfr method show`."""
    from labapp.acquisition.methods import METHOD_SETTINGS

    sub = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    save = sub.add_parser("save", help="write a new method file")
    save.add_argument("file", help="the method file to write (NAME.json; never overwritten)")
    save.add_argument("--from", dest="from_run", metavar="RUN", help="take the settings a run was recorded with "
                      "(and its calibration copy, unless --calibration)")
    save.add_argument("--name", help="the method's name (default: the file's name)")
    save.add_argument("--calibration", help="bench calibration JSON the method requires (its SHA-256 is recorded)")
    save.add_argument("--no-steady-stop", action="store_true", help="runs of the method do not stop at steady state")
    save.add_argument("--accept-released", action="append", type=_released, default=[], metavar="H:LOW:HIGH",
                      help="acceptance: released at H hours between LOW and HIGH %% of the weighed mass (repeatable)")
    save.add_argument("--accept-f2", type=finite_float, metavar="MIN", help="acceptance: f2 against the reference "
                      "at least MIN")
    group = save.add_argument_group("settings (without --from)")
    for setting in METHOD_SETTINGS:
        if setting.flag:
            add_setting(group, setting)
    show = sub.add_parser("show", help="print a method file's settings, calibration and criteria")
    show.add_argument("file")


def run(args: argparse.Namespace) -> int:
    """Save or show; one line per setting and criterion."""
    from pathlib import Path

    from labapp.acquisition.methods import (
        METHOD_SETTINGS,
        Criterion,
        load_method,
        make_method,
        method_from_run,
        save_method,
    )

    if args.action == "show":
        method = load_method(args.file)
    else:
        name = args.name or Path(args.file).stem
        criteria = tuple(Criterion("released_percent", low, high, hours) for hours, low, high in args.accept_released)
        criteria += (Criterion("f2", args.accept_f2),) if args.accept_f2 is not None else ()
        if args.from_run:
            method = method_from_run(args.from_run, name, args.calibration, criteria)
        else:
            values = {s.name: getattr(args, s.name, s.default) for s in METHOD_SETTINGS}
            method = make_method(name, values, not args.no_steady_stop, args.calibration, criteria)
        path = save_method(method, args.file)
        method = load_method(path)
        print(f"method saved: {path} (SHA-256 {method.sha256})")
    print(f"method {method.name!r} by {method.created_by} at {method.created_utc}")
    for setting in METHOD_SETTINGS:
        value = method.settings[setting.name]
        shown = "none" if value is None else f"{setting.shown(value):g} {setting.display_unit}"
        print(f"  {setting.label:<36} {shown}")
    print(f"  {'stop at steady state':<36} {'yes' if method.stop_on_steady else 'no'}")
    print(f"  {'calibration':<36} {method.calibration_file or 'any'}")
    for criterion in method.acceptance:
        print(f"  acceptance: {criterion.text()}")
    return 0
