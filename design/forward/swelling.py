"""Channels shut by swelling: the void a swollen print plugs (a geometry step before eq. 5).

A water-soluble print swells on wetting, and a channel narrower than the swelling width w stays shut
(the paper's failed ICO print of CSG-1, Figs. 9-11). The plug holds no drug and dissolves at the material's
rate, so a shut channel opens only as the front dissolving its walls reaches it.

In the forward model this is a preprocessing step on the density: the plug voxels get the slowness of
solid (eq. 2 with rho = 1) and keep their own weight rho_i (eq. 7), so they delay the front without
releasing anything. The plug is a function of the thresholded density (rho >= 1/2), constant under small
changes of rho except where a voxel crosses 1/2; the gradient of `design.forward.simulator.release_gradient`
holds the plug fixed, exact wherever the threshold is not crossed (a finite-difference step does not
cross it).

A void voxel is in a channel narrower than w when, along one of the grid's axes, the run of void voxels
through it, from solid to solid, is shorter than w (voxels times dx). The bath beyond an ordinary face of the
grid never ends; a mirror face reflects. A slot of whole voxels is then shut exactly when narrower than w, up
to the face it opens on, and so is a narrow groove, while a face, an outer edge, the staircase of a voxelised
curved surface and the concave corners of a wide chamber are left alone (a diagonal ray across a concave
corner would be short, and filling it would make a new corner: the axes alone keep the test idempotent). A
channel at an angle to the axes is measured along them, so one at 45 degrees counts as up to sqrt(2) wider.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from design._validate import check_mirror
from design.errors import DesignError

SOLID_LEVEL = 0.5
"""Density at and above which a voxel counts as solid."""
_DIRECTIONS = np.eye(3, dtype=np.int64)
"""The directions a channel's width is measured along: the grid's axes."""


@njit(cache=True, nogil=True)
def _walk(solid, i, j, k, di, dj, dk, limit, mirror):
    """Void voxels beyond (i, j, k) along (di, dj, dk) before solid; ``limit`` (never shorter) on leaving the
    grid through an ordinary face (the bath) or after ``limit`` steps. A mirror face (index -1 of a mirrored
    axis) reflects: index -1 - v is the image of v."""
    shape = solid.shape
    count = 0
    while count < limit:
        i += di
        j += dj
        k += dk
        if i >= shape[0] or j >= shape[1] or k >= shape[2]:
            return limit
        if (i < 0 and not mirror[0]) or (j < 0 and not mirror[1]) or (k < 0 and not mirror[2]):
            return limit
        ri = -1 - i if i < 0 else i
        rj = -1 - j if j < 0 else j
        rk = -1 - k if k < 0 else k
        if ri >= shape[0] or rj >= shape[1] or rk >= shape[2]:   # reflected past the far face: the bath
            return limit
        if solid[ri, rj, rk]:
            return count
        count += 1
    return limit


@njit(cache=True, nogil=True)
def _narrow(solid, dx, width, directions, mirror):
    shut = np.zeros(solid.shape, dtype=np.bool_)
    n0, n1, n2 = solid.shape
    for i in range(n0):
        for j in range(n1):
            for k in range(n2):
                if solid[i, j, k]:
                    continue
                for d in range(directions.shape[0]):
                    di, dj, dk = directions[d, 0], directions[d, 1], directions[d, 2]
                    step = dx * np.sqrt(float(di * di + dj * dj + dk * dk))
                    limit = int(np.ceil(width / step)) + 1
                    run = 1 + _walk(solid, i, j, k, di, dj, dk, limit, mirror)
                    if run * step < width:
                        run += _walk(solid, i, j, k, -di, -dj, -dk, limit, mirror)
                        if run * step < width:
                            shut[i, j, k] = True
                            break
    return shut


def shut_channels(rho: np.ndarray, dx_mm: float, width_mm: float, mirror: tuple[bool, ...] | None = None
                  ) -> np.ndarray:
    """Void voxels plugged by swelling: those of channels narrower than ``width_mm`` (module docstring).

    Parameters
    ----------
    rho : (H, W) or (D, H, W) ndarray of float
        Density of the simulated grid (a half/quadrant/octant with `mirror`); solid where rho >= 1/2.
    dx_mm : float
        Voxel edge, mm.
    width_mm : float
        Swelling width w, mm: channels narrower than this are shut; 0 shuts none.
    mirror : tuple of bool, optional
        Per axis, a mirror plane at the index-0 face (a channel continues into its mirror image).

    Returns
    -------
    ndarray of bool, grid shape
        True on the plugged void voxels.

    Examples
    --------
    A 2-voxel slot (0.4 mm at 0.2 mm voxels) is shut by 0.6 mm of swelling, not by 0.4 mm:

    >>> rho = np.ones((12, 8)); rho[5:7, 2:] = 0.0
    >>> int(shut_channels(rho, 0.2, 0.6).sum()), int(shut_channels(rho, 0.2, 0.4).sum())
    (12, 0)
    """
    rho = np.asarray(rho)
    if not (np.isfinite(width_mm) and width_mm >= 0):
        raise DesignError(f"swelling width must be a finite number >= 0 mm, got {width_mm}")
    solid = rho >= SOLID_LEVEL
    if width_mm == 0 or not solid.any():
        return np.zeros(rho.shape, dtype=bool)
    mirror = check_mirror(mirror, rho.ndim)
    grid = solid if solid.ndim == 3 else solid[:, :, None]
    flags = np.array(tuple(mirror) + (False,) * (3 - rho.ndim), dtype=np.bool_)
    directions = _DIRECTIONS if rho.ndim == 3 else _DIRECTIONS[_DIRECTIONS[:, 2] == 0]
    shut = _narrow(np.ascontiguousarray(grid), float(dx_mm), float(width_mm), directions, flags)
    return shut.reshape(rho.shape)
