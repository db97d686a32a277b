"""A drug mesh and a barrier mesh voxelised on one grid (the input of the two-material forward model)."""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import trimesh

from design._validate import check_positive
from design.errors import DesignError
from design.files.meshio import checked_mesh
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
        Voxels inside both meshes (counted as drug).
    """

    rho_d: np.ndarray
    rho_b: np.ndarray
    dx_mm: float
    origin_mm: np.ndarray
    overlap_voxels: int


def union_bounds(*meshes: trimesh.Trimesh) -> np.ndarray:
    """(2, 3) lower and upper corners of the box holding every mesh, mm."""
    return np.array([np.min([m.bounds[0] for m in meshes], axis=0), np.max([m.bounds[1] for m in meshes], axis=0)])


def two_material_grid(drug: trimesh.Trimesh, barrier: trimesh.Trimesh, *, resolution: int | None = None,
                      voxel_size_mm: float | None = None) -> TwoMaterialGrid:
    """Voxelise a drug mesh and a barrier mesh at the centres of one grid.

    Parameters
    ----------
    drug, barrier : trimesh.Trimesh
        Closed meshes, mm.
    resolution : int, optional
        Voxels along the longest side of the box holding both meshes (default `DEFAULT_RESOLUTION`).
    voxel_size_mm : float, optional
        Voxel edge length, mm (instead of `resolution`).

    Returns
    -------
    TwoMaterialGrid

    Raises
    ------
    DesignError
        For a mesh that is not closed, both or an invalid size, or meshes with no drug voxel.
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
    origin, shape = grid_for(bounds, dx)
    inside_d = voxelize(drug, dx, origin_mm=origin, shape=shape)
    inside_b = voxelize(barrier, dx, origin_mm=origin, shape=shape)
    if not inside_d.any():
        raise DesignError(f"the drug mesh holds no voxel centre at voxels of {dx:.4g} mm; raise the resolution")
    overlap = int(np.count_nonzero(inside_d & inside_b))
    log.info("two materials on %s voxels of %.4g mm: %d drug, %d barrier, %d overlapping (drug)", shape, dx,
             int(inside_d.sum()), int(inside_b.sum()) - overlap, overlap)
    return TwoMaterialGrid(rho_d=inside_d.astype(np.float64), rho_b=(inside_b & ~inside_d).astype(np.float64),
                           dx_mm=dx, origin_mm=origin, overlap_voxels=overlap)
