"""The differentiable forward release simulator: density in, release curve out (sections 3.2-3.5).

`simulate` solves eq. (5) by fast marching on the density's slowness field (eq. 2) and samples the
ramp release curve (eqs. 6-7); `release_gradient` returns the exact gradient of any objective of that
curve (and of the dissolution times) with respect to the density, through the ramp, eq. (2) and the
adjoint sweep (eq. 10).

Mirror symmetry: with ``mirror[a]`` set, the grid is the half of the object on the positive side of a
mirror plane at the index-0 face of axis a; the full object is
``np.concatenate([np.flip(half, a), half], a)``. Released volumes are always the full object's.

Anisotropy: with ``anisotropy`` a != 1 the erosion speed along axis 2 (z, the build direction) is a
times the in-plane speed; eq. (5) is solved on spacings (dx, dx, dx / a) in the travel-time metric (see
`design.forward.fmm`), and a voxel's ramp of eq. (6) spans its metric edge along its main upwind
axis (the one of its smallest upwind value), L_i = n_i h_d: dx in plane, dx / a along z. A plane
front parallel to any face then dissolves one layer of voxels per layer crossing time, the ramps of
successive layers tiling time exactly as in the isotropic model (L_i = n_i dx). The axis is fixed
under small changes of the density, so L_i's choice carries no gradient. u and tau stay in in-plane mm.

Swelling: with ``swelling_mm`` w > 0, channels narrower than w are shut (`design.forward.swelling`): their void
voxels take the slowness of solid in eq. (2) but keep their own weight in eq. (7), so the front crosses them
at the material's rate and they release nothing. The plug depends on the thresholded density only and is held
fixed by the gradient (exact wherever no voxel crosses the threshold).
"""
from __future__ import annotations

import functools
import logging
from dataclasses import dataclass, field

import numpy as np

from design._validate import check_density, check_mirror, check_positive
from design.errors import DesignError  # re-exported: the base exception of design/
from design.forward.fmm import MarchBuffers, Marching, axis_weights, eikonal_residual, march, march_adjoint, upwind_spacing
from design.forward.release import ramp_release, ramp_release_vjp
from design.forward.swelling import shut_channels

log = logging.getLogger(__name__)

N_MIN = 1e-6
"""Slowness of void (eq. 2)."""
DEFAULT_STEPS = 1000
"""Default number of tau steps: dtau = T / 1000 (section 3.4)."""
RESIDUAL_TOL = 1e-12
"""Largest residual of eq. (5), relative to T, accepted by ``simulate(check=True)``."""


@dataclass(frozen=True)
class Release:
    """A simulated release curve and the state its gradient needs.

    Attributes
    ----------
    tau_mm : (K,) ndarray of float, mm
        tau_k = k dtau, k = 0..K-1; the last is `total_time_mm`.
    released_mm3 : (K,) ndarray of float, mm^3
        Cumulative released solid volume of the full object (mirror copies included), eq. (7).
    total_time_mm : float
        T, the largest dissolution time of the fully solid (simulated) domain, mm.
    u_mm : ndarray of float, grid shape, mm
        Dissolution time of every voxel of the simulated grid (read-only).
    dx_mm : float
        Voxel edge length, mm.
    mirror : tuple of bool
        Per axis, True for a mirror plane at the index-0 face.
    anisotropy : float
        Erosion speed along z over the in-plane speed (1: the paper's isotropic model).
    swelling_mm : float
        Channels narrower than this were shut (0: none).
    plug : ndarray of bool, grid shape, or None
        The void voxels shut by swelling (read-only; None without swelling).
    """

    tau_mm: np.ndarray
    released_mm3: np.ndarray
    total_time_mm: float
    u_mm: np.ndarray
    dx_mm: float
    mirror: tuple[bool, ...]
    _rho: np.ndarray = field(repr=False)
    _marching: Marching = field(repr=False)
    anisotropy: float = 1.0
    _ramp: float | np.ndarray | None = field(default=None, repr=False)
    swelling_mm: float = 0.0
    plug: np.ndarray | None = field(default=None, repr=False)

    @property
    def ramp_mm(self) -> float | np.ndarray:
        """Ramp length per unit slowness of eq. (6), mm: dx, or per voxel its main upwind axis's metric spacing."""
        return self.dx_mm if self._ramp is None else self._ramp

    @property
    def dtau_mm(self) -> float:
        """The tau step, mm."""
        return self.total_time_mm / (len(self.tau_mm) - 1)

    @property
    def multiplicity(self) -> int:
        """Copies of the simulated grid in the full object: 2 per mirrored axis."""
        return 2 ** sum(self.mirror)

    @property
    def volume_mm3(self) -> float:
        """Solid volume of the full object, sum of rho dx^3 over all copies, mm^3."""
        return float(self._rho.sum()) * self.dx_mm ** 3 * self.multiplicity


def slowness(rho: np.ndarray) -> np.ndarray:
    """Reciprocal dissolution speed n = rho + (1 - rho) n_min (eq. 2)."""
    return rho + (1.0 - rho) * N_MIN


@functools.lru_cache(maxsize=32)
def _unit_total_time(shape: tuple[int, ...], mirror: tuple[bool, ...], anisotropy: float = 1.0) -> float:
    marching = march(np.ones(shape), 1.0, mirror, anisotropy=anisotropy)
    return float(marching.interior(marching.u_pad).max())


def total_time(shape: tuple[int, ...], dx_mm: float, mirror: tuple[bool, ...] | None = None,
               anisotropy: float = 1.0) -> float:
    """T, the largest dissolution time of the all-solid grid (cached per shape and mirror), mm.

    Parameters
    ----------
    shape : tuple of int
        Grid shape (2D or 3D) of the simulated domain.
    dx_mm : float
        Voxel edge length, mm.
    mirror : tuple of bool, optional
        Mirror flags per axis.
    anisotropy : float
        Erosion speed along z over the in-plane speed.
    """
    shape = tuple(int(s) for s in shape)
    if len(shape) not in (2, 3) or min(shape) < 1:
        raise DesignError(f"grid shape must be 2D or 3D with positive sizes, got {shape}")
    dx = check_positive("dx_mm", dx_mm)
    # u scales linearly with dx, so one solve at dx = 1 serves every voxel size
    mirror = check_mirror(mirror, len(shape))
    if anisotropy == 1.0:
        return _unit_total_time(shape, mirror) * dx
    return _unit_total_time(shape, mirror, float(anisotropy)) * dx


def simulate(rho: np.ndarray, dx_mm: float, *, mirror: tuple[bool, ...] | None = None,
             dtau_mm: float | None = None, total_time_mm: float | None = None,
             check: bool = False, buffers: MarchBuffers | None = None, anisotropy: float = 1.0,
             swelling_mm: float = 0.0) -> Release:
    """Simulate the release curve of a density field.

    Parameters
    ----------
    rho : (H, W) or (D, H, W) ndarray of float in [0, 1]
        Density of the simulated domain (a half/quadrant/octant when `mirror` is set).
    dx_mm : float
        Voxel edge length, mm.
    mirror : tuple of bool, optional
        Per axis, True for a mirror plane at the index-0 face instead of a dissolving face.
    dtau_mm : float, optional
        Time step, mm; rounded so that T is a whole number of steps. Default T / 1000.
    total_time_mm : float, optional
        Curve length T, mm; default the all-solid domain's largest dissolution time.
    check : bool
        Verify eq. (5) at every voxel (residual <= 1e-12 T, round-off of u); costs one extra pass.
    buffers : MarchBuffers, optional
        Fast-marching work arrays to reuse (repeated solves on one grid); the gradient of the
        previous `Release` simulated with them is then no longer available.
    anisotropy : float
        Erosion speed along axis 2 (z) over the in-plane speed, > 0; 1 (default) is the paper's
        isotropic model. Needs a 3D grid unless 1.
    swelling_mm : float
        Swelling width, mm: channels narrower than this are shut until the front dissolving their walls
        reaches them (module docstring); 0 (default) shuts none.

    Returns
    -------
    Release

    Raises
    ------
    DesignError
        On invalid input, or when `check` finds a residual above tolerance.
    """
    rho = np.array(check_density(rho))  # a private copy: the Release keeps it read-only
    dx = check_positive("dx_mm", dx_mm)
    mirror = check_mirror(mirror, rho.ndim)
    anisotropy = float(anisotropy)
    axis_weights(rho.ndim, anisotropy)  # validates before any solve
    big_t = total_time(rho.shape, dx, mirror, anisotropy) if total_time_mm is None else check_positive(
        "total_time_mm", total_time_mm)
    steps = DEFAULT_STEPS if dtau_mm is None else max(1, int(round(big_t / check_positive("dtau_mm", dtau_mm))))
    swelling = float(swelling_mm)
    plug = shut_channels(rho, dx, swelling, mirror) if swelling != 0.0 else None
    if plug is not None and not plug.any():
        plug = None
    n = slowness(rho if plug is None else np.where(plug, 1.0, rho))
    marching = march(n, dx, mirror, buffers, anisotropy)
    # one compact copy of u: the curve, its gradient and callers then read 8 bytes per voxel, not a record
    u = np.ascontiguousarray(marching.interior(marching.u_pad))
    if check:
        worst = float(np.abs(eikonal_residual(marching)).max())
        if worst > RESIDUAL_TOL * big_t:
            raise DesignError(f"eq. (5) residual {worst:.3g} mm exceeds {RESIDUAL_TOL:g} T = {RESIDUAL_TOL * big_t:.3g} mm")
        log.debug("eq. (5) residual %.3g mm", worst)
    multiplicity = 2 ** sum(mirror)
    ramp = None if anisotropy == 1.0 else upwind_spacing(marching)
    curve = ramp_release(u.ravel(), (n * (dx if ramp is None else ramp)).ravel(),
                         (rho * (dx ** 3 * multiplicity)).ravel(), big_t / steps, steps + 1)
    u.flags.writeable = False
    rho.flags.writeable = False
    if plug is not None:
        plug.flags.writeable = False
    return Release(tau_mm=np.linspace(0.0, big_t, steps + 1), released_mm3=curve, total_time_mm=big_t,
                   u_mm=u, dx_mm=dx, mirror=mirror, _rho=rho, _marching=marching, anisotropy=anisotropy,
                   _ramp=ramp, swelling_mm=swelling, plug=plug)


def release_gradient(release: Release, dJ_dC: np.ndarray, dJ_du: np.ndarray | None = None) -> np.ndarray:
    """Exact gradient dJ/drho of an objective of the release curve and the dissolution times.

    Parameters
    ----------
    release : Release
        The result of :func:`simulate` at the density of interest.
    dJ_dC : (K,) ndarray of float
        Partial derivatives of J with respect to `release.released_mm3`, per mm^3.
    dJ_du : ndarray of float, grid shape, optional
        Partial derivatives of J with respect to `release.u_mm`, per mm.

    Returns
    -------
    ndarray of float, grid shape
        dJ/drho for the simulated grid.
    """
    g = np.asarray(dJ_dC, dtype=np.float64)
    if g.shape != release.tau_mm.shape:
        raise DesignError(f"dJ_dC must have shape {release.tau_mm.shape}, got {g.shape}")
    rho = release._rho
    dx = release.dx_mm
    n = slowness(rho if release.plug is None else np.where(release.plug, 1.0, rho))
    scale = dx ** 3 * release.multiplicity
    ramp = release.ramp_mm
    u_bar, length_bar, weight_bar = ramp_release_vjp(release.u_mm.ravel(), (n * ramp).ravel(),
                                                     (rho * scale).ravel(), release.dtau_mm, g)
    u_bar = u_bar.reshape(rho.shape)
    if dJ_du is not None:
        extra = np.asarray(dJ_du, dtype=np.float64)
        if extra.shape != rho.shape:
            raise DesignError(f"dJ_du must have the grid shape {rho.shape}, got {extra.shape}")
        u_bar = u_bar + extra
    n_bar = march_adjoint(release._marching, u_bar) + length_bar.reshape(rho.shape) * ramp
    # chain rule through w = rho dx^3 m and eq. (2): dn/drho = 1 - n_min, 0 in a plug (its n is solid's)
    dn_drho = 1.0 - N_MIN if release.plug is None else np.where(release.plug, 0.0, 1.0 - N_MIN)
    return weight_bar.reshape(rho.shape) * scale + n_bar * dn_drho
