"""A drug mesh and a barrier mesh voxelised on one grid (the input of the two-material forward model)."""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import trimesh

from design._validate import check_positive
from design.errors import DesignError
from design.files.meshio import checked_mesh
from design.files.pipeline import SYMMETRY_TOLERANCE, parse_symmetry
from design.geometry.bodies import mirror_mismatch
from design.geometry.voxelize import DEFAULT_RESOLUTION, grid_for, voxelize

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TwoMaterialGrid:
    """Drug and barrier densities on the voxel grid covering both meshes.

    Attributes
    ----------
    rho_d, rho_b : (X, Y, Z) ndarray of float in {0, 1}
        Drug and barrier voxels (voxel centres inside each mesh); where both meshes hold a centre the
        voxel is drug.
    dx_mm : float
        Voxel edge length, mm.
    origin_mm : (3,) ndarray of float
        Corner of voxel (0, 0, 0), mm.
    overlap_voxels : int
        Voxels inside both meshes (counted as drug), in the simulated part of the grid.
    mirror : tuple of bool
        Per axis, True for a mirror plane at the index-0 face (through the centre of the box holding both).
    """

    rho_d: np.ndarray
    rho_b: np.ndarray
    dx_mm: float
    origin_mm: np.ndarray
    overlap_voxels: int
    mirror: tuple[bool, ...] = (False, False, False)


def union_bounds(*meshes: trimesh.Trimesh) -> np.ndarray:
    """(2, 3) lower and upper corners of the box holding every mesh, mm."""
    return np.array([np.min([m.bounds[0] for m in meshes], axis=0), np.max([m.bounds[1] for m in meshes], axis=0)])


def two_material_grid(drug: trimesh.Trimesh, barrier: trimesh.Trimesh, *, resolution: int | None = None,
                      voxel_size_mm: float | None = None, symmetry: str = "") -> TwoMaterialGrid:
    """Voxelise a drug mesh and a barrier mesh at the centres of one grid.

    Parameters
    ----------
    drug, barrier : trimesh.Trimesh
        Closed meshes, mm.
    resolution : int, optional
        Voxels along the longest side of the box holding both meshes (default `DEFAULT_RESOLUTION`).
    voxel_size_mm : float, optional
        Voxel edge length, mm (instead of `resolution`).
    symmetry : str
        Axis letters of mirror planes through the centre of the box holding both meshes (e.g. ``"xy"``):
        the grid is the half/quadrant/octant on their positive side. Each material must be symmetric
        about them to within `SYMMETRY_TOLERANCE` of its voxelised volume.

    Returns
    -------
    TwoMaterialGrid

    Raises
    ------
    DesignError
        For a mesh that is not closed, both or an invalid size, meshes with no drug voxel, or a claimed
        mirror plane that a material is not symmetric about.
    """
    drug, barrier = checked_mesh(drug, "drug mesh"), checked_mesh(barrier, "barrier mesh")
    if resolution is not None and voxel_size_mm is not None:
        raise DesignError("give either resolution or voxel_size_mm, not both")
    bounds = union_bounds(drug, barrier)
    if voxel_size_mm is None:
        n = DEFAULT_RESOLUTION if resolution is None else int(resolution)
        if n < 2:
            raise DesignError(f"resolution must be >= 2 voxels, got {resolution}")
        dx = float((bounds[1] - bounds[0]).max()) / n
    else:
        dx = check_positive("voxel_size_mm", voxel_size_mm)
    mirror = parse_symmetry(symmetry)
    origin, shape = grid_for(bounds, dx)
    inside_d = voxelize(drug, dx, origin_mm=origin, shape=shape)
    if not inside_d.any():
        raise DesignError(f"the drug mesh holds no voxel centre at voxels of {dx:.4g} mm; raise the resolution")
    barrier_solid = voxelize(barrier, dx, origin_mm=origin, shape=shape)
    inside_b, overlap = barrier_solid & ~inside_d, barrier_solid & inside_d
    if any(mirror):
        _check_symmetric({"drug mesh": inside_d, "barrier mesh": inside_b}, mirror, symmetry)
        # the full grid is centred on the box, so each mirrored axis's upper half is the simulated part
        half = tuple(slice(n // 2, None) if m else slice(None) for n, m in zip(shape, mirror))
        inside_d, inside_b, overlap = inside_d[half], inside_b[half], overlap[half]
        origin = np.where(mirror, 0.5 * (bounds[0] + bounds[1]), origin)
    log.info("two materials on %s voxels of %.4g mm (mirror %s): %d drug, %d barrier, %d overlapping (drug)",
             inside_d.shape, dx, mirror, int(inside_d.sum()), int(inside_b.sum()), int(overlap.sum()))
    return TwoMaterialGrid(rho_d=inside_d.astype(np.float64), rho_b=inside_b.astype(np.float64), dx_mm=dx,
                           origin_mm=origin, overlap_voxels=int(np.count_nonzero(overlap)), mirror=mirror)


def _check_symmetric(materials: dict[str, np.ndarray], mirror: tuple[bool, ...], symmetry: str) -> None:
    off = [f"{name} ({miss:.1%} of its volume has no mirror image)" for name, inside in materials.items()
           if (miss := mirror_mismatch(inside, mirror)) > SYMMETRY_TOLERANCE]
    if off:
        raise DesignError(f"--symmetry {symmetry}: not symmetric about the planes through the centre of the box "
                          f"holding both meshes: {'; '.join(off)}; at most {SYMMETRY_TOLERANCE:.1%} may differ")
