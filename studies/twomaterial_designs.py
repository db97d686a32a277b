"""Two-material designs of three targets one material cannot release (docs/evidence/materials.md).

Runs `design.files.twomaterial_run.run_two_material` for each target and space into
``OUT/<name>-<space>-<resolution>`` and prints one table row per design; copies each design's ``materials.png``
to ``docs/figures/materials_design_<name>_<space>_<resolution>.png``.

    python -m studies.twomaterial_designs OUT [--resolution 48] [--max-iter 150] [--spaces nfc,extruded]
        [--targets delay-zero,pulses,constant]
"""
from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

from design.files.twomaterial_run import run_two_material
from design.inverse.twomaterial_problem import TwoMaterialSettings

TARGETS = {
    "delay-zero": ("delay-zero:delay=2,rate=10,volume=20", 0.25),
    "pulses": ("pulses:volume=8,width=1.25,gap=2", 0.25),
    "constant": ("constant:rate=4,volume=16", 0.0),
}
"""Name -> (target spec, barrier speed) of the three targets."""


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--resolution", type=int, default=48)
    parser.add_argument("--max-iter", type=int, default=150)
    parser.add_argument("--spaces", default="nfc,extruded")
    parser.add_argument("--targets", default=",".join(TARGETS))
    parser.add_argument("--figures", type=Path, default=Path("docs/figures"))
    parser.add_argument("--no-reference", action="store_true", help="skip the two-material reference evaluator")
    args = parser.parse_args(argv)
    print("| target | s | space | resolution | grid fit | reference fit | density fit | pieces (print/drug/barrier) "
          "| thinnest wall (mm) | cover (mm) | thickened | seconds |")
    for name in args.targets.split(","):
        spec, s = TARGETS[name]
        for space in args.spaces.split(","):
            out = args.out / f"{name}-{space}-{args.resolution}"
            out.mkdir(parents=True, exist_ok=True)
            t0 = time.process_time()
            r = run_two_material(TwoMaterialSettings(spec, s, space=space, resolution=args.resolution,
                                                     max_iter=args.max_iter), out, reference=not args.no_reference)
            m = r.summary
            ref = "-" if m["reference_fit"] is None else f"{m['reference_fit']:.3f}"
            wall = "-" if m["barrier"]["min_wall_mm"] is None else f"{m['barrier']['min_wall_mm']:.3f}"
            print(f"| {spec} | {s:g} | {space} | {args.resolution} | {m['grid_fit']:.3f} | {ref} | {m['density_fit']:.3f} | "
                  f"{m['print_pieces']}/{m['drug']['pieces']}/{m['barrier']['pieces']} | {wall} | "
                  f"{m['barrier']['cover_mm']:.3f} | {m['thickened_voxels']} | {time.process_time() - t0:.0f} CPU |",
                  flush=True)
            if args.figures:
                shutil.copyfile(out / "materials.png", args.figures / f"materials_design_{name}_{space}_{args.resolution}.png")


if __name__ == "__main__":
    main()
