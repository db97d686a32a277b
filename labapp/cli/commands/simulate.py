"""`sfr simulate`: the release curve of a mesh, a sample shape or a density array."""
from __future__ import annotations

import argparse
import sys

from labapp.cli import interrupt
from labapp.cli.argtypes import bounded, nonnegative_float, positive_float, positive_int
from labapp.cli.commands._barrier import add_barrier_arguments, run_barrier
from labapp.jobs.meshunits import MIN_RESOLUTION, MM_PER_UNIT

MAX_RESOLUTION = 1024
"""Most voxels along the longest side ``--resolution`` takes (far past what fits in memory for most parts; the
grid's memory is checked before it is allocated)."""

NAME = "simulate"
HELP = "simulate the release curve of a mesh (STL/OBJ/PLY/OFF/3MF), sample:NAME or a density .npy/.npz"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", metavar="INPUT",
                        help="mesh file (mm unless --units), density array (.npz with rho and dx_mm, or .npy with --voxel-size), "
                             "or sample:NAME (sphere, pill, spinner_top, csg, polyhedron)")
    size = parser.add_mutually_exclusive_group()
    size.add_argument("--resolution", type=bounded(MIN_RESOLUTION, MAX_RESOLUTION, integer=True, unit="voxels"),
                      metavar="N", help=f"--model grid/mc: voxels along the longest bounding-box side "
                                        f"({MIN_RESOLUTION}-{MAX_RESOLUTION}, default 64)")
    size.add_argument("--voxel-size", type=positive_float, metavar="MM", help="--model grid/mc: voxel edge length in mm")
    parser.add_argument("--units", default="mm", choices=tuple(MM_PER_UNIT),
                        help="units of the mesh file's coordinates (default mm); a size implausible for a printed "
                             "object is warned about with the likely unit")
    parser.add_argument("--symmetry", default="", metavar="AXES",
                        help="--model grid/mc: mirror planes through the bounding-box centre on these axes, e.g. xyz: simulates "
                             "one half/quadrant/octant; the curve is still the full object's")
    parser.add_argument("--out", default="simulation", metavar="DIR", help="output folder (default ./simulation)")
    parser.add_argument("--simcal", metavar="SIMCAL.json",
                        help="simulation calibration (sfr calibrate-sim): also write release_physical.csv "
                             "(t_s,released_g,conc_g_per_kg) and release_physical.png; its anisotropy applies to "
                             "the exact model, a surface offset or swelling takes the grid model at its resolution")
    parser.add_argument("--water-g", type=positive_float, help="bath water for the physical curve, g (default: the "
                        "calibration's)")
    parser.add_argument("--model", choices=("exact", "grid", "mc"), default=None,
                        help="exact (the default for a mesh): exact surface distances on a lattice sized by the "
                             "part's thickness, within 0.4%% of its volume as stated; grid (the default for a density "
                             "array): first-order fast marching on voxels, its error estimated; mc: the kinetic "
                             "Monte Carlo baseline (release.csv in seconds with the spread over seeds, "
                             "release_physical.csv)")
    parser.add_argument("--seeds", type=positive_int, default=4, help="--model mc: runs averaged (default 4)")
    parser.add_argument("--mc-calibration", metavar="MC.json",
                        help="--model mc: tuned (A, E_a) from sfr evaluate; without it --mc-a and --mc-ea")
    parser.add_argument("--mc-a", type=positive_float, metavar="PER_S",
                        help="--model mc without a calibration: pre-exponential factor A, 1/s (default 1: time "
                             "in units of 1/A)")
    parser.add_argument("--mc-ea", type=nonnegative_float, metavar="J_PER_MOL",
                        help="--model mc without a calibration: activation energy per solid neighbour, J/mol "
                             "(default 5000)")
    add_barrier_arguments(parser)


def _progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)
    interrupt.check()   # a safe point between the job's steps


def _run_mc(args: argparse.Namespace) -> int:
    """``--model mc``: the Monte Carlo job with a tuned calibration or explicit (A, E_a)."""
    from design.montecarlo.erosion import MonteCarloParams
    from labapp.errors import UsageError
    from labapp.jobs.simulate_mc import UNCALIBRATED, McCalibration, load_mc_calibration, simulate_mc_job

    if args.simcal:
        raise UsageError("--simcal calibrates the forward model; the Monte Carlo model takes --mc-calibration")
    if args.mc_calibration:
        if args.mc_a is not None or args.mc_ea is not None:
            raise UsageError("give either --mc-calibration or --mc-a/--mc-ea, not both")
        calibration = load_mc_calibration(args.mc_calibration)
        if args.resolution is None and args.voxel_size is None:
            args.resolution = calibration.resolution
    else:
        calibration = McCalibration(MonteCarloParams(1.0 if args.mc_a is None else args.mc_a,
                                                     5000.0 if args.mc_ea is None else args.mc_ea))
        print(f"sfr simulate: no --mc-calibration: {UNCALIBRATED}", file=sys.stderr)
    result = simulate_mc_job(args.input, args.out, calibration, resolution=args.resolution,
                             voxel_size_mm=args.voxel_size, symmetry=args.symmetry, units=args.units,
                             seeds=args.seeds, water_g=args.water_g, progress=_progress)
    s = result.summary
    if not s["calibrated"]:
        print(f"uncalibrated: {s['calibration_note']}")
    print(f"Monte Carlo: {s['physical']['mass_g']:.3f} g released over {s['physical']['duration_s'] / 3600:.2f} h, "
          f"spread over {len(s['seeds'])} seeds up to {s['spread_max_g']:.4f} g ({calibration.describe()}), "
          f"{s['seconds']:.2f} s -> {result.out}")
    return 0


def run(args: argparse.Namespace) -> int:
    """Simulate with ``--out`` locked against a second writer (:mod:`labapp.records.lock`)."""
    from labapp.records.lock import folder_lock

    with folder_lock(args.out):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    import json

    import numpy as np

    if args.barrier is not None or args.barrier_speed is not None:
        return run_barrier(args, _progress)
    if args.model == "mc":
        return _run_mc(args)

    from labapp.jobs.compare import release_summary
    from labapp.jobs.physical import write_release_physical
    from labapp.jobs.simulate import simulate as simulate_job
    from labapp.jobs.simulate import write_file
    from labapp.records.simcal import check_resolution, load_simcal

    simcal, model = None, args.model
    if args.simcal:
        simcal = load_simcal(args.simcal)
        if model == "grid":
            if args.voxel_size is not None:
                print(f"sfr simulate: {args.simcal} holds for resolution {simcal.resolution}; drop --voxel-size",
                      file=sys.stderr)
                return 2
            args.resolution, model = check_resolution(simcal, args.resolution), "grid"
    result = simulate_job(args.input, args.out, resolution=args.resolution, voxel_size_mm=args.voxel_size,
                          symmetry=args.symmetry, units=args.units, progress=_progress, model=model,
                          physics=None if simcal is None else simcal.physics)
    release, summary, out = result.release, result.summary, result.out
    seconds = summary["seconds"]
    if simcal is not None:
        from analysis.bands import BAND_LEVEL
        from labapp.jobs.bands import source_release_exact, source_simulator

        tau, released = source_release_exact(args.input, release, simcal.physics, args.units,
                                             resolution=simcal.resolution, symmetry=args.symmetry,
                                             method=simcal.release_method)
        physical = write_release_physical(tau, released, simcal, out, args.water_g,
                                          title=args.input, simulate_at=source_simulator(
                                              args.input, simcal.resolution, symmetry=args.symmetry, units=args.units,
                                              method=simcal.release_method))
        grams = np.loadtxt(physical, delimiter=",", skiprows=1)
        summary["physical"] = {"simcal": str(simcal.path), "model": simcal.cal.model,
                               "mass_g": float(grams[-1, 1]), "duration_s": float(grams[-1, 0]),
                               "water_g": args.water_g or simcal.water_g,
                               "release": release_summary(grams[:, 0], grams[:, 1], None, "prediction")}
        write_file(out / "summary.json", (json.dumps(summary, indent=2) + "\n").encode())
        print(f"predicted: {grams[-1, 1]:.3f} g released over {grams[-1, 0] / 3600:.2f} h "
              f"({simcal.describe()}) -> {physical}")
        if grams.shape[1] > 3:
            print(f"  {100 * BAND_LEVEL:.0f}% band (calibration uncertainty and leave-one-out residuals): final mass "
                  f"{grams[-1, 3]:.3f}-{grams[-1, 4]:.3f} g, widest {np.max(grams[:, 4] - grams[:, 3]):.3f} g")
        else:
            print(f"  no error band: {simcal.path} was made without one; recalibrate with sfr calibrate-sim")
    error = summary["error"]
    estimate = ("not estimated" if error["error_mm3"] is None else
                f"within {error['error_mm3']:.3g} mm^3 ({error['error_fraction']:.2%} of the volume) of the physical "
                f"release ({error['method']})")
    if summary["model"] == "exact":
        how = f"exact model ({summary['method']}), lattice {summary['lattice']['spacing_mm']:.4g} mm"
    else:
        how = f"grid model, {summary['voxels']:,} voxels of {summary['voxel_size_mm']:.4g} mm"
    print(f"volume {release.volume_mm3:.1f} mm^3, T = {release.total_time_mm:.3f} mm, {how}, {seconds:.2f} s -> {out}")
    print(f"error: the simulated curve is {estimate}")
    for warning in summary["warnings"]:
        print(f"warning: {warning}")
    return 0
