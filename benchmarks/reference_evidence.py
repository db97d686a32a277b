"""Evidence for docs/forward.md#reference-evaluator: the reference evaluator against analytic releases.

Releases each validation shape of tests/design/forward/test_reference.py (sphere, cylinder, box off the
lattice, torus, a sphere with an off-centre sealed void, a ball in a sealed void inside a shell) with
`design.forward.reference.reference_release` at each lattice size and prints one markdown row per shape
and size: the largest error against the analytic curve and the stated error estimate, both as a
percentage of the volume, and the wall time on one core.

    python benchmarks/reference_evidence.py [--cells 64 160]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "design" / "forward"))
from test_reference import box, cylinder, hollow, nested, sphere, torus  # noqa: E402

from design.forward.reference import DEFAULT_CELLS, reference_release  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs="+", default=[64, DEFAULT_CELLS])
    args = parser.parse_args()
    reference_release(box()[0], [0.0, 1.0], cells=16)  # compile the kernels outside the timings
    print("| shape | faces | cells | max error, % of volume | stated estimate, % | seconds |")
    print("|---|---|---|---|---|---|")
    for shape in (sphere, cylinder, box, torus, hollow, nested):
        mesh, depth, exact = shape()
        tau = np.linspace(0.0, 1.02 * depth, 1001)
        for cells in args.cells:
            ref = reference_release(mesh, tau, cells=cells)
            error = np.abs(ref.released_mm3 - exact(tau)).max() / ref.volume_mm3
            print(f"| {shape.__name__} | {len(mesh.faces)} | {cells} | {100 * error:.3f} | "
                  f"{100 * ref.relative_error:.3f} | {ref.seconds:.1f} |", flush=True)


if __name__ == "__main__":
    main()
