"""`sfr design`: inverse design of a shape whose simulated release matches a target curve."""
from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from labapp.cli import interrupt
from labapp.cli.argtypes import finite_float, nonnegative_float, positive_float, positive_int
from labapp.errors import EXIT_FAILED, UsageError
from labapp.jobs.meshunits import MM_PER_UNIT

log = logging.getLogger(__name__)

NAME = "design"
HELP = "design a printable shape whose release matches a target curve (mesh, CSV or analytic)"
RECORDS = True
"""Acts as a named operator (``--operator``, ``$SFR_OPERATOR``): see :mod:`labapp.cli.operator`."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--target", help="sample shape name, mesh file (.stl/.obj/.ply/.off/.3mf), "
                        "tau_mm,released_mm3 CSV, zero-order[:final=F,duration=D] / accel:q=Q[,final=F,duration=D], or a "
                        "measured curve in grams over seconds (a run folder, curve.csv or any t_s,released_g CSV; "
                        "needs --simcal)")
    parser.add_argument("--space", choices=("nfc", "extruded", "ico"),
                        help="design space: nfc (free 3D, the default), extruded (2D field over a height), ico (free "
                             "3D, printable without supports along +z: incremental compliance, section 3.6)")
    parser.add_argument("--preset", metavar="paper:NAME",
                        help="hyperparameters of the paper's Tables 1-2 (e.g. paper:pill, paper:design-4) for the "
                             "options not given")
    parser.add_argument("--w-fab", type=nonnegative_float,
                        help="weight w_f of the ICO term (ico; default 3000; J_fab is 1 at the start design)")
    parser.add_argument("--layers", type=positive_int, help="ICO partial designs L along +z (default 8)")
    parser.add_argument("--ico-coarsen", type=positive_int, metavar="VOX",
                        help="design voxels per elasticity element edge of the ICO term (default 2)")
    parser.add_argument("--stiffness-law", choices=("simp", "ramp"),
                        help="ICO stiffness interpolation: simp (p = 3, default) or ramp (q = 3)")
    parser.add_argument("--resolution", type=positive_int,
                        help="voxels along the domain's longest side (even; default 64)")
    parser.add_argument("--units", choices=tuple(MM_PER_UNIT),
                        help="units of a mesh target's coordinates (default mm); copied into the run scaled to mm")
    parser.add_argument("--domain-mm", type=positive_float, nargs=3, metavar=("X", "Y", "Z"),
                        help="design domain size, mm (default: source bounding box plus margin, cubic for nfc)")
    parser.add_argument("--w-binary", type=nonnegative_float, help="weight of J_binary (default per space, Tables 1-2)")
    parser.add_argument("--radius", type=positive_float, help="smoothing radius, voxels (default: --radius-mm)")
    parser.add_argument("--radius-mm", type=positive_float, metavar="MM",
                        help="smoothing radius, mm: the minimum feature size at any resolution (default 1)")
    parser.add_argument("--allow-pieces", action="store_true",
                        help="drop the connectivity penalty: the design may fall apart into pieces")
    parser.add_argument("--w-connect", type=nonnegative_float,
                        help="weight of the connectivity penalty J_conn (default 5; 10 for analytic targets "
                             "in extruded)")
    parser.add_argument("--w-channel", type=nonnegative_float,
                        help="weight of the channel-width term J_chan, which keeps open channels at least the "
                             "calibration's swelling width (--simcal with one; default 100, 0 = off)")
    parser.add_argument("--starts", type=positive_int,
                        help="seeded starts: from resolution 128 on at half the resolution, the best then refined "
                             "at full resolution; below it each a whole run, the best print kept (default 4 for nfc "
                             "and extruded designs of a source shape at resolution 128 or finer, 3 for extruded "
                             "designs of a curve target, one from each start outline: square, cross, ring; else 1: "
                             "a single run)")
    parser.add_argument("--beta", type=positive_float, help="projection steepness (default 3)")
    parser.add_argument("--beta-final", type=positive_float,
                        help="beta continuation: raise beta to this over the run in 4 stages (default 12 for nfc "
                             "and extruded, 64 for analytic targets there, fixed for ico; equal to --beta: "
                             "fixed)")
    parser.add_argument("--rate-window", type=positive_float, metavar="VOX",
                        help="finite-difference span of the rate-fit term's rates, voxels (default 1)")
    parser.add_argument("--w-rate", type=nonnegative_float,
                        help="weight of the rate-fit term J_rate (default 1 for analytic targets, else 0)")
    parser.add_argument("--rate-span", type=finite_float, nargs=2, metavar=("LO", "HI"),
                        help="J_rate compares rates between the times the target reaches these fractions of "
                             "its release (default 0.05 0.95; 0 1 = whole curve)")
    parser.add_argument("--robust-eta", type=nonnegative_float, metavar="D",
                        help="robust formulation: fit the designs projected at 1/2 - D, 1/2, 1/2 + D "
                             "(0 = off; 3 simulations per evaluation; default 0.1 for analytic targets "
                             "in nfc and extruded, else 0)")
    parser.add_argument("--height", type=positive_float, metavar="MM",
                        help="extrusion height, mm (default: the source's height, else the domain's)")
    parser.add_argument("--max-iter", type=positive_int, help="maximum objective evaluations (default 500)")
    parser.add_argument("--physical-correction", metavar="{defect,none}",
                        help="how the printed solid's true release is made to meet the target: defect (default: "
                             "rounds that re-aim the design grid by the bias the reference evaluator finds in the "
                             "print, within --max-iter) or none (the design grid's release alone)")
    parser.add_argument("--correction-rounds", type=positive_int, metavar="N",
                        help="defect-correction rounds (default 2, each 10%% of --max-iter)")
    parser.add_argument("--bounds", choices=("cosine", "box"),
                        help="how L-BFGS keeps rho_hat in [0, 1] (default cosine)")
    parser.add_argument("--optimizer", help="lbfgs (default: lean L-BFGS, exact resume) or nlopt's LD_LBFGS, "
                        "LD_MMA, LD_CCSAQ (box bounds need one of these); checked by the design configuration")
    parser.add_argument("--line-search", help="the lbfgs optimiser's line search: luksan (default; the rule of "
                        "nlopt's LD_LBFGS) or strong-wolfe; checked by the design configuration")
    parser.add_argument("--warn-channel-mm", type=nonnegative_float, help="warn below this channel width, mm")
    parser.add_argument("--formats", nargs="*", default=[], choices=("3mf", "obj"), help="extra mesh formats")
    parser.add_argument("--allow-infeasible", action="store_true", help="optimise even if the target fails checks")
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


def _progress(max_iter: int):
    """Live progress on stderr: one rewritten line on a terminal, otherwise a line every 10 evaluations
    and at the last."""
    tty = sys.stderr.isatty()

    def show(k: int, x, terms: dict) -> None:
        interrupt.check()   # a safe point after an evaluation: Ctrl-C stops the run here (checkpoint, outputs)
        if not tty and k % 10 and k < max_iter:
            return
        phase = f"{terms['phase']}: " if "phase" in terms else ""
        line = (f"{phase}it {k:4d}/{max_iter}  J {terms['J']:.5g}  fit {terms['J_fit']:.4g}"
                f"  binary {terms['J_binary']:.4g}"
                f"  |g| {terms['grad_norm']:.3g}  {terms['seconds']:.0f}s  ETA <= {terms['eta_s'] / 60:.1f} min")
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
    from labapp.jobs.design import design as design_job
    from labapp.jobs.design import failed_design
    from labapp.jobs.physical import TARGET_CSV, adjustment_line, read_measured_target
    from labapp.records.lock import folder_lock
    from labapp.records.simcal import SimCalError, load_simcal

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
    pairs = (("target", args.target), ("space", args.space), ("resolution", args.resolution),
             ("max_iter", args.max_iter), ("starts", args.starts), ("rate_window_vox", args.rate_window),
             ("rate_span", tuple(args.rate_span) if args.rate_span else None), ("robust_eta", args.robust_eta),
             ("layers", args.layers), ("ico_coarsen", args.ico_coarsen), ("stiffness_law", args.stiffness_law),
             ("bounds", args.bounds), ("line_search", args.line_search), ("warn_channel_mm", args.warn_channel_mm),
             ("domain_mm", tuple(args.domain_mm) if args.domain_mm else None), ("height_mm", args.height),
             ("w_binary", args.w_binary), ("radius_vox", args.radius), ("radius_mm", args.radius_mm),
             ("allow_pieces", args.allow_pieces or None), ("w_connect", args.w_connect), ("w_channel", args.w_channel),
             ("beta", args.beta),
             ("beta_final", args.beta_final), ("w_rate", args.w_rate), ("preset", args.preset),
             ("w_fab", args.w_fab), ("optimizer", args.optimizer or None),
             ("allow_infeasible", args.allow_infeasible or None), ("formats", tuple(args.formats) or None),
             ("physical_correction", args.physical_correction), ("correction_rounds", args.correction_rounds))
    return {name: value for name, value in pairs if value is not None}
