"""`sfr analyze`: a run folder (or plain image folder) to curve.csv, cells.csv and curve.png."""
from __future__ import annotations

import argparse
import logging
import sys

from labapp.argtypes import nonnegative_int, positive_float, positive_int

log = logging.getLogger(__name__)

NAME = "analyze"
HELP = "turn a run folder or image folder into a release curve (curve.csv, cells.csv, summary.json, curve.png)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr analyze`."""
    parser.add_argument("run", help="run folder (frames.csv [+ run.json]) or a plain folder of images")
    parser.add_argument("--calibration", required=True, help="bench calibration JSON (sfr calibrate-bench)")
    parser.add_argument("--out", help="output folder (default: RUN/analysis)")
    parser.add_argument("--interval", type=positive_float, help="frame interval, s, for images without EXIF times")
    parser.add_argument("--water-g", type=positive_float, help="water mass, g (default: run.json, else the calibration's)")
    parser.add_argument("--window-s", type=positive_float, help="Savitzky-Golay window, s (default 330 = 30 frames at 11 s)")
    parser.add_argument("--order", type=nonnegative_int, help="Savitzky-Golay polynomial order (default 2)")
    parser.add_argument("--workers", type=positive_int, help="decoding threads (default: all cores)")
    parser.add_argument("--reduce", type=int, choices=(1, 2, 4, 8),
                        help="decode downscaled by this factor (default: the calibration's)")
    parser.add_argument("--no-plot", action="store_true", help="skip curve.png")


def run(args: argparse.Namespace) -> int:
    """Analyse, write the outputs, print a summary."""
    import json

    from analysis import steady_state
    from labapp.jobs import analyse_run

    live = sys.stderr.isatty()  # a terminal gets one updating line, a log file one line per step

    def progress(done: int, total: int) -> None:
        if done == total or done % (10 if live else 100) == 0:
            print(f"{chr(13) if live else ''}analysed {done}/{total} frames",
                  end="\n" if done == total or not live else "", file=sys.stderr, flush=True)

    result = analyse_run(args.run, args.calibration, args.out, interval_s=args.interval, water_g=args.water_g,
                         window_s=args.window_s, order=args.order, workers=args.workers, reduce=args.reduce,
                         plot=not args.no_plot, progress=progress)
    curve, out = result.curve, result.out
    for message in curve.warnings:
        print(f"warning: {message}", file=sys.stderr)
    done = steady_state(curve.t_s, curve.conc_smooth_g_per_kg)
    print(f"{len(curve.files)} frames over {curve.t_s[-1] - curve.t_s[0]:.0f} s "
          f"(pixels linearised from sRGB before photometry); "
          f"{int((curve.n_rejected > 0).sum())} frames had cells rejected")
    print(f"final concentration {curve.conc_smooth_g_per_kg[-1]:.4f} g/kg, released "
          f"{curve.released_g[-1]:.4f} g in {curve.water_g:g} g water; steady state: {'yes' if done else 'no'}")
    release = json.loads((out / "summary.json").read_text())["release"]
    if "error" in release:
        print(f"release metrics: none ({release['error']})")
    else:
        print(f"MDT {release['mdt_s']:.0f} s, DE {release['de_pct']:.1f} % to {release['until_s']:.0f} s; "
              f"best model fit {release['best_fit_text'] or 'none'}")
    print(f"wrote {out / 'curve.csv'}, {out / 'cells.csv'}, {out / 'summary.json'}"
          + ("" if args.no_plot else f", {out / 'curve.png'}"))
    return 0
