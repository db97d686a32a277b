"""Source shapes for the robustness evidence (docs/benchmarks.md#tools-for-design-experiments).

Writes closed meshes in mm, each scaled to the sample shapes' volume (`design.geometry.shapes.VOLUME_MM3`),
none of them shipped as a sample. Sources the design defaults are tuned on (`TUNING`):

- ``stadium_tablet``: a stadium (rectangle with round ends) extruded, itself an extrusion;
- ``disc_three_holes``: a disc with three through-holes on a circle, itself an extrusion;
- ``hex_prism``: a hexagonal prism, itself an extrusion;
- ``ellipsoid``: an ellipsoid with semi-axes 1 : 0.7 : 0.5;
- ``frustum``: a truncated cone;
- ``bow``: two square pyramids joined at their tips by a short square neck (a polyhedral bow).

Held-out sources, none of which the defaults are tuned on (`FURTHER`):

- ``ring``: an annulus, radii 3 and 8, height 6, an extrusion;
- ``cone``: a cone standing on its base;
- ``capsule``: a capsule lying on its side (axis along x);
- ``slotted_box``: a 16 x 10 x 8 box with a 10 x 3 through-slot along the build axis, an extrusion.

Held-out sources with a void centre or without mirror symmetry (`FRESH`):

- ``tube``: a tube, radii 4 and 6.5, height 14, standing on the build axis, an extrusion;
- ``torus``: a torus lying flat;
- ``l_bracket``: an L-shaped prism, an extrusion without mirror symmetry;
- ``asterisk``: a six-armed star prism turned by 15 degrees, an extrusion without mirror symmetry.

    python -m benchmarks.robust_sources OUT_DIR

Last line: ``sources: <count>``.
"""
from __future__ import annotations

import argparse
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
import trimesh

from design.geometry.shapes import VOLUME_MM3

EXTRUSIONS = ("stadium_tablet", "disc_three_holes", "hex_prism", "ring", "slotted_box", "tube", "l_bracket",
              "asterisk")
"""The sources that are extrusions along z (the build axis), so the extruded space holds them."""


def _stadium_tablet() -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=(2.0, 2.0, 1.2))
    caps = [trimesh.creation.cylinder(radius=1.0, height=1.2, sections=48).apply_translation([x, 0, 0])
            for x in (-1.0, 1.0)]
    return trimesh.boolean.union([box, *caps], engine="manifold")


def _disc_three_holes() -> trimesh.Trimesh:
    disc = trimesh.creation.cylinder(radius=3.0, height=1.6, sections=64)
    holes = [trimesh.creation.cylinder(radius=0.55, height=4.0, sections=32).apply_translation(
        [1.6 * np.cos(a), 1.6 * np.sin(a), 0.0]) for a in np.deg2rad([90.0, 210.0, 330.0])]
    return trimesh.boolean.difference([disc, *holes], engine="manifold")


def _hex_prism() -> trimesh.Trimesh:
    return trimesh.creation.cylinder(radius=1.0, height=1.3, sections=6)


def _ellipsoid() -> trimesh.Trimesh:
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    mesh.apply_scale([1.0, 0.7, 0.5])
    return mesh


def _frustum() -> trimesh.Trimesh:
    profile = np.array([[0.0, 0.0], [1.0, 0.0], [0.45, 1.2], [0.0, 1.2]])
    return trimesh.creation.revolve(profile, sections=64)


def _bow() -> trimesh.Trimesh:
    pyramid = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0], [0, 0, 1.6]], dtype=float)
    left = trimesh.convex.convex_hull(pyramid @ np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], dtype=float).T
                                      - [0.15, 0, 0])
    right = left.copy().apply_transform(trimesh.transformations.reflection_matrix([0, 0, 0], [1, 0, 0]))
    right.invert()
    right.fix_normals()
    neck = trimesh.creation.box(extents=(2.2, 0.5, 0.5))
    return trimesh.boolean.union([left, right, neck], engine="manifold")


def _ring() -> trimesh.Trimesh:
    return trimesh.creation.annulus(r_min=3.0, r_max=8.0, height=6.0, sections=64)


def _cone() -> trimesh.Trimesh:
    return trimesh.creation.cone(radius=1.0, height=1.5, sections=64)


def _capsule() -> trimesh.Trimesh:
    mesh = trimesh.creation.capsule(height=2.0, radius=1.0, count=[32, 32])
    return mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2.0, [0, 1, 0]))


def _slotted_box() -> trimesh.Trimesh:
    slot = trimesh.creation.box(extents=(10.0, 3.0, 12.0))
    return trimesh.boolean.difference([trimesh.creation.box(extents=(16.0, 10.0, 8.0)), slot], engine="manifold")


def _tube() -> trimesh.Trimesh:
    return trimesh.creation.annulus(r_min=4.0, r_max=6.5, height=14.0, sections=64)


def _torus() -> trimesh.Trimesh:
    return trimesh.creation.torus(major_radius=3.0, minor_radius=1.0, major_sections=64, minor_sections=32)


def _l_bracket() -> trimesh.Trimesh:
    foot = trimesh.creation.box(extents=(3.0, 1.0, 1.0)).apply_translation([1.5, 0.5, 0.0])
    leg = trimesh.creation.box(extents=(1.0, 2.5, 1.0)).apply_translation([0.5, 1.25, 0.0])
    return trimesh.boolean.union([foot, leg], engine="manifold")


def _asterisk() -> trimesh.Trimesh:
    bars = [trimesh.creation.box(extents=(3.0, 0.6, 0.8)).apply_transform(
        trimesh.transformations.rotation_matrix(np.deg2rad(15.0 + 60.0 * k), [0, 0, 1])) for k in range(3)]
    return trimesh.boolean.union(bars, engine="manifold")


TUNING = {"stadium_tablet": _stadium_tablet, "disc_three_holes": _disc_three_holes, "hex_prism": _hex_prism,
          "ellipsoid": _ellipsoid, "frustum": _frustum, "bow": _bow}
"""Sources that were in use while the design defaults were chosen."""
FURTHER = {"ring": _ring, "cone": _cone, "capsule": _capsule, "slotted_box": _slotted_box}
FRESH = {"tube": _tube, "torus": _torus, "l_bracket": _l_bracket, "asterisk": _asterisk}
BUILDERS = {**TUNING, **FURTHER, **FRESH}


def centred(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """``mesh`` moved to centre its bounding box at the origin and scaled to volume `VOLUME_MM3`, mm."""
    mesh.apply_translation(-mesh.bounds.mean(axis=0))
    mesh.apply_scale((VOLUME_MM3 / mesh.volume) ** (1.0 / 3.0))
    return mesh


def source(name: str) -> trimesh.Trimesh:
    """A closed mesh centred at the origin with volume `VOLUME_MM3`, mm."""
    mesh = BUILDERS[name]()
    if not mesh.is_watertight:
        raise RuntimeError(f"source {name} is not watertight")
    return centred(mesh)


def write_sources(names: Iterable[str], make: Callable[[str], trimesh.Trimesh], description: str) -> None:
    """The command line of a source script: write ``make(name)`` as ``OUT_DIR/<name>.stl`` for every name."""
    parser = argparse.ArgumentParser(description=description.splitlines()[0])
    parser.add_argument("out_dir", type=Path)
    args = parser.parse_args()
    args.out_dir.mkdir(parents=True, exist_ok=True)
    names = list(names)
    for name in names:
        mesh = make(name)
        mesh.export(args.out_dir / f"{name}.stl")
        print(f"{name}: {mesh.volume:.1f} mm^3, extents {np.round(mesh.extents, 2).tolist()} mm")
    print(f"sources: {len(names)}")


def main() -> None:
    write_sources(BUILDERS, source, __doc__)


if __name__ == "__main__":
    main()
