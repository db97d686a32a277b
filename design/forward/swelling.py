"""Channels shut by swelling: the void a swollen print plugs (a geometry step before eq. 5).

A water-soluble print swells on wetting, and a channel narrower than the swelling width w stays shut
(the paper's failed ICO print of CSG-1, Figs. 9-11): water first meets the solid's morphological closing
by a ball of diameter w, not the solid itself. The plug holds no drug and dissolves at the material's
rate, so a shut channel opens only as the front dissolving its walls reaches it.

In the forward model this is a preprocessing step on the density: the plug voxels get the slowness of
solid (eq. 2 with rho = 1) and keep their own weight rho_i (eq. 7), so they delay the front without
releasing anything. The plug is a function of the thresholded density (rho >= 1/2), constant under small
changes of rho except where a voxel crosses 1/2; the gradient of `design.forward.simulator.release_gradient`
holds the plug fixed, exact wherever the threshold is not crossed (a finite-difference step does not
cross it).

The closing is computed on subvoxels of half the voxel edge, where the centre-line of a slot of any whole
number of voxels carries subvoxel centres: the void's open part is the union of balls of diameter w
centred on the void subvoxels farther than w/2 from every solid subvoxel (the morphological opening of the
void), and a void voxel is shut when at least half of its subvoxels lie outside it. A slot of whole voxels
narrower than w (or as wide) is then shut, a wider one is open, and a face or an outer edge is never
thickened.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from design._validate import check_mirror
from design.errors import DesignError

SOLID_LEVEL = 0.5
"""Density at and above which a voxel counts as solid for the closing."""


def _pad(solid: np.ndarray, width: int, mirror: tuple[bool, ...]) -> np.ndarray:
    """Pad with bath on ordinary faces and with the mirror image on mirrored index-0 faces."""
    out = solid
    for axis, m in enumerate(mirror):
        spec = [(0, 0)] * solid.ndim
        spec[axis] = (width, 0)
        out = np.pad(out, spec, mode="symmetric") if m else np.pad(out, spec, constant_values=False)
        spec[axis] = (0, width)
        out = np.pad(out, spec, constant_values=False)
    return out


def shut_channels(rho: np.ndarray, dx_mm: float, width_mm: float, mirror: tuple[bool, ...] | None = None
                  ) -> np.ndarray:
    """Void voxels plugged by swelling: the closing of the solid by a ball of diameter ``width_mm``, less the solid.

    Parameters
    ----------
    rho : (H, W) or (D, H, W) ndarray of float
        Density of the simulated grid (a half/quadrant/octant with `mirror`); solid where rho >= 1/2.
    dx_mm : float
        Voxel edge, mm.
    width_mm : float
        Swelling width w, mm: channels narrower than this are shut; 0 shuts none.
    mirror : tuple of bool, optional
        Per axis, a mirror plane at the index-0 face (the closing sees the mirror image across it).

    Returns
    -------
    ndarray of bool, grid shape
        True on the plugged void voxels.

    Examples
    --------
    A 2-voxel slot (0.4 mm at 0.2 mm voxels) is shut by 0.6 mm of swelling, not by 0.3 mm:

    >>> rho = np.ones((12, 8)); rho[5:7, 2:] = 0.0
    >>> int(shut_channels(rho, 0.2, 0.6).sum()), int(shut_channels(rho, 0.2, 0.3).sum())
    (12, 0)
    """
    rho = np.asarray(rho)
    if not (np.isfinite(width_mm) and width_mm >= 0):
        raise DesignError(f"swelling width must be a finite number >= 0 mm, got {width_mm}")
    solid = rho >= SOLID_LEVEL
    if width_mm == 0 or not solid.any():
        return np.zeros(rho.shape, dtype=bool)
    mirror = check_mirror(mirror, rho.ndim)
    half = 0.5 * width_mm
    step = 0.5 * dx_mm
    sub = solid
    for axis in range(rho.ndim):
        sub = np.repeat(sub, 2, axis=axis)
    pad = int(np.ceil(half / step)) + 2
    padded = _pad(sub, pad, mirror)
    core = ndimage.distance_transform_edt(~padded, sampling=step) > half   # centres of balls that fit
    opened = ndimage.distance_transform_edt(~core, sampling=step) <= half
    shut = (~padded & ~opened)[tuple(slice(pad, pad + 2 * n) for n in rho.shape)]
    blocks = shut.reshape([v for n in rho.shape for v in (n, 2)]).sum(axis=tuple(range(1, 2 * rho.ndim, 2)))
    return (blocks >= 2 ** (rho.ndim - 1)) & ~solid
