"""Exact voxelisation of a closed triangle mesh by winding numbers at voxel centres.

One ray per column of voxel centres runs along axis 2 (z). A triangle is hit by the ray through
(x, y) when (x, y) lies in its xy projection; a crossing through a face whose outward normal points
down (-z) enters the solid (+1), one through a face pointing up leaves it (-1). The winding number of
a voxel centre is the sum of the crossings below it, and the centre is inside when it is positive: the
union of overlapping bodies, and a cavity (an inward-facing inner shell) subtracted from its solid.
Points on a projected edge or vertex are decided by a symbolic perturbation of the ray,
(x + e, y + e^2), evaluated with each edge oriented from its lower to its higher vertex index so that
both triangles sharing an edge see bit-identical values: a ray through an edge crosses exactly one
of the two triangles (or, at a silhouette, both or neither), and the winding numbers stay exact.

Grid convention: array axis a is mesh coordinate a (x, y, z); voxel (i, j, k) has its centre at
origin_mm + (i + 1/2, j + 1/2, k + 1/2) dx_mm.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import trimesh
from numba import njit

from design._validate import check_mirror, check_positive
from design.errors import DesignError

log = logging.getLogger(__name__)

DEFAULT_RESOLUTION = 64
"""Voxels along a body's longest side when neither a resolution nor a voxel size is given: a design's domain
(`design.inverse.config.DesignConfig.resolution`), ``sfr simulate``'s mesh and a simulation calibration's meshes."""
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
def _crossings(vertices, faces, x0, y0, dx, nx, ny, count_only, counts, offsets, zs, signs):
    """Count (count_only) or record the z and the winding step (+1 entering, -1 leaving) of every
    ray/triangle crossing, per column."""
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
                    signs[offsets[col] + fill[col]] = -orient  # a face seen clockwise from above faces down
                    fill[col] += 1


@njit(cache=True, nogil=True)
def _fill(zs, signs, offsets, counts, z0, dx, nz, out):
    """Mark the voxel centres of positive winding number; return (the last column whose winding does not
    return to 0 or -1, the lowest and highest winding, the first column with a winding outside 0..1 or -1)."""
    bad = -1
    low, high, odd = 0, 0, -1
    for col in range(counts.shape[0]):
        c = counts[col]
        if c == 0:
            continue
        order = np.argsort(zs[offsets[col]:offsets[col] + c], kind="mergesort")
        z = zs[offsets[col]:offsets[col] + c][order]
        step = signs[offsets[col]:offsets[col] + c][order]
        winding = 0
        for m in range(c):
            winding += step[m]
            if winding < low or winding > high:
                low, high = min(low, winding), max(high, winding)
                if odd < 0 and (winding < 0 or winding > 1):
                    odd = col
            if winding > 0 and m + 1 < c:
                k_lo = max(int(np.ceil((z[m] - z0) / dx - 0.5)), 0)  # first centre above this crossing
                k_hi = min(int(np.ceil((z[m + 1] - z0) / dx - 0.5)), nz)  # first centre at/above the next
                for k in range(k_lo, k_hi):
                    out[col, k] = True
        if winding != 0:
            bad = col
    return bad, low, high, odd


@dataclass(frozen=True)
class Winding:
    """Voxel centres inside a mesh and the range of winding numbers its rays met.

    ``low``/``high`` are the lowest and highest winding numbers (0 and 1 for one outward-facing closed
    surface; below 0 where a surface faces inward with no solid around it, above 1 where bodies overlap
    or a surface passes through itself). ``odd_mm`` is a point (mm) on a ray where one was first outside
    0..1, or None.
    """

    inside: np.ndarray
    low: int
    high: int
    odd_mm: tuple[float, float] | None


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
        True where the voxel centre's winding number is positive (inside the union of the mesh's bodies).

    Raises
    ------
    DesignError
        For a zero or negative voxel size, or a mesh whose crossings do not sum to zero (not closed).
    """
    dx = check_positive("dx_mm", dx_mm)
    mirror = check_mirror(mirror, 3)
    default_origin, default_shape = grid_for(mesh.bounds, dx, mirror)
    origin = default_origin if origin_mm is None else np.asarray(origin_mm, dtype=np.float64)
    shape = default_shape if shape is None else tuple(int(s) for s in shape)
    if len(shape) != 3 or min(shape) < 1:
        raise DesignError(f"voxel grid shape must be 3 positive sizes, got {shape}")
    return winding(mesh, dx, origin, shape).inside


def winding(mesh: trimesh.Trimesh, dx_mm: float, origin_mm: np.ndarray, shape: tuple[int, int, int]) -> Winding:
    """Winding numbers of a mesh on a voxel grid (see :func:`voxelize` for the grid).

    Raises
    ------
    DesignError
        For a mesh whose crossings do not sum to zero along a ray (not closed, or faces not consistently
        oriented).
    """
    vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    nx, ny, nz = shape
    counts = np.zeros(nx * ny, dtype=np.int64)
    empty = np.zeros(0)
    no_signs = np.zeros(0, dtype=np.int64)
    _crossings(vertices, faces, origin_mm[0], origin_mm[1], dx_mm, nx, ny, True, counts, counts, empty, no_signs)
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
    zs = np.empty(int(counts.sum()))
    signs = np.empty(zs.size, dtype=np.int64)
    _crossings(vertices, faces, origin_mm[0], origin_mm[1], dx_mm, nx, ny, False, counts, offsets, zs, signs)
    out = np.zeros((nx * ny, nz), dtype=bool)
    bad, low, high, odd = _fill(zs, signs, offsets, counts, origin_mm[2], dx_mm, nz, out)
    if bad >= 0:
        raise DesignError(f"mesh is not closed or its faces are not consistently oriented: the ray through "
                          f"{_column_mm(bad, ny, origin_mm, dx_mm)} mm enters its surface more often than it "
                          "leaves it")
    log.debug("voxelised %d faces onto %s voxels of %.4g mm", len(faces), shape, dx_mm)
    return Winding(out.reshape(shape), int(low), int(high), None if odd < 0 else _column_mm(odd, ny, origin_mm, dx_mm))


def _column_mm(col: int, ny: int, origin_mm: np.ndarray, dx_mm: float) -> tuple[float, float]:
    """The (x, y) of a voxel column's ray, mm."""
    i, j = divmod(col, ny)
    return (round(float(origin_mm[0] + (i + 0.5) * dx_mm), 3), round(float(origin_mm[1] + (j + 0.5) * dx_mm), 3))
