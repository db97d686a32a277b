"""Tuning the Monte Carlo baseline against measured curves: the 16-point (A, E_a) grid of section 5.1.

A only rescales the time of :mod:`design.montecarlo.erosion` (a run at A = 1 with step A dt gives every voxel's
dissolution time in units of 1/A, exactly), so :func:`unit_runs` simulates each object once per E_a and
seed, and :func:`tune_mc` scores every A of the grid by rescaling those runs, optionally on a subset of
the objects (leave-one-out).
"""
from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from design._validate import check_positive
from design.errors import DesignError
from design.montecarlo.erosion import BATH_TEMP_K, DEFAULT_SEEDS, MonteCarloParams, erosion_times

log = logging.getLogger(__name__)

DEFAULT_EA_J_PER_MOL = (2500.0, 5000.0, 10000.0, 20000.0)
"""Activation energies of the default tuning grid, J/mol (E_a / RT = 0.9 ... 7 at 70 C)."""
A_FACTORS = (2 ** -0.375, 2 ** -0.125, 2 ** 0.125, 2 ** 0.375)
"""Default A values of the tuning grid: these factors (steps of 2^(1/4)) times the A that matches the objects'
median half-release time."""


@dataclass(frozen=True)
class McGridPoint:
    """One (A, E_a) combination of the tuning grid and its error.

    Attributes
    ----------
    a_per_s : float, 1/s
    ea_j_per_mol : float, J/mol
    rms : float
        Mean over the calibration objects of the RMS difference between the simulated and measured
        fraction released, at the measured sample times (0.01 = 1 % of the object's mass).
    """

    a_per_s: float
    ea_j_per_mol: float
    rms: float


@dataclass(frozen=True, eq=False)
class McTuning:
    """The result of :func:`tune_mc`.

    Attributes
    ----------
    params : MonteCarloParams
        The chosen parameters (the grid's best E_a with A refined, unless ``refine=False``), for ``dx_mm``.
    rms : float
        Their mean RMS error (fraction of mass).
    per_object_rms : tuple of float
        Their RMS error per calibration object.
    grid : tuple of McGridPoint
        Every combination searched, in search order.
    grid_best : McGridPoint
    seeds : tuple of int
    """

    params: MonteCarloParams
    rms: float
    per_object_rms: tuple[float, ...]
    grid: tuple[McGridPoint, ...]
    grid_best: McGridPoint
    seeds: tuple[int, ...]


def _fraction_at(sorted_s: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Fraction of voxels dissolved by dimensionless times ``s`` (one run's sorted A t values)."""
    return np.searchsorted(sorted_s, s, side="right") / sorted_s.size


@dataclass(frozen=True, eq=False)
class McUnitRuns:
    """Monte Carlo runs at A = 1 of a set of objects, for every E_a of a tuning grid.

    A run at A = 1 yields each voxel's dissolution time in units of 1/A; any A then follows by scaling
    time (exact: the step is fixed in units of A dt). A is quoted at the median voxel size ``dx_ref_mm``
    and scaled to each object's own (:meth:`MonteCarloParams.at_voxel_size`).

    Attributes
    ----------
    ea_values : tuple of float, J/mol
    dx_mm : (M,) ndarray of float, mm
        Voxel size of each object.
    temp_k : float, K
    seeds : tuple of int
    sorted_at : dict of float to list of list of ndarray
        Per E_a, per object, per seed: the sorted dimensionless dissolution times A t of its voxels.
    """

    ea_values: tuple[float, ...]
    dx_mm: np.ndarray
    temp_k: float
    seeds: tuple[int, ...]
    sorted_at: dict = field(repr=False)

    @property
    def dx_ref_mm(self) -> float:
        """The voxel size A is quoted at (the median of the objects'), mm."""
        return float(np.median(self.dx_mm))

    def fraction(self, ea_j_per_mol: float, k: int, a_per_s: float, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and spread (standard deviation over seeds) of object ``k``'s fraction dissolved at ``t_s``.

        Parameters
        ----------
        ea_j_per_mol : float
            One of ``ea_values``.
        k : int
            Object index.
        a_per_s : float
            A at ``dx_ref_mm``, 1/s.
        t_s : (N,) ndarray of float, s

        Returns
        -------
        mean, std : (N,) ndarray of float, fraction of the object's solid volume
        """
        scale = a_per_s * self.dx_ref_mm / self.dx_mm[k]
        each = np.array([_fraction_at(s, np.asarray(t_s, float) * scale) for s in self.sorted_at[float(ea_j_per_mol)][k]])
        return each.mean(axis=0), each.std(axis=0)


def unit_runs(objects: Sequence[tuple[np.ndarray, float, tuple[bool, ...] | None]], *,
              ea_values: Sequence[float] = DEFAULT_EA_J_PER_MOL, temp_k: float = BATH_TEMP_K,
              seeds: int | Sequence[int] = DEFAULT_SEEDS,
              progress: Callable[[int, int], None] | None = None) -> McUnitRuns:
    """Simulate every object once per E_a and seed at A = 1 (the expensive part of :func:`tune_mc`).

    Parameters
    ----------
    objects : sequence of (rho, dx_mm, mirror)
        Density grids of the calibration objects (as for :func:`simulate_mc`).
    ea_values : sequence of float
        Activation energies, J/mol (default :data:`DEFAULT_EA_J_PER_MOL`).
    temp_k : float
        Bath temperature, K.
    seeds : int or sequence of int
        Runs per object and E_a.
    progress : callable, optional
        ``progress(done, total)`` after each (E_a, object).

    Returns
    -------
    McUnitRuns
    """
    if not objects:
        raise DesignError("give at least one object")
    if not ea_values:
        raise DesignError("give at least one activation energy")
    seed_list = tuple(range(int(seeds))) if isinstance(seeds, (int, np.integer)) else tuple(int(s) for s in seeds)
    dxs = np.array([check_positive("dx_mm", dx) for _, dx, _ in objects])
    total = len(ea_values) * len(objects)
    sorted_at = {}
    for e, ea in enumerate(ea_values):
        unit = MonteCarloParams(1.0, float(ea), temp_k)
        per_object = []
        for k, (rho, _dx, mirror) in enumerate(objects):
            per_object.append([np.sort(tt[np.isfinite(tt)].ravel())
                               for tt in (erosion_times(rho, unit, seed=s, mirror=mirror) for s in seed_list)])
            if progress is not None:
                progress(e * len(objects) + k + 1, total)
        sorted_at[float(ea)] = per_object
    return McUnitRuns(tuple(float(e) for e in ea_values), dxs, float(temp_k), seed_list, sorted_at)


def tune_mc(runs: McUnitRuns, measured: Sequence[tuple[np.ndarray, np.ndarray]], *,
            a_values: Sequence[float] | None = None, refine: bool = True,
            subset: Sequence[int] | None = None) -> McTuning:
    """Grid search of (A, E_a) against measured release curves (section 5.1: 4 x 4 = 16 combinations).

    Every A of the grid is scored by rescaling the runs at A = 1 (no further simulation). With
    ``a_values`` None, the A values for each E_a are :data:`A_FACTORS` times the A that matches the
    objects' median half-release time.

    Parameters
    ----------
    runs : McUnitRuns
        From :func:`unit_runs` on the calibration objects.
    measured : sequence of (t_s, fraction)
        Each object's measured curve: times, s, since the drop, and the fraction of its weighed mass
        released (0 .. 1); one per object of ``runs``.
    a_values : sequence of float, optional
        Pre-exponential factors, 1/s, at ``runs.dx_ref_mm``.
    refine : bool
        After the grid, refine A at the best E_a by a bounded 1-D search between its grid neighbours.
    subset : sequence of int, optional
        Tune on these objects only (leave-one-out); default all.

    Returns
    -------
    McTuning
    """
    from scipy.optimize import minimize_scalar

    if len(measured) != len(runs.dx_mm):
        raise DesignError(f"give one measured curve per object: {len(runs.dx_mm)} objects, {len(measured)} curves")
    use = list(range(len(measured))) if subset is None else [int(i) for i in subset]
    if not use:
        raise DesignError("tuning needs at least one object")
    curves = {}
    for i in use:
        t, f = (np.asarray(x, float) for x in measured[i])
        if t.ndim != 1 or t.shape != f.shape or t.size < 2 or not (np.all(np.isfinite(t)) and np.all(np.isfinite(f))):
            raise DesignError(f"measured curve {i}: times and fractions must be finite 1-D arrays of equal length >= 2")
        if not f.max() >= 0.5:
            raise DesignError(f"measured curve {i} reaches only {f.max():.0%} of its mass; tuning needs at least 50 %")
        curves[i] = (t, f)
    dx_ref = runs.dx_ref_mm

    def errors(ea: float, a: float) -> np.ndarray:
        return np.array([float(np.sqrt(np.mean((runs.fraction(ea, i, a, t)[0] - f) ** 2)))
                         for i, (t, f) in curves.items()])

    grid = []
    for ea in runs.ea_values:
        ratios = []
        for i, (t, f) in curves.items():
            t_half = float(np.interp(0.5, np.maximum.accumulate(f), t))
            s_half = np.median([s[s.size // 2] for s in runs.sorted_at[ea][i]])
            ratios.append(s_half / t_half * runs.dx_mm[i] / dx_ref)
        a_star = float(np.median(ratios))
        for a in (a_values if a_values is not None else [a_star * x for x in A_FACTORS]):
            grid.append(McGridPoint(float(a), ea, float(errors(ea, float(a)).mean())))
    best = min(grid, key=lambda g: g.rms)
    a_best = best.a_per_s
    if refine:
        same = sorted(g.a_per_s for g in grid if g.ea_j_per_mol == best.ea_j_per_mol)
        i = same.index(best.a_per_s)
        lo = same[i - 1] if i > 0 else best.a_per_s / 2
        hi = same[i + 1] if i + 1 < len(same) else best.a_per_s * 2
        sol = minimize_scalar(lambda q: errors(best.ea_j_per_mol, math.exp(q)).mean(),
                              bounds=(math.log(lo), math.log(hi)), method="bounded", options={"xatol": 1e-4})
        if sol.fun < best.rms:
            a_best = math.exp(float(sol.x))
    per_object = errors(best.ea_j_per_mol, a_best)
    params = MonteCarloParams(a_best, best.ea_j_per_mol, runs.temp_k, dx_ref)
    log.info("Monte Carlo tuning: A = %.4g 1/s, E_a = %.4g J/mol, RMS %.2f %% (grid best %.2f %%)", a_best,
             best.ea_j_per_mol, 100 * per_object.mean(), 100 * best.rms)
    return McTuning(params, float(per_object.mean()), tuple(float(x) for x in per_object), tuple(grid), best,
                    runs.seeds)
