"""Evidence for docs/forward.md#reference-evaluator: the reference evaluator against analytic releases.

Releases each mesh of `benchmarks.analytic` (the validation shapes of tests/design/forward/test_reference.py:
sphere, cylinder, box off the lattice, torus, a sphere with an off-centre sealed void, a ball in a sealed void
inside a shell) with
`design.forward.reference.reference_release` at each lattice size and prints one markdown row per shape
and size: the largest error against the analytic curve and the stated error estimate, both as a
percentage of the volume, and the wall time on one core.

    python -m studies.reference_evidence [--cells 64 160]
"""
from __future__ import annotations

import argparse

import numpy as np

from benchmarks.analytic import MESHES, box
from design.forward.reference import DEFAULT_CELLS, reference_release


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs="+", default=[64, DEFAULT_CELLS])
    args = parser.parse_args()
    reference_release(box()[0], [0.0, 1.0], cells=16)  # compile the kernels outside the timings
    print("| shape | faces | cells | max error, % of volume | stated estimate, % | seconds |")
    print("|---|---|---|---|---|---|")
    for shape in MESHES:
        mesh, depth, exact = shape()
        tau = np.linspace(0.0, 1.02 * depth, 1001)
        for cells in args.cells:
            ref = reference_release(mesh, tau, cells=cells)
            error = np.abs(ref.released_mm3 - exact(tau)).max() / ref.volume_mm3
            print(f"| {shape.__name__} | {len(mesh.faces)} | {cells} | {100 * error:.3f} | "
                  f"{100 * ref.relative_error:.3f} | {ref.seconds:.1f} |", flush=True)


if __name__ == "__main__":
    main()
