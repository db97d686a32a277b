"""Exact voxelisation of a closed triangle mesh by ray parity at voxel centres.

One ray per column of voxel centres runs along axis 2 (z). A triangle is hit by the ray through
(x, y) when (x, y) lies in its xy projection; the crossings, sorted along z, alternate between
entering and leaving the solid, so a voxel centre is inside when an odd number of crossings lies
below it. Points on a projected edge or vertex are decided by a symbolic perturbation of the ray,
(x + e, y + e^2), evaluated with each edge oriented from its lower to its higher vertex index so that
both triangles sharing an edge see bit-identical values: a ray through an edge crosses exactly one
of the two triangles (or, at a silhouette, both or neither), and parity stays exact.

Grid convention: array axis a is mesh coordinate a (x, y, z); voxel (i, j, k) has its centre at
origin_mm + (i + 1/2, j + 1/2, k + 1/2) dx_mm.
"""
from __future__ import annotations

import logging

import numpy as np
import trimesh
from numba import njit

from design._validate import check_mirror, check_positive
from design.errors import DesignError

log = logging.getLogger(__name__)

RAY_OFFSET = (1e-7, 0.7e-7)
"""Offset of every ray from its voxel centre, voxel edges. The side tests are evaluated in floating
point: a mesh vertex within round-off (~1e-16 dx) of a ray, as marching-cubes vertices on the voxel
centre lines are, can be put on different sides by different edges, and a ray then meets an odd number
of triangles. Offset by this much, no vertex of a closed mesh built on the grid lies within round-off of
a ray; the offset points the same way as the symbolic perturbation (+x, then +y), which still decides
exact ties."""


@njit(cache=True, nogil=True)
def _side(px, py, ax, ay, bx, by):
    """Sign of the perturbed point's side of the directed edge a -> b (a has the lower index)."""
    e = (bx - ax) * (py - ay) - (by - ay) * (px - ax)
    if e > 0.0:
        return 1
    if e < 0.0:
        return -1
    # e == 0: perturb the point by (eps, eps^2); e changes by -(by - ay) eps + (bx - ax) eps^2
    dy = by - ay
    if dy != 0.0:
        return -1 if dy > 0.0 else 1
    return 1 if bx - ax > 0.0 else -1


@njit(cache=True, nogil=True)
def _crossings(vertices, faces, x0, y0, dx, nx, ny, count_only, counts, offsets, zs):
    """Count (count_only) or record the z of every ray/triangle crossing, per column."""
    fill = np.zeros(nx * ny, dtype=np.int64)
    for f in range(faces.shape[0]):
        ia, ib, ic = faces[f, 0], faces[f, 1], faces[f, 2]
        xa, ya = vertices[ia, 0], vertices[ia, 1]
        xb, yb = vertices[ib, 0], vertices[ib, 1]
        xc, yc = vertices[ic, 0], vertices[ic, 1]
        area = (xb - xa) * (yc - ya) - (yb - ya) * (xc - xa)
        if area == 0.0:
            continue  # vertical in projection: a perturbed ray never meets it
        orient = 1 if area > 0.0 else -1
        i_lo = max(int(np.ceil((min(xa, xb, xc) - x0) / dx - 0.5)) - 1, 0)
        i_hi = min(int(np.floor((max(xa, xb, xc) - x0) / dx - 0.5)) + 1, nx - 1)
        j_lo = max(int(np.ceil((min(ya, yb, yc) - y0) / dx - 0.5)) - 1, 0)
        j_hi = min(int(np.floor((max(ya, yb, yc) - y0) / dx - 0.5)) + 1, ny - 1)
        for i in range(i_lo, i_hi + 1):
            px = x0 + (i + 0.5 + RAY_OFFSET[0]) * dx
            for j in range(j_lo, j_hi + 1):
                py = y0 + (j + 0.5 + RAY_OFFSET[1]) * dx
                inside = True
                w = np.zeros(3)
                for e in range(3):
                    p = faces[f, e]
                    q = faces[f, (e + 1) % 3]
                    lo, hi, sgn = (p, q, 1) if p < q else (q, p, -1)
                    if _side(px, py, vertices[lo, 0], vertices[lo, 1], vertices[hi, 0], vertices[hi, 1]) * sgn != orient:
                        inside = False
                        break
                    # barycentric weight of the vertex opposite this edge
                    w[(e + 2) % 3] = ((vertices[q, 0] - vertices[p, 0]) * (py - vertices[p, 1])
                                      - (vertices[q, 1] - vertices[p, 1]) * (px - vertices[p, 0])) / area
                if not inside:
                    continue
                col = i * ny + j
                if count_only:
                    counts[col] += 1
                else:
                    # relative to vertex a, so that a horizontal face gives its z exactly
                    za = vertices[ia, 2]
                    zs[offsets[col] + fill[col]] = za + w[1] * (vertices[ib, 2] - za) + w[2] * (vertices[ic, 2] - za)
                    fill[col] += 1


@njit(cache=True, nogil=True)
def _fill(zs, offsets, counts, z0, dx, nz, out):
    bad = -1
    for col in range(counts.shape[0]):
        c = counts[col]
        if c == 0:
            continue
        if c % 2 == 1:
            bad = col
            continue
        z = np.sort(zs[offsets[col]:offsets[col] + c])
        for m in range(0, c, 2):
            k_lo = max(int(np.ceil((z[m] - z0) / dx - 0.5)), 0)  # first centre above the entry
            k_hi = min(int(np.ceil((z[m + 1] - z0) / dx - 0.5)), nz)  # first centre at/above the exit
            for k in range(k_lo, k_hi):
                out[col, k] = True
    return bad


def grid_for(bounds_mm: np.ndarray, dx_mm: float, mirror: tuple[bool, ...] = (False, False, False)
             ) -> tuple[np.ndarray, tuple[int, int, int]]:
    """The voxel grid covering a bounding box, centred on it; mirrored axes start at its centre.

    Parameters
    ----------
    bounds_mm : (2, 3) ndarray of float, mm
        Lower and upper corners.
    dx_mm : float
        Voxel edge length, mm.
    mirror : tuple of bool
        Per axis, True to cover only the half above the box centre (mirror plane at the centre).

    Returns
    -------
    origin_mm : (3,) ndarray of float, mm
    shape : tuple of int
    """
    lo, hi = np.asarray(bounds_mm, dtype=np.float64)
    centre = 0.5 * (lo + hi)
    half_counts = np.maximum(np.ceil((hi - centre) / dx_mm - 1e-9), 1).astype(int)
    origin = np.where(mirror, centre, centre - half_counts * dx_mm)
    shape = tuple(int(c) if m else int(2 * c) for c, m in zip(half_counts, mirror))
    return origin, shape


def voxelize(mesh: trimesh.Trimesh, dx_mm: float, *, origin_mm: np.ndarray | None = None,
             shape: tuple[int, int, int] | None = None, mirror: tuple[bool, ...] | None = None) -> np.ndarray:
    """Voxel centres inside a closed mesh.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Watertight triangle mesh, mm.
    dx_mm : float
        Voxel edge length, mm.
    origin_mm : (3,) array of float, optional
        Corner of voxel (0, 0, 0), mm; default from :func:`grid_for` on the mesh bounds.
    shape : tuple of int, optional
        Grid shape; default from :func:`grid_for`.
    mirror : tuple of bool, optional
        Used by the default grid: mirrored axes start at the bounding-box centre.

    Returns
    -------
    (X, Y, Z) ndarray of bool
        True where the voxel centre is inside the mesh.

    Raises
    ------
    DesignError
        For a zero or negative voxel size, or a mesh whose crossings do not pair up (not closed).
    """
    dx = check_positive("dx_mm", dx_mm)
    mirror = check_mirror(mirror, 3)
    default_origin, default_shape = grid_for(mesh.bounds, dx, mirror)
    origin = default_origin if origin_mm is None else np.asarray(origin_mm, dtype=np.float64)
    shape = default_shape if shape is None else tuple(int(s) for s in shape)
    if len(shape) != 3 or min(shape) < 1:
        raise DesignError(f"voxel grid shape must be 3 positive sizes, got {shape}")
    vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    nx, ny, nz = shape
    counts = np.zeros(nx * ny, dtype=np.int64)
    empty = np.zeros(0)
    _crossings(vertices, faces, origin[0], origin[1], dx, nx, ny, True, counts, counts, empty)
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
    zs = np.empty(int(counts.sum()))
    _crossings(vertices, faces, origin[0], origin[1], dx, nx, ny, False, counts, offsets, zs)
    out = np.zeros((nx * ny, nz), dtype=bool)
    bad = _fill(zs, offsets, counts, origin[2], dx, nz, out)
    if bad >= 0:
        raise DesignError(f"mesh is not closed: the ray through column {divmod(bad, ny)} crosses its surface "
                          "an odd number of times")
    log.debug("voxelised %d faces onto %s voxels of %.4g mm", len(faces), shape, dx)
    return out.reshape(shape)
