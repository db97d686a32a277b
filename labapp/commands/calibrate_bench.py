"""`sfr calibrate-bench`: fit the per-cell Beer-Lambert calibration from a series of known concentrations."""
from __future__ import annotations

import argparse
import logging
import sys

log = logging.getLogger(__name__)

NAME = "calibrate-bench"
HELP = "fit the bench calibration (transmittance vs concentration per cell) from a masses.csv image series"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `sfr calibrate-bench`."""
    parser.add_argument("folder", help="folder with the images and masses.csv (file,added_mass_g cumulative, g)")
    parser.add_argument("--water-g", type=float, default=500.0, help="water mass, g (default 500)")
    parser.add_argument("--crop", help="x,y,size of the square crop inside the beaker, px "
                                       "(default: the series' run.json crop, else centred at W/4, H/2, side min(W,H)/4)")
    parser.add_argument("--grid", type=int, default=10, help="cells per side (default 10)")
    parser.add_argument("--mirror-col", type=float, help="column of the mirror axis, px (default: image centre)")
    parser.add_argument("--no-mirror", action="store_true",
                        help="skip the mirror normalisation (for comparison only)")
    parser.add_argument("--reduce", type=int, default=1, choices=(1, 2, 4, 8),
                        help="decode downscaled by this factor (default 1)")
    parser.add_argument("--camera", default="", help="camera settings to record, e.g. 'aperture=22,shutter=1/125,iso=160'")
    parser.add_argument("--out", default="calibration.json", help="output JSON (default calibration.json)")


def _parse_crop(text: str) -> tuple[int, int, int]:
    try:
        x, y, size = (int(v) for v in text.split(","))
    except ValueError:
        raise SystemExit(f"--crop {text!r}: expected three integers x,y,size (px)") from None
    return x, y, size


def _recorded_crop(folder) -> tuple[int, int, int] | None:
    """The crop a series recorded by `sfr lab`/`sfr run` stored in its run.json, if any (x, y, size px)."""
    import json

    try:
        crop = json.loads((folder / "run.json").read_text())["crop"]
        return int(crop["x"]), int(crop["y"]), int(crop["size"])
    except FileNotFoundError:
        return None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SystemExit(f"error: {folder / 'run.json'} has no usable crop {{x, y, size}} (px): {exc}") from None


def run(args: argparse.Namespace) -> int:
    """Read the series, fit, save; print a per-level and per-cell summary."""
    import csv
    from pathlib import Path

    import numpy as np

    from analysis import AnalysisError, CropGeometry, decode_image, default_geometry, fit_bench_calibration, read_cells

    folder = Path(args.folder)
    try:
        with open(folder / "masses.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
        files = [folder / r["file"] for r in rows]
        masses = np.array([float(r["added_mass_g"]) for r in rows])
    except (OSError, KeyError, ValueError) as exc:
        print(f"error: cannot read {folder / 'masses.csv'} (columns file,added_mass_g): {exc}", file=sys.stderr)
        return 2
    if np.any(np.diff(masses) < 0):
        print("error: added_mass_g must be cumulative (never decreasing) in masses.csv", file=sys.stderr)
        return 2
    conc = masses / args.water_g * 1000.0
    camera = dict(item.split("=", 1) for item in args.camera.split(",") if "=" in item)
    try:
        shape = decode_image(files[0]).shape[:2] if files else None
        if shape is None:
            raise AnalysisError(f"{folder / 'masses.csv'} lists no images")
        crop = _parse_crop(args.crop) if args.crop else _recorded_crop(folder)
        if crop:
            geometry = CropGeometry(*crop, args.grid, args.mirror_col, not args.no_mirror)
        else:
            base = default_geometry(shape, args.grid)
            geometry = CropGeometry(base.x, base.y, base.size, args.grid, args.mirror_col, not args.no_mirror)
        cells = np.array([read_cells(f, geometry, reduce=args.reduce, expect_shape=shape) for f in files])
        cal = fit_bench_calibration(cells, conc, geometry, args.water_g, camera, image_shape=shape,
                                    reduce=args.reduce)
        cal.save(args.out)
    except AnalysisError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    g = geometry.grid
    print(f"crop x={geometry.x} y={geometry.y} size={geometry.size} px, {g}x{g} cells, "
          f"mirror {'off' if args.no_mirror else 'on'}; {len(files)} frames, {np.unique(conc).size} levels "
          f"{', '.join(f'{c:.3f}' for c in np.unique(conc))} g/kg")
    print(f"k per g/kg: median {np.median(cal.k):.4f}, range {cal.k.min():.4f}..{cal.k.max():.4f}; "
          f"t0 median {np.median(cal.t0):.4f}")
    print(f"fit residual (relative rms): median {np.median(cal.rms_rel):.2e}, worst {cal.rms_rel.max():.2e}")
    bad = [divmod(int(i), g) for i in np.flatnonzero(~cal.good)]
    print(f"cells not used: {bad if bad else 'none'}")
    print(f"wrote {args.out}")
    return 0
