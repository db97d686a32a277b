"""`sfr calibrate-bench`: fit the per-cell Beer-Lambert calibration from a series of known concentrations, or
record that series on the bench first (``--record``)."""
from __future__ import annotations

import argparse
import dataclasses

from labapp.acquisition.devices import CAMERA_SPECS
from labapp.acquisition.settings import (
    BATH_SETTINGS,
    GRID,
    MIRROR_COL,
    REDUCE,
    SERIES_REDUCE,
    SETTLE,
    SIM_SPEED,
    WATER,
    parse_masses,
)
from labapp.cli.argtypes import add_setting, add_settings
from labapp.errors import EXIT_INTERRUPTED

NAME = "calibrate-bench"
HELP = ("fit the bench calibration (transmittance vs concentration per cell) from a masses.csv image series; "
        "--record captures the series on the bench first")
RECORDS = True
"""Acts as a named operator (``--operator``, ``$SFR_OPERATOR``): see :mod:`labapp.cli.operator`."""
_REDUCE = dataclasses.replace(REDUCE, default=None, note=f"default {REDUCE.default} for a fit of FOLDER, "
                                                         f"{SERIES_REDUCE.default} with --record")
_SETTLE = dataclasses.replace(SETTLE, default=None, note=f"default {SETTLE.default:g} s with --simulate, 0 s on a "
                                                         "real bench (enter each mass once the piece has dissolved)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr calibrate-bench`: the fit's, then recording (bench, masses, bath)."""
    parser.add_argument("folder", nargs="?",
                        help="folder with the images and masses.csv (file,added_mass_g cumulative, g); "
                             "omitted with --record")
    add_setting(parser, WATER)
    parser.add_argument("--crop", type=_parse_crop,
                        help="x,y,size of the square crop inside the beaker, px (default: the series' run.json "
                             "crop, else centred at W/4, H/2, side min(W,H)/4; --record: the simulated scene's, "
                             "needed on a real bench)")
    for setting in (GRID, MIRROR_COL, _REDUCE):
        add_setting(parser, setting)
    parser.add_argument("--no-mirror", action="store_true",
                        help="skip the mirror normalisation (for comparison only; not with --record)")
    parser.add_argument("--camera", default="",
                        help="camera settings, e.g. 'aperture=22,shutter=1/125,iso=160': recorded with the fit; "
                             "with --record applied to the camera (default: f/22, 1/125 s, ISO 160, JPEG Fine)")
    parser.add_argument("--out", help="output JSON, a new file outside the series folder (default calibration.json); "
                                      "with --record the fit is bench_calibration.json in the new series folder")
    record = parser.add_argument_group("recording a series on the bench")
    record.add_argument("--record", metavar="DATA_DIR",
                        help="capture a calibration series into a new folder in DATA_DIR (clear water, then one frame "
                             "per cumulative mass) and fit it, as the GUI's calibration wizard does")
    record.add_argument("--camera-spec", default="gphoto2", help=f"camera to capture with: {CAMERA_SPECS}")
    record.add_argument("--hotplate", help="hotplate serial port or URL (omit: no hotplate)")
    record.add_argument("--simulate", action="store_true",
                        help="the simulated bench: simulated camera + Heidolph emulator, filament added by itself")
    add_setting(record, SIM_SPEED)
    record.add_argument("--masses", type=_parse_masses, default=(),
                        help="cumulative masses the simulated bench adds by itself, g, e.g. 0.25,0.5,1,1.5,2 "
                             "(omit: enter each mass at the prompt)")
    add_setting(record, _SETTLE)
    record.add_argument("--name", default="calibration", help="series name (part of the folder name)")
    add_settings(parser, BATH_SETTINGS, "bath (with --record)", skip=(WATER,))


def _parse_crop(text: str) -> tuple[int, int, int]:
    try:
        x, y, size = (int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected three integers x,y,size (px)") from None
    if min(x, y) < 0 or size < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected x, y >= 0 and size >= 1 (px)")
    return x, y, size


def _parse_masses(text: str) -> tuple[float, ...]:
    from labapp.errors import UsageError

    try:
        return parse_masses(text)
    except UsageError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _camera_pairs(text: str) -> dict[str, str]:
    return dict(item.split("=", 1) for item in text.split(",") if "=" in item)


def run(args: argparse.Namespace) -> int:
    """Fit a series folder, or record a series and fit it; print a per-level and per-cell summary."""
    from labapp.errors import UsageError

    if args.record:
        return _record(args)
    if args.folder is None:
        raise UsageError("give the calibration-series FOLDER to fit, or --record DATA_DIR to capture a series")
    import sys

    from labapp.cli import interrupt
    from labapp.jobs.calibrate_bench import calibrate_series

    out = args.out or "calibration.json"
    interrupt.set_hint(f"nothing written ({out} not made); rerun the same command to fit the series")
    cal = calibrate_series(args.folder, out, water_g=args.water_g, crop=args.crop, grid=args.grid,
                           mirror_col=args.mirror_col, mirror=not args.no_mirror,
                           reduce=REDUCE.default if args.reduce is None else args.reduce,
                           camera=_camera_pairs(args.camera), progress=lambda done, total: interrupt.check(),
                           on_warning=lambda message: print(f"warning: {message}", file=sys.stderr, flush=True))
    _summary(cal, mirror=not args.no_mirror)
    print(f"wrote {out}")
    return 0


def _summary(cal, mirror: bool) -> None:
    import numpy as np

    geometry, levels = cal.geometry, np.unique(cal.conc_levels_g_per_kg)
    g = geometry.grid
    print(f"crop x={geometry.x} y={geometry.y} size={geometry.size} px, {g}x{g} cells, "
          f"mirror {'on' if mirror else 'off'}; {len(cal.conc_levels_g_per_kg)} frames, {levels.size} levels "
          f"{', '.join(f'{c:.3f}' for c in levels)} g/kg")
    print(f"k per g/kg: median {np.median(cal.k):.4f}, range {cal.k.min():.4f}..{cal.k.max():.4f}; "
          f"t0 median {np.median(cal.t0):.4f}")
    print(f"fit residual (relative rms): median {np.median(cal.rms_rel):.2e}, worst {cal.rms_rel.max():.2e}")
    bad = [divmod(int(i), g) for i in np.flatnonzero(~cal.good)]
    print(f"cells not used: {bad if bad else 'none'}")


def _camera_settings(text: str):
    """``aperture=22,shutter=1/125,iso=160,format=JPEG Fine`` as camera settings (the others: the defaults)."""
    from drivers.camera.base import CameraSettings
    from labapp.errors import UsageError

    keys = {"aperture": "aperture", "shutter": "shutter_speed", "shutter_speed": "shutter_speed", "iso": "iso",
            "format": "image_format", "image_format": "image_format"}
    pairs = _camera_pairs(text)
    unknown = sorted(set(pairs) - set(keys))
    if unknown:
        raise UsageError(f"--camera: unknown setting(s) {', '.join(unknown)}; expected aperture, shutter, iso, format")
    return CameraSettings(**{keys[k]: v.strip() or None for k, v in pairs.items()})


def _record(args: argparse.Namespace) -> int:
    """Capture a series on the bench (real or simulated) with the engine, fit it, print the summary."""
    import logging
    import math

    from analysis import BenchCalibration
    from labapp.acquisition.calseries import MIN_LEVELS
    from labapp.acquisition.clock import make_clock
    from labapp.acquisition.engine import Engine
    from labapp.acquisition.events import Outcome
    from labapp.acquisition.settings import BathSettings
    from labapp.acquisition.status import RunStatus
    from labapp.cli.argtypes import setting_values
    from labapp.cli.drive import drive, write_line
    from labapp.errors import JobFailed, UsageError
    from labapp.jobs.series import new_series, simulated_series_bench
    from labapp.records.outpaths import check_data_dir

    for given, what in ((args.folder, "a FOLDER to fit"), (args.out, "--out"), (args.no_mirror, "--no-mirror")):
        if given:
            raise UsageError(f"--record captures a new series and saves its fit in the series folder; "
                             f"{what} does not go with it")
    check_data_dir(args.record, "--record")
    if not args.verbose:
        logging.getLogger().setLevel(logging.WARNING)
    speed = (math.inf if args.speed == 0 else args.speed) if args.simulate else None
    clock = make_clock(speed)
    bath = BathSettings(**setting_values(args, BATH_SETTINGS))
    sim = None
    try:
        if args.simulate:
            sim = simulated_series_bench(clock, bath.water_g)
            bench, crop = sim.bench(), args.crop or sim.scene.default_crop()
        else:
            if args.crop is None:
                raise UsageError("--record on a real bench needs --crop x,y,size (px): the square inside the beaker "
                                 "(find it with `sfr lab`'s live view or from a test frame)")
            from labapp.acquisition.devices import make_bench

            bench, crop = make_bench(args.camera_spec, args.hotplate, _camera_settings(args.camera)), args.crop
        proc = new_series(bench, args.record, crop, bath=bath, masses_g=args.masses, settle_s=args.settle_s,
                          name=args.name, grid=args.grid, mirror_col=args.mirror_col,
                          reduce=SERIES_REDUCE.default if args.reduce is None else args.reduce,
                          clock_speed=clock.speed)
        engine = Engine(clock)
        status = RunStatus()
        engine.subscribe(status.update)
        engine.subscribe(_level_printer(write_line))
        engine.subscribe(_mass_prompter(engine, write_line))
        outcome = drive(engine, proc, status)
    finally:
        if sim is not None:
            sim.close()
    folder = proc.run.path if proc.run is not None else None
    if outcome == Outcome.FAILED:
        raise JobFailed(f"calibration series failed: {engine.error}"
                        + (f" ({len(proc.masses)} levels kept in {folder})" if folder else " (no folder written)"))
    if proc.calibration_path is None:
        raise JobFailed(f"calibration series {outcome} with {len(proc.masses)} level(s) in {folder}: no calibration "
                        f"({MIN_LEVELS} levels are needed to fit); see its events.log")
    _summary(BenchCalibration.load(proc.calibration_path), mirror=True)
    write_line(f"series {outcome}: {len(proc.masses)} levels in {folder}; calibration {proc.calibration_path}")
    from labapp.cli import interrupt

    interrupt.set_hint(f"the series stopped cleanly with {len(proc.masses)} levels in {folder}, fitted into "
                       f"{proc.calibration_path}")
    return EXIT_INTERRUPTED if interrupt.requested() and outcome == Outcome.STOPPED else 0


def _level_printer(write_line):
    import sys

    from labapp.acquisition.events import CalibrationLevel

    start = "\r" if sys.stdout.isatty() else ""     # over the status line on a terminal only

    def on_event(event) -> None:
        if isinstance(event, CalibrationLevel):
            write_line(f"{start}level {event.index}: {event.file}, {event.added_mass_g:g} g added, "
                       f"{event.conc_g_per_kg:.4f} g/kg")
    return on_event


def _mass_prompter(engine, write_line):
    """On each mass prompt, read the cumulative mass (g) from stdin in a daemon thread (Ctrl-C still works); an
    empty line or the end of the input finishes the series."""
    import math
    import sys
    import threading

    from labapp.acquisition.events import Prompt, PromptKind
    from labapp.acquisition.settings import ADDED_MASS

    def read_mass() -> None:
        while True:
            line = sys.stdin.readline()
            text = line.strip()
            if not text:
                engine.answer(PromptKind.ADDED_MASS, "")
                return
            try:
                mass = float(text)
            except ValueError:
                mass = math.nan
            if ADDED_MASS.allows(mass):
                engine.answer(PromptKind.ADDED_MASS, mass)
                return
            write_line(f"{text!r}: expected the cumulative mass in g, {ADDED_MASS.range_text()} (empty: finish)")

    def on_event(event) -> None:
        if isinstance(event, Prompt) and event.prompt == PromptKind.ADDED_MASS and not event.auto:
            write_line(f"\n>>> {event.text}")
            threading.Thread(target=read_mass, daemon=True).start()
    return on_event
