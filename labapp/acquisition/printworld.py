"""The simulated bench's physical world: how a printed object really dissolves, which is not the model's.

The forward model (``design.forward``) erodes the mesh isotropically at unit speed from its surface.
Real FDM prints differ (paper section 5, Figs. 5 and 9-11; Markl et al., Pharm Res 2017), and this world
gives each simulated print those differences:

- **anisotropy**: water enters along the layers; the erosion rate along the build axis (z) is
  ``anisotropy`` times the in-plane rate (an ellipsoidal speed: the metric with z scaled);
- **offset**: the printed surface lies ``offset_mm`` outside the mesh's (negative: inside), so the print
  is a little larger or smaller than designed;
- **swelling**: the material swells on wetting, and channels narrower than ``swelling_mm`` stay shut:
  the swollen material plugs them (the morphological closing of the solid by a ball of that diameter
  is what water first touches), and a plug, which holds no drug, dissolves at the material's rate, so a
  shut channel opens only as the front dissolving its walls reaches it;
- **wetting lag**: nothing dissolves for ``wetting_lag_s`` after the drop.

Its release is computed with no code of the forward model's fast marching: the print is voxelised on a
fine grid of its own, and the arrival times come from scikit-fmm's travel-time solver (an independent
implementation) on grid spacings scaled for the anisotropy, so that a bug in one cannot hide in the other.
"""
from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np
import skfmm
import trimesh
from scipy import ndimage

from design.forward.reference import signed_distance
from design.geometry.voxelize import grid_for, voxelize

log = logging.getLogger(__name__)

WORLD_RESOLUTION = 128
"""Voxels along the longest side of the world's grid. The release is resolved to about half a voxel of
depth over the surface: for a 1326 mm^3 sample about 1% of its volume, well below the effects modelled."""


@dataclass(frozen=True)
class PrintPhysics:
    """How one simulated print dissolves (see the module docstring). Identity values switch an effect off."""

    anisotropy: float = 1.0
    """Build-direction (z) erosion rate / in-plane rate."""
    offset_mm: float = 0.0
    """Printed surface outside (+) or inside (-) the mesh's surface, mm."""
    swelling_mm: float = 0.0
    """Channels narrower than this (mm) are shut until their walls dissolve."""
    wetting_lag_s: float = 0.0
    """Seconds after the drop before erosion starts."""

    @classmethod
    def draw(cls, seed: int) -> PrintPhysics:
        """A hidden draw from the documented ranges: anisotropy 0.6-1.6 (layers dissolve faster or slower
        than the plane), offset -0.05..+0.15 mm (PVA prints measured 7.5 +- 0.75% larger in volume, Markl
        et al. 2017: about +0.1 mm on a 12 mm object), swelling 0.3-0.8 mm, wetting lag 60-600 s."""
        rng = np.random.default_rng([seed, 35])
        return cls(anisotropy=float(np.exp(rng.uniform(np.log(0.6), np.log(1.6)))),
                   offset_mm=float(rng.uniform(-0.05, 0.15)), swelling_mm=float(rng.uniform(0.3, 0.8)),
                   wetting_lag_s=float(rng.uniform(60.0, 600.0)))

    def without(self, *effects: str) -> PrintPhysics:
        """This physics with the named effects (field names) switched off."""
        identity = PrintPhysics()
        return dataclasses.replace(self, **{name: getattr(identity, name) for name in effects})


@dataclass(frozen=True)
class WorldRelease:
    """A print's release in the world's own units: erosion depth in in-plane mm, released volume mm^3."""

    tau_mm: np.ndarray
    released_mm3: np.ndarray
    volume_mm3: float
    """The printed solid's volume (mesh volume changed by the offset), mm^3."""
    voxel_mm: float


SEALED_VOID_SPEED = 1.0e3
"""Front speed inside a sealed void once reached (water floods it), relative to the erosion of the solid."""
BAND_VOXELS = 3
"""Within this many voxels of the surface the print's signed distance is exact (point to triangle);
farther out only its sign matters to the solvers, and the voxels' own distance transform gives it."""


def _print_distance(mesh: trimesh.Trimesh, offset_mm: float, margin_mm: float, resolution: int
                    ) -> tuple[np.ndarray, float]:
    """Signed distance to the printed surface (positive inside, mm) at the centres of a grid padded by
    ``margin_mm``, and the grid's spacing (mm): the mesh's exact signed distance plus ``offset_mm``."""
    h = float(mesh.extents.max() + 2 * margin_mm) / resolution
    lo, hi = mesh.bounds
    origin, shape = grid_for(np.array([lo - margin_mm, hi + margin_mm]), h)
    inside = voxelize(mesh, h, origin_mm=origin, shape=shape)
    rough = np.where(inside, ndimage.distance_transform_edt(inside, sampling=h),
                     -ndimage.distance_transform_edt(~inside, sampling=h))
    band = np.abs(rough) <= BAND_VOXELS * h
    centres = origin + (np.argwhere(band) + 0.5) * h
    sd = rough.copy()
    sd[band] = signed_distance(mesh, centres)
    return sd + offset_mm, h


def _closing(solid: np.ndarray, h: float, width_mm: float) -> np.ndarray:
    """The solid with every gap narrower than ``width_mm`` filled (closing by a ball of that diameter)."""
    if width_mm <= 0:
        return solid
    r = 0.5 * width_mm
    grown = ndimage.distance_transform_edt(~solid, sampling=h) <= r
    return ndimage.distance_transform_edt(grown, sampling=h) > r


def _sum_min(tau: np.ndarray, x: np.ndarray, c: np.ndarray) -> np.ndarray:
    """sum_i c_i min(tau, x_i) at each tau."""
    order = np.argsort(x)
    x, c = x[order], c[order]
    k = np.searchsorted(x, tau, side="right")
    below = np.concatenate([[0.0], np.cumsum(c * x)])
    above = np.concatenate([[0.0], np.cumsum(c)])
    return below[k] + tau * (above[-1] - above[k])


def world_release(mesh: trimesh.Trimesh, physics: PrintPhysics, *, resolution: int = WORLD_RESOLUTION,
                  samples: int = 401) -> WorldRelease:
    """The release of ``mesh`` printed with ``physics``: volume dissolved against in-plane erosion depth.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The designed solid, mm (watertight).
    physics : PrintPhysics
        The print's physics (its wetting lag is a time shift, applied by the caller with its rate).
    resolution : int
        Voxels along the padded grid's longest side.
    samples : int
        Points of the returned curve, from 0 to full dissolution.
    """
    margin = max(physics.offset_mm, 0.0) + (BAND_VOXELS + 2) * float(mesh.extents.max()) / resolution
    sd, h = _print_distance(mesh, physics.offset_mm, margin, resolution)
    solid = sd > 0
    shut = _closing(solid, h, physics.swelling_mm) & ~solid  # channels plugged by swollen material
    # sealed voids hold air: water enters one only when the front dissolving its wall reaches it, then floods it
    water, _ = ndimage.label(~solid & ~shut)
    sealed = (water > 0) & ~np.isin(water, np.unique(np.concatenate([water[0], water[-1], water[:, 0], water[:, -1],
                                                                        water[:, :, 0], water[:, :, -1]], axis=None)))
    # the surface water first touches: the print's, except across the plugs and around sealed voids
    phi = np.where(shut | sealed, 0.5 * h, sd)
    # the anisotropy as a metric: a z step of h counts as h / anisotropy of in-plane erosion depth; a reached void
    # floods at once (a speed of SEALED_VOID_SPEED)
    speed = np.where(sealed, SEALED_VOID_SPEED, 1.0)
    arrival = np.asarray(skfmm.travel_time(phi, speed, dx=[h, h, h / physics.anisotropy], order=2))
    # each voxel holds the fraction of the print the surface's distance gives it (exact for a plane
    # parallel to a face), and releases it linearly as the front crosses the voxel
    weight = np.clip(0.5 + sd / h, 0.0, 1.0)
    cells = weight > 0
    t = np.where(phi[cells] > 0, arrival[cells], 0.0)
    w = weight[cells]
    width = h * max(1.0, 1.0 / physics.anisotropy)  # the longest voxel edge in erosion depth
    begin, finish = np.maximum(t - 0.5 * width, 0.0), t + 0.5 * width  # no cell dissolves before the drop
    slope = w / (finish - begin)
    tau = np.linspace(0.0, float(finish.max()), samples)
    volume = float(w.sum()) * h ** 3
    released = np.clip((_sum_min(tau, finish, slope) - _sum_min(tau, begin, slope)) * h ** 3, 0.0, volume)
    log.debug("world release: %d voxels of %.3f mm, volume %.1f mm^3, physics %s", solid.size, h, volume, physics)
    return WorldRelease(tau, released, volume, h)
