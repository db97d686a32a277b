"""Procedural sample shapes: closed meshes in mm, each scaled to the same ~1.75 g print (section 5.1)."""
from __future__ import annotations

import numpy as np
import trimesh

from design.errors import DesignError
from design.material import PRINT_DENSITY_G_PER_CM3

PRINT_MASS_G = 1.75
"""Mass of every sample print, g (the paper's forward-model shapes weigh ~1.75 g)."""
VOLUME_MM3 = PRINT_MASS_G / PRINT_DENSITY_G_PER_CM3 * 1000.0
"""Solid volume of every sample shape, mm^3 (about 1326)."""

SAMPLE_SHAPES: tuple[str, ...] = ("sphere", "pill", "spinner_top", "csg", "polyhedron")


def _sphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=3, radius=1.0)


def _pill() -> trimesh.Trimesh:
    # a capsule 3 radii long between its cap centres, lying along x
    mesh = trimesh.creation.capsule(height=3.0, radius=1.0, count=[24, 24])
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    return mesh


def _spinner_top() -> trimesh.Trimesh:
    # profile (radius, height) revolved about z: a cone tip, a wide disc and a stem
    profile = np.array([[0.0, 0.0], [7.0, 5.0], [7.0, 7.0], [2.0, 7.0], [2.0, 12.0], [0.0, 12.0]])
    return trimesh.creation.revolve(profile, sections=48)


def _csg() -> trimesh.Trimesh:
    # a block with two round through-holes and a square pocket (boolean difference via manifold3d)
    block = trimesh.creation.box(extents=(16.0, 12.0, 8.0))
    hole = trimesh.creation.cylinder(radius=2.0, height=20.0, sections=32)
    holes = [hole.copy().apply_translation([x, 0.0, 0.0]) for x in (-4.5, 4.5)]
    pocket = trimesh.creation.box(extents=(4.0, 4.0, 6.0)).apply_translation([0.0, 0.0, 4.0])
    return trimesh.boolean.difference([block, *holes, pocket], engine="manifold")


def _polyhedron() -> trimesh.Trimesh:
    # the regular dodecahedron as the convex hull of its 20 vertices
    phi = (1.0 + np.sqrt(5.0)) / 2.0
    cube = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    rest = []
    for a in (-1, 1):
        for b in (-1, 1):
            rest += [(0, a / phi, b * phi), (a / phi, b * phi, 0), (a * phi, 0, b / phi)]
    return trimesh.convex.convex_hull(np.array(cube + rest, dtype=float))


_BUILDERS = {"sphere": _sphere, "pill": _pill, "spinner_top": _spinner_top, "csg": _csg,
             "polyhedron": _polyhedron}


def sample_shape(name: str) -> trimesh.Trimesh:
    """A built-in closed mesh in mm, centred at the origin, of volume `VOLUME_MM3`.

    Parameters
    ----------
    name : str
        One of `SAMPLE_SHAPES`.

    Returns
    -------
    trimesh.Trimesh

    Raises
    ------
    DesignError
        For an unknown name.
    """
    if name not in _BUILDERS:
        raise DesignError(f"unknown sample shape {name!r}; choose one of {', '.join(SAMPLE_SHAPES)}")
    mesh = _BUILDERS[name]()
    mesh.apply_translation(-mesh.bounds.mean(axis=0))
    mesh.apply_scale((VOLUME_MM3 / mesh.volume) ** (1.0 / 3.0))
    if not mesh.is_watertight:
        raise DesignError(f"sample shape {name!r} came out not watertight (a bug in design.geometry.shapes)")
    return mesh
