"""`sfr analyze`: a run folder (or plain image folder) to curve.csv, cells.csv and curve.png; several run
folders at once (on a local Dask cluster or a scheduler) to one summary table (`labapp.scaleout.batch`)."""
from __future__ import annotations

import argparse
import json
import sys

from labapp.acquisition.settings import WATER
from labapp.cli import interrupt
from labapp.cli.argtypes import nonnegative_int, positive_float, positive_int, setting_type
from labapp.cli.commands.sweep import progress_printer
from labapp.errors import UsageError

NAME = "analyze"
HELP = ("turn a run folder or image folder into a release curve (curve.csv, cells.csv, summary.json, curve.png); "
        "several runs: on Dask, one summary table")
RECORDS = True
"""Acts as a named operator (``--operator``, ``$SFR_OPERATOR``): see :mod:`labapp.cli.operator`."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr analyze`."""
    parser.add_argument("run", nargs="+", help="run folder (frames.csv [+ run.json]) or a plain folder of images; "
                        "several: a batch into --out with one summary table")
    parser.add_argument("--calibration", help="bench calibration JSON (sfr calibrate-bench; default: the run's own "
                        "calibration.json; required for a batch)")
    parser.add_argument("--out", help="output folder (default: RUN/analysis; required for a batch)")
    parser.add_argument("--reason", help="why a recorded run is analysed again (in its audit trail)")
    parser.add_argument("--reference", metavar="CURVE",
                        help="batch: f1/f2 of every run against this curve file or run folder")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="batch: tcp://HOST:PORT of a running Dask scheduler (default: a local cluster)")
    parser.add_argument("--interval", type=positive_float, help="frame interval, s, for images without EXIF times")
    parser.add_argument("--water-g", type=setting_type(WATER), help=f"water mass, g (default: run.json, else the "
                        f"calibration's; {WATER.range_text()})")
    parser.add_argument("--window-s", type=positive_float, help="Savitzky-Golay window, s (default 330 = 30 frames at 11 s)")
    parser.add_argument("--order", type=nonnegative_int, help="Savitzky-Golay polynomial order (default 2)")
    parser.add_argument("--workers", type=positive_int, help="decoding threads (default: all cores; 1 per run in a "
                                                             "batch)")
    parser.add_argument("--reduce", type=int, choices=(1, 2, 4, 8),
                        help="decode downscaled by this factor (default: the calibration's)")
    parser.add_argument("--no-plot", action="store_true", help="skip curve.png")


def run(args: argparse.Namespace) -> int:
    """Analyse, write the outputs, print a summary."""
    if len(args.run) > 1 or args.scheduler or args.reference:
        return _run_batch(args)
    args.run = args.run[0]

    from analysis import steady_state
    from labapp.jobs.analyse import analyse_run

    live = sys.stderr.isatty()  # a terminal gets one updating line, a log file one line per step
    interrupt.set_hint("no curve written (the frames analysed so far are kept in the cell cache); rerun the "
                       "same command to finish")

    def progress(done: int, total: int) -> None:
        if done == total or done % (10 if live else 100) == 0:
            print(f"{chr(13) if live else ''}analysed {done}/{total} frames",
                  end="\n" if done == total or not live else "", file=sys.stderr, flush=True)
        interrupt.check()   # a safe point: between two frames

    result = analyse_run(args.run, args.calibration, args.out, interval_s=args.interval, water_g=args.water_g,
                         window_s=args.window_s, order=args.order, workers=args.workers, reduce=args.reduce,
                         plot=not args.no_plot, progress=progress, reason=args.reason)
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


def _run_batch(args: argparse.Namespace) -> int:
    """Many runs: the analysis job on Dask workers, one row each in ``--out/batch_summary.csv``."""
    from labapp.records.lock import folder_lock
    from labapp.scaleout.batch import TASK_MEMORY_GB, RowStatus, analyse_many, check_runs
    from labapp.scaleout.cluster import dashboard_link, dask_client

    if not args.out:
        raise UsageError("a batch of runs (several runs, --reference or --scheduler) needs --out: the folder that "
                         "gets one analysis folder per run and batch_summary.csv")
    if not args.calibration:
        raise UsageError("a batch of runs (several runs, --reference or --scheduler) needs --calibration: the bench "
                         "calibration every run is analysed with")
    check_runs(args.run)        # before the cluster starts
    interrupt.set_hint(f"the runs analysed so far are in {args.out}/batch_summary.csv; rerun the same command to "
                       "analyse them all")
    show, stopping = progress_printer(), []

    def progress(p) -> None:
        show(p)
        if interrupt.requested() and not stopping:  # a safe point: a run finished (runs still going are cancelled);
            stopping.append(True)                   # the batch's last report, after the stop, returns
            raise interrupt.Interrupted
    options = dict(interval_s=args.interval, water_g=args.water_g, window_s=args.window_s, order=args.order,
                   reduce=args.reduce, plot=not args.no_plot, **({"workers": args.workers} if args.workers else {}))
    with (folder_lock(args.out), interrupt.handling(on_second=interrupt.raise_now),
          dask_client(args.scheduler, task_memory_gb=TASK_MEMORY_GB) as client):
        link = dashboard_link(client)
        print(f"analysing {len(args.run)} runs on {args.scheduler or 'a local cluster'}"
              + (f"; Dask dashboard: {link}" if link else ""), file=sys.stderr)
        result = analyse_many(args.run, args.calibration, args.out, client, reference=args.reference,
                              on_progress=progress, **options)
    failed = [r for r in result.rows if r["status"] != RowStatus.DONE]
    for row in failed:
        print(f"{row['status']}: {row['run']}: {row.get('error', '')}", file=sys.stderr)
    print(f"{len(result.rows) - len(failed)} of {len(result.rows)} runs analysed; wrote {result.table}")
    return 130 if result.stopped else 1 if failed else 0
