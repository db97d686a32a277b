"""`sfr demo`: a complete simulated bench session without a screen (the README's first command)."""
from __future__ import annotations

import argparse
import logging

log = logging.getLogger(__name__)

NAME = "demo"
HELP = "simulated bench session: calibration series, a run of a sample object (hours in ~2 min), analysis, plots"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr demo`."""
    parser.add_argument("--out", default="sfr-demo", help="output folder (default ./sfr-demo); a new "
                        "sub-folder per demo session")
    parser.add_argument("--sample", default="pill", help="shipped sample object (pill, sphere, spinner_top, "
                        "csg, polyhedron; default pill)")
    parser.add_argument("--interval", type=float, default=11.0, help="frame interval, s (default 11, the paper's)")


def run(args: argparse.Namespace) -> int:
    """Run the session, printing progress; end with where the results are."""
    import time
    from pathlib import Path

    from labapp.demo import run_demo
    from labapp.storage import sanitize_name

    out = Path(args.out) / time.strftime(f"%Y%m%d-%H%M%S_{sanitize_name(args.sample)}")
    print(f"sfr demo: a simulated bench session in {out}", flush=True)
    if not args.verbose:   # the injected faults are the point of the run's event log, not of the terminal
        logging.getLogger().setLevel(logging.ERROR)
    result = run_demo(out, sample=args.sample, interval_s=args.interval, progress=lambda s: print(s, flush=True))
    print()
    print(f"done in {result.wall_s:.0f} s (wall) for {result.duration_s / 3600:.2f} h of simulated bench time")
    print(f"  frames analysed       {result.n_frames}")
    print(f"  final concentration   {result.final_conc_g_per_kg:.4f} g/kg measured, "
          f"{result.true_final_conc_g_per_kg:.4f} g/kg true")
    print(f"  RMS error vs truth    {result.rms_error_g_per_kg:.4f} g/kg "
          f"({100 * result.rms_error_g_per_kg / result.true_final_conc_g_per_kg:.2f} % of final)")
    print(f"  warnings in event log {result.faults_logged} (injected faults: camera busy, corrupt frame, "
          "hotplate link drop)")
    print("results:")
    print(f"  calibration   {result.calibration_path}")
    print(f"  run folder    {result.run_dir}   (sfr verify {result.run_dir})")
    print(f"  curve         {result.curve_csv}")
    print(f"  picture       {result.figure}")
    print(f"  summary       {result.summary_path}")
    return 0
