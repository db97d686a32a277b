"""Two materials, a drug and a barrier, on one grid: the release curve and its exact gradient.

Each voxel holds a drug density rho_d and a barrier density rho_b with rho_d + rho_b <= 1; the rest is
void. The drug erodes at the calibrated rate (slowness 1, eq. 2's solid), the barrier at ``s`` times that
rate (slowness k = 1 / s), void at once (slowness n_min). Eq. (2) becomes the linear mixture

    n = rho_d + k rho_b + (1 - rho_d - rho_b) n_min,

computed as ``rho + (1 - rho) n_min + rho_b (k - 1)`` with rho = rho_d + rho_b, so that s = 1 gives the
one-material slowness of rho bit for bit. Eq. (5) is solved on n by the same first-order fast marcher,
and only the drug releases: eq. (7) weights each voxel's ramp (eq. 6, length n_i dx) by rho_d,i dx^3.
The gradient runs through eq. (7), eq. (2) and the adjoint sweep (eq. 10) exactly as for one material,
with dn/drho_d = 1 - n_min, dn/drho_b = k - n_min and dn/ds = -rho_b / s^2.

An insoluble barrier (s = 0) has the finite slowness k = `N_INSOLUBLE` = 1e12: crossing one voxel of
barrier density rho_b takes at least rho_b 1e12 dx / sqrt(3) (the three-term solve of eq. 5), while any
path through drug and void alone reaches a voxel within ``V dx`` (V the voxel count: each voxel on a
face-connected path adds at most n dx <= dx). A drug voxel with u beyond V dx is therefore behind barrier
on every path: it is *sealed*, and it never releases (its ramp lies beyond any curve sampled up to V dx).
The separation holds wherever rho_b > sqrt(3) V / 1e12 (3e-5 on a 256^3 grid); fainter barrier traces
are crossed in finite time, as their density says. The error of treating s = 0 this way is zero on the
curve: no sealed voxel contributes to any sample up to V dx, and every other voxel's u is that of the
insoluble model, because a barrier voxel (u >= 1e12 rho_b dx / sqrt(3)) is never upwind of it.

Mirror planes and build-direction anisotropy work as in `design.forward.simulator`. Swelling does not
apply to two materials.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from design._validate import check_density, check_mirror, check_positive
from design.errors import DesignError
from design.forward.fmm import Marching, axis_weights, march, march_adjoint, upwind_spacing
from design.forward.release import ramp_release, ramp_release_vjp
from design.forward.simulator import DEFAULT_STEPS, N_MIN, total_time

N_INSOLUBLE = 1e12
"""Slowness per unit barrier density of an insoluble barrier (s = 0); see the module docstring."""
DENSITY_SUM_TOL = 1e-12
"""Round-off allowed in rho_d + rho_b <= 1."""


@dataclass(frozen=True)
class TwoMaterialRelease:
    """The drug's simulated release from a drug/barrier composite and the state its gradient needs.

    Attributes
    ----------
    tau_mm : (K,) ndarray of float, mm
        tau_k = k dtau; the last is `total_time_mm`.
    released_mm3 : (K,) ndarray of float, mm^3
        Cumulative released drug volume of the full object (mirror copies included), eq. (7).
    total_time_mm : float
        T, the curve's length, mm.
    u_mm : ndarray of float, grid shape, mm
        Dissolution time of every voxel (read-only); sealed voxels have u > `open_time_mm`.
    dx_mm : float
    mirror : tuple of bool
    anisotropy : float
    barrier_speed : float
        s, the barrier's erosion speed over the drug's; 0 for an insoluble barrier.
    sealed : ndarray of bool, grid shape
        Drug voxels sealed inside an insoluble barrier (never released); all False for s > 0.
    open_time_mm : float
        Longest dissolution time of a voxel reached without crossing barrier when s = 0 (V dx, module
        docstring); inf for s > 0.
    """

    tau_mm: np.ndarray
    released_mm3: np.ndarray
    total_time_mm: float
    u_mm: np.ndarray
    dx_mm: float
    mirror: tuple[bool, ...]
    anisotropy: float
    barrier_speed: float
    sealed: np.ndarray
    open_time_mm: float
    _rho_d: np.ndarray = field(repr=False)
    _rho_b: np.ndarray = field(repr=False)
    _marching: Marching = field(repr=False)
    _ramp: float | np.ndarray = field(repr=False)

    @property
    def dtau_mm(self) -> float:
        """The tau step, mm."""
        return self.total_time_mm / (len(self.tau_mm) - 1)

    @property
    def multiplicity(self) -> int:
        """Copies of the simulated grid in the full object: 2 per mirrored axis."""
        return 2 ** sum(self.mirror)

    @property
    def drug_density(self) -> np.ndarray:
        """rho_d of the simulated grid (read-only)."""
        return self._rho_d

    @property
    def barrier_density(self) -> np.ndarray:
        """rho_b of the simulated grid (read-only)."""
        return self._rho_b

    @property
    def drug_volume_mm3(self) -> float:
        """Drug volume of the full object, mm^3."""
        return float(self._rho_d.sum()) * self.dx_mm ** 3 * self.multiplicity

    @property
    def barrier_volume_mm3(self) -> float:
        """Barrier volume of the full object, mm^3."""
        return float(self._rho_b.sum()) * self.dx_mm ** 3 * self.multiplicity

    @property
    def sealed_mm3(self) -> float:
        """Drug volume sealed inside an insoluble barrier (never released), full object, mm^3."""
        return float(self._rho_d[self.sealed].sum()) * self.dx_mm ** 3 * self.multiplicity


@dataclass(frozen=True)
class TwoMaterialGradient:
    """dJ/drho_d and dJ/drho_b (grid shape) and dJ/ds (None for an insoluble barrier, s = 0)."""

    drug: np.ndarray
    barrier: np.ndarray
    speed: float | None


def check_barrier_speed(s: object) -> float:
    """Return the barrier's relative erosion speed as a float after checking it is finite and >= 0."""
    try:
        x = float(s)
    except (TypeError, ValueError) as exc:
        raise DesignError(f"barrier speed must be a number, got {s!r}") from exc
    if not math.isfinite(x) or x < 0.0:
        raise DesignError(f"barrier speed must be finite and >= 0 (0: insoluble), got {x:g}")
    return x


def barrier_slowness(s: float) -> float:
    """k, the barrier's slowness relative to the drug's: 1 / s, or `N_INSOLUBLE` for s = 0."""
    return N_INSOLUBLE if s == 0.0 else 1.0 / s


def two_material_slowness(rho_d: np.ndarray, rho_b: np.ndarray, s: float) -> np.ndarray:
    """n = rho_d + rho_b / s + (1 - rho_d - rho_b) n_min (eq. 2 with two materials; module docstring)."""
    rho = rho_d + rho_b
    return rho + (1.0 - rho) * N_MIN + rho_b * (barrier_slowness(s) - 1.0)


def _check_pair(rho_d: object, rho_b: object) -> tuple[np.ndarray, np.ndarray]:
    drug = np.array(check_density(rho_d, "drug"))
    barrier = np.array(check_density(rho_b, "barrier"))
    if barrier.shape != drug.shape:
        raise DesignError(f"barrier density shape {barrier.shape} differs from the drug's {drug.shape}")
    excess = drug + barrier - 1.0
    if excess.max() > DENSITY_SUM_TOL:
        first = tuple(int(i) for i in np.unravel_index(int(np.argmax(excess)), drug.shape))
        raise DesignError(f"drug + barrier density must be <= 1 in every voxel; {int(np.sum(excess > DENSITY_SUM_TOL))} "
                          f"voxels exceed it, the most at index {first} ({1.0 + excess[first]:.6g})")
    return drug, barrier


def simulate_two(rho_d: np.ndarray, rho_b: np.ndarray, dx_mm: float, barrier_speed: float, *,
                 mirror: tuple[bool, ...] | None = None, dtau_mm: float | None = None,
                 total_time_mm: float | None = None, anisotropy: float = 1.0) -> TwoMaterialRelease:
    """Simulate the drug's release from a drug/barrier composite.

    Parameters
    ----------
    rho_d, rho_b : (H, W) or (D, H, W) ndarray of float in [0, 1]
        Drug and barrier densities on one grid, rho_d + rho_b <= 1 per voxel.
    dx_mm : float
        Voxel edge length, mm.
    barrier_speed : float
        s >= 0: the barrier erodes at s times the drug's rate; 0 is insoluble.
    mirror : tuple of bool, optional
        Per axis, True for a mirror plane at the index-0 face.
    dtau_mm : float, optional
        Time step, mm; rounded so that T is a whole number of steps. Default T / 1000.
    total_time_mm : float, optional
        Curve length T, mm. Default: the later of the all-drug domain's largest dissolution time and the
        last unsealed drug voxel's dissolution time (so the curve reaches the drug's full release). That
        default depends on the design; pass T to compare or differentiate curves on one tau grid.
    anisotropy : float
        Erosion speed along axis 2 (z) over the in-plane speed, for both materials.

    Returns
    -------
    TwoMaterialRelease
    """
    drug, barrier = _check_pair(rho_d, rho_b)
    dx = check_positive("dx_mm", dx_mm)
    s = check_barrier_speed(barrier_speed)
    mirror = check_mirror(mirror, drug.ndim)
    anisotropy = float(anisotropy)
    axis_weights(drug.ndim, anisotropy)  # validates before any solve
    n = two_material_slowness(drug, barrier, s)
    marching = march(n, dx, mirror, None, anisotropy)
    u = np.ascontiguousarray(marching.interior(marching.u_pad))
    open_time = drug.size * dx * max(1.0, 1.0 / anisotropy) if s == 0.0 else math.inf
    sealed = (drug > 0.0) & (u > open_time)
    if total_time_mm is None:
        released = (drug > 0.0) & ~sealed
        big_t = max(total_time(drug.shape, dx, mirror, anisotropy), float(u[released].max()) if released.any() else 0.0)
    else:
        big_t = check_positive("total_time_mm", total_time_mm)
    steps = DEFAULT_STEPS if dtau_mm is None else max(1, int(round(big_t / check_positive("dtau_mm", dtau_mm))))
    ramp = dx if anisotropy == 1.0 else upwind_spacing(marching)
    scale = dx ** 3 * 2 ** sum(mirror)
    curve = ramp_release(u.ravel(), (n * ramp).ravel(), (drug * scale).ravel(), big_t / steps, steps + 1)
    for a in (u, drug, barrier, sealed):
        a.flags.writeable = False
    return TwoMaterialRelease(tau_mm=np.linspace(0.0, big_t, steps + 1), released_mm3=curve, total_time_mm=big_t,
                              u_mm=u, dx_mm=dx, mirror=mirror, anisotropy=anisotropy, barrier_speed=s, sealed=sealed,
                              open_time_mm=open_time, _rho_d=drug, _rho_b=barrier, _marching=marching, _ramp=ramp)


def two_material_gradient(release: TwoMaterialRelease, dJ_dC: np.ndarray,
                          dJ_du: np.ndarray | None = None) -> TwoMaterialGradient:
    """Exact gradient of an objective of the drug's release curve (and the dissolution times).

    Parameters
    ----------
    release : TwoMaterialRelease
        The result of :func:`simulate_two` at the densities of interest.
    dJ_dC : (K,) ndarray of float
        dJ/d `release.released_mm3`, per mm^3.
    dJ_du : ndarray of float, grid shape, optional
        dJ/d `release.u_mm`, per mm.

    Returns
    -------
    TwoMaterialGradient
        dJ/drho_d, dJ/drho_b and dJ/ds (None when s = 0, where k is the constant `N_INSOLUBLE`).
    """
    g = np.asarray(dJ_dC, dtype=np.float64)
    if g.shape != release.tau_mm.shape:
        raise DesignError(f"dJ_dC must have shape {release.tau_mm.shape}, got {g.shape}")
    drug, barrier, s = release._rho_d, release._rho_b, release.barrier_speed
    n = two_material_slowness(drug, barrier, s)
    scale = release.dx_mm ** 3 * release.multiplicity
    ramp = release._ramp
    u_bar, length_bar, weight_bar = ramp_release_vjp(release.u_mm.ravel(), (n * ramp).ravel(), (drug * scale).ravel(),
                                                     release.dtau_mm, g)
    u_bar = u_bar.reshape(drug.shape)
    if dJ_du is not None:
        extra = np.asarray(dJ_du, dtype=np.float64)
        if extra.shape != drug.shape:
            raise DesignError(f"dJ_du must have the grid shape {drug.shape}, got {extra.shape}")
        u_bar = u_bar + extra
    # eq. (10) gives dJ/dn; the ramp length n_i L_i adds its own term (eq. 6)
    n_bar = march_adjoint(release._marching, u_bar) + length_bar.reshape(drug.shape) * ramp
    k = barrier_slowness(s)
    speed = None if s == 0.0 else float(-np.sum(n_bar * barrier)) / (s * s)
    return TwoMaterialGradient(drug=weight_bar.reshape(drug.shape) * scale + n_bar * (1.0 - N_MIN),
                               barrier=n_bar * (k - N_MIN), speed=speed)


def barrier_cover(rho_d: np.ndarray, rho_b: np.ndarray, dx_mm: float, *, mirror: tuple[bool, ...] | None = None,
                  anisotropy: float = 1.0) -> float:
    """The least barrier thickness that water crosses to reach any drug, mm.

    Eq. (5) solved on the slowness ``rho_b + (1 - rho_b) n_min`` counts only barrier along a path: its
    solution at a drug voxel is the least barrier (in barrier density x length) between the outside and
    that voxel. The drug's release starts once the front has crossed this thickness at the barrier's speed
    s, at cover / s: a delay D needs a cover of at least D s. First-order in dx like every solve of eq. (5)
    (the voxelised barrier's own staircase included). About 0 (void's slowness n_min) when drug touches
    the outside or an opening.

    Parameters
    ----------
    rho_d, rho_b : ndarray of float in [0, 1]
        Drug and barrier densities on one grid.
    dx_mm : float
    mirror : tuple of bool, optional
    anisotropy : float

    Returns
    -------
    float
        min over voxels with drug of the barrier crossed to reach them, mm; inf without drug.
    """
    drug, barrier = _check_pair(rho_d, rho_b)
    dx = check_positive("dx_mm", dx_mm)
    mirror = check_mirror(mirror, drug.ndim)
    if not (drug > 0.0).any():
        return math.inf
    marching = march(barrier + (1.0 - barrier) * N_MIN, dx, mirror, None, float(anisotropy))
    return float(marching.interior(marching.u_pad)[drug > 0.0].min())

