"""`sfr calibrate-bench`: fit the per-cell Beer-Lambert calibration from a series of known concentrations."""
from __future__ import annotations

import argparse

from labapp.cli.argtypes import finite_float, positive_float, positive_int

NAME = "calibrate-bench"
HELP = "fit the bench calibration (transmittance vs concentration per cell) from a masses.csv image series"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr calibrate-bench`."""
    parser.add_argument("folder", help="folder with the images and masses.csv (file,added_mass_g cumulative, g)")
    parser.add_argument("--water-g", type=positive_float, default=500.0, help="water mass, g (default 500)")
    parser.add_argument("--crop", type=_parse_crop,
                        help="x,y,size of the square crop inside the beaker, px (default: the series' run.json "
                             "crop, else centred at W/4, H/2, side min(W,H)/4)")
    parser.add_argument("--grid", type=positive_int, default=10, help="cells per side (default 10)")
    parser.add_argument("--mirror-col", type=finite_float, help="column of the mirror axis, px (default: image centre)")
    parser.add_argument("--no-mirror", action="store_true",
                        help="skip the mirror normalisation (for comparison only)")
    parser.add_argument("--reduce", type=int, default=1, choices=(1, 2, 4, 8),
                        help="decode downscaled by this factor (default 1)")
    parser.add_argument("--camera", default="", help="camera settings to record, e.g. 'aperture=22,shutter=1/125,iso=160'")
    parser.add_argument("--out", default="calibration.json",
                        help="output JSON, a new file outside the series folder (default calibration.json)")


def _parse_crop(text: str) -> tuple[int, int, int]:
    try:
        x, y, size = (int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected three integers x,y,size (px)") from None
    if min(x, y) < 0 or size < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected x, y >= 0 and size >= 1 (px)")
    return x, y, size


def run(args: argparse.Namespace) -> int:
    """Read the series, fit, save; print a per-level and per-cell summary."""
    import numpy as np

    from labapp.jobs.calibrate_bench import calibrate_series

    camera = dict(item.split("=", 1) for item in args.camera.split(",") if "=" in item)
    cal = calibrate_series(args.folder, args.out, water_g=args.water_g, crop=args.crop, grid=args.grid,
                           mirror_col=args.mirror_col, mirror=not args.no_mirror, reduce=args.reduce, camera=camera)
    geometry, levels = cal.geometry, np.unique(cal.conc_levels_g_per_kg)
    g = geometry.grid
    print(f"crop x={geometry.x} y={geometry.y} size={geometry.size} px, {g}x{g} cells, "
          f"mirror {'off' if args.no_mirror else 'on'}; {len(cal.conc_levels_g_per_kg)} frames, {levels.size} levels "
          f"{', '.join(f'{c:.3f}' for c in levels)} g/kg")
    print(f"k per g/kg: median {np.median(cal.k):.4f}, range {cal.k.min():.4f}..{cal.k.max():.4f}; "
          f"t0 median {np.median(cal.t0):.4f}")
    print(f"fit residual (relative rms): median {np.median(cal.rms_rel):.2e}, worst {cal.rms_rel.max():.2e}")
    bad = [divmod(int(i), g) for i in np.flatnonzero(~cal.good)]
    print(f"cells not used: {bad if bad else 'none'}")
    print(f"wrote {args.out}")
    return 0
