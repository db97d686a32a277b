"""`sfr compare`: f1/f2, MDT, DE and model fits of two release curves (A is the reference)."""
from __future__ import annotations

import argparse

from labapp.cli.argtypes import nonnegative_int, positive_float

NAME = "compare"
HELP = "compare two release curves as dissolution testing does: f1/f2, MDT, DE, model fits (A is the reference)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr compare`."""
    for name, role in (("a", "reference"), ("b", "test")):
        parser.add_argument(name, metavar=name.upper(),
                            help=f"the {role}: curve.csv, release_physical.csv, curves_physical.csv, a run folder, "
                                 f"a t_s,released_g CSV, or replicates separated by commas (averaged)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    parser.add_argument("--plot", nargs="?", const="compare.png", metavar="PNG",
                        help="also draw both curves with their f2 points and best fits (default compare.png)")
    parser.add_argument("--until", type=positive_float, metavar="S",
                        help="MDT and DE up to this time, s (default: the end of the shorter curve)")
    parser.add_argument("--times", metavar="S,S,...",
                        help="f1/f2 time points, s (default: the sparser curve's samples, or a regular grid)")
    parser.add_argument("--rule", choices=("either", "both"), default="either",
                        help="the point after 85 %% is where either curve (EMA, default) or both (FDA) pass it")
    parser.add_argument("--bootstrap", type=nonnegative_int, default=0, metavar="N",
                        help="with replicates: a 90 %% bootstrap interval of f2 from N samples (e.g. 10000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the bootstrap (default 0)")
    parser.add_argument("--calibration", help="bench calibration JSON for run folders without calibration.json")


def _times(text: str | None) -> list[float] | None:
    from labapp.errors import UsageError

    if text is None:
        return None
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError as exc:
        raise UsageError(f"--times {text!r}: expected numbers in s separated by commas") from exc


def run(args: argparse.Namespace) -> int:
    """Compare, then print the table or the JSON; draw the picture with --plot."""
    import json

    from labapp.errors import UsageError
    from labapp.jobs.compare import compare_curves, format_table, plot_comparison
    from labapp.records.outpaths import check_out

    a = [p for p in args.a.split(",") if p]
    b = [p for p in args.b.split(",") if p]
    if args.bootstrap and max(len(a), len(b)) < 2:
        raise UsageError("--bootstrap needs replicate curves: give A or B as several files separated by commas")
    if args.bootstrap < 0:
        raise UsageError(f"--bootstrap {args.bootstrap}: expected a number of samples >= 100, or 0 for none")
    plot = check_out(args.plot, "compare", a + b, file=True, option="--plot") if args.plot else None
    calibration = None
    if args.calibration:
        from analysis import BenchCalibration

        calibration = BenchCalibration.load(args.calibration)
    result = compare_curves(a, b, calibration=calibration, until_s=args.until, times_s=_times(args.times),
                            rule=args.rule, n_boot=args.bootstrap, seed=args.seed)
    if args.json:
        print(json.dumps(result.to_dict(), indent=2))
    else:
        print(format_table(result))
    if plot is not None:
        plot_comparison(result, plot)
        if not args.json:
            print(f"wrote {plot}")
    return 0
