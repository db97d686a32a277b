"""`sfr emulate heidolph`: a Heidolph MR Hei-Tec on a pseudo-terminal for any serial program."""
from __future__ import annotations

import argparse
import time

from labapp.cli.argtypes import nonnegative_float, positive_float

NAME = "emulate"
HELP = "run a device emulator (prints its device path first; Ctrl-C or SIGTERM ends it and removes it)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("device", choices=["heidolph"], help="device to emulate")
    parser.add_argument("--speed", type=positive_float, default=1.0, help="time acceleration of the thermal model")
    parser.add_argument("--watchdog-s", type=positive_float, default=10.0, help="silence before 'PC Err', s")
    parser.add_argument("--no-probe", action="store_true", help="no external probe (reports 999.9)")
    parser.add_argument("--seed", type=int, default=None, help="seed of the read-out noise")
    parser.add_argument("--status-every-s", type=nonnegative_float, default=0.0,
                        help="print the plate state every this many seconds (0: never)")


def _interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def run(args: argparse.Namespace) -> int:
    """Start the emulator, print its device path, run until Ctrl-C or SIGTERM, then clean up."""
    import signal

    from drivers.sim.heidolph_emulator import HeidolphEmulator

    signal.signal(signal.SIGTERM, _interrupt)      # a service manager's stop cleans up like Ctrl-C

    emulator = HeidolphEmulator(speed=args.speed, watchdog_s=args.watchdog_s, probe_connected=not args.no_probe,
                                seed=args.seed)
    try:  # a stop request may come as soon as the path is out, before the loop is reached
        print(emulator.start(), flush=True)
        while True:
            time.sleep(args.status_every_s or 3600.0)
            if args.status_every_s:
                s = emulator.state
                print(f"t={s.sim_time_s:.0f}s set={s.setpoint_c:.1f}C/{s.setpoint_rpm:.0f}rpm "
                      f"heat={int(s.heating)} stir={int(s.stirring)} plate={s.plate_c:.1f}C "
                      f"water={s.water_c:.1f}C speed={s.speed_rpm:.0f}rpm pc_err={int(s.pc_err)}", flush=True)
    except KeyboardInterrupt:
        return 0
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a second stop request does not cut the clean-up short
        emulator.stop()
