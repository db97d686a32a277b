"""`sfr demo`: a complete simulated bench session without a screen (the README's first command)."""
from __future__ import annotations

import argparse
import logging

from labapp.cli.argtypes import positive_float

NAME = "demo"
HELP = ("the whole loop on the simulated bench: calibration series, runs of sample objects, calibrate-sim, a run "
        "of a further object, a design from its measured curve, one picture")
RECORDS = "optional"
"""Acts as ``--operator`` or ``$SFR_OPERATOR`` when given, else as the built-in demo operator (no users file
needed): see :mod:`labapp.cli.operator`."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr demo`."""
    parser.add_argument("--out", default="sfr-demo", help="output folder (default ./sfr-demo); a new "
                        "sub-folder per demo session")
    parser.add_argument("--sample", default="pill", help="the further object, whose measured curve is the design "
                        "target (pill or polyhedron; sphere, spinner_top, csg and a flat and a tall print are the "
                        "calibration set)")
    parser.add_argument("--seed", type=int, default=None, help="seed of the simulated bench's hidden material: its "
                        "rate, density and print physics (default: the demo's own material)")
    parser.add_argument("--interval", type=positive_float, default=11.0, help="frame interval of the further object's run, s "
                        "(default 11, the paper's)")


def run(args: argparse.Namespace) -> int:
    """Run the session, printing progress; end with where the results are."""

    from labapp.acquisition.simbench import Material
    from labapp.cli import interrupt
    from labapp.jobs.demo import check_demo, run_demo
    from labapp.records.fileio import timestamp_name
    from labapp.records.outpaths import check_data_dir

    check_demo(args.sample, args.interval)   # every input before the first line of work
    out = check_data_dir(args.out) / timestamp_name(args.sample)
    interrupt.set_hint(f"{out} holds the steps finished so far; run sfr demo again for a new session")

    def progress(text: str) -> None:
        print(text, flush=True)
        interrupt.check()   # a safe point between the demo's steps
    print(f"sfr demo: measure -> calibrate -> design on the simulated bench, in {out}", flush=True)
    if not args.verbose:   # the injected faults are the point of the run's event log, not of the terminal
        logging.getLogger().setLevel(logging.ERROR)
    from labapp.records import operators

    operator = operators.given() or operators.DEMO_OPERATOR     # not the login name: the demo's own operator
    print(f"operator: {operator}" + (" (built-in: records only on the simulated bench)"
                                     if operator == operators.DEMO_OPERATOR else ""), flush=True)
    with operators.acting_as(operator):
        r = run_demo(out, sample=args.sample, interval_s=args.interval, progress=progress,
                     material=None if args.seed is None else Material.draw(args.seed))
    print()
    print(f"done in {r.wall_s:.0f} s (wall)")
    print(f"  time scale            {r.seconds_per_mm:.1f} s/mm calibrated, {r.true_seconds_per_mm:.1f} s/mm the "
          f"calibration prints' hidden mean ({100 * (r.seconds_per_mm / r.true_seconds_per_mm - 1):+.1f}%)")
    print(f"  print physics kept    {r.physics}")
    print(f"  effective density     {r.density_g_per_cm3:.4f} g/cm^3 calibrated, {r.true_density_g_per_cm3:.4f} "
          f"hidden ({100 * (r.density_g_per_cm3 / r.true_density_g_per_cm3 - 1):+.1f}%): weighed grams per mm^3 of the "
          f"modelled print (the prints' own density over their true volume: {r.material_density_g_per_cm3:.4f})")
    print("  leave-one-out         " + ", ".join(f"{name} {100 * e:.2f}%" for name, e in r.loo)
          + " (RMS error / weighed mass)")
    print(f"  '{args.sample}' predicted from its mesh and weighed mass: {100 * r.rel_rmse_prediction:.2f}% RMS of its "
          f"measured final mass ({r.n_frames} frames, {r.duration_s / 3600:.2f} h, {r.faults_logged} warnings in its event log)")
    print(f"  design for its measured curve: predicted within {100 * r.rel_rmse_design:.2f}% RMS")
    print("results:")
    print(f"  bench calibration     {r.calibration_path}")
    print(f"  simulation calib.     {r.simcal_path}  (loo.csv, simcal.png beside it)")
    print(f"  run folder            {r.run_dir}   (sfr verify {r.run_dir})")
    print(f"  measured curve        {r.curve_csv}")
    print(f"  design                {r.design_dir}")
    print(f"  picture               {r.figure}")
    print(f"  summary               {r.summary_path}  (hidden truth: {r.out_dir / 'truth.json'})")
    return 0
