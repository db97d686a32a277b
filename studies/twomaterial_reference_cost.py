"""The two-material reference evaluator on analytic cases and on coated parts (docs/evidence/materials.md).

Prints one table row per case: the analytic cases with their error against the exact release, and the coated
parts (the 1326 mm^3 pill in box coats, a coated slab, the designs' capped column) with the lattice chosen, the
stated error and the CPU seconds of the evaluation.

    python -m studies.twomaterial_reference_cost [--cases analytic,pill,slab,column] [--pill pill1_0.3,...]
"""
from __future__ import annotations

import argparse
import time

import numpy as np
import trimesh

from design.forward.solid_lattice import TooThinError
from design.forward.twomaterial_reference import two_material_reference_release
from design.geometry.shapes import sample_shape


def box(lo, hi) -> trimesh.Trimesh:
    """An axis-aligned box from corner ``lo`` to corner ``hi``, mm."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return trimesh.creation.box(hi - lo).apply_translation((lo + hi) / 2)


def analytic_cases() -> list[tuple]:
    """(name, drug, barrier, s, tau, exact release, keyword arguments) of the analytic cases."""
    tau_slab, tau_coat, tau_col = np.linspace(0.0, 0.6, 31), np.linspace(0.0, 3.2, 65), np.linspace(0.0, 1.8, 37)
    slab = [box([-1.2, -1.2, -0.4], [1.2, 1.2, 0.4]), box([-1.2, -1.2, -0.5], [1.2, 1.2, 0.5]), 0.5, tau_slab]
    design_tau = np.array([2.5, 3.0, 3.5])
    return [
        ("half cube", box([-1, -1, -1], [1, 1, 0]), box([-1, -1, 0], [1, 1, 1]), 1.0, np.linspace(0, 1.1, 45),
         lambda t: 0.5 * (8.0 - np.clip(2.0 - 2.0 * t, 0.0, None) ** 3), {}),
        ("cup", box([-1, -1, -1], [1, 1, 0]), box([-1.5, -1.5, -1.5], [1.5, 1.5, 0]), 0.0, np.linspace(0, 1.2, 25),
         lambda t: 4 * np.clip(t, 0, 1), {}),
        *[(f"slab, anisotropy {a:g}", *slab, lambda t, a=a: 4.608 - (2.4 - 2 * t).clip(0) ** 2
           * (0.8 - 2 * a * np.maximum(t - 0.1 / (0.5 * a), 0)).clip(0), {"anisotropy": a}) for a in (1.0, 0.5)],
        ("coated cube (tolerance 1%)", box([-1] * 3, [1] * 3), box([-2] * 3, [2] * 3), 0.5, tau_coat,
         lambda t: 8.0 - np.clip(2.0 - 2.0 * (t - 2.0), 0.0, 2.0) ** 3, {"tolerance": 0.01}),
        ("small capped column", box([-0.6, -0.6, -0.8], [0.6, 0.6, 0.8]), box([-1.2, -1.2, -1.0], [1.2, 1.2, 1.0]),
         0.25, tau_col, lambda t: 2.88 * np.clip(t - 0.8, 0, 0.8), {}),
        ("the designs' capped column", box([-1.2, -1.2, -1.9], [1.2, 1.2, 1.9]),
         box([-2.4, -2.4, -2.38], [2.4, 2.4, 2.38]), 0.25, design_tau, lambda t: 11.52 * (t - 1.92), {}),
    ]


def coated_parts(pills: list[str]) -> dict[str, tuple]:
    """name -> (drug, barrier, s): the pill in box coats (``pill<coat>_<s>``), a coated slab, the capped column."""
    pill = sample_shape("pill")
    lo, hi = pill.bounds
    parts = {"slab": (box([-5, -5, -1], [5, 5, 1]), box([-6, -6, -2], [6, 6, 2]), 0.3),
             "column": (box([-1.2, -1.2, -1.9], [1.2, 1.2, 1.9]), box([-2.4, -2.4, -2.38], [2.4, 2.4, 2.38]), 0.25)}
    for name in pills:
        coat, s = (float(v) for v in name[len("pill"):].split("_"))
        parts[name] = (pill, box(lo - coat, hi + coat), s)
    return parts


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default="analytic,pill,slab,column")
    parser.add_argument("--pill", default="pill0.5_0.3,pill0.5_1,pill1_0,pill1_0.3,pill1_1,pill2_0.3,pill2_1")
    args = parser.parse_args(argv)
    cases = args.cases.split(",")
    if "analytic" in cases:
        print("| case | s | drug (mm^3) | error (mm^3) | stated (mm^3) | h (mm) | CPU s |")
        for name, drug, barrier, s, tau, exact, kw in analytic_cases():
            c = time.process_time()
            ref = two_material_reference_release(drug, barrier, s, tau, **kw)
            error = np.abs(ref.released_mm3 - exact(ref.tau_mm)).max()
            print(f"| {name} | {s:g} | {ref.volume_mm3:.4g} | {error:.2g} | {ref.error_mm3:.2g} | {ref.cell_mm:.3g} | "
                  f"{time.process_time() - c:.1f} |", flush=True)
    parts = coated_parts(args.pill.split(",") if "pill" in cases else [])
    print("| part | s | h (mm) | stated (% of the drug) | sealed (mm^3) | CPU s | wall s |")
    for name, (drug, barrier, s) in parts.items():
        if name.startswith("pill") or name in cases:
            c, w = time.process_time(), time.perf_counter()
            try:
                ref = two_material_reference_release(drug, barrier, s)
            except TooThinError as exc:
                print(f"| {name} | {s:g} | refused: {exc.spacing_mm:.3g} mm needed | - | - | "
                      f"{time.process_time() - c:.1f} | {time.perf_counter() - w:.1f} |", flush=True)
                continue
            print(f"| {name} | {s:g} | {ref.cell_mm:.3g} | {100 * ref.relative_error:.3g} | {ref.sealed_mm3:.4g} | "
                  f"{time.process_time() - c:.1f} | {time.perf_counter() - w:.1f} |", flush=True)


if __name__ == "__main__":
    main()
