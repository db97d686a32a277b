"""How precisely the voxel simulator measures the rate deviation metric (docs/benchmarks.md#tools-for-design-experiments).

`design.inverse.rate.rate_deviation` judges a release on 20 sub-intervals of its 10%-90% span; where
that span is a few voxels of tau, each sub-interval is a fraction of a voxel
(`design.inverse.rate.RATE_SPAN_MIN_VOX`). This simulates a thin plate (16 x 16 mm, thickness c) whose exact release is
known, ``C(t) = abc - (a - 2t)(b - 2t)(c - 2t)``, voxelised on the voxels of a curve target's
default 20 mm domain at RESOLUTION voxels, aligned with the grid and turned by 17 degrees, each at the
grid's origin and at two random sub-voxel offsets, and prints the metric of the simulated and of the
exact curve. Their difference is the simulator's error in the metric for that placement.

    python -m studies.rate_metric_grid [--resolution 128 256] [--thickness 2.0]

Last line: ``largest error: <points> at <resolution>, ...``.
"""
from __future__ import annotations

import argparse

import numpy as np
import trimesh

from design.forward.simulator import simulate
from design.geometry.voxelize import voxelize
from design.inverse.rate import rate_deviation

DOMAIN_MM = 20.0
"""Edge of the zero-order runs' cubic domain, mm (its voxel at a given resolution)."""
SIDE_MM = 16.0
"""The plate's side, mm."""


def plate_metric(dx_mm: float, thickness_mm: float, angle_deg: float, offset_vox: np.ndarray) -> tuple[float, float]:
    """Rate deviation of the simulated and of the exact release of one placed plate."""
    plate = trimesh.creation.box(extents=(SIDE_MM, SIDE_MM, thickness_mm))
    plate.apply_transform(trimesh.transformations.rotation_matrix(np.deg2rad(angle_deg), [0.0, 0.0, 1.0]))
    side = 2 * int(np.ceil((1.5 * SIDE_MM / dx_mm + 8) / 2))
    height = 2 * int(np.ceil((thickness_mm / dx_mm + 8) / 2))
    shape = (side, side, height)
    origin = -0.5 * dx_mm * np.asarray(shape, float) + offset_vox * dx_mm
    rho = voxelize(plate, dx_mm, origin_mm=origin, shape=shape)
    release = simulate(rho, dx_mm, total_time_mm=0.65 * thickness_mm)
    t = np.minimum(release.tau_mm, 0.5 * thickness_mm)
    exact = SIDE_MM ** 2 * thickness_mm - (SIDE_MM - 2 * t) ** 2 * (thickness_mm - 2 * t)
    return rate_deviation(release.tau_mm, release.released_mm3), rate_deviation(release.tau_mm, exact)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", type=int, nargs="+", default=[128, 256])
    parser.add_argument("--thickness", type=float, default=2.0, help="plate thickness, mm")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    worst = []
    print("| resolution | angle | offset | simulated | exact | error (points) |")
    print("|---|---|---|---|---|---|")
    for resolution in args.resolution:
        errors = []
        for angle in (0.0, 17.0):
            for k in range(3):
                offset = rng.uniform(0.0, 1.0, 3) if k else np.zeros(3)
                simulated, exact = plate_metric(DOMAIN_MM / resolution, args.thickness, angle, offset)
                errors.append(100.0 * (simulated - exact))
                print(f"| {resolution} | {angle:g} | {k} | {simulated:.2%} | {exact:.2%} | {errors[-1]:+.2f} |",
                      flush=True)
        worst.append(f"{max(errors, key=abs):+.2f} at {resolution}")
    print("largest error: " + ", ".join(worst))


if __name__ == "__main__":
    main()
