"""From an optimised density to a printable solid (section 5.2).

A contour of the density is extracted with marching cubes on the zero-padded full density, which
makes it a closed, outward-oriented surface in mm; re-voxelising that solid gives the binary
design whose simulated release is the achieved curve reported next to the target, as in the
paper's plots.

The paper cuts at rho = 1/2. The smoothing filter leaves a grey boundary layer (section 5.2: "Imperfections
in the fits ... are introduced almost entirely by the density rounding step"), and the 1/2 contour
of an optimised design holds up to a few per cent less material than the density does, which the
binary fit then shows as a release short of the target
(docs/design.md#from-density-to-print-designfabricationextractpy-designfilesoutputspy). The level is
therefore chosen so that the solid keeps the density's mass
(`mass_preserving_level`, the volume-preserving threshold of Heaviside-projection topology
optimisation), within `LEVEL_RANGE` around 1/2.
"""
from __future__ import annotations

import numpy as np
import trimesh
from scipy import ndimage
from skimage.measure import marching_cubes

from design.errors import DesignError
from design.geometry.voxelize import voxelize

LEVEL_GAP = 1e-3
"""Densities within this of the iso-level are moved this far from it, each on its own side, and the
contour is drawn half this above the level. Marching cubes puts a vertex on the grid point of a value
at the level, and resolves a face whose bilinear centre value equals the level (a solid-void
checkerboard: voxels touching along an edge only) differently in its two cells; either leaves the
surface open. Drawn above the level, such voxels stay apart, as `count_pieces` counts them. The
surface moves by at most this fraction of a voxel per unit density step."""


LEVEL_RANGE = (0.4, 0.6)
"""Bounds of the extraction level. An optimised design's mass-preserving level lies within a few
hundredths of 1/2 (``extraction_level`` in a run's ``summary.json``; studies/recut_runs.py compares
the cuts, docs/benchmarks.md#studies); a density grey enough to need a level
outside this range is not a design any single cut stands for."""


def mass_preserving_level(rho_full: np.ndarray) -> float:
    """Iso-level whose voxel solid ``rho >= level`` holds the density's mass, within `LEVEL_RANGE`.

    The solid keeps ``k = round(sum rho)`` voxels, the ``k`` densest: the level lies halfway between
    the k-th and (k+1)-th largest densities (voxels of equal density stay on one side together).

    Parameters
    ----------
    rho_full : ndarray of float
        Density in [0, 1] (any shape; unfolded, so that every voxel counts once).

    Returns
    -------
    float
        The level, in ``LEVEL_RANGE``.
    """
    flat = np.asarray(rho_full, dtype=float).ravel()
    k = int(round(float(flat.sum())))
    lo, hi = LEVEL_RANGE
    if k <= 0:
        return hi
    if k >= flat.size:
        return lo
    kth, next_ = -np.partition(-flat, (k - 1, k))[[k - 1, k]]
    return float(np.clip(0.5 * (kth + next_), lo, hi))


def density_mesh(rho_full: np.ndarray, dx_mm: float, origin_mm: np.ndarray, level: float = 0.5) -> trimesh.Trimesh:
    """Watertight triangle mesh of ``rho >= level``, mm.

    Parameters
    ----------
    rho_full : (D, H, W) ndarray of float
        Full (unfolded) density in [0, 1]; voxel i is centred at ``origin + (i + 1/2) dx``.
    dx_mm : float
        Voxel edge, mm.
    origin_mm : (3,) array_like of float
        Corner of the grid, mm.
    level : float
        Iso-value (1/2 in the paper; `mass_preserving_level` for a design's output).

    Raises
    ------
    DesignError
        If no voxel reaches the level, or the contour is not a closed surface.
    """
    if rho_full.ndim != 3 or not np.any(rho_full >= level):
        raise DesignError(f"no density reaches {level} on the {rho_full.shape} grid: nothing to extract")
    padded = np.pad(np.asarray(rho_full, dtype=float), 1)  # zero layer closes every surface
    near = np.abs(padded - level) < LEVEL_GAP
    padded[near] = np.where(padded[near] >= level, level + LEVEL_GAP, level - LEVEL_GAP)
    verts, faces, _, _ = marching_cubes(padded, level=level + LEVEL_GAP / 2, spacing=(dx_mm,) * 3)
    # padded index p sits at origin + (p - 1/2) dx
    verts = verts + np.asarray(origin_mm, float) - 0.5 * dx_mm
    mesh = trimesh.Trimesh(vertices=verts, faces=faces, process=True)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.remove_unreferenced_vertices()
    if not mesh.is_watertight:
        raise DesignError(f"extracted contour is not watertight ({len(mesh.faces)} faces)")
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def revoxelize(mesh: trimesh.Trimesh, dx_mm: float, origin_mm: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    """The solid of a closed mesh on the design grid, (D, H, W) ndarray of bool."""
    return np.asarray(voxelize(mesh, dx_mm, origin_mm=np.asarray(origin_mm, float), shape=tuple(shape))) > 0.5


def count_pieces(solid: np.ndarray) -> int:
    """Face-connected components of a voxel solid (a print must be one piece)."""
    return int(ndimage.label(solid)[1])


def centred_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Voxel intersection-over-union of two solids after moving b's centroid onto a's."""
    if not a.any() or not b.any():
        return 0.0
    shift = np.round(np.array(ndimage.center_of_mass(a)) - np.array(ndimage.center_of_mass(b))).astype(int)
    moved = ndimage.shift(b.astype(np.uint8), shift, order=0) > 0
    return float(np.count_nonzero(a & moved) / np.count_nonzero(a | moved))
