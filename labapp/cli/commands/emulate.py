"""`sfr emulate heidolph`: a Heidolph MR Hei-Tec on a pseudo-terminal for any serial program."""
from __future__ import annotations

import argparse
import time

from labapp.cli import interrupt
from labapp.cli.argtypes import nonnegative_float, positive_float
from labapp.errors import EXIT_INTERRUPTED

NAME = "emulate"
HELP = "run a device emulator (prints its device path first; Ctrl-C or SIGTERM ends it and removes it)"
POLL_S = 0.1
"""How often the emulator's command looks for a stop request, s."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("device", choices=["heidolph"], help="device to emulate")
    parser.add_argument("--speed", type=positive_float, default=1.0, help="time acceleration of the thermal model")
    parser.add_argument("--watchdog-s", type=positive_float, default=10.0, help="silence before 'PC Err', s")
    parser.add_argument("--no-probe", action="store_true", help="no external probe (reports 999.9)")
    parser.add_argument("--seed", type=int, default=None, help="seed of the read-out noise")
    parser.add_argument("--status-every-s", type=nonnegative_float, default=0.0,
                        help="print the plate state every this many seconds (0: never)")


def run(args: argparse.Namespace) -> int:
    """Start the emulator, print its device path, run until Ctrl-C or SIGTERM (exit code 130), then clean up."""
    from drivers.sim.heidolph_emulator import HeidolphEmulator

    emulator = HeidolphEmulator(speed=args.speed, watchdog_s=args.watchdog_s, probe_connected=not args.no_probe,
                                seed=args.seed)
    interrupt.set_hint("the emulator stopped and removed its device")
    # a stop request may come as soon as the path is out; a second one does not cut the clean-up short
    with interrupt.handling("stopping the emulator", on_second=lambda: None):
        try:
            print(emulator.start(), flush=True)
            next_status = time.monotonic() + args.status_every_s
            while not interrupt.requested():
                time.sleep(POLL_S)
                if args.status_every_s and time.monotonic() >= next_status:
                    next_status += args.status_every_s
                    s = emulator.state
                    print(f"t={s.sim_time_s:.0f}s set={s.setpoint_c:.1f}C/{s.setpoint_rpm:.0f}rpm "
                          f"heat={int(s.heating)} stir={int(s.stirring)} plate={s.plate_c:.1f}C "
                          f"water={s.water_c:.1f}C speed={s.speed_rpm:.0f}rpm pc_err={int(s.pc_err)}", flush=True)
        finally:
            emulator.stop()
    return EXIT_INTERRUPTED
