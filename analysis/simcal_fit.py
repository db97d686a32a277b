"""The simulation-to-bench scales fitted to measured shapes (paper section 4.3, Appendix B), and leave-one-out.

The mass scale is pooled over shapes (total weighed mass / total simulated volume). The time scale, one
``seconds_per_mm`` shared by all shapes, minimises the sum over shapes of the section 4.3 loss on
mass-normalised curves (C = released / final)

    L = int w_s |k C_s'(k t) - C_r'(t)| + |C_s(k t) - C_r(t)| dt,   k = 1 / seconds_per_mm, w_s = 1,

with C_r' the slope of the Savitzky-Golay fit (:func:`analysis.smooth_curve`). Time runs in hours inside
L, as in the paper's figures, so that for runs of a few hours both terms are of order one. The integral
covers the measured span only (a run stopped early still calibrates), and each run may carry a drop-time
offset t0 (C_r(t) is compared with C_s(k (t - t0)), |t0| <= ``max_offset_s``), so a drop logged a few
frames off does not bias k. L is not smooth in k: a log-spaced scan brackets the minimum and a bounded
Brent search refines it; offsets and k are then refined in turn. For the ``saturation`` model
(:class:`analysis.simcal.SimCal`), c_sat is fitted by a bounded search over 1 / c_sat (0 = the constant model)
around a time-scale fit at each value.

Leave-one-out (section 5.1): each shape is predicted from its own weighed mass with the time scale (and
c_sat) fitted without it; ``rel_rmse`` = RMS(predicted - measured released g) / weighed mass over the
measured samples, with no offset (a drop-time error counts as prediction error).
"""
from __future__ import annotations

import copy
import logging
import math
from collections.abc import Callable, Sequence

import numpy as np
from scipy.optimize import minimize_scalar

from analysis.curve import DEFAULT_ORDER, DEFAULT_WINDOW_S, smooth_curve
from analysis.errors import AnalysisError
from analysis.simcal import MODELS, LooShape, ShapeRun, SimCal, SimCalFit

log = logging.getLogger(__name__)

SECONDS_PER_MM_BOUNDS = (1.0, 1.0e6)
"""Search range of the time scale, s per mm of tau."""
DEFAULT_MAX_OFFSET_S = 120.0
"""Default bound on a run's drop-time offset, s (about ten frames at 11 s)."""
LAG_BOUNDS_S = (0.0, 1200.0)
"""Search range of the wetting lag, s (PVA prints wet for one to ten minutes before they release)."""
W_SLOPE = 1.0
"""w_s of the section 4.3 loss (1, as in the paper)."""
_HOUR_S = 3600.0
_SCAN_PER_DECADE = 24
_ROUNDS = 3
_LAG_SCAN = 41      # lag grid points over LAG_BOUNDS_S (30 s apart)
_LAG_ROUNDS = 5


class PreparedRun:
    """A shape's normalised curves, sampled where the loss needs them (computed once)."""

    def __init__(self, shape: ShapeRun, window_s: float, order: int) -> None:
        self.shape = shape
        self.tau = np.asarray(shape.tau_mm, float)
        self.sim = np.asarray(shape.released_mm3, float) / shape.volume_mm3
        self.sim_slope = np.gradient(self.sim, self.tau)          # dC_s/dtau, 1/mm
        self.t = np.asarray(shape.t_s, float)
        rel = np.asarray(shape.released_g, float) / shape.mass_g
        self.meas = smooth_curve(self.t, rel, window_s=window_s, order=order)
        self.meas_slope = smooth_curve(self.t, rel, window_s=window_s, order=order, deriv=1) * _HOUR_S   # 1/h
        dt = np.diff(self.t) / _HOUR_S
        self.weight = np.concatenate([[0.5 * dt[0]], 0.5 * (dt[1:] + dt[:-1]), [0.5 * dt[-1]]])   # trapezoid, h
        self.load_fraction = shape.mass_g / shape.water_g   # g of release per g of water when complete

    def with_simulation(self, shape: ShapeRun) -> PreparedRun:
        """This run's prepared measured curves with another simulation of its shape (same measured run)."""
        other = copy.copy(self)
        other.shape = shape
        other.tau = np.asarray(shape.tau_mm, float)
        other.sim = np.asarray(shape.released_mm3, float) / shape.volume_mm3
        other.sim_slope = np.gradient(other.sim, other.tau)
        return other

    def _clock(self, inv_csat: float) -> tuple[np.ndarray | None, np.ndarray]:
        """The model's clock in units of seconds_per_mm at each simulated tau (None: the constant rate's, tau
        itself) and the simulated slope on it, dC_s/dtau times the bath's free fraction."""
        if inv_csat <= 0:
            return None, self.sim_slope
        free = 1.0 - inv_csat * 1000.0 * self.load_fraction * self.sim
        steps = 0.5 * (1.0 / free[1:] + 1.0 / free[:-1]) * np.diff(self.tau)
        return np.concatenate([[0.0], np.cumsum(steps)]), self.sim_slope * free

    def loss(self, seconds_per_mm: float, inv_csat: float, offset_s: float) -> float:
        """Section 4.3's L for this run (hours), the simulated curve on the clock of the model."""
        return float(self.losses(np.array([seconds_per_mm]), np.array([offset_s]), inv_csat)[0])

    def losses(self, seconds_per_mm: np.ndarray, offset_s: np.ndarray, inv_csat: float = 0.0) -> np.ndarray:
        """:meth:`loss` at M pairs (seconds_per_mm, offset_s) at once, (M,). The clock scales with seconds_per_mm,
        so the measured time t - offset maps to tau through the clock at (t - offset) / seconds_per_mm (tau itself,
        clipped to the simulated range, at a constant rate)."""
        s, offset = np.broadcast_arrays(np.asarray(seconds_per_mm, float), np.asarray(offset_s, float))
        s = s.reshape(-1, 1)
        t = self.t[None, :] - offset.reshape(-1, 1)
        x = t / s
        clock, slope = self._clock(inv_csat)
        if clock is None:
            tau, end = np.minimum(np.maximum(x, self.tau[0]), self.tau[-1]), self.tau[-1]
        else:
            tau, end = np.interp(x, clock, self.tau), clock[-1]
        started = (t > 0) & (x < end)
        pred = np.interp(tau, self.tau, self.sim)
        pred_slope = np.where(started, np.interp(tau, self.tau, slope), 0.0) * (_HOUR_S / s)
        return np.sum(self.weight * (W_SLOPE * np.abs(pred_slope - self.meas_slope) + np.abs(pred - self.meas)), axis=1)


def _bounded(f: Callable[[float], float], lo: float, hi: float, xatol: float) -> tuple[float, float]:
    res = minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": xatol})
    return float(res.x), float(res.fun)


def _scan_then_refine(f: Callable[[float], float], grid: np.ndarray, xatol: float,
                      on_grid: Callable[[np.ndarray], np.ndarray] | None = None) -> tuple[float, float]:
    """Robust 1-D minimum of a non-smooth f: best grid point, then Brent between its neighbours. ``on_grid``, when
    given, is f on the whole grid at once (vectorised)."""
    values = np.asarray(on_grid(grid), float) if on_grid is not None else np.array([f(x) for x in grid])
    i = int(np.argmin(values))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    x, fx = _bounded(f, lo, hi, xatol) if hi > lo else (float(grid[i]), float(values[i]))
    return (x, fx) if fx <= values[i] else (float(grid[i]), float(values[i]))


def _fit_time(prepared: Sequence[PreparedRun], inv_csat: float, max_offset_s: float,
              around: float | None = None, lag: bool = False) -> tuple[float, float, list[float], list[float]]:
    """Shared seconds_per_mm, wetting lag (with ``lag``; else 0) and per-run offsets for a given 1/c_sat;
    returns (s, lag_s, offsets, losses).

    Run i's measured time is compared at t - lag - t0_i. The lag is shared by all runs (a property of the
    material); the offsets are each run's jitter of its logged drop, bounded by ``max_offset_s``. A shift common to
    every run cannot tell one from the other, so with the lag fitted the offsets are centred: their mean goes into
    the lag (clipped to `LAG_BOUNDS_S`), and the lag is the mean delay of the runs.
    """
    offsets = [0.0] * len(prepared)
    lag_s = 0.0

    def total(log_s: float) -> float:
        s = math.exp(log_s)
        return sum(p.loss(s, inv_csat, lag_s + o) for p, o in zip(prepared, offsets))

    def total_on(log_s: np.ndarray) -> np.ndarray:   # the scans are vectorised (PreparedRun.losses)
        return sum(p.losses(np.exp(log_s), lag_s + o, inv_csat) for p, o in zip(prepared, offsets))

    lo, hi = (math.log(b) for b in SECONDS_PER_MM_BOUNDS)
    full_grid = np.linspace(lo, hi, int(round((hi - lo) / math.log(10) * _SCAN_PER_DECADE)) + 1)
    if around is None:
        log_s, _ = _scan_then_refine(total, full_grid, 1e-5, total_on)
    else:
        grid = np.linspace(math.log(around) - 0.3, math.log(around) + 0.3, 13)
        log_s, _ = _scan_then_refine(total, grid, 1e-5, total_on)
        if min(log_s - grid[0], grid[-1] - log_s) < 0.5 * (grid[1] - grid[0]):   # at the window's edge: scan all
            log_s, _ = _scan_then_refine(total, full_grid, 1e-5, total_on)
    lag_grid = np.linspace(*LAG_BOUNDS_S, _LAG_SCAN)
    # a lag changes the time scale the first scan found (it absorbed the delay): more rounds, a wider step
    rounds, window = (_LAG_ROUNDS, 0.15) if lag else (_ROUNDS if max_offset_s > 0 else 0, 0.05)
    for _ in range(rounds):
        s = math.exp(log_s)
        if lag:
            lag_s, _ = _scan_then_refine(
                lambda d: sum(p.loss(s, inv_csat, d + o) for p, o in zip(prepared, offsets)), lag_grid, 0.1,
                lambda ds: sum(p.losses(s, ds + o, inv_csat) for p, o in zip(prepared, offsets)))
        if max_offset_s > 0:
            offset_grid = np.linspace(-max_offset_s, max_offset_s, 17)
            offsets = [_scan_then_refine(lambda o, p=p: p.loss(s, inv_csat, lag_s + o), offset_grid, 0.1,
                                         lambda os_, p=p: p.losses(s, lag_s + os_, inv_csat))[0]
                       for p in prepared]
            if lag:
                moved = min(max(lag_s + float(np.mean(offsets)), LAG_BOUNDS_S[0]), LAG_BOUNDS_S[1])
                offsets = [o + lag_s - moved for o in offsets]
                lag_s = moved
        log_s, _ = _bounded(total, log_s - window, log_s + window, 1e-6)
    s = math.exp(log_s)
    return s, lag_s, offsets, [p.loss(s, inv_csat, lag_s + o) for p, o in zip(prepared, offsets)]


def prepare_runs(shapes: Sequence[ShapeRun], window_s: float, order: int) -> list[PreparedRun]:
    """The shapes' curves prepared for the loss (``window_s``, ``order``: Savitzky-Golay settings).

    Raises
    ------
    AnalysisError
        An empty or duplicate-named set.
    """
    if not shapes:
        raise AnalysisError("a calibration needs at least one shape")
    names = [s.name for s in shapes]
    if len(set(names)) != len(names):
        raise AnalysisError(f"shape names must be unique, got {names}")
    return [PreparedRun(s, window_s, order) for s in shapes]


def fit_prepared(prepared: Sequence[PreparedRun], model: str, max_offset_s: float,
                 around: float | None = None, lag: bool = False) -> SimCalFit:
    """:func:`fit_simcal` on prepared runs; ``around`` (s per mm), when given, is where the time-scale scan
    starts (a window of it, all of the range if the minimum is at the window's edge)."""
    if model not in MODELS:
        raise AnalysisError(f"model {model!r} is not one of {', '.join(MODELS)}")
    if not 0 <= max_offset_s < math.inf:
        raise AnalysisError(f"max_offset_s = {max_offset_s!r} must be >= 0 and finite")
    shapes = [p.shape for p in prepared]
    g_per_mm3 = float(sum(s.mass_g for s in shapes) / sum(s.volume_mm3 for s in shapes))
    s, lag_s, offsets, losses = _fit_time(prepared, 0.0, max_offset_s, around=around, lag=lag)
    inv_csat = 0.0
    if model == "saturation":
        # 1/c_sat from 0 (constant rate) to where the most loaded bath would reach 90% of saturation
        top = 0.9 / (1000.0 * max(p.load_fraction for p in prepared))
        fits: dict[float, tuple[float, float, list[float], list[float]]] = {0.0: (s, lag_s, offsets, losses)}

        def objective(x: float) -> float:
            if x not in fits:
                fits[x] = _fit_time(prepared, x, max_offset_s, around=s, lag=lag)
            return float(sum(fits[x][3]))

        inv_csat, _ = _scan_then_refine(objective, np.linspace(0.0, top, 10), top * 1e-4)
        objective(inv_csat)
        s, lag_s, offsets, losses = fits[inv_csat]
        if inv_csat <= 0:   # the constant model fits best: a bath that never saturates (c_sat 1e6 x the bound)
            inv_csat = top * 1e-6
    cal = SimCal(model, s, g_per_mm3, 1.0 / inv_csat if model == "saturation" else None, lag_s)
    return SimCalFit(cal, tuple(sh.g_per_mm3 for sh in shapes), tuple(offsets), tuple(losses))


def fit_simcal(shapes: Sequence[ShapeRun], model: str = "constant", *, max_offset_s: float = DEFAULT_MAX_OFFSET_S,
               window_s: float = DEFAULT_WINDOW_S, order: int = DEFAULT_ORDER, lag: bool = False) -> SimCalFit:
    """Fit the simulation-to-bench map to measured shapes (section 4.3; Appendix B for ``saturation``).

    Parameters
    ----------
    shapes : sequence of ShapeRun
        At least one; the time scale is shared by all.
    model : {'constant', 'saturation'}
    max_offset_s : float
        Bound on each run's drop-time offset, s (0: no offsets).
    window_s, order
        Savitzky-Golay settings for the measured curves and their slopes.
    lag : bool
        Fit a wetting lag shared by all runs (``SimCal.lag_s``); else none.

    Returns
    -------
    SimCalFit

    Raises
    ------
    AnalysisError
        An unknown model, an empty or duplicate-named set.
    """
    return fit_prepared(prepare_runs(shapes, window_s, order), model, max_offset_s, lag=lag)


def leave_one_out(shapes: Sequence[ShapeRun], model: str = "constant", *,
                  max_offset_s: float = DEFAULT_MAX_OFFSET_S, window_s: float = DEFAULT_WINDOW_S,
                  order: int = DEFAULT_ORDER, progress: Callable[[int, int], None] | None = None,
                  lag: bool = False) -> tuple[LooShape, ...]:
    """Predict each shape with a calibration fitted to the others (section 5.1's cross-validation).

    Parameters
    ----------
    shapes : sequence of ShapeRun
        At least two.
    model, max_offset_s, window_s, order, lag
        As in :func:`fit_simcal`.
    progress : callable, optional
        ``progress(done, total)`` after each left-out shape.

    Returns
    -------
    tuple of LooShape
        In the order of ``shapes``.
    """
    prepared = prepare_runs(shapes, window_s, order)
    if len(prepared) < 2:
        raise AnalysisError("leave-one-out needs at least two shapes")
    out = []
    for i, p in enumerate(prepared):
        cal = fit_prepared(prepared[:i] + prepared[i + 1:], model, max_offset_s, lag=lag).cal
        out.append(LooShape.of(cal, p.shape))
        log.info("leave-one-out %s (%s): rel_rmse %.2f%%", p.shape.name, model, 100 * out[-1].rel_rmse)
        if progress is not None:
            progress(i + 1, len(prepared))
    return tuple(out)
