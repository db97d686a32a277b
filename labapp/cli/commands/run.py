"""`sfr run`: a release run from the terminal, on the bench or simulated, with a live status line."""
from __future__ import annotations

import argparse
import dataclasses
import logging

from labapp.cli.argtypes import finite_float, nonnegative_float, positive_float

NAME = "run"
HELP = "acquire a release run (real bench or --simulate) with a live status line; --resume continues one"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr run`."""
    parser.add_argument("--camera", default="gphoto2", help="gphoto2 | gphoto2:MODEL@PORT | folder:PATH")
    parser.add_argument("--hotplate", help="hotplate serial port or URL (omit: no hotplate)")
    parser.add_argument("--out", default="runs", help="data directory; the run gets a new folder in it")
    parser.add_argument("--simulate", action="store_true",
                        help="simulated camera + Heidolph emulator + a dissolving sample object")
    parser.add_argument("--speed", type=nonnegative_float, default=100.0,
                        help="simulated time acceleration (default 100; 0 = as fast as frames render)")
    parser.add_argument("--sample", default="pill", help="shipped sample object of the simulated bench")
    parser.add_argument("--resume", metavar="RUN_FOLDER",
                        help="continue an interrupted run into its folder (its run.json says whether it was "
                             "simulated); a finished run or any other folder is refused untouched")
    parser.add_argument("--calibration", help="bench calibration JSON (live concentration, steady-state stop); "
                        "with --simulate and none given, a simulated calibration series runs first")
    parser.add_argument("--name", default="run", help="run name (part of the folder name)")
    parser.add_argument("--object", default="", help="object description")
    parser.add_argument("--object-mass", type=positive_float, help="object mass, g")
    parser.add_argument("--water-g", type=positive_float, default=500.0, help="water mass, g (default 500)")
    parser.add_argument("--interval", type=positive_float, default=11.0, help="frame interval, s (default 11)")
    parser.add_argument("--setpoint", type=finite_float, default=70.0, help="bath temperature, C (default 70)")
    parser.add_argument("--rpm", type=nonnegative_float, default=150.0, help="stirring speed, rpm (default 150)")
    parser.add_argument("--max-hours", type=positive_float, default=4.0, help="stop after this long, h (default 4)")
    parser.add_argument("--no-steady-stop", action="store_true", help="do not stop at steady state")
    parser.add_argument("--notes", default="", help="free text stored in run.json")
    parser.add_argument("--auto-drop", action="store_true", help="time zero as soon as the bath is stable and the "
                        "reference is taken (drop the object then); default with --simulate, else Enter confirms")


_quiet: list[bool] = []


def _write_line(text: str, end: str = "\n") -> None:
    """Write to stdout unless its reader has gone (``sfr run | head``): then stay quiet, the run goes on."""
    import sys

    if _quiet:
        return
    try:
        sys.stdout.write(text + end)
        sys.stdout.flush()
    except (BrokenPipeError, ValueError):
        from labapp.cli.main import _quiet_stdout

        _quiet.append(True)
        _quiet_stdout()


def _status_printer(status):
    import shutil

    def show() -> None:
        width = shutil.get_terminal_size((120, 20)).columns - 1
        _write_line("\r" + status.line(width).ljust(width), end="")
    return show


def run(args: argparse.Namespace) -> int:
    """Check everything, build the bench, walk the run procedure, print the status line until it ends."""
    import math
    from pathlib import Path

    from analysis import BenchCalibration
    from labapp.acquisition.clock import make_clock
    from labapp.acquisition.procedures import RunConfig
    from labapp.acquisition.status import RunStatus
    from labapp.errors import UsageError
    from labapp.jobs.run import new_run, resumable, resume_run
    from labapp.records.outpaths import check_data_dir

    if not args.verbose:
        logging.getLogger().setLevel(logging.WARNING)
    sample, simulate = args.sample, args.simulate
    if args.resume:
        stored = resumable(args.resume).meta          # refuses anything but an interrupted run, untouched
        if args.simulate and not stored.get("simulated"):
            raise UsageError(f"{args.resume} was recorded on the real bench; resume it without --simulate")
        simulate = bool(stored.get("simulated"))
        sample = stored.get("object_name") or sample
        config = None
    else:
        check_data_dir(args.out)
        config = RunConfig(name=args.name, interval_s=args.interval, setpoint_c=args.setpoint,
                           speed_rpm=args.rpm, max_duration_s=args.max_hours * 3600,
                           stop_on_steady=not args.no_steady_stop, water_g=args.water_g,
                           object_mass_g=args.object_mass, object_name=args.object, notes=args.notes,
                           auto_drop=simulate or args.auto_drop)
    speed = (math.inf if args.speed == 0 else args.speed) if simulate else None
    calibration = BenchCalibration.load(args.calibration) if args.calibration else None
    sim = None
    if args.resume:
        from labapp.acquisition.simbench import resume_clock
        clock = resume_clock(Path(args.resume), speed) if simulate else make_clock(None)
    else:
        clock = make_clock(speed)
    try:
        if simulate:
            from labapp.acquisition.simbench import SimulatedBench
            if calibration is None and not args.resume:
                from labapp.jobs.demo import simulated_calibration
                _write_line("no --calibration: running a simulated calibration series first ...")
                calibration, cal_path = simulated_calibration(Path(args.out))
                _write_line(f"calibration: {cal_path}")
            sim = SimulatedBench(clock, sample=sample)
            bench = sim.bench()
            if config is not None:
                config = dataclasses.replace(
                    config, object_mass_g=config.object_mass_g or sim.release.mass_g,
                    object_name=config.object_name or sim.release.name)
        else:
            from labapp.acquisition.devices import make_bench
            bench = make_bench(args.camera, args.hotplate)
        if args.resume:
            proc = resume_run(Path(args.resume), bench, calibration)
        else:
            proc = new_run(config, bench, Path(args.out), calibration)
        return _drive(proc, clock, bench, RunStatus())
    finally:
        if sim is not None:
            sim.close()


def _drive(proc, clock, bench, status) -> int:
    import signal

    from labapp.acquisition.engine import Engine
    from labapp.acquisition.events import Prompt

    engine = Engine(clock)
    engine.subscribe(status.update)
    engine.subscribe(lambda e: _write_line(f"\n>>> {e.text} (press Enter)")
                     if isinstance(e, Prompt) and not e.auto else None)
    show = _status_printer(status)
    interrupts = []

    def on_sigint(signum, frame) -> None:
        interrupts.append(signum)
        if len(interrupts) == 1:
            _write_line("\nstopping cleanly (heating off, run finalised); Ctrl-C again aborts")
            engine.stop()
        else:
            engine.abort()
    previous = signal.signal(signal.SIGINT, on_sigint)
    previous_term = signal.signal(signal.SIGTERM, on_sigint)   # a service manager's stop: the same clean stop
    try:
        engine.start(proc)
        _answer_prompts(engine, proc)
        while engine.join(0.25) is None:
            show()
        show()
    finally:
        signal.signal(signal.SIGINT, previous)
        signal.signal(signal.SIGTERM, previous_term)
    _write_line("")
    folder = proc.run.path if proc.run is not None else None
    if engine.outcome == "failed":
        from labapp.errors import JobFailed

        where = f" ({len(proc.run.frames)} frames kept in {folder})" if folder is not None else " (no run folder written)"
        raise JobFailed(f"run failed: {engine.error}{where}")
    _write_line(f"run {engine.outcome}: {len(proc.run.frames) if proc.run else 0} frames in {folder}")
    return 0 if engine.outcome in ("complete", "stopped") else 1


def _answer_prompts(engine, proc) -> None:
    """On a real bench the drop is confirmed with Enter (in a daemon thread, so Ctrl-C still works)."""
    import sys
    import threading

    if proc.config.auto_drop or not sys.stdin.isatty():
        return

    def wait_enter() -> None:
        sys.stdin.readline()
        engine.answer("drop", True)
    threading.Thread(target=wait_enter, daemon=True).start()
