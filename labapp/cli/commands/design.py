"""`sfr design`: inverse design of a shape whose simulated release matches a target curve."""
from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from labapp.cli import interrupt
from labapp.cli.argtypes import add_design_option
from labapp.cli.eta import eta_text
from labapp.errors import EXIT_FAILED, UsageError
from labapp.jobs.meshunits import MM_PER_UNIT

log = logging.getLogger(__name__)

NAME = "design"
HELP = "design a printable shape whose release matches a target curve (mesh, CSV or analytic)"
RECORDS = True
"""Acts as a named operator (``--operator``, ``$SFR_OPERATOR``): see :mod:`labapp.cli.operator`."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from design.inverse.settings import OPTIONS, RESOLUTION

    parser.add_argument("--target", help="sample shape name, mesh file (.stl/.obj/.ply/.off/.3mf), "
                        "tau_mm,released_mm3 CSV, zero-order[:final=F,duration=D] / accel:q=Q[,final=F,duration=D], or a "
                        "measured curve in grams over seconds (a run folder, curve.csv or any t_s,released_g CSV; "
                        "needs --simcal)")
    for setting in OPTIONS:
        add_design_option(parser, setting)
        if setting is RESOLUTION:   # a mesh target's units, beside the resolution
            parser.add_argument("--units", choices=tuple(MM_PER_UNIT), help="units of a mesh target's coordinates "
                                "(default mm); copied into the run scaled to mm")
    parser.add_argument("--resume", action="store_true", help="continue the stopped run in --out with everything it "
                        "started with: the copy of its target (a warning if the original has changed since), its "
                        "calibration and settings (options given must match them; --max-iter may raise the limit); "
                        "a finished run is left as it is")
    parser.add_argument("--simcal", metavar="SIMCAL.json",
                        help="simulation calibration (sfr calibrate-sim): maps a measured target to simulation "
                             "units and adds the design's predicted release in grams over seconds "
                             "(curves_physical.csv, rel_rmse_physical, report.png in g over h)")
    parser.add_argument("--calibration", metavar="BENCH_CAL.json",
                        help="bench calibration for a run-folder target (default: the run's own)")
    parser.add_argument("--out", required=True, help="run folder")
    from labapp.cli.commands._design_barrier import add_barrier_design_arguments
    add_barrier_design_arguments(parser)


def _progress(max_iter: int):
    """Live progress on stderr: one rewritten line on a terminal, otherwise a line every 10 evaluations
    and at the last."""
    tty = sys.stderr.isatty()

    def show(k: int, x, terms: dict) -> None:
        interrupt.check()   # a safe point after an evaluation: Ctrl-C stops the run here (checkpoint, outputs)
        limit = terms.get("limit", max_iter)  # the evaluations of the run the phase is part of
        if not tty and k % 10 and k < limit:
            return
        phase = f"{terms['phase']}: " if "phase" in terms else ""
        line = (f"{phase}it {k:4d}/{limit}  J {terms['J']:.5g}  fit {terms['J_fit']:.4g}"
                f"  binary {terms['J_binary']:.4g}"
                f"  |g| {terms['grad_norm']:.3g}  {terms['seconds']:.0f}s  {eta_text(terms.get('eta_s'))}")
        print(("\r" + line + "   ") if tty else line, end="" if tty else "\n", file=sys.stderr, flush=True)
    return show


def _stored_max_iter(out: str) -> int:
    from design.errors import DesignError
    from design.files.records import load_config

    try:
        return load_config(Path(out)).max_iter
    except DesignError:
        return 0  # run_design reports the missing or broken run folder


def run(args: argparse.Namespace) -> int:
    # the design and analysis packages load here, not with the module: `sfr --help` stays instant
    from analysis import BenchCalibration
    from design.files.summary_text import summary_lines
    from design.inverse.config import DesignConfig
    from design.inverse.status import DesignStatus
    from labapp.cli.commands._design_barrier import run_barrier_design, wants_barrier_design
    from labapp.jobs.design import design as design_job
    from labapp.jobs.design import failed_design
    from labapp.jobs.physical import TARGET_CSV, adjustment_line, read_measured_target
    from labapp.records.lock import folder_lock
    from labapp.records.simcal import SimCalError, load_simcal

    if wants_barrier_design(args):     # two materials: labapp.cli.commands._design_barrier
        return run_barrier_design(args, _given_options(args))
    try:
        options = _given_options(args)
        if args.resume:
            config = None
        else:
            if not args.target:
                raise UsageError("--target is required (unless --resume)")
            # options left out take DesignConfig's defaults, the ones the GUI starts from too
            config = DesignConfig(**options)
        max_iter = config.max_iter if config else max(args.max_iter or 0, _stored_max_iter(args.out))
        if args.calibration and args.resume:
            raise UsageError(f"--calibration is used when a run starts, to convert a measured target (kept in "
                             f"{args.out}); drop it to resume")
        simcal = load_simcal(args.simcal) if args.simcal else None
        bench = BenchCalibration.load(args.calibration) if args.calibration else None
        interrupt.set_hint(f"the best design so far is saved in {args.out}; resume with: sfr design --resume "
                           f"--out {args.out}")
        with folder_lock(args.out):
            result, physical = design_job(config, args.out, resume=args.resume, units=args.units, simcal=simcal,
                                           bench_calibration=bench, on_iteration=_progress(max_iter),
                                           on_warning=lambda message: print(f"\nwarning: {message}", file=sys.stderr),
                                           options=options if args.resume else None)
    finally:
        print(file=sys.stderr)          # ends the progress line, also before an error's line
    s = physical or result.outputs.summary
    if result.unchanged:
        print(f"already finished: nothing to do ({result.out_dir} is left as it is)")
    try:
        measured = read_measured_target(Path(result.out_dir) / TARGET_CSV)
    except SimCalError as exc:
        print(f"warning: {exc}", file=sys.stderr)
    else:
        if measured is not None:       # a measured target: what making it feasible changed, as the launcher says
            print(adjustment_line(measured))
    for line in summary_lines(s, result.out_dir):
        print(line)
    log.debug("summary %s", json.dumps(s))
    if result.status == DesignStatus.INTERRUPTED:
        return 130
    failure = failed_design(s)
    if failure is not None and result.status.finished:
        print(f"error: {failure}", file=sys.stderr)
        return EXIT_FAILED
    return 0


def _given_options(args: argparse.Namespace) -> dict:
    """The design settings given on the command line, as `DesignConfig` fields (``target`` included)."""
    from design.inverse.settings import OPTIONS

    given = {} if args.target is None else {"target": args.target}
    for setting in OPTIONS:
        value = getattr(args, setting.name)
        value = tuple(value) if isinstance(value, list) else value
        if value is not None and value is not False and value != ():   # a switch or a list left out
            given[setting.name] = value
    return given
