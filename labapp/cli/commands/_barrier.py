"""`sfr simulate INPUT --barrier MESH --barrier-speed S`: the options and their run (a drug inside a barrier)."""
from __future__ import annotations

import argparse
from collections.abc import Callable

from labapp.cli.argtypes import nonnegative_float


def add_barrier_arguments(parser: argparse.ArgumentParser) -> None:
    """The two-material options of `sfr simulate`."""
    group = parser.add_argument_group("two materials (the drug INPUT inside a barrier)")
    group.add_argument("--barrier", metavar="MESH",
                       help="the barrier's solid (mesh or sample:NAME, same --units): INPUT is the drug inside it, "
                            "and where the two overlap the drug wins; release.csv is the drug's release")
    group.add_argument("--barrier-speed", type=nonnegative_float, metavar="S",
                       help="with --barrier, required: the barrier's erosion speed over the drug's (0: insoluble; "
                            "drug it seals never releases and is reported)")


def run_barrier(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    """Run `sfr simulate` given ``--barrier`` or ``--barrier-speed``: refuse the options that do not apply, simulate,
    print the summary."""
    from labapp.errors import UsageError
    from labapp.jobs.simulate_barrier import simulate_barrier

    if args.barrier is None:
        raise UsageError("--barrier-speed applies to a drug inside a barrier: give --barrier MESH")
    if args.barrier_speed is None:
        raise UsageError("--barrier needs --barrier-speed S (the barrier's erosion speed over the drug's; 0: insoluble)")
    refused = [name for name, given in ((f"--model {args.model}", args.model == "mc"),
                                        ("--simcal", bool(args.simcal)), ("--water-g", args.water_g is not None)) if given]
    if refused:
        raise UsageError(f"--barrier does not take {', '.join(refused)}: two materials are simulated by the exact "
                         "model (the default) or the grid model, without a calibration")
    if args.model in (None, "exact"):
        return _run_exact(args, progress)
    result = simulate_barrier(args.input, args.barrier, args.out, barrier_speed=args.barrier_speed,
                              resolution=args.resolution, voxel_size_mm=args.voxel_size, symmetry=args.symmetry,
                              units=args.units, progress=progress)
    s = result.summary
    print(f"drug {s['volume_mm3']:.1f} mm^3 in {s['barrier_volume_mm3']:.1f} mm^3 of barrier at speed "
          f"{s['barrier_speed']:g}: T = {s['total_time_mm']:.3f} mm, {s['voxels']:,} voxels, {s['seconds']:.2f} s "
          f"-> {result.out}")
    starts = s["release_starts_mm"]
    if starts == 0.0:
        print("barrier cover: none, some drug is open to the bath; its release starts at tau = 0")
    else:
        print(f"barrier cover: at least {s['barrier_cover_mm']:.3g} mm of barrier between the outside and the drug; "
              + ("the drug is sealed" if starts is None else f"its release starts at tau = {starts:.3g} mm"))
    if s["sealed_mm3"] > 0:
        print(f"sealed: {s['sealed_mm3']:.4g} mm^3 of drug in {len(s['sealed_regions_mm3'])} region(s) never releases")
    error = s["error"]
    if error["error_mm3"] is not None:
        print(f"error: the simulated curve is within about {error['error_mm3']:.3g} mm^3 "
              f"({error['error_fraction']:.2%} of the drug) of the physical release ({error['method']})")
    return 0


def _run_exact(args: argparse.Namespace, progress: Callable[[str], None]) -> int:
    """The default: the two-material reference evaluator, its summary printed."""
    from labapp.errors import UsageError
    from labapp.jobs.simulate_barrier import simulate_barrier_exact

    given = [name for name, v in (("--resolution", args.resolution), ("--voxel-size", args.voxel_size),
                                  ("--symmetry", args.symmetry)) if v]
    if given:
        raise UsageError(f"{', '.join(given)} set the grid model's voxels; the exact model sizes its lattice by the "
                         "drug: drop them or add --model grid")
    s = simulate_barrier_exact(args.input, args.barrier, args.out, barrier_speed=args.barrier_speed, units=args.units,
                               progress=progress)
    print(f"drug {s['volume_mm3']:.1f} mm^3 in {s['barrier_volume_mm3']:.1f} mm^3 of barrier at speed "
          f"{s['barrier_speed']:g}: exact model ({s['method']}), lattice {s['lattice']['spacing_mm']:.4g} mm, "
          f"{s['seconds']:.2f} s -> {args.out}")
    if s["sealed_mm3"] > 0:
        print(f"sealed: {s['sealed_mm3']:.4g} mm^3 of drug in {len(s['sealed_regions_mm3'])} region(s) never releases")
    error = s["error"]
    print(f"error: within {error['error_mm3']:.3g} mm^3 ({error['error_fraction']:.2%} of the drug), "
          f"{error['method']}")
    return 0
