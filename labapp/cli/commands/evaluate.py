"""`sfr evaluate`: the forward model against the Monte Carlo baseline on a calibration set (paper Fig. 8)."""
from __future__ import annotations

import argparse
import sys

from labapp.cli.argtypes import bounded, positive_int

NAME = "evaluate"
HELP = ("measured vs forward model (leave-one-out) vs Monte Carlo on a calibration set, with f2 and RMS "
        "(paper Fig. 8); also writes the Monte Carlo calibration mc.json")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr evaluate`."""
    from labapp.jobs.calibrate_sim import MAX_RESOLUTION, MIN_RESOLUTION

    parser.add_argument("set", metavar="SET.csv", help="calibration set: run,mesh,object_mass_g rows (as for "
                        "sfr calibrate-sim), paths relative to the file")
    parser.add_argument("--calibration", help="bench calibration JSON for run folders (default: each run's own)")
    parser.add_argument("--out", required=True, metavar="DIR", help="new output folder")
    parser.add_argument("--resolution", type=bounded(MIN_RESOLUTION, MAX_RESOLUTION, integer=True, unit="voxels"),
                        help="voxels along each mesh's longest side, both models "
                        "(default: sfr calibrate-sim's)")
    parser.add_argument("--seeds", type=positive_int, default=4, help="Monte Carlo runs averaged per object (default 4)")


def run(args: argparse.Namespace) -> int:
    """Evaluate, print the table, say where everything is."""
    from labapp.cli import interrupt
    from labapp.jobs.evaluate import evaluate_models, markdown_table
    from labapp.records.lock import folder_lock

    def progress(fraction: float, message: str) -> None:
        print(f"[{100 * fraction:3.0f}%] {message}", file=sys.stderr, flush=True)
        interrupt.check()   # a safe point between the job's steps

    interrupt.set_hint(f"the evaluation in {args.out} is incomplete; rerun the same command into a new folder")
    with folder_lock(args.out):
        result = evaluate_models(args.set, args.calibration, args.out, resolution=args.resolution, seeds=args.seeds,
                                 progress=progress)
    print(markdown_table(result.doc))
    mc = result.doc["mc_calibration"]
    print(f"Monte Carlo tuned on all objects: A = {mc['a_per_s']:.4g} 1/s, E_a = {mc['ea_j_per_mol'] / 1000:.3g} "
          f"kJ/mol, RMS {100 * mc['rms']:.2f}% -> {result.out / 'mc.json'} (sfr simulate --model mc --mc-calibration)")
    print(f"wrote {result.out}/evaluation.json, evaluation.csv, evaluation.md, evaluation.png, simcal/")
    return 0
