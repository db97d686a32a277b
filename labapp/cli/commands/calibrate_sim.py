"""`sfr calibrate-sim`: calibrate the simulator against measured runs (paper section 4.3)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from labapp.cli.argtypes import bounded, nonnegative_float, nonnegative_int, positive_float, positive_int

NAME = "calibrate-sim"
HELP = "fit seconds per mm and grams per mm^3 from measured runs and their meshes (simcal.json, loo.csv, simcal.png)"
RECORDS = True
"""Acts as a named operator (``--operator``, ``$SFR_OPERATOR``): see :mod:`labapp.cli.operator`."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr calibrate-sim`."""
    from analysis.physics_fit import DISCRETISATION_FACTOR
    from analysis.physics_grid import DEFAULT_PHYSICS, PHYSICS_CHOICES
    from analysis.simcal_fit import DEFAULT_MAX_OFFSET_S
    from design.geometry.voxelize import DEFAULT_RESOLUTION
    from labapp.jobs.calibrate_sim import MAX_RESOLUTION, MIN_RESOLUTION

    parser.add_argument("set_csv", metavar="SET.csv", nargs="?",
                        help="columns run,mesh,object_mass_g; run = run folder or curve CSV, paths relative to "
                             "the file; an empty mass is read from the run's run.json (not with --plan); an optional "
                             "barrier_mesh column marks coated prints, which give the barrier's speed")
    _add_plan_arguments(parser)
    parser.add_argument("--calibration", help="bench calibration JSON for the run folders (default: each run's own)")
    parser.add_argument("--out", required=True, help="output folder (must not hold a calibration yet)")
    parser.add_argument("--model", default="auto", choices=("auto", "constant", "saturation"),
                        help="model used for prediction: constant rate, Appendix B's saturating bath, or auto "
                             "(the lower leave-one-out error; both are always reported)")
    parser.add_argument("--physics", default=DEFAULT_PHYSICS, choices=PHYSICS_CHOICES,
                        help="print physics of the forward model to fit with the scales: the build-direction "
                             "anisotropy (z / in-plane erosion rate), the surface offset (print larger or smaller "
                             "than its mesh, mm), the swelling width (channels narrower are shut until their walls "
                             "dissolve, mm), the wetting lag (s after the drop, shared by all runs: lag), sets joined by +, "
                             "all four, or auto (every subset; a parameter is kept only where "
                             f"leave-one-out shows it earns it). Default {DEFAULT_PHYSICS}; none: the isotropic model "
                             "of the mesh as designed")
    parser.add_argument("--resolution", type=bounded(MIN_RESOLUTION, MAX_RESOLUTION, integer=True, unit="voxels"),
                        default=DEFAULT_RESOLUTION,
                        help=f"voxels along each mesh's longest side (default {DEFAULT_RESOLUTION})")
    parser.add_argument("--second-resolution", type=nonnegative_int, default=None,
                        help=f"refit the fitted print physics at this resolution too and add its discretisation bias "
                             f"to each parameter's uncertainty (default {DISCRETISATION_FACTOR:g} x --resolution; "
                             "0 = not)")
    parser.add_argument("--max-offset-s", type=nonnegative_float, default=DEFAULT_MAX_OFFSET_S,
                        help=f"bound on each run's drop-time offset, s (default {DEFAULT_MAX_OFFSET_S:g}; 0 = none)")


def _add_plan_arguments(parser: argparse.ArgumentParser) -> None:
    from labapp.jobs.plan import PLAN_NOISE, PLAN_POINTS, PLAN_PRINTS

    parser.add_argument("--plan", action="store_true",
                        help="no calibration: propose which shapes to print (shipped samples, generated flat, tall and "
                             "channelled shapes) to separate the --physics parameters, with each parameter's expected "
                             "standard error (plan.csv, plan.json and the generated shapes' STL files in --out)")
    parser.add_argument("--plan-prints", type=positive_int, default=PLAN_PRINTS,
                        help=f"with --plan: how many prints to propose (default {PLAN_PRINTS})")
    parser.add_argument("--plan-noise", type=positive_float, default=PLAN_NOISE,
                        help=f"with --plan: calibration error per independent point, fraction of the weighed mass "
                             f"(default {PLAN_NOISE:g})")
    parser.add_argument("--plan-points", type=positive_int, default=PLAN_POINTS,
                        help=f"with --plan: independent points per run (default {PLAN_POINTS})")


def _run_plan(args: argparse.Namespace) -> int:
    from labapp.errors import UsageError
    from labapp.jobs.plan import plan_prints

    if args.set_csv is not None:
        raise UsageError("--plan proposes prints before any run: give no SET.csv with it")
    plan = plan_prints(args.physics, args.out, prints=args.plan_prints, noise=args.plan_noise,
                       points=args.plan_points, resolution=args.resolution,
                       progress=lambda text: print(text, file=sys.stderr, flush=True))
    print(f"calibration prints for {', '.join(plan.parameters)} (error {100 * plan.noise:g}% of the mass at "
          f"{plan.points} independent points per run):")
    print(f"  {'#':>2s} {'shape':16s} " + " ".join(f"{'std ' + p:>18s}" for p in plan.parameters) + "  why")
    for k, step in enumerate(plan.steps, start=1):
        print(f"  {k:2d} {step.name:16s} " + " ".join(f"{step.std[p]:18.3g}" for p in plan.parameters)
              + f"  {step.why}")
    print("expected standard errors (log_seconds and anisotropy relative): "
          + ", ".join(f"{p} {v:.3g}" for p, v in plan.std.items()))
    print(f"wrote {Path(args.out) / 'plan.csv'}, {Path(args.out) / 'plan.json'}")
    return 0


def run(args: argparse.Namespace) -> int:
    """Calibrate, print the leave-one-out table and where the files are."""
    from labapp.cli import interrupt
    from labapp.errors import UsageError
    from labapp.jobs.calibrate_sim import calibrate_sim

    if args.plan:
        return _run_plan(args)
    if args.set_csv is None:
        raise UsageError("give the calibration set SET.csv (or --plan to propose which shapes to print)")

    def progress(fraction: float, message: str) -> None:
        print(f"[{100 * fraction:3.0f}%] {message}", file=sys.stderr, flush=True)
        interrupt.check()   # a safe point: before a run is read and simulated, before a fit

    interrupt.set_hint(f"nothing written into {args.out}; rerun the same command to calibrate")
    done = calibrate_sim(args.set_csv, args.calibration, args.out, model=args.model, resolution=args.resolution,
                         max_offset_s=args.max_offset_s, physics=args.physics,
                         second_resolution=args.second_resolution, progress=progress)
    print_summary(done.doc)
    out = Path(args.out)
    print(f"wrote {out / 'simcal.json'}, {out / 'loo.csv'}, {out / 'simcal.png'}")
    return 0


def print_summary(doc: dict) -> None:
    """The fitted scales and the leave-one-out table of both models."""
    sat = doc["saturation_g_per_kg"]
    print(f"model {doc['model']}: {doc['seconds_per_mm']:.1f} s per mm of tau, {doc['g_per_mm3'] * 1000:.4f} g/cm^3"
          + ("" if sat is None else f", c_sat {sat:.3g} g/kg") + f", resolution {doc['resolution']}")
    physics = doc.get("physics") or {}
    if physics.get("candidates"):
        print(f"print physics '{physics['choice']}': " + ", ".join(
            f"{p} {physics[p]:.3g} +/- {physics['uncertainty'][p]:.2g}" for p in physics["fitted"]) or "none")
        for name, c in physics["candidates"].items():
            values = ", ".join(f"{p} {c['values'][p]:.3g}" for p in c["fitted"]) or "isotropic, mesh as designed"
            print(f"  {name:10s} leave-one-out {100 * c['loo_rel_rmse_mean']:.2f}%  ({values})")
    models = list(doc["models"])
    print("leave-one-out rel. RMSE (% of weighed mass):")
    print(f"  {'run':40s} " + " ".join(f"{m:>11s}" for m in models))
    for i, row in enumerate(doc["loo"]):
        name = Path(row["run"]).name
        print(f"  {name:40.40s} " + " ".join(f"{100 * doc['models'][m]['loo'][i]['rel_rmse']:10.2f}%" for m in models))
    print(f"  {'mean':40s} " + " ".join(f"{100 * doc['models'][m]['loo_rel_rmse_mean']:10.2f}%" for m in models))
    band = doc.get("band")
    if band:
        cov = band["loo_coverage"]
        print(f"error bands ({100 * band['level']:.0f}%): {cov['points_inside']} of {cov['points']} held-out points "
              f"({100 * cov['fraction']:.1f}%) inside the band from the other runs; per run "
              + ", ".join(f"{100 * c:.0f}%" for c in cov["per_run"]))
    barrier = doc.get("barrier")
    if barrier:
        print(f"barrier speed {barrier['speed']:.4f} +- {barrier['error']:.4f} from {len(barrier['runs'])} coated prints "
              f"(runs' standard error {barrier['standard_error']:.4f}; at the calibration's rate "
              f"{barrier['speed_at_calibrated_rate']:.4f})")

