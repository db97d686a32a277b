"""`sfr lab`: the bench GUI (PySide6 + pyqtgraph).

Ctrl-C in its terminal (SIGINT) and SIGTERM close the window as closing it mid-run does, without asking: a
run is interrupted (heating and stirring off, the folder left resumable); the exit status is then 130
(SIGINT) or 143 (SIGTERM); see :class:`labapp.gui.app.SignalStop`. At the login dialog they close it and nothing
starts (the same exit statuses; :func:`labapp.gui.login.ask_operator`).
"""
from __future__ import annotations

import argparse

from labapp.acquisition.settings import SIM_SPEED
from labapp.cli.argtypes import add_setting, positive_float

NAME = "lab"
HELP = ("start the bench GUI; --simulate runs it on the simulated camera, hotplate emulator and sample object; "
        "Ctrl-C or SIGTERM interrupt a run resumably (heating off) and exit with 130 or 143")
RECORDS = "optional"
"""Acts as ``--operator`` or ``$SFR_OPERATOR`` when given; else the GUI asks for the operator and their password
(:mod:`labapp.gui.login`)."""
SIGNALS = False
"""The GUI handles Ctrl-C and SIGTERM itself (labapp.gui.app): closing the window as an operator would."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr lab`."""
    parser.add_argument("--data", default="runs", help="data directory for runs and calibrations (default ./runs)")
    parser.add_argument("--simulate", action="store_true", help="offer the simulated bench")
    add_setting(parser, SIM_SPEED)
    parser.add_argument("--sample", default="pill", help="sample object of the simulated bench (default pill)")
    parser.add_argument("--calibration", help="bench calibration JSON to make active")
    parser.add_argument("--autostart", action="store_true", help="start a run at once (simulated: the object drops "
                        "by itself; with no --calibration a simulated calibration series runs first)")
    parser.add_argument("--screenshot", metavar="PNG", help="save a screenshot of the window after --quit-after")
    parser.add_argument("--quit-after", type=positive_float, metavar="S",
                        help="close after S seconds (scripted sessions, e.g. with QT_QPA_PLATFORM=offscreen)")


NO_DISPLAY = ("no display to open the window on (DISPLAY and WAYLAND_DISPLAY are unset): log in to the "
              "bench's desktop, use `ssh -X`, or run headless with QT_QPA_PLATFORM=offscreen (e.g. "
              "`QT_QPA_PLATFORM=offscreen sfr lab --simulate --autostart --quit-after 60 --screenshot lab.png`); "
              "to acquire from a terminal use `sfr run`")


def _check_display() -> None:
    """Refuse, with what to do instead, to start a window where there is no display."""
    import os
    import sys

    from labapp.errors import UsageError

    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
                                                 or os.environ.get("QT_QPA_PLATFORM")):
        raise UsageError(NO_DISPLAY)


def run(args: argparse.Namespace) -> int:
    """Start the GUI; returns when the window closes."""
    import math
    from pathlib import Path

    from labapp.records.outpaths import check_data_dir

    _check_display()
    check_data_dir(args.data, "--data")
    from labapp.gui.app import launch

    speed = (math.inf if args.speed == 0 else args.speed) if args.simulate else None
    calibration = args.calibration
    if args.autostart and args.simulate and not calibration:
        from labapp.jobs.demo import simulated_calibration
        print("running a simulated calibration series first ...", flush=True)
        calibration = str(simulated_calibration(Path(args.data))[1])
    code = launch(Path(args.data), args.simulate, speed, args.sample, calibration, args.autostart,
                  args.quit_after, args.screenshot)
    if args.screenshot:
        print(f"screenshot: {args.screenshot}")
    return code
