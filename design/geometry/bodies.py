"""The solid a closed mesh bounds: its bodies checked, overlapping bodies united.

A mesh file may hold several closed bodies. Outward-facing bodies are solid; an inward-facing body
inside a solid is a cavity. The solid is where the winding number is positive
(`design.geometry.voxelize`), so two overlapping bodies mean their union, not the exclusive-or that
ray parity would give. Every other path (exact distances, printing) needs one clean surface, so
overlapping bodies are united here with manifold3d's exact booleans. A mesh that faces inward with no
solid around it, or a body whose surface passes through itself, has no well-defined inside and is
refused with where it goes wrong.
"""
from __future__ import annotations

import logging

import numpy as np
import trimesh

from design.errors import DesignError
from design.geometry.voxelize import grid_for, winding

log = logging.getLogger(__name__)

CHECK_RESOLUTION = 96
"""Voxels along a body's longest side on which its winding numbers are checked: a self-intersection
or an overlap thinner than about one such voxel is not seen (and changes the volume by less than one
voxel layer over its extent)."""


def _winding_range(mesh: trimesh.Trimesh) -> tuple[int, int, tuple[float, float] | None]:
    dx = float(mesh.extents.max()) / CHECK_RESOLUTION
    origin, shape = grid_for(mesh.bounds, dx)
    w = winding(mesh, dx, origin, shape)
    return w.low, w.high, w.odd_mm


def solid_mesh(mesh: trimesh.Trimesh, source: str = "mesh") -> tuple[trimesh.Trimesh, list[str]]:
    """The mesh of the solid that `mesh` bounds, and notes on what was changed.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        A watertight mesh, mm, with one or more bodies.
    source : str
        Named in messages (the file).

    Returns
    -------
    mesh : trimesh.Trimesh
        `mesh` itself when its bodies do not overlap; else the union of its solid bodies less its cavities.
    notes : list of str
        What was changed (the bodies united and the volume they shared), for the user.

    Raises
    ------
    DesignError
        For faces that are not consistently oriented, an inside-out mesh or body (negative volume with no
        solid around it), or a body whose surface passes through itself.
    """
    if not mesh.is_winding_consistent:
        raise DesignError(f"{source}: its faces are not consistently oriented (some normals point in, some "
                          "out), so its inside is undefined; repair the mesh's normals")
    if mesh.volume <= 0:
        raise DesignError(f"{source}: is inside out (its normals point inward: volume {mesh.volume:.4g} mm^3); "
                          "flip its faces")
    bodies = mesh.split(only_watertight=False) if len(mesh.faces) else []
    for k, body in enumerate(bodies, 1):
        low, high, where = _winding_range(body)
        sign = 1 if body.volume > 0 else -1
        if (sign > 0 and (low < 0 or high > 1)) or (sign < 0 and (low < -1 or high > 0)):
            name = f"body {k} of {len(bodies)}" if len(bodies) > 1 else "its surface"
            raise DesignError(f"{source}: {name} passes through itself (the ray at x, y = {where} mm crosses it "
                              "out of order), so its inside is undefined; repair the mesh")
    low, high, where = _winding_range(mesh)
    if low < 0:
        raise DesignError(f"{source}: a body faces inward with no solid around it (at x, y = {where} mm): it is "
                          "inside out, or a cavity pokes out of its solid; flip that body's faces")
    if high <= 1:
        return mesh, []
    solids = [b for b in bodies if b.volume > 0]
    cavities = [b for b in bodies if b.volume < 0]
    united = trimesh.boolean.union(solids, engine="manifold")
    if cavities:
        hollow = [trimesh.Trimesh(c.vertices, c.faces[:, ::-1]) for c in cavities]
        united = trimesh.boolean.difference([united, *hollow], engine="manifold")
    if not united.is_watertight or united.volume <= 0:
        raise DesignError(f"{source}: its {len(solids)} bodies overlap and could not be united into one closed "
                          "solid; unite them in a CAD program")
    shared = sum(b.volume for b in solids) - sum(-c.volume for c in cavities) - united.volume
    note = (f"{source}: {len(solids)} overlapping bodies united into one solid of {united.volume:.4g} mm^3 "
            f"(they shared {shared:.4g} mm^3)")
    log.info("%s", note)
    return united, [note]


def mirror_mismatch(inside: np.ndarray, mirror: tuple[bool, ...]) -> float:
    """Fraction of a voxelised solid's volume whose mirror image is outside it.

    Parameters
    ----------
    inside : (X, Y, Z) ndarray of bool
        The full solid on a grid centred on its bounding box (`grid_for` without mirror), so that
        reversing an axis reflects about the bounding-box centre plane.
    mirror : tuple of bool
        The axes with a claimed mirror plane.

    Returns
    -------
    float
        Worst axis's |solid \\ reflected solid| / |solid|: 0 for a symmetric shape.
    """
    total = int(inside.sum())
    if total == 0:
        return 0.0
    worst = 0
    for axis, m in enumerate(mirror):
        if m:
            worst = max(worst, int(np.count_nonzero(inside & ~np.flip(inside, axis=axis))))
    return worst / total
