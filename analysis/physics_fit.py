"""Print physics fitted with the simulation-to-bench scales (:mod:`analysis.physics_grid`), with leave-one-out,
standard errors and their discretisation term, and the choice of the parameter set leave-one-out prefers.

Each candidate parameter value is scored by the section 4.3 loss of the constant-rate scales fitted at it
(:mod:`analysis.simcal_fit`); the analysis never simulates: the caller gives ``shapes_at(values)``.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from analysis.curve import DEFAULT_ORDER, DEFAULT_WINDOW_S
from analysis.errors import AnalysisError
from analysis.physics_grid import (
    FIT_IDENTITY,
    FIT_PARAMETERS,
    LAG,
    PHYSICS_GRIDS,
    PHYSICS_IDENTITY,
    PHYSICS_PARAMETERS,
    PHYSICS_SETS,
    grid_coord,
    physics_search,
)
from analysis.simcal import LooShape, ShapeRun
from analysis.simcal_fit import DEFAULT_MAX_OFFSET_S, PreparedRun, fit_prepared, prepare_runs

log = logging.getLogger(__name__)

EARN_MARGIN = 0.05
"""A parameter set is kept over a smaller one only if its mean leave-one-out error is lower by more than this
fraction: a parameter must earn its place, not win by the noise of the fit."""
EARN_SIGMAS = 2.0
"""... and only if each of its parameters lies more than this many standard errors from its identity value."""
MIN_RUNS_TO_CHOOSE = 3
"""Fewest runs from which ``auto`` chooses print physics: with two, each leave-one-out refit rests on one run, and
the spread of two refits is no standard error to judge a parameter by; fewer runs keep the isotropic model."""
LAG_FLOOR_S = 1.0
"""Least standard error of the wetting lag, s."""


@dataclass(frozen=True)
class PhysicsFit:
    """Print physics fitted with the scales.

    Attributes
    ----------
    fitted : tuple of str
        The parameters fitted (names of `FIT_PARAMETERS`); the others stay at `FIT_IDENTITY`.
    values : dict
        Every parameter's value (fitted or identity), the wetting lag `LAG` included.
    uncertainty : dict
        Per fitted parameter, its standard error: the largest of the jackknife over the leave-one-out
        fits, a tenth of its grid step and the spread of a flat minimum (for the offset and the swelling width
        also the floor the caller gives).
    loss : float
        Section 4.3 loss of the scales fitted at `values`.
    loo : tuple of LooShape
        Each shape predicted with physics and scales fitted without it.
    loo_values : tuple of dict
        The parameter values fitted without each shape.
    """

    fitted: tuple[str, ...]
    values: dict
    uncertainty: dict
    loss: float
    loo: tuple[LooShape, ...]
    loo_values: tuple[dict, ...]

    @property
    def loo_rel_rmse_mean(self) -> float:
        """Mean leave-one-out relative RMSE."""
        return float(np.mean([s.rel_rmse for s in self.loo]))


class _Simulations:
    """The calibration shapes' measured curves, prepared once, with their simulations at any physics values
    (asked of ``shapes_at`` once per values)."""

    def __init__(self, shapes_at: Callable[[dict], Sequence[ShapeRun]], max_offset_s: float, window_s: float,
                 order: int) -> None:
        self._shapes_at = shapes_at
        self.base = prepare_runs(shapes_at(dict(PHYSICS_IDENTITY)), window_s, order)   # the measured curves, smoothed once
        self.around = fit_prepared(self.base, "constant", max_offset_s).cal.seconds_per_mm
        """The identity physics' time scale, s per mm: where every refit's scan starts."""
        self._prepared: dict[tuple, list[PreparedRun]] = {}

    def at(self, values: dict) -> list[PreparedRun]:
        """The prepared runs with the shapes simulated at ``values``."""
        key = tuple(round(values[p], 9) for p in PHYSICS_PARAMETERS)
        if key not in self._prepared:
            self._prepared[key] = [b.with_simulation(sh) for b, sh in zip(self.base, self._shapes_at(values))]
        return self._prepared[key]


def fit_physics(shapes_at: Callable[[dict], Sequence[ShapeRun]], fitted: Sequence[str], *,
                max_offset_s: float = DEFAULT_MAX_OFFSET_S, window_s: float = DEFAULT_WINDOW_S,
                order: int = DEFAULT_ORDER, progress: Callable[[int, int], None] | None = None,
                offset_floor_mm: float = 0.0, losses: dict | None = None) -> PhysicsFit:
    """Fit print physics and the constant-rate scales together, with leave-one-out and uncertainties.

    Each candidate parameter value is scored by the section 4.3 loss of the scales fitted at it (the
    time scale and the drop offsets refitted for every value, the mass scale pooled), summed over shapes;
    the parameters minimise it (:func:`analysis.physics_grid.physics_search`). Leave-one-out refits the physics
    and the scales without each shape and predicts it from its weighed mass; the spread of those refits gives
    each parameter's jackknife standard error.

    Parameters
    ----------
    shapes_at : callable
        ``shapes_at(values)``: the calibration shapes (same order and names every call) simulated with the
        parameter values ``values`` (a dict over `PHYSICS_PARAMETERS`).
    fitted : sequence of str
        Parameters to fit (a subset of `FIT_PARAMETERS`; empty: the identity physics). The wetting lag `LAG`
        is fitted with the time scale inside every loss evaluation (:func:`analysis.simcal_fit._fit_time`), not
        searched on a grid; its standard error is the jackknife over the leave-one-out refits, at least
        `LAG_FLOOR_S`.
    max_offset_s, window_s, order
        As in :func:`analysis.simcal_fit.fit_simcal`.
    progress : callable, optional
        ``progress(done, total)`` after the full fit and each left-out shape.
    offset_floor_mm : float
        Least standard error of the offset and of the swelling width, mm: a voxelised surface is placed, and a
        channel's width measured, only to within its voxels (the caller passes half the simulations' voxel edge).
    losses : dict, optional
        The losses evaluated, per (physics values, left-out shape, lag fitted): a dict the caller shares between
        the fits of several parameter sets on the same shapes and settings, so that a candidate value two sets
        search (every set with the anisotropy scans its grid at the identity offset) is fitted once.

    Returns
    -------
    PhysicsFit
    """
    unknown = [p for p in fitted if p not in FIT_PARAMETERS]
    if unknown:
        raise AnalysisError(f"unknown print physics {unknown}; known: {', '.join(FIT_PARAMETERS)}")
    lag = LAG in fitted
    simulated = [p for p in fitted if p in PHYSICS_PARAMETERS]
    sims = _Simulations(shapes_at, max_offset_s, window_s, order)
    losses = {} if losses is None else losses

    def loss_without(skip: int | None) -> Callable[[dict], float]:
        def loss_at(values: dict) -> float:
            key = (tuple(round(values[p], 9) for p in PHYSICS_PARAMETERS), skip, lag)
            if key not in losses:
                sub = [p for j, p in enumerate(sims.at(values)) if j != skip]
                losses[key] = fit_prepared(sub, "constant", max_offset_s, sims.around, lag=lag).loss
            return losses[key]
        return loss_at

    n = len(sims.base)
    if n < 2:
        raise AnalysisError("fitting print physics needs at least two shapes (leave-one-out)")
    flat: dict[str, float] = {}
    values = physics_search(loss_without(None), simulated, flat=flat) if simulated else dict(PHYSICS_IDENTITY)
    full = fit_prepared(sims.at(values), "constant", max_offset_s, lag=lag)
    values = {**values, LAG: full.cal.lag_s}
    if progress is not None:
        progress(1, n + 1)
    loo, loo_values = [], []
    for i in range(n):
        v = physics_search(loss_without(i), simulated, near=values) if simulated else dict(PHYSICS_IDENTITY)
        shapes = sims.at(v)
        cal = fit_prepared(shapes[:i] + shapes[i + 1:], "constant", max_offset_s, lag=lag).cal
        v = {**v, LAG: cal.lag_s}
        loo.append(LooShape.of(cal, shapes[i].shape))
        loo_values.append(v)
        log.info("leave-one-out %s (physics %s): %s, rel_rmse %.2f%%", loo[-1].name, "+".join(fitted) or "none", v,
                 100 * loo[-1].rel_rmse)
        if progress is not None:
            progress(i + 2, n + 1)
    uncertainty = _standard_errors(fitted, values, loo_values, flat, offset_floor_mm)
    return PhysicsFit(tuple(fitted), values, uncertainty, full.loss, tuple(loo), tuple(loo_values))


def _standard_errors(fitted: Sequence[str], values: dict, loo_values: Sequence[dict], flat: dict[str, float],
                     offset_floor_mm: float) -> dict:
    """Per fitted parameter, its standard error (:attr:`PhysicsFit.uncertainty`): the jackknife over the
    leave-one-out values, with the floors of :func:`fit_physics`."""
    n = len(loo_values)
    uncertainty = {}
    for p in fitted:
        coords = np.array([grid_coord(p, v[p]) for v in loo_values])
        jack = math.sqrt((n - 1) / n * float(np.sum((coords - coords.mean()) ** 2)))
        if p == LAG:   # continuous, no grid: at least the search's resolution
            uncertainty[p] = float(max(jack, LAG_FLOOR_S))
            continue
        step = abs(grid_coord(p, PHYSICS_GRIDS[p][1]) - grid_coord(p, PHYSICS_GRIDS[p][0]))
        # a flat minimum of half-width a: any value in it fits alike (uniform: standard error a / sqrt(3))
        se = max(jack, 0.1 * step, flat.get(p, 0.0) / math.sqrt(3.0))
        # anisotropy is searched in log: its standard error is relative, reported in its own unit
        uncertainty[p] = float(values[p] * se) if p == "anisotropy" else float(max(se, offset_floor_mm))
    return uncertainty


DISCRETISATION_FACTOR = 1.5
"""The second resolution of the discretisation term, as a multiple of the calibration's (:func:`refit_physics`)."""


def refit_physics(shapes_at: Callable[[dict], Sequence[ShapeRun]], fitted: Sequence[str], near: dict, *,
                  max_offset_s: float = DEFAULT_MAX_OFFSET_S, window_s: float = DEFAULT_WINDOW_S,
                  order: int = DEFAULT_ORDER) -> dict:
    """The print physics fitted to all shapes again, on other simulations of them (the calibration meshes at a
    second resolution): the same loss and search as :func:`fit_physics`, within
    `analysis.physics_grid._LOO_WINDOW` grid points of ``near`` (the first fit), without leave-one-out. Returns
    every parameter's value."""
    if not fitted:
        return dict(FIT_IDENTITY)
    lag = LAG in fitted
    simulated = [p for p in fitted if p in PHYSICS_PARAMETERS]
    sims = _Simulations(shapes_at, max_offset_s, window_s, order)
    values = (physics_search(lambda v: fit_prepared(sims.at(v), "constant", max_offset_s, sims.around, lag=lag).loss,
                             simulated, near=near) if simulated else dict(PHYSICS_IDENTITY))
    return {**values, LAG: fit_prepared(sims.at(values), "constant", max_offset_s, lag=lag).cal.lag_s}


def with_discretisation(uncertainty: dict, values: dict, refit: dict,
                        factor: float = DISCRETISATION_FACTOR) -> tuple[dict, dict]:
    """Standard errors with a discretisation term: each parameter's bias at the calibration's resolution,
    estimated from its refit at ``factor`` times that resolution (:func:`refit_physics`), added in quadrature,
    sqrt(se^2 + b^2).

    The jackknife over leave-one-out refits measures how much the fit moves with the shapes, not the bias every
    refit shares because the meshes are voxelised (a 0.45 mm voxel on a 3.6 mm slab). For an error that falls
    like the voxel size h, theta_h - theta_(h / f) = b (1 - 1 / f): the bias at h is b = |theta_h - theta_(h / f)|
    f / (f - 1) (3 x the difference for f = 1.5; a conservative bound for errors that fall faster than h).

    Returns
    -------
    uncertainty : dict
        Per parameter of ``uncertainty``, the combined standard error.
    bias : dict
        Per parameter, the estimated discretisation bias b.
    """
    if not factor > 1:
        raise AnalysisError(f"the second resolution must be finer: factor {factor!r} must be > 1")
    bias = {p: abs(float(refit[p]) - float(values[p])) * factor / (factor - 1.0) for p in uncertainty}
    return {p: float(math.hypot(float(uncertainty[p]), bias[p])) for p in uncertainty}, bias


def choose_physics(fits: dict[str, PhysicsFit]) -> str:
    """The physics set leave-one-out prefers: the smallest mean error, a larger set kept only if it beats
    every smaller one it contains by `EARN_MARGIN` and each of its parameters is `EARN_SIGMAS` standard errors
    from its identity value (``none`` is the isotropic model of the mesh as designed)."""
    def size(name: str) -> int:
        return len(PHYSICS_SETS[name])

    chosen = "none" if "none" in fits else min(fits, key=size)
    for name in sorted(fits, key=size):
        if name == chosen:
            continue
        smaller = [m for m in fits if size(m) < size(name) and set(PHYSICS_SETS[m]) <= set(PHYSICS_SETS[name])]
        earns = all(fits[name].loo_rel_rmse_mean < (1 - EARN_MARGIN) * fits[m].loo_rel_rmse_mean for m in smaller)
        # and every parameter it fits is resolved away from its identity value
        earns = earns and all(abs(fits[name].values[p] - FIT_IDENTITY[p]) > EARN_SIGMAS * fits[name].uncertainty[p]
                              for p in fits[name].fitted)
        if earns and fits[name].loo_rel_rmse_mean < fits[chosen].loo_rel_rmse_mean:
            chosen = name
    return chosen
