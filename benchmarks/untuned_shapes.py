"""Source shapes no design default was chosen on, for the physical-correction study (docs/design.md#physical-correction).

Each builder returns a closed mesh; `source` centres it and scales it to the sample shapes' volume
(`design.geometry.shapes.VOLUME_MM3`). None of them is a shipped sample or a source of
benchmarks/robust_sources.py. The random ones (a perturbed polyhedron) take their numbers from a fixed seed,
so a name always builds the same mesh.

- ``tilted_capsule``: a capsule turned 35 degrees out of the xy-plane;
- ``triaxial_ellipsoid``: an ellipsoid with semi-axes 1 : 0.62 : 0.38, turned about z and x;
- ``fused_spheres``: two spheres of radii 1 and 0.75 whose centres are 1.2 apart;
- ``truncated_pyramid``: a square frustum, base 2, top 0.9, height 1.1;
- ``hemisphere``: a dome standing on its flat face;
- ``rock``: the convex hull of 40 seeded points on a sphere, radii varied by 25%;
- ``star_prism``: a five-pointed star prism (an extrusion);
- ``octagon_bore``: an octagonal prism with an off-centre round bore (an extrusion);
- ``disc_offset_holes``: a disc with two holes of different sizes away from its centre (an extrusion);
- ``c_ring``: a ring with a 60 degree gap (an extrusion);
- ``rounded_box_bore``: a box with rounded vertical edges and a central round bore (an extrusion);
- ``cross_prism``: a plus-sign prism with unequal arms (an extrusion).

    python -m benchmarks.untuned_shapes OUT_DIR

Last line: ``sources: <count>``.
"""
from __future__ import annotations

import manifold3d
import numpy as np
import trimesh

from benchmarks import robust_sources

SEED = 20261203
"""Seed of the shapes drawn at random (``rock``)."""


def _tilted_capsule() -> trimesh.Trimesh:
    mesh = trimesh.creation.capsule(height=2.4, radius=0.8, count=[32, 32])
    return mesh.apply_transform(trimesh.transformations.rotation_matrix(np.deg2rad(55.0), [0, 1, 0]))


def _triaxial_ellipsoid() -> trimesh.Trimesh:
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    mesh.apply_scale([1.0, 0.62, 0.38])
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.deg2rad(25.0), [0, 0, 1]))
    return mesh.apply_transform(trimesh.transformations.rotation_matrix(np.deg2rad(20.0), [1, 0, 0]))


def _fused_spheres() -> trimesh.Trimesh:
    big = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    small = trimesh.creation.icosphere(subdivisions=4, radius=0.75).apply_translation([1.2, 0.0, 0.0])
    return trimesh.boolean.union([big, small], engine="manifold")


def _truncated_pyramid() -> trimesh.Trimesh:
    b, t, h = 1.0, 0.45, 1.1
    points = [(x * b, y * b, 0.0) for x in (-1, 1) for y in (-1, 1)] + [(x * t, y * t, h) for x in (-1, 1) for y in (-1, 1)]
    return trimesh.convex.convex_hull(np.array(points, dtype=float))


def _hemisphere() -> trimesh.Trimesh:
    angles = np.linspace(0.0, np.pi / 2.0, 24)
    profile = np.vstack([[0.0, 0.0], np.column_stack([np.cos(angles), np.sin(angles)])])
    return trimesh.creation.revolve(profile, sections=64)


def _rock() -> trimesh.Trimesh:
    rng = np.random.default_rng(SEED)
    directions = rng.standard_normal((40, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    radii = 1.0 + 0.25 * rng.uniform(-1.0, 1.0, 40)
    return trimesh.convex.convex_hull(directions * radii[:, None])


def _prism(outline: np.ndarray, height: float, holes: list[np.ndarray] | None = None) -> trimesh.Trimesh:
    """The prism of a polygon (x, y rows) with holes, ``height`` along z (manifold3d's even-odd fill)."""
    solid = manifold3d.CrossSection([outline, *(holes or [])]).extrude(height).to_mesh()
    return trimesh.Trimesh(vertices=solid.vert_properties[:, :3], faces=solid.tri_verts)


def _circle(cx: float, cy: float, r: float, n: int = 48) -> np.ndarray:
    a = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.column_stack([cx + r * np.cos(a), cy + r * np.sin(a)])


def _star_prism() -> trimesh.Trimesh:
    a = np.pi / 2.0 + np.arange(10) * np.pi / 5.0
    r = np.where(np.arange(10) % 2 == 0, 1.0, 0.45)
    return _prism(np.column_stack([r * np.cos(a), r * np.sin(a)]), 0.5)


def _octagon_bore() -> trimesh.Trimesh:
    a = np.pi / 8.0 + np.arange(8) * np.pi / 4.0
    return _prism(np.column_stack([np.cos(a), np.sin(a)]), 0.9, [_circle(0.3, 0.1, 0.3)[::-1]])


def _disc_offset_holes() -> trimesh.Trimesh:
    return _prism(_circle(0.0, 0.0, 1.0, 96), 0.45, [_circle(0.45, 0.2, 0.28)[::-1], _circle(-0.4, -0.35, 0.18)[::-1]])


def _c_ring() -> trimesh.Trimesh:
    a = np.deg2rad(np.linspace(30.0, 330.0, 61))
    outline = np.vstack([np.column_stack([np.cos(a), np.sin(a)]), np.column_stack([0.6 * np.cos(a[::-1]),
                                                                                    0.6 * np.sin(a[::-1])])])
    return _prism(outline, 0.5)


def _rounded_box_bore() -> trimesh.Trimesh:
    w, d, r = 1.0, 0.7, 0.25
    corners = [(w - r, d - r, 0.0), (-w + r, d - r, 90.0), (-w + r, -d + r, 180.0), (w - r, -d + r, 270.0)]
    outline = np.vstack([np.column_stack([cx + r * np.cos(np.deg2rad(s + np.linspace(0, 90, 9))),
                                          cy + r * np.sin(np.deg2rad(s + np.linspace(0, 90, 9)))])
                         for cx, cy, s in corners])
    return _prism(outline, 0.8, [_circle(0.0, 0.0, 0.3)[::-1]])


def _cross_prism() -> trimesh.Trimesh:
    outline = np.array([[-1.0, -0.25], [-0.25, -0.25], [-0.25, -0.7], [0.25, -0.7], [0.25, -0.25], [0.6, -0.25],
                        [0.6, 0.25], [0.25, 0.25], [0.25, 1.0], [-0.25, 1.0], [-0.25, 0.25], [-1.0, 0.25]])
    return _prism(outline, 0.6)


SOLIDS = {"tilted_capsule": _tilted_capsule, "triaxial_ellipsoid": _triaxial_ellipsoid,
          "fused_spheres": _fused_spheres, "truncated_pyramid": _truncated_pyramid, "hemisphere": _hemisphere,
          "rock": _rock}
"""Sources that are not extrusions along z."""
EXTRUSIONS = {"star_prism": _star_prism, "octagon_bore": _octagon_bore, "disc_offset_holes": _disc_offset_holes,
              "c_ring": _c_ring, "rounded_box_bore": _rounded_box_bore, "cross_prism": _cross_prism}
"""Sources that are extrusions along z (the build axis), so the extruded space can hold them exactly."""
BUILDERS = {**SOLIDS, **EXTRUSIONS}


def source(name: str) -> trimesh.Trimesh:
    """The closed mesh ``name`` centred at the origin with volume `VOLUME_MM3`, mm."""
    mesh = BUILDERS[name]()
    mesh.process(validate=True)
    if not mesh.is_watertight or not mesh.is_volume:
        raise RuntimeError(f"source {name} is not a closed volume")
    return robust_sources.centred(mesh)


def main() -> None:
    robust_sources.write_sources(BUILDERS, source, __doc__)


if __name__ == "__main__":
    main()
