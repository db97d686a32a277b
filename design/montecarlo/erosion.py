"""Kinetic Monte Carlo voxel erosion: the baseline the forward model is compared with (section 5.1).

In the spirit of Nisser et al. (TEI 2019), voxels are the sites of a lattice. A solid voxel is exposed
when one of its face neighbours is solvent (void connected to the bath; a closed cavity fills when the
erosion first opens it). In each time step dt every exposed voxel dissolves with probability

    p_b = 1 - exp(-dt A exp(-b E_a / (R T))),

an Arrhenius rate with b its number of solid face neighbours, A the pre-exponential factor (1/s), E_a
the activation energy per solid neighbour (J/mol) and T the bath temperature. Sites with fewer solid
neighbours (edges, corners, kinks) go first, so a flat face erodes by nucleation of pits and their
spreading. All decisions of a step are taken on the state at its start (synchronous update). The
voxel size enters the physics: a face recedes by about one voxel per nucleation-and-spread cycle, so a
calibration holds for the voxel size it was tuned at (:meth:`MonteCarloParams.at_voxel_size` rescales A).

The simulation only depends on A through A t: a run with A = 1 and step A dt serves every A by scaling
time, which makes the grid search over (A, E_a) cost one simulation per E_a
(:func:`design.montecarlo.tuning.tune_mc`).
Mirror planes are unfolded: the full object is simulated, so the copies erode independently.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from design._validate import check_density, check_mirror, check_positive
from design.errors import DesignError
from design.forward.simulator import DEFAULT_STEPS

GAS_CONSTANT = 8.314462618
"""Molar gas constant R, J/(mol K)."""
BATH_TEMP_K = 343.15
"""Bath temperature of the measurements, 70 C (section 4.2), K."""
DEFAULT_SEEDS = 4
"""Independent runs averaged by default."""
KINK_PROBABILITY = 0.02
"""Default dt: a kink voxel (ndim solid neighbours, the site that unzips a surface step) dissolves with this
probability per step."""
SOLID_LEVEL = 0.5
"""Density at or above which a voxel is a solid lattice site."""
MAX_STEPS = 20_000_000


@dataclass(frozen=True)
class MonteCarloParams:
    """Arrhenius parameters of the erosion model, in physical units.

    Attributes
    ----------
    a_per_s : float
        Pre-exponential factor A, 1/s.
    ea_j_per_mol : float
        Activation energy per solid face neighbour E_a, J/mol (>= 0).
    temp_k : float
        Bath temperature T, K (default 343.15 K = 70 C).
    dx_mm : float or None
        Voxel size the parameters hold for (the one they were tuned at), mm; None: any.
    """

    a_per_s: float
    ea_j_per_mol: float
    temp_k: float = BATH_TEMP_K
    dx_mm: float | None = None

    def __post_init__(self) -> None:
        check_positive("a_per_s", self.a_per_s)
        check_positive("temp_k", self.temp_k)
        if not (math.isfinite(self.ea_j_per_mol) and self.ea_j_per_mol >= 0):
            raise DesignError(f"ea_j_per_mol must be finite and >= 0, got {self.ea_j_per_mol!r}")
        if self.dx_mm is not None:
            check_positive("dx_mm", self.dx_mm)

    @property
    def epsilon(self) -> float:
        """E_a / (R T): the log of the rate ratio between b and b + 1 solid neighbours."""
        return self.ea_j_per_mol / (GAS_CONSTANT * self.temp_k)

    def rates_per_s(self, ndim: int = 3) -> np.ndarray:
        """(2 ndim + 1,) ndarray of float, 1/s: A exp(-b E_a / (R T)) for b = 0 .. 2 ndim."""
        return self.a_per_s * np.exp(-np.arange(2 * ndim + 1) * self.epsilon)

    def at_voxel_size(self, dx_mm: float) -> MonteCarloParams:
        """The parameters for another voxel size: A scaled by dx_tuned / dx, so that a face keeps its speed
        in mm/s (one voxel per cycle); the surface roughness, in voxels, is unchanged."""
        dx = check_positive("dx_mm", dx_mm)
        if self.dx_mm is None or math.isclose(dx, self.dx_mm, rel_tol=1e-9):
            return MonteCarloParams(self.a_per_s, self.ea_j_per_mol, self.temp_k, dx)
        return MonteCarloParams(self.a_per_s * self.dx_mm / dx, self.ea_j_per_mol, self.temp_k, dx)

    def to_dict(self) -> dict:
        return {"a_per_s": self.a_per_s, "ea_j_per_mol": self.ea_j_per_mol, "temp_k": self.temp_k,
                "dx_mm": self.dx_mm}

    @classmethod
    def from_dict(cls, data: dict) -> MonteCarloParams:
        try:
            return cls(float(data["a_per_s"]), float(data["ea_j_per_mol"]), float(data.get("temp_k", BATH_TEMP_K)),
                       None if data.get("dx_mm") is None else float(data["dx_mm"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise DesignError(f"Monte Carlo parameters need numbers a_per_s, ea_j_per_mol [, temp_k, dx_mm]; "
                              f"got {data!r} ({exc})") from exc


@dataclass(frozen=True, eq=False)
class MonteCarloRelease:
    """Release curves of several seeded Monte Carlo runs and their mean.

    Attributes
    ----------
    t_s : (K,) ndarray of float, s
        Common time grid (default 0 to the last voxel's dissolution over all runs).
    released_mm3 : (K,) ndarray of float, mm^3
        Mean cumulative released volume over the runs.
    released_std_mm3 : (K,) ndarray of float, mm^3
        Standard deviation over the runs (the spread between seeds; 0 for one run).
    runs_mm3 : (S, K) ndarray of float, mm^3
        Each run's curve.
    volume_mm3 : float
        Solid volume of the full object (voxels at density >= 0.5), mm^3.
    dt_s : float
        Time step, s.
    seeds : tuple of int
    params : MonteCarloParams
    dissolution_s : (S, ...) ndarray of float, s
        Per run, the time each voxel of the full (unfolded) grid dissolved; NaN for void.
    """

    t_s: np.ndarray
    released_mm3: np.ndarray
    released_std_mm3: np.ndarray
    runs_mm3: np.ndarray
    volume_mm3: float
    dt_s: float
    seeds: tuple[int, ...]
    params: MonteCarloParams
    dissolution_s: np.ndarray = field(repr=False)


def _unfold(rho: np.ndarray, mirror: tuple[bool, ...]) -> np.ndarray:
    for axis, m in enumerate(mirror):
        if m:
            rho = np.concatenate([np.flip(rho, axis), rho], axis)
    return rho


@njit(cache=True)
def _flood(start, wet, solid, offsets, surface, in_surface, n_surface, stack):
    """Mark the dry void region containing ``start`` wet and queue its solid neighbours as exposed."""
    top = 0
    stack[top] = start
    top += 1
    wet[start] = 1
    while top > 0:
        top -= 1
        i = stack[top]
        for off in offsets:
            j = i + off
            if solid[j]:
                if not in_surface[j]:
                    in_surface[j] = 1
                    surface[n_surface] = j
                    n_surface += 1
            elif not wet[j]:
                wet[j] = 1
                stack[top] = j
                top += 1
    return n_surface


@njit(cache=True)
def _erode(solid, wet, neighbours, offsets, probability, seed, max_steps):
    """Synchronous kinetic Monte Carlo erosion on a flattened padded grid.

    solid, wet : uint8 flags; the padding is wet void. neighbours : int8 solid face-neighbour counts.
    probability : per-step dissolution probability by neighbour count. Returns the step (1-based) at
    which each site dissolved, -1 for void, or -2 everywhere if ``max_steps`` was reached.
    """
    np.random.seed(seed)
    size = solid.size
    step_of = np.full(size, -1, np.int64)
    surface = np.empty(size, np.int64)
    in_surface = np.zeros(size, np.uint8)
    stack = np.empty(size, np.int64)
    removed = np.empty(size, np.int64)
    n_surface = 0
    remaining = 0
    for i in range(size):
        if solid[i]:
            remaining += 1
            for off in offsets:
                if wet[i + off]:
                    in_surface[i] = 1
                    surface[n_surface] = i
                    n_surface += 1
                    break
    step = 0
    while remaining > 0:
        step += 1
        if step > max_steps:
            step_of[:] = -2
            return step_of
        n_removed = 0
        for k in range(n_surface):
            i = surface[k]
            if np.random.random() < probability[neighbours[i]]:
                removed[n_removed] = i
                n_removed += 1
        for k in range(n_removed):
            solid[removed[k]] = 0
            step_of[removed[k]] = step
        remaining -= n_removed
        for k in range(n_removed):
            i = removed[k]
            wet[i] = 1
            for off in offsets:
                j = i + off
                if solid[j]:
                    neighbours[j] -= 1
                    if not in_surface[j]:
                        in_surface[j] = 1
                        surface[n_surface] = j
                        n_surface += 1
                elif not wet[j]:
                    n_surface = _flood(j, wet, solid, offsets, surface, in_surface, n_surface, stack)
        kept = 0
        for k in range(n_surface):
            i = surface[k]
            if solid[i]:
                surface[kept] = i
                kept += 1
            else:
                in_surface[i] = 0
        n_surface = kept
    return step_of


def _lattice(rho: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Padded flat solid/wet flags, solid-neighbour counts and flat neighbour offsets."""
    solid = np.pad(rho >= SOLID_LEVEL, 1).astype(np.uint8)
    strides = np.array([int(np.prod(solid.shape[a + 1:])) for a in range(solid.ndim)], dtype=np.int64)
    offsets = np.concatenate([strides, -strides])
    flat = solid.ravel()
    inner = np.zeros(solid.shape, bool)
    inner[(slice(1, -1),) * solid.ndim] = True
    inner = inner.ravel()
    idx = np.flatnonzero(inner)
    neighbours = np.zeros(flat.size, np.int8)
    for off in offsets:
        neighbours[idx] += flat[idx + off]
    # the bath: padding, plus every void voxel connected to it through void faces
    from scipy.ndimage import label

    void_regions, _ = label(solid == 0)
    outside = np.unique(void_regions[~inner.reshape(solid.shape)])
    wet = np.isin(void_regions, outside[outside > 0]).astype(np.uint8).ravel()
    return flat.copy(), wet, neighbours, offsets


def default_dt_s(params: MonteCarloParams, ndim: int = 3) -> float:
    """The time step at which a kink voxel (ndim solid neighbours) dissolves with probability
    :data:`KINK_PROBABILITY`, s."""
    return -math.log1p(-KINK_PROBABILITY) / float(params.rates_per_s(ndim)[ndim])


def erosion_times(rho: np.ndarray, params: MonteCarloParams, *, seed: int = 0, dt_s: float | None = None,
                  mirror: tuple[bool, ...] | None = None) -> np.ndarray:
    """Time at which each voxel of one seeded run dissolves.

    Parameters
    ----------
    rho : (H, W) or (D, H, W) ndarray of float in [0, 1]
        Density; voxels at >= 0.5 are solid sites. With ``mirror``, the half stored as for
        :func:`design.forward.simulator.simulate`.
    params : MonteCarloParams
    seed : int
        Seed of the run's random numbers; the same seed gives the same run.
    dt_s : float, optional
        Time step, s (default :func:`default_dt_s`).
    mirror : tuple of bool, optional
        Mirror flags per axis; the grid is unfolded to the full object.

    Returns
    -------
    ndarray of float, s, full-object grid shape
        Dissolution time of every solid voxel (a multiple of ``dt_s``), NaN for void.
    """
    rho = check_density(rho)
    full = _unfold(rho, check_mirror(mirror, rho.ndim))
    dt = default_dt_s(params, full.ndim) if dt_s is None else check_positive("dt_s", dt_s)
    probability = -np.expm1(-dt * params.rates_per_s(full.ndim))
    solid, wet, neighbours, offsets = _lattice(full)
    steps = _erode(solid, wet, neighbours, offsets, probability, int(seed), MAX_STEPS)
    if steps.size and steps[0] == -2:
        raise DesignError(f"Monte Carlo erosion did not finish in {MAX_STEPS} steps of {dt:g} s; "
                          f"raise dt_s or A")
    steps = steps.reshape(np.array(full.shape) + 2)[(slice(1, -1),) * full.ndim]
    return np.where(steps > 0, steps * dt, np.nan)


def simulate_mc(rho: np.ndarray, dx_mm: float, params: MonteCarloParams, *, mirror: tuple[bool, ...] | None = None,
                seeds: int | Sequence[int] = DEFAULT_SEEDS, dt_s: float | None = None,
                samples: int = DEFAULT_STEPS + 1, t_s: np.ndarray | None = None,
                progress: Callable[[int, int], None] | None = None) -> MonteCarloRelease:
    """Average the release curves of several seeded Monte Carlo runs.

    Parameters
    ----------
    rho : (H, W) or (D, H, W) ndarray of float in [0, 1]
        Density grid (see :func:`erosion_times`).
    dx_mm : float
        Voxel edge length, mm. When ``params.dx_mm`` differs, A is rescaled (:meth:`MonteCarloParams.at_voxel_size`).
    params : MonteCarloParams
    mirror : tuple of bool, optional
    seeds : int or sequence of int
        Number of runs (seeds 0 .. n-1) or the seeds themselves.
    dt_s : float, optional
        Time step, s (default :func:`default_dt_s`).
    samples : int
        Points of the common time grid from 0 to the last dissolution (default 1001).
    t_s : (K,) ndarray of float, optional
        The common time grid itself, s (increasing; replaces ``samples``), e.g. to compare runs.
    progress : callable, optional
        ``progress(done, total)`` after every run.

    Returns
    -------
    MonteCarloRelease
    """
    dx = check_positive("dx_mm", dx_mm)
    params = params.at_voxel_size(dx)
    seed_list = tuple(range(int(seeds))) if isinstance(seeds, (int, np.integer)) else tuple(int(s) for s in seeds)
    if not seed_list:
        raise DesignError("seeds must name at least one run")
    if int(samples) < 2:
        raise DesignError(f"samples must be >= 2, got {samples!r}")
    rho = check_density(rho)
    dt = default_dt_s(params, rho.ndim) if dt_s is None else check_positive("dt_s", dt_s)
    times = []
    for k, seed in enumerate(seed_list):
        times.append(erosion_times(rho, params, seed=seed, dt_s=dt, mirror=mirror))
        if progress is not None:
            progress(k + 1, len(seed_list))
    times = np.array(times)
    voxel = dx ** rho.ndim
    solid_count = int(np.isfinite(times[0]).sum())
    if solid_count == 0:
        raise DesignError(f"no voxel at density >= {SOLID_LEVEL}: nothing to erode")
    if t_s is None:
        grid = np.linspace(0.0, float(np.nanmax(times)), int(samples))
    else:
        grid = np.asarray(t_s, dtype=float)
        if grid.ndim != 1 or grid.size < 2 or not np.all(np.isfinite(grid)) or np.any(np.diff(grid) <= 0):
            raise DesignError("t_s must be a finite, strictly increasing 1-D array of at least 2 times")
    runs = np.array([np.searchsorted(np.sort(tt[np.isfinite(tt)]), grid, side="right") for tt in times]) * voxel
    return MonteCarloRelease(grid, runs.mean(axis=0), runs.std(axis=0), runs, solid_count * voxel, dt, seed_list,
                             params, times)
