"""The solid a closed mesh bounds: its bodies checked, overlapping bodies united.

A mesh file may hold several closed bodies. Outward-facing bodies are solid; an inward-facing body
inside a solid is a cavity. The solid is where the winding number is positive
(`design.geometry.voxelize`), so two overlapping bodies mean their union, not the exclusive-or that
ray parity would give. Every other path (exact distances, printing) needs one clean surface, so
overlapping bodies, and bodies that touch (whose shared surface water cannot reach), are united here with
manifold3d's exact booleans. A mesh that faces inward with no
solid around it, or a body whose surface passes through itself, has no well-defined inside and is
refused with where it goes wrong.
"""
from __future__ import annotations

import numpy as np
import trimesh

from design.errors import DesignError
from design.geometry.voxelize import grid_for, winding

TOUCH_FRACTION = 1e-6
"""Two bodies closer than this fraction of their size touch: they are one solid (the surface they share is not
wetted)."""
CHECK_RESOLUTION = 96
"""Voxels along a body's longest side on which its winding numbers are checked: a self-intersection
or an overlap thinner than about one such voxel is not seen (and changes the volume by less than one
voxel layer over its extent)."""


def _winding_range(mesh: trimesh.Trimesh) -> tuple[int, int, tuple[float, float] | None]:
    dx = float(mesh.extents.max()) / CHECK_RESOLUTION
    origin, shape = grid_for(mesh.bounds, dx)
    w = winding(mesh, dx, origin, shape)
    return w.low, w.high, w.odd_mm


def _samples(body: trimesh.Trimesh) -> np.ndarray:
    """A body's vertices, face centroids and edge midpoints."""
    vx = body.vertices[body.faces]
    return np.concatenate([body.vertices, vx.mean(axis=1), 0.5 * (vx + np.roll(vx, 1, axis=1)).reshape(-1, 3)])


def _on_surface(points: np.ndarray, body: trimesh.Trimesh, tol: float) -> bool:
    """Whether any point lies within ``tol`` of one of the body's triangles (its plane, inside its edges)."""
    lo, hi = points.min(axis=0) - tol, points.max(axis=0) + tol
    vx = body.vertices[body.faces]
    keep = np.all((vx.max(axis=1) >= lo) & (vx.min(axis=1) <= hi), axis=1)
    vx, normal = vx[keep], body.face_normals[keep]
    for k in range(0, len(points), 256):
        p = points[k:k + 256, None, :] - vx[None, :, 0, :]  # (P, F, 3) from each triangle's first vertex
        e1, e2 = vx[:, 1] - vx[:, 0], vx[:, 2] - vx[:, 0]
        d11, d12, d22 = (e1 * e1).sum(-1), (e1 * e2).sum(-1), (e2 * e2).sum(-1)
        p1, p2 = (p * e1).sum(-1), (p * e2).sum(-1)
        det = d11 * d22 - d12 * d12
        u = (d22 * p1 - d12 * p2) / det
        v = (d11 * p2 - d12 * p1) / det
        slack = tol / np.sqrt(np.maximum(d11, d22))
        on = (np.abs((p * normal).sum(-1)) <= tol) & (u >= -slack) & (v >= -slack) & (u + v <= 1 + slack)
        if on.any():
            return True
    return False


def _touching(solids: list[trimesh.Trimesh]) -> bool:
    """Whether two solid bodies touch: a vertex, edge midpoint or face centroid of one lies on the other's surface
    (within `TOUCH_FRACTION` of the pair's size)."""
    for i, a in enumerate(solids):
        for b in solids[i + 1:]:
            tol = TOUCH_FRACTION * float(max(a.extents.max(), b.extents.max()))
            for one, other in ((a, b), (b, a)):
                pts = _samples(one)
                pts = pts[np.all((pts >= other.bounds[0] - tol) & (pts <= other.bounds[1] + tol), axis=1)]
                if len(pts) and _on_surface(pts, other, tol):
                    return True
    return False


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
        `mesh` itself when its bodies neither overlap nor touch; else the union of its solid bodies less its
        cavities (separate bodies stay separate bodies of the one mesh).
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
    solids = [b for b in bodies if b.volume > 0]
    cavities = [b for b in bodies if b.volume < 0]
    if high <= 1 and not _touching(solids):
        return mesh, []
    united = trimesh.boolean.union(solids, engine="manifold")
    if cavities:
        hollow = [trimesh.Trimesh(c.vertices, c.faces[:, ::-1]) for c in cavities]
        united = trimesh.boolean.difference([united, *hollow], engine="manifold")
    if not united.is_watertight or united.volume <= 0:
        raise DesignError(f"{source}: its {len(solids)} bodies overlap and could not be united into one closed "
                          "solid; unite them in a CAD program")
    shared = sum(b.volume for b in solids) - sum(-c.volume for c in cavities) - united.volume
    note = (f"{source}: {len(solids)} {'overlapping' if high > 1 else 'touching'} bodies united into one solid of "
            f"{united.volume:.4g} mm^3 (they shared {shared:.4g} mm^3)")
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
