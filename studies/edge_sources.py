"""Sources at the edges of what `sfr design` takes (docs/benchmarks.md#tools-for-design-experiments).

Unlike `benchmarks/robust_sources.py`, these keep their own size and placement, since those are what
they test:

- ``tilted_offcentre_box``: a 12 x 8 x 5 mm box turned 30 degrees about an oblique axis and moved to
  (40, -25, 7) mm, so neither centred nor aligned with the grid;
- ``wafer``: a 20 x 20 x 1.5 mm plate, thinner than twice the default 1 mm smoothing radius;
- ``rod``: a cylinder 3 mm across and 25 mm long on the build axis;
- ``two_bodies``: two 10 mm cubes 20 mm apart, a source that is itself two pieces;
- ``tiny_sphere``: a sphere of radius 2.3 mm (51 mm^3);
- ``sphere_cm``: a sphere of radius 0.6 written in cm (run with ``--units cm``);
- ``open_sphere``: a sphere with four faces removed, not watertight (refused).

    python -m studies.edge_sources OUT_DIR

Last line: ``sources: <count>``.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import trimesh


def _tilted_offcentre_box() -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=(12.0, 8.0, 5.0))
    box.apply_transform(trimesh.transformations.rotation_matrix(np.deg2rad(30.0), [1.0, 0.3, 0.0]))
    return box.apply_translation([40.0, -25.0, 7.0])


def _two_bodies() -> trimesh.Trimesh:
    cubes = [trimesh.creation.box(extents=(10.0, 10.0, 10.0)).apply_translation([x, 0.0, 0.0]) for x in (0.0, 30.0)]
    return trimesh.util.concatenate(cubes)


def _open_sphere() -> trimesh.Trimesh:
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=5.0)
    sphere.update_faces(np.arange(len(sphere.faces)) > 3)
    return sphere


BUILDERS = {
    "tilted_offcentre_box": _tilted_offcentre_box,
    "wafer": lambda: trimesh.creation.box(extents=(20.0, 20.0, 1.5)),
    "rod": lambda: trimesh.creation.cylinder(radius=1.5, height=25.0, sections=32),
    "two_bodies": _two_bodies,
    "tiny_sphere": lambda: trimesh.creation.icosphere(subdivisions=3, radius=2.3),
    "sphere_cm": lambda: trimesh.creation.icosphere(subdivisions=3, radius=0.6),
    "open_sphere": _open_sphere,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir", type=Path)
    args = parser.parse_args()
    args.out_dir.mkdir(parents=True, exist_ok=True)
    for name, build in BUILDERS.items():
        mesh = build()
        mesh.export(args.out_dir / f"{name}.stl")
        print(f"{name}: watertight {mesh.is_watertight}, extents {np.round(mesh.extents, 2).tolist()}")
    print(f"sources: {len(BUILDERS)}")


if __name__ == "__main__":
    main()
