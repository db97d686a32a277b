"""`sfr compare`: f1/f2 under a regulator's rule, MDT, DE and model fits of two release curves (A is the
reference); with replicate units (`--reference ... --test ...`), the CV per time point, the bootstrap of f2,
Tsong's MSD and Hoffelder's T^2."""
from __future__ import annotations

import argparse

from labapp.cli.argtypes import bounded, nonnegative_int, positive_float

NAME = "compare"
HELP = ("compare release curves as dissolution testing does: f1/f2 under a regulator's rule, MDT, DE, model fits; "
        "replicate units: CV, bootstrap f2, MSD and T^2")
RULES = ("ema", "fda", "who", "canada", "anvisa")
"""The names of ``analysis.regulatory.RULE_NAMES`` (kept here so that ``sfr --help`` imports no numerics)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr compare`."""
    for name, role in (("a", "reference"), ("b", "test")):
        parser.add_argument(name, metavar=name.upper(), nargs="?",
                            help=f"the {role} curve: curve.csv, release_physical.csv, curves_physical.csv, a run "
                                 f"folder, or a t_s,released_g CSV")
    parser.add_argument("--reference", nargs="+", action="extend", metavar="UNIT",
                        help="replicate units of the reference: one curve or run folder per unit (repeatable), or "
                             "one CSV with t_min (or t_s, t_h) and one column of percent released per unit")
    parser.add_argument("--test", nargs="+", action="extend", metavar="UNIT",
                        help="replicate units of the test, as --reference")
    parser.add_argument("--rule", choices=RULES, default="ema",
                        help="the regulator whose f2 rule applies: the 85 %% cut, the CV limits at the early and "
                             "later points, and whether a CV failure refuses f2 or warns (default ema)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    parser.add_argument("--plot", nargs="?", const="compare.png", metavar="PNG",
                        help="also draw the curves with their f2 points (default compare.png)")
    parser.add_argument("--until", type=positive_float, metavar="S",
                        help="two curves: MDT and DE up to this time, s (default: the end of the shorter curve)")
    parser.add_argument("--times", metavar="S,S,...",
                        help="f2 time points, s (default: the curves' common samples, or a regular grid)")
    parser.add_argument("--bootstrap", type=nonnegative_int, default=0, metavar="N",
                        help="replicate units: bootstrap f2 over units with N samples (e.g. 10000): five estimators, "
                             "normal, basic, percentile and BCa 90 %% intervals")
    parser.add_argument("--seed", type=int, default=306,
                        help="R's set.seed value of the bootstrap (default 306, bootf2's; the same seed draws the "
                             "same samples as bootf2)")
    parser.add_argument("--mtad", type=bounded(0.0, 50.0, low_open=True, unit="%"), default=10.0, metavar="PCT",
                        help="replicate units: largest tolerable mean difference per point of the MSD and T^2 tests, "
                             "%% (default 10)")
    parser.add_argument("--signif", type=bounded(0.0, 1.0, low_open=True), metavar="ALPHA",
                        help="replicate units: significance level of the MSD and T^2 tests (default 0.05)")
    parser.add_argument("--both-tr-85", action="store_true",
                        help="replicate units, --rule fda: the older reading of the FDA's 85 %% sentence (a point "
                             "is dropped only once both means exceed 85 %%), which published values such as Shah "
                             "et al. 1998's use; bootf2's both.TR.85")
    parser.add_argument("--cutoff", type=bounded(0.0, 100.0, low_open=True, unit="%"), metavar="PCT",
                        help="replicate units: f2 stops after the first point above this release, %% (default 85)")
    parser.add_argument("--bounds", type=_bounds, metavar="LOW,HIGH",
                        help="replicate units: the profile portion of the MSD and T^2 tests, %% released: points "
                             "with both means above LOW, up to the first above HIGH (default 1,85; disprofas' bounds)")
    parser.add_argument("--calibration", help="bench calibration JSON for run folders without calibration.json")


def _given(**options) -> dict:
    """The options given on the command line (the others take the job's defaults)."""
    return {name: value for name, value in options.items() if value is not None}


def _bounds(text: str) -> tuple[float, float]:
    """``LOW,HIGH`` in %, 0 <= LOW <= HIGH <= 100."""
    try:
        low, high = (float(p) for p in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected LOW,HIGH in %, e.g. 1,85") from None
    if not 0 <= low <= high <= 100:
        raise argparse.ArgumentTypeError(f"{text!r}: expected 0 <= LOW <= HIGH <= 100 (%)")
    return low, high


def _times(text: str | None) -> list[float] | None:
    from labapp.errors import UsageError

    if text is None:
        return None
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError as exc:
        raise UsageError(f"--times {text!r}: expected numbers in s separated by commas") from exc


def run(args: argparse.Namespace) -> int:
    """Compare two curves or two sets of units, then print the table or the JSON; draw with --plot."""
    import json
    from pathlib import Path

    from labapp.errors import UsageError
    from labapp.jobs.compare import compare_curves, compare_sets
    from labapp.jobs.compare_tables import format_set_table, format_table, plot_comparison, plot_sets
    from labapp.records.outpaths import check_out

    sets = args.reference is not None or args.test is not None
    if sets:
        if args.a is not None or args.b is not None:
            raise UsageError("give either two curves A B, or replicate units with --reference and --test, not both")
        if not args.reference or not args.test:
            raise UsageError("replicate units need both --reference UNIT... and --test UNIT...")
        if args.until is not None:
            raise UsageError("--until applies to two curves; the mean curves of replicate units run to their end")
        inputs = args.reference + args.test
    else:
        if args.a is None or args.b is None:
            raise UsageError("give two curves A (the reference) and B (the test), or replicate units with "
                             "--reference UNIT... --test UNIT...")
        if args.bootstrap:
            raise UsageError("--bootstrap needs replicate units: give each product's units with --reference and --test")
        for name, value in (("--both-tr-85", args.both_tr_85 or None), ("--cutoff", args.cutoff),
                            ("--bounds", args.bounds), ("--signif", args.signif)):
            if value is not None:
                raise UsageError(f"{name} applies to replicate units: give each product's units with --reference "
                                 "and --test")
        for name, value in (("A", args.a), ("B", args.b)):
            if "," in value and not Path(value).exists():
                raise UsageError(f"{name} {value!r}: replicate units are given as --reference UNIT... --test UNIT..., "
                                 f"not separated by commas")
        inputs = [args.a, args.b]
    if args.bootstrap and args.bootstrap < 100:
        raise UsageError(f"--bootstrap {args.bootstrap}: expected a number of samples >= 100, or 0 for none")
    if args.both_tr_85 and args.rule != "fda":
        raise UsageError(f"--both-tr-85 is a reading of the FDA's rule; it needs --rule fda (given: {args.rule})")
    plot = check_out(args.plot, "compare", inputs, file=True, option="--plot") if args.plot else None
    calibration = None
    if args.calibration:
        from analysis import BenchCalibration

        calibration = BenchCalibration.load(args.calibration)
    if sets:
        result = compare_sets(args.reference, args.test, calibration=calibration, rule=args.rule,
                              times_s=_times(args.times), n_boot=args.bootstrap, seed=args.seed, mtad=args.mtad,
                              both_tr_85=args.both_tr_85, **_given(signif=args.signif, cutoff_pct=args.cutoff,
                                                                   bounds=args.bounds))
        text, draw = format_set_table, plot_sets
    else:
        result = compare_curves(args.a, args.b, calibration=calibration, until_s=args.until,
                                times_s=_times(args.times), rule=args.rule)
        text, draw = format_table, plot_comparison
    print(json.dumps(result.to_dict(), indent=2) if args.json else text(result))
    if plot is not None:
        draw(result, plot)
        if not args.json:
            print(f"wrote {plot}")
    return 0
