"""`sfr simulate`: the release curve of a mesh, a sample shape or a density array."""
from __future__ import annotations

import argparse
import logging
import sys

log = logging.getLogger(__name__)

NAME = "simulate"
HELP = "simulate the release curve of a mesh (STL/OBJ/PLY/OFF/3MF), sample:NAME or a density .npy/.npz"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", metavar="INPUT",
                        help="mesh file in mm, density array (.npz with rho and dx_mm, or .npy with --voxel-size), "
                             "or sample:NAME (sphere, pill, spinner_top, csg, polyhedron)")
    size = parser.add_mutually_exclusive_group()
    size.add_argument("--resolution", type=int, metavar="N",
                      help="voxels along the longest bounding-box side (default 64)")
    size.add_argument("--voxel-size", type=float, metavar="MM", help="voxel edge length in mm")
    parser.add_argument("--symmetry", default="", metavar="AXES",
                        help="mirror planes through the bounding-box centre on these axes, e.g. xyz: simulates "
                             "one half/quadrant/octant; the curve is still the full object's")
    parser.add_argument("--out", default="simulation", metavar="DIR", help="output folder (default ./simulation)")
    parser.add_argument("--simcal", metavar="SIMCAL.json",
                        help="simulation calibration (sfr calibrate-sim): also write release_physical.csv "
                             "(t_s,released_g,conc_g_per_kg) and release_physical.png; simulates at its resolution")
    parser.add_argument("--water-g", type=float, help="bath water for the physical curve, g (default: the "
                        "calibration's)")


def _progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def _save_plot(tau_mm, released_mm3, path, title: str) -> None:
    """The cumulative curve and its rate dC/dtau, one above the other."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(6, 6), constrained_layout=True)
    top.plot(tau_mm, released_mm3)
    top.set_ylabel("released volume C (mm$^3$)")
    top.set_title(f"simulated release: {title}")
    bottom.plot(tau_mm, np.gradient(released_mm3, tau_mm))
    bottom.set_ylabel("rate dC/d$\\tau$ (mm$^3$/mm)")
    bottom.set_xlabel("dissolution time $\\tau$ (mm dissolved)")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    import json
    import time
    from pathlib import Path

    import numpy as np

    from design import DesignError, simulate
    from design.pipeline import input_grid

    from labapp.simcal import check_resolution, load_simcal
    from labapp.targets import write_release_physical

    simcal = None
    if args.simcal:
        simcal = load_simcal(args.simcal)
        if args.voxel_size is not None:
            print(f"sfr simulate: {args.simcal} holds for resolution {simcal.resolution}; drop --voxel-size",
                  file=sys.stderr)
            return 2
        args.resolution = check_resolution(simcal, args.resolution)
    start = time.perf_counter()
    try:
        _progress(f"[1/3] loading and voxelising {args.input} ...")
        rho, dx, mirror = input_grid(args.input, resolution=args.resolution, voxel_size_mm=args.voxel_size,
                                     symmetry=args.symmetry)
        _progress(f"[2/3] fast marching {rho.size:,} voxels of {dx:.4g} mm "
                  f"({time.perf_counter() - start:.1f} s) ...")
        release = simulate(rho, dx, mirror=mirror)
    except DesignError as exc:
        print(f"sfr simulate: {exc}", file=sys.stderr)
        return 2
    seconds = time.perf_counter() - start
    out = Path(args.out)
    _progress(f"[3/3] writing {out}/ ({seconds:.1f} s)")
    out.mkdir(parents=True, exist_ok=True)
    np.savetxt(out / "release.csv", np.column_stack([release.tau_mm, release.released_mm3]), delimiter=",",
               header="tau_mm,released_mm3", comments="", fmt="%.9g")
    summary = {
        "input": args.input,
        "volume_mm3": release.volume_mm3,
        "total_time_mm": release.total_time_mm,
        "voxels": int(rho.size),
        "grid_shape": list(rho.shape),
        "voxel_size_mm": dx,
        "mirror": list(mirror),
        "dtau_mm": release.dtau_mm,
        "seconds": seconds,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    _save_plot(release.tau_mm, release.released_mm3, out / "release.png", args.input)
    if simcal is not None:
        physical = write_release_physical(release.tau_mm, release.released_mm3, simcal, out, args.water_g,
                                          title=args.input)
        grams = np.loadtxt(physical, delimiter=",", skiprows=1)
        summary["physical"] = {"simcal": str(simcal.path), "model": simcal.cal.model,
                               "mass_g": float(grams[-1, 1]), "duration_s": float(grams[-1, 0]),
                               "water_g": args.water_g or simcal.water_g}
        (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
        print(f"predicted: {grams[-1, 1]:.3f} g released over {grams[-1, 0] / 3600:.2f} h "
              f"({simcal.describe()}) -> {physical}")
    print(f"volume {release.volume_mm3:.1f} mm^3, T = {release.total_time_mm:.3f} mm, {rho.size:,} voxels, "
          f"{seconds:.2f} s -> {out}")
    return 0
