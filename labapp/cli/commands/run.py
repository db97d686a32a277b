"""`sfr run`: a release run from the terminal, on the bench or simulated, with a live status line."""
from __future__ import annotations

import argparse
import dataclasses
import logging

from labapp.acquisition.devices import CAMERA_SPECS
from labapp.acquisition.settings import BATH_SETTINGS, INTERVAL, MAX_DURATION, MIN_DURATION, OBJECT_MASS, SIM_SPEED
from labapp.cli import interrupt
from labapp.cli.argtypes import add_setting, add_settings, setting_values
from labapp.errors import EXIT_INTERRUPTED

NAME = "run"
HELP = "acquire a release run (real bench or --simulate) with a live status line; --resume continues one"
RECORDS = True
"""Acts as a named operator (``--operator``, ``$SFR_OPERATOR``): see :mod:`labapp.cli.operator`."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr run`: the bench, the run's settings and the bath's (from their declarations)."""
    parser.add_argument("--camera", default="gphoto2", help=CAMERA_SPECS)
    parser.add_argument("--hotplate", help="hotplate serial port or URL (omit: no hotplate)")
    parser.add_argument("--out", default="runs", help="data directory; the run gets a new folder in it")
    parser.add_argument("--simulate", action="store_true",
                        help="simulated camera + Heidolph emulator + a dissolving sample object")
    add_setting(parser, SIM_SPEED)
    parser.add_argument("--sample", default="pill", help="shipped sample object of the simulated bench")
    parser.add_argument("--resume", metavar="RUN_FOLDER",
                        help="continue an interrupted run into its folder (its run.json says whether it was "
                             "simulated); a finished run or any other folder is refused untouched")
    parser.add_argument("--calibration", help="bench calibration JSON (live concentration, steady-state stop); "
                        "with --simulate and none given, a simulated calibration series runs first")
    parser.add_argument("--method", metavar="METHOD.json", help="method file (sfr method save): its bath, interval, "
                        "stop rule and calibration are the run's (an option contradicting it is refused); run.json "
                        "records its path and SHA-256")
    parser.add_argument("--name", default="run", help="run name (part of the folder name)")
    parser.add_argument("--object", default="", help="object description")
    for setting in (OBJECT_MASS, INTERVAL, MAX_DURATION, MIN_DURATION):
        add_setting(parser, setting)
    parser.add_argument("--no-steady-stop", action="store_true", help="do not stop at steady state")
    parser.add_argument("--notes", default="", help="free text stored in run.json")
    parser.add_argument("--auto-drop", action="store_true", help="time zero as soon as the bath is stable and the "
                        "reference is taken (drop the object then); default with --simulate, else Enter confirms")
    add_settings(parser, BATH_SETTINGS, "bath")


def run(args: argparse.Namespace) -> int:
    """Check everything, build the bench, walk the run procedure, print the status line until it ends; a resumed
    run's folder is locked while it is written (a second resume is refused)."""
    from pathlib import Path

    from labapp.records.lock import folder_lock

    if not (args.resume and Path(args.resume).is_dir()):
        return _run(args)
    with folder_lock(args.resume):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    import math
    from pathlib import Path

    from analysis import BenchCalibration
    from labapp.acquisition.clock import make_clock
    from labapp.acquisition.procedures import RunConfig
    from labapp.acquisition.settings import BathSettings
    from labapp.acquisition.status import RunStatus
    from labapp.cli.drive import write_line
    from labapp.errors import UsageError
    from labapp.jobs.run import check_run_data_dir, new_run, resumable, resume_run

    if not args.verbose:
        logging.getLogger().setLevel(logging.WARNING)
    sample, simulate = args.sample, args.simulate
    if args.resume:
        stored = resumable(args.resume).record        # refuses anything but an interrupted run, untouched
        if args.simulate and not stored.simulated:
            raise UsageError(f"{args.resume} was recorded on the real bench; resume it without --simulate")
        simulate = stored.simulated
        sample = stored.object_name or sample
        config = None
    else:
        check_run_data_dir(args.out)       # before the simulated calibration and the bench: nothing heats in vain
        config = RunConfig(name=args.name, interval_s=args.interval_s, max_duration_s=args.max_duration_s,
                           stop_on_steady=not args.no_steady_stop, min_duration_s=args.min_duration_s,
                           object_mass_g=args.object_mass_g,
                           object_name=args.object, notes=args.notes, auto_drop=simulate or args.auto_drop,
                           bath=BathSettings(**setting_values(args, BATH_SETTINGS)))
    method = None
    if args.method and not args.resume:
        from labapp.acquisition.methods import load_method

        method = load_method(args.method)
        config = method.apply(config)
        args.calibration = method.check_calibration(args.calibration)
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
                write_line("no --calibration: running a simulated calibration series first ...")
                calibration, cal_path = simulated_calibration(Path(args.out))
                write_line(f"calibration: {cal_path}")
            water_g = config.bath.water_g if config is not None else stored.water_g
            sim = SimulatedBench(clock, sample=sample, water_g=water_g)
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
            proc = new_run(config, bench, Path(args.out), calibration, method=method)
        return _drive(proc, clock, RunStatus())
    finally:
        if sim is not None:
            sim.close()


def _drive(proc, clock, status) -> int:
    from labapp.acquisition.engine import Engine
    from labapp.acquisition.events import Outcome, Prompt
    from labapp.cli.drive import drive, write_line

    engine = Engine(clock)
    engine.subscribe(status.update)
    engine.subscribe(lambda e: write_line(f"\n>>> {e.text} (press Enter)")
                     if isinstance(e, Prompt) and not e.auto else None)
    outcome = drive(engine, proc, status, started=lambda: _answer_prompts(engine, proc))
    folder = proc.run.path if proc.run is not None else None
    if outcome == Outcome.FAILED:
        from labapp.errors import JobFailed

        where = f" ({len(proc.run.frames)} frames kept in {folder})" if folder is not None else " (no run folder written)"
        raise JobFailed(f"run failed: {engine.error}{where}")
    write_line(f"run {outcome}: {len(proc.run.frames) if proc.run else 0} frames in {folder}")
    interrupt.set_hint(f"the run stopped cleanly with {len(proc.run.frames) if proc.run else 0} frames in {folder}")
    if interrupt.requested() and outcome == Outcome.STOPPED:
        return EXIT_INTERRUPTED
    return 0 if outcome in (Outcome.COMPLETE, Outcome.STOPPED) else 1


def _answer_prompts(engine, proc) -> None:
    """On a real bench the drop is confirmed with Enter (in a daemon thread, so Ctrl-C still works)."""
    import sys
    import threading

    from labapp.acquisition.events import PromptKind

    if proc.config.auto_drop or not sys.stdin.isatty():
        return

    def wait_enter() -> None:
        sys.stdin.readline()
        engine.answer(PromptKind.DROP, True)
    threading.Thread(target=wait_enter, daemon=True).start()
