"""Simulation-to-bench calibration (paper section 4.3, Appendix B): grams per mm^3 and seconds per mm.

The forward model works in simulation units (tau = depth dissolved, mm; released solid, mm^3); the bench
measures seconds and grams. Two maps bridge them:

- mass: released grams per mm^3 of simulated solid, ``g_per_mm3 = weighed mass / simulated final volume``
  per shape, pooled over shapes as total weighed mass / total simulated volume;
- time: one ``seconds_per_mm`` shared by all shapes (tau = t / seconds_per_mm), minimising the sum over
  shapes of the section 4.3 loss on mass-normalised curves (C = released / final)

      L = int w_s |k C_s'(k t) - C_r'(t)| + |C_s(k t) - C_r(t)| dt,   k = 1 / seconds_per_mm, w_s = 1,

  with C_r' the slope of the Savitzky-Golay fit (:func:`analysis.smooth_curve`). Time runs in hours inside
  L, as in the paper's figures, so that for runs of a few hours both terms are of order one. The integral
  covers the measured span only (a run stopped early still calibrates), and each run may carry a drop-time
  offset t0 (C_r(t) is compared with C_s(k (t - t0)), |t0| <= ``max_offset_s``), so a drop logged a few
  frames off does not bias k. L is not smooth in k: a log-spaced scan brackets the minimum and a bounded
  Brent search refines it; offsets and k are then refined in turn.

The second model (``saturation``, Appendix B) lets the bath slow the front as it fills:
d tau / dt = k (1 - c(t) / c_sat), with c(t) the bath concentration (g/kg) of the run's own water mass, so
runs with different water masses share one c_sat. Its clock is t(tau) = (1/k) int_0^tau dtau' / g(tau'),
g = 1 - m(tau') / (c_sat W) (trapezoid on the simulated tau grid); c_sat is fitted by a bounded search
over 1 / c_sat (0 = the constant model) around a time-scale fit at each value.

Leave-one-out (section 5.1): each shape is predicted from its own weighed mass with the time scale (and
c_sat) fitted without it; ``rel_rmse`` = RMS(predicted - measured released g) / weighed mass over the
measured samples, with no offset (a drop-time error counts as prediction error).
"""
from __future__ import annotations

import copy
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from analysis.curve import DEFAULT_ORDER, DEFAULT_WINDOW_S, smooth_curve
from analysis.errors import AnalysisError

log = logging.getLogger(__name__)

MODELS = ("constant", "saturation")
"""Calibration models: constant rate (Appendix A, eq. 11 with a constant bath) and the concentration-dependent
rate of Appendix B."""
DENSITY_RANGE_G_PER_CM3 = (0.8, 2.0)
"""Weighed mass / simulated volume outside this range means a wrong mesh, unit or mass."""
MIN_RELEASE_FRACTION = 0.05
"""A run whose measured release never reaches this fraction of its weighed mass shows no release."""
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


@dataclass(frozen=True, eq=False)
class ShapeRun:
    """One calibration shape: its simulated release and its measured run.

    Attributes
    ----------
    name : str
        Named in messages and results (e.g. the SET.csv row and run).
    tau_mm : (K,) ndarray of float, mm
        Simulated tau grid from 0 to complete dissolution.
    released_mm3 : (K,) ndarray of float, mm^3
        Simulated cumulative released volume; its last value is the simulated solid volume.
    t_s : (N,) ndarray of float, s since the drop, strictly increasing
    released_g : (N,) ndarray of float, g
        Measured (smoothed) release; may stop before complete dissolution.
    mass_g : float
        Weighed mass of the printed object, g.
    water_g : float
        Water mass of the run, g.
    """

    name: str
    tau_mm: np.ndarray
    released_mm3: np.ndarray
    t_s: np.ndarray
    released_g: np.ndarray
    mass_g: float
    water_g: float

    def __post_init__(self) -> None:
        tau, vol = np.asarray(self.tau_mm, float), np.asarray(self.released_mm3, float)
        if tau.ndim != 1 or tau.shape != vol.shape or tau.size < 3 or np.any(np.diff(tau) <= 0):
            raise AnalysisError(f"{self.name}: the simulated curve needs >= 3 increasing tau samples")
        if not vol[-1] > 0:
            raise AnalysisError(f"{self.name}: the simulated solid has no volume")
        t, rel = np.asarray(self.t_s, float), np.asarray(self.released_g, float)
        if t.ndim != 1 or t.shape != rel.shape or t.size < 5:
            raise AnalysisError(f"{self.name}: the measured curve needs >= 5 samples, got {t.size}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(rel))) or np.any(np.diff(t) <= 0):
            raise AnalysisError(f"{self.name}: measured times must be finite and increasing, releases finite")
        for field_name in ("mass_g", "water_g"):
            value = getattr(self, field_name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise AnalysisError(f"{self.name}: {field_name} = {value!r} must be a positive number of grams")
        density = self.mass_g / vol[-1] * 1000.0
        lo, hi = DENSITY_RANGE_G_PER_CM3
        if not lo <= density <= hi:
            raise AnalysisError(f"{self.name}: weighed {self.mass_g:g} g over the simulated {vol[-1]:.1f} mm^3 "
                                f"means {density:.3g} g/cm^3, outside {lo:g}-{hi:g} g/cm^3 (wrong mesh, mesh unit "
                                "or mass?)")
        if np.max(rel) < MIN_RELEASE_FRACTION * self.mass_g:
            raise AnalysisError(f"{self.name}: the run shows no release (at most {np.max(rel):.3g} g of the weighed "
                                f"{self.mass_g:g} g); was the object dropped, and is it the right run?")

    @property
    def volume_mm3(self) -> float:
        """Simulated solid volume, mm^3."""
        return float(self.released_mm3[-1])

    @property
    def g_per_mm3(self) -> float:
        """This shape's mass scale: weighed mass / simulated volume, g/mm^3."""
        return self.mass_g / self.volume_mm3


@dataclass(frozen=True)
class SimCal:
    """The simulation-to-bench map.

    Attributes
    ----------
    model : {'constant', 'saturation'}
    seconds_per_mm : float
        Seconds per mm of tau (into clean water for ``saturation``).
    g_per_mm3 : float
        Released grams per mm^3 of simulated solid.
    saturation_g_per_kg : float or None
        c_sat of the ``saturation`` model, g/kg; None for ``constant``.
    lag_s : float
        Wetting lag, s: the print releases nothing for this long after the drop, then as the model says (a
        property of the material and the print shared by every run; 0: none). The bench's time t is the model's
        clock plus the lag.
    """

    model: str
    seconds_per_mm: float
    g_per_mm3: float
    saturation_g_per_kg: float | None = None
    lag_s: float = 0.0

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise AnalysisError(f"model {self.model!r} is not one of {', '.join(MODELS)}")
        for name in ("seconds_per_mm", "g_per_mm3"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise AnalysisError(f"{name} = {value!r} must be positive")
        if (self.model == "saturation") != (self.saturation_g_per_kg is not None):
            raise AnalysisError("saturation_g_per_kg is given exactly for the 'saturation' model")
        if self.saturation_g_per_kg is not None and not self.saturation_g_per_kg > 0:
            raise AnalysisError(f"saturation_g_per_kg = {self.saturation_g_per_kg!r} must be positive")
        if not (math.isfinite(self.lag_s) and self.lag_s >= 0):
            raise AnalysisError(f"lag_s = {self.lag_s!r} must be a number of seconds >= 0")

    def clock_s(self, tau_mm: np.ndarray, released_g: np.ndarray, water_g: float) -> np.ndarray:
        """Physical time at each tau sample, s (tau / k, or Appendix B's remapping).

        Parameters
        ----------
        tau_mm : (K,) ndarray of float, mm
        released_g : (K,) ndarray of float, g released by each tau
        water_g : float
            Water mass of the bath, g.

        Raises
        ------
        AnalysisError
            If the release would saturate the bath.
        """
        tau = np.asarray(tau_mm, float)
        if self.saturation_g_per_kg is None:
            return tau * self.seconds_per_mm
        capacity_g = self.saturation_g_per_kg * water_g / 1000.0
        free = 1.0 - np.asarray(released_g, float) / capacity_g
        if np.any(free <= 0):
            raise AnalysisError(f"{np.max(released_g):.3g} g saturates {water_g:g} g of water at c_sat = "
                                f"{self.saturation_g_per_kg:.3g} g/kg; dissolution would never finish")
        inv = 1.0 / free
        steps = 0.5 * (inv[1:] + inv[:-1]) * np.diff(tau)
        return np.concatenate([[0.0], np.cumsum(steps)]) * self.seconds_per_mm

    def to_physical(self, tau_mm: np.ndarray, released_mm3: np.ndarray, t_s: np.ndarray, water_g: float,
                    mass_g: float | None = None) -> np.ndarray:
        """Predicted released grams at times ``t_s`` from a simulated curve.

        Parameters
        ----------
        tau_mm, released_mm3 : (K,) ndarray of float
            Simulated curve from tau = 0.
        t_s : (Q,) ndarray of float, s since the drop
        water_g : float
            Water mass, g (used by ``saturation``).
        mass_g : float, optional
            Weighed mass, g, when known (default: ``g_per_mm3`` times the simulated volume).

        Returns
        -------
        (Q,) ndarray of float, g
            Nothing before the wetting lag (``lag_s``), then the simulated release on the model's clock.
        """
        vol = np.asarray(released_mm3, float)
        grams = vol * (self.g_per_mm3 if mass_g is None else mass_g / vol[-1])
        return np.interp(np.asarray(t_s, float) - self.lag_s, self.clock_s(tau_mm, grams, water_g), grams, left=0.0)

    def to_simulation(self, t_s: np.ndarray, released_g: np.ndarray, water_g: float) -> tuple[np.ndarray, np.ndarray]:
        """A measured curve in simulation units: tau (mm) and released volume (mm^3).

        The measured release is known at every t, so Appendix B's ODE integrates directly:
        tau(t) = k int_lag^t (1 - c(t') / c_sat) dt' (trapezoid), tau = (t - lag) / seconds_per_mm for
        ``constant``: the model's clock starts when the wetting lag ends.

        Parameters
        ----------
        t_s : (N,) ndarray of float, s since the drop, increasing, >= ``lag_s`` (the release before the lag
            ends is nothing the model can make)
        released_g : (N,) ndarray of float, g
        water_g : float

        Returns
        -------
        tau_mm, released_mm3 : (N,) ndarray of float
        """
        t = np.asarray(t_s, float) - self.lag_s
        grams = np.asarray(released_g, float)
        if self.saturation_g_per_kg is None:
            tau = t / self.seconds_per_mm
        else:
            free = 1.0 - grams / (self.saturation_g_per_kg * water_g / 1000.0)
            steps = 0.5 * (free[1:] + free[:-1]) * np.diff(t)
            tau = (t[0] * free[0] + np.concatenate([[0.0], np.cumsum(steps)])) / self.seconds_per_mm
        return tau, grams / self.g_per_mm3


@dataclass(frozen=True)
class SimCalFit:
    """A calibration fitted to a set of shapes.

    Attributes
    ----------
    cal : SimCal
    g_per_mm3_per_shape : tuple of float
        Each shape's weighed mass / simulated volume, g/mm^3.
    offsets_s : tuple of float
        Each run's fitted drop-time offset t0, s (measured t = true t + t0).
    loss_per_shape : tuple of float
        Each shape's section 4.3 loss L at the fit (time in hours).
    """

    cal: SimCal
    g_per_mm3_per_shape: tuple[float, ...]
    offsets_s: tuple[float, ...]
    loss_per_shape: tuple[float, ...]

    @property
    def loss(self) -> float:
        """Sum of L over the shapes."""
        return float(sum(self.loss_per_shape))


@dataclass(frozen=True, eq=False)
class LooShape:
    """One shape predicted by a calibration fitted without it.

    Attributes
    ----------
    name : str
    cal : SimCal
        The calibration fitted on the other shapes.
    t_s : (N,) ndarray of float, s
    measured_g, predicted_g : (N,) ndarray of float, g
    rel_rmse : float
        RMS(predicted - measured) / weighed mass.
    """

    name: str
    cal: SimCal
    t_s: np.ndarray
    measured_g: np.ndarray
    predicted_g: np.ndarray
    rel_rmse: float


class _Prepared:
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

    def with_simulation(self, shape: ShapeRun) -> _Prepared:
        """This run's prepared measured curves with another simulation of its shape (same measured run)."""
        other = copy.copy(self)
        other.shape = shape
        other.tau = np.asarray(shape.tau_mm, float)
        other.sim = np.asarray(shape.released_mm3, float) / shape.volume_mm3
        other.sim_slope = np.gradient(other.sim, other.tau)
        return other

    def loss(self, seconds_per_mm: float, inv_csat: float, offset_s: float) -> float:
        """Section 4.3's L for this run (hours), the simulated curve on the clock of the model."""
        free = 1.0 - inv_csat * 1000.0 * self.load_fraction * self.sim
        if inv_csat > 0:
            steps = 0.5 * (1.0 / free[1:] + 1.0 / free[:-1]) * np.diff(self.tau)
            clock = np.concatenate([[0.0], np.cumsum(steps)]) * seconds_per_mm
        else:
            clock = self.tau * seconds_per_mm
        t = self.t - offset_s
        tau = np.interp(t, clock, self.tau)
        started = (t > 0) & (t < clock[-1])
        pred = np.interp(tau, self.tau, self.sim)
        pred_slope = np.where(started, np.interp(tau, self.tau, self.sim_slope * free), 0.0) \
            * (_HOUR_S / seconds_per_mm)
        return float(np.sum(self.weight * (W_SLOPE * np.abs(pred_slope - self.meas_slope) + np.abs(pred - self.meas))))


def _bounded(f: Callable[[float], float], lo: float, hi: float, xatol: float) -> tuple[float, float]:
    res = minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": xatol})
    return float(res.x), float(res.fun)


def _scan_then_refine(f: Callable[[float], float], grid: np.ndarray, xatol: float) -> tuple[float, float]:
    """Robust 1-D minimum of a non-smooth f: best grid point, then Brent between its neighbours."""
    values = np.array([f(x) for x in grid])
    i = int(np.argmin(values))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    x, fx = _bounded(f, lo, hi, xatol) if hi > lo else (float(grid[i]), float(values[i]))
    return (x, fx) if fx <= values[i] else (float(grid[i]), float(values[i]))


def _fit_time(prepared: Sequence[_Prepared], inv_csat: float, max_offset_s: float,
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

    lo, hi = (math.log(b) for b in SECONDS_PER_MM_BOUNDS)
    full_grid = np.linspace(lo, hi, int(round((hi - lo) / math.log(10) * _SCAN_PER_DECADE)) + 1)
    if around is None:
        log_s, _ = _scan_then_refine(total, full_grid, 1e-5)
    else:
        grid = np.linspace(math.log(around) - 0.3, math.log(around) + 0.3, 13)
        log_s, _ = _scan_then_refine(total, grid, 1e-5)
        if min(log_s - grid[0], grid[-1] - log_s) < 0.5 * (grid[1] - grid[0]):   # at the window's edge: scan all
            log_s, _ = _scan_then_refine(total, full_grid, 1e-5)
    lag_grid = np.linspace(*LAG_BOUNDS_S, _LAG_SCAN)
    # a lag changes the time scale the first scan found (it absorbed the delay): more rounds, a wider step
    rounds, window = (_LAG_ROUNDS, 0.15) if lag else (_ROUNDS if max_offset_s > 0 else 0, 0.05)
    for _ in range(rounds):
        s = math.exp(log_s)
        if lag:
            lag_s, _ = _scan_then_refine(
                lambda d: sum(p.loss(s, inv_csat, d + o) for p, o in zip(prepared, offsets)), lag_grid, 0.1)
        if max_offset_s > 0:
            offset_grid = np.linspace(-max_offset_s, max_offset_s, 17)
            offsets = [_scan_then_refine(lambda o, p=p: p.loss(s, inv_csat, lag_s + o), offset_grid, 0.1)[0]
                       for p in prepared]
            if lag:
                moved = min(max(lag_s + float(np.mean(offsets)), LAG_BOUNDS_S[0]), LAG_BOUNDS_S[1])
                offsets = [o + lag_s - moved for o in offsets]
                lag_s = moved
        log_s, _ = _bounded(total, log_s - window, log_s + window, 1e-6)
    s = math.exp(log_s)
    return s, lag_s, offsets, [p.loss(s, inv_csat, lag_s + o) for p, o in zip(prepared, offsets)]


def _prepare(shapes: Sequence[ShapeRun], window_s: float, order: int) -> list[_Prepared]:
    if not shapes:
        raise AnalysisError("a calibration needs at least one shape")
    names = [s.name for s in shapes]
    if len(set(names)) != len(names):
        raise AnalysisError(f"shape names must be unique, got {names}")
    return [_Prepared(s, window_s, order) for s in shapes]


def _fit_prepared(prepared: Sequence[_Prepared], model: str, max_offset_s: float,
                  around: float | None = None, lag: bool = False) -> SimCalFit:
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
    return _fit_prepared(_prepare(shapes, window_s, order), model, max_offset_s, lag=lag)


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
    prepared = _prepare(shapes, window_s, order)
    if len(prepared) < 2:
        raise AnalysisError("leave-one-out needs at least two shapes")
    out = []
    for i, p in enumerate(prepared):
        cal = _fit_prepared(prepared[:i] + prepared[i + 1:], model, max_offset_s, lag=lag).cal
        sh = p.shape
        predicted = cal.to_physical(sh.tau_mm, sh.released_mm3, sh.t_s, sh.water_g, mass_g=sh.mass_g)
        measured = np.asarray(sh.released_g, float)
        rel = float(np.sqrt(np.mean((predicted - measured) ** 2)) / sh.mass_g)
        out.append(LooShape(sh.name, cal, np.asarray(sh.t_s, float), measured, predicted, rel))
        log.info("leave-one-out %s (%s): rel_rmse %.2f%%", sh.name, model, 100 * rel)
        if progress is not None:
            progress(i + 1, len(prepared))
    return tuple(out)


# ---------------------------------------------------------------------------------------------------------
# Print physics: parameters of the forward model itself (design.forward: anisotropy, surface offset, swelling), fitted
# with the scales. The analysis never simulates: the caller gives ``shapes_at(values)``, the calibration
# shapes simulated with those parameter values (the job caches them per mesh and values).

PHYSICS_PARAMETERS = ("anisotropy", "offset_mm", "swelling_mm")
"""Print physics the calibration can fit: z / in-plane erosion rate, printed surface outside the mesh's (mm), the
width below which channels are shut by the swollen material until their walls dissolve (mm)."""
PHYSICS_IDENTITY = {"anisotropy": 1.0, "offset_mm": 0.0, "swelling_mm": 0.0}
"""Values that switch each effect off (the paper's isotropic model of the mesh as designed)."""
PHYSICS_GRIDS = {"anisotropy": tuple(float(x) for x in np.exp(np.linspace(math.log(0.5), math.log(2.0), 13))),
                 "offset_mm": tuple(float(x) for x in np.round(np.linspace(-0.2, 0.3, 11), 6)),
                 "swelling_mm": tuple(float(x) for x in np.round(np.linspace(0.0, 1.2, 13), 6))}
"""Search grid of each parameter (anisotropy log-spaced by a factor 1.12, offset in 0.05 mm steps, swelling width
in 0.1 mm steps from none to 1.2 mm); the minimum is refined by a parabola through the best grid point and its
neighbours (the swelling width changes the release in voxel steps, so its loss is often flat over several grid
points: the middle of that flat minimum is taken, `_flat_run`)."""
LAG = "wetting_lag_s"
"""The wetting lag (``SimCal.lag_s``, s) as a fitted parameter: not a parameter of the forward model (nothing is
simulated again for it) but of its clock, fitted with the time scale inside every loss evaluation
(:func:`_fit_time`), searched on `LAG_BOUNDS_S`."""
FIT_PARAMETERS = PHYSICS_PARAMETERS + (LAG,)
"""Every parameter ``--physics`` can fit: the forward model's print physics and the wetting lag."""
FIT_IDENTITY = {**PHYSICS_IDENTITY, LAG: 0.0}
"""Values that switch each fitted effect off."""
_SIMULATED_SETS = {"none": (), "anisotropy": ("anisotropy",), "offset": ("offset_mm",), "swelling": ("swelling_mm",),
                   "anisotropy+offset": ("anisotropy", "offset_mm"), "anisotropy+swelling": ("anisotropy", "swelling_mm"),
                   "offset+swelling": ("offset_mm", "swelling_mm"), "anisotropy+offset+swelling": PHYSICS_PARAMETERS}
PHYSICS_SETS = {**{k: v for k, v in _SIMULATED_SETS.items() if k != "anisotropy+offset+swelling"},
                **{("lag" if k == "none" else f"{k}+lag"): v + (LAG,) for k, v in _SIMULATED_SETS.items()
                   if k != "anisotropy+offset+swelling"},
                "anisotropy+offset+swelling": PHYSICS_PARAMETERS, "all": FIT_PARAMETERS}
"""The parameter sets ``auto`` fits (every subset of `FIT_PARAMETERS`); a named ``--physics`` fits its own set and
``none``. ``all`` fits every parameter, the wetting lag included."""
PHYSICS_CHOICES = tuple(PHYSICS_SETS) + ("auto",)
"""``--physics`` values: a set of `PHYSICS_SETS` to fit; ``auto`` fits every subset and keeps the one leave-one-out
prefers."""
EARN_MARGIN = 0.05
"""A parameter set is kept over a smaller one only if its mean leave-one-out error is lower by more than this
fraction: a parameter must earn its place, not win by the noise of the fit."""
EARN_SIGMAS = 2.0
"""... and only if each of its parameters lies more than this many standard errors from its identity value."""
LAG_FLOOR_S = 1.0
"""Least standard error of the wetting lag, s."""
_PHYSICS_ROUNDS = 2
_LOO_WINDOW = 3


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


def _grid_coord(name: str, x: float) -> float:
    return math.log(x) if name == "anisotropy" else x


def _from_coord(name: str, c: float) -> float:
    return math.exp(c) if name == "anisotropy" else c


def _flat_run(losses: Sequence[float], i: int) -> tuple[int, int]:
    """The grid points either side of i whose loss equals the minimum (the same simulations: a voxel-step
    parameter such as the swelling width changes nothing between them)."""
    tol = 1e-12 * max(abs(losses[i]), 1e-300)
    a = b = i
    while a > 0 and abs(losses[a - 1] - losses[i]) <= tol:
        a -= 1
    while b < len(losses) - 1 and abs(losses[b + 1] - losses[i]) <= tol:
        b += 1
    return a, b


def _refine(name: str, grid: Sequence[float], i: int, losses: Sequence[float]) -> float:
    """Vertex of the parabola through grid point i and its neighbours (in log for anisotropy), kept between them;
    the middle of a flat minimum (`_flat_run`) when several grid points share it."""
    a, b = _flat_run(losses, i)
    if b > a:
        return float(_from_coord(name, 0.5 * (_grid_coord(name, grid[a]) + _grid_coord(name, grid[b]))))
    if i == 0 or i == len(grid) - 1:
        return float(grid[i])
    c = [_grid_coord(name, grid[j]) for j in (i - 1, i, i + 1)]
    f = [losses[j] for j in (i - 1, i, i + 1)]
    den = (c[0] - c[1]) * (c[0] - c[2]) * (c[1] - c[2])
    a = (c[2] * (f[1] - f[0]) + c[1] * (f[0] - f[2]) + c[0] * (f[2] - f[1])) / den
    b = (c[2] ** 2 * (f[0] - f[1]) + c[1] ** 2 * (f[2] - f[0]) + c[0] ** 2 * (f[1] - f[2])) / den
    if not a > 0:
        return float(grid[i])
    return float(_from_coord(name, min(max(-b / (2 * a), c[0]), c[2])))


def _nearest(p: str, value: float) -> int:
    return int(np.argmin([abs(_grid_coord(p, g) - _grid_coord(p, value)) for g in PHYSICS_GRIDS[p]]))


def _physics_search(loss_at: Callable[[dict], float], fitted: Sequence[str], near: dict | None = None,
                    flat: dict | None = None) -> dict:
    """Coordinate search over the grids of the ``fitted`` parameters (values on grid points), then a parabola
    refinement of each from its grid neighbours. Returns every parameter's value. With ``near`` (values), the
    search starts there and covers `_LOO_WINDOW` grid points either side of it (leave-one-out refits). ``flat``,
    when given, receives per parameter the half-width of its flat minimum (`_flat_run`, in its grid coordinate;
    0 for a single best point)."""
    start = near or PHYSICS_IDENTITY
    index = {p: _nearest(p, start[p]) for p in fitted}
    span = {p: (0, len(PHYSICS_GRIDS[p])) if near is None else
            (max(index[p] - _LOO_WINDOW, 0), min(index[p] + _LOO_WINDOW + 1, len(PHYSICS_GRIDS[p]))) for p in fitted}

    def point(overrides: dict) -> dict:
        values = dict(PHYSICS_IDENTITY)
        values.update({p: PHYSICS_GRIDS[p][k] for p, k in index.items()})
        values.update(overrides)
        return values

    profiles: dict[str, list[float]] = {}
    for _ in range(_PHYSICS_ROUNDS if len(fitted) > 1 else 1):
        for p in fitted:
            lo, hi = span[p]
            grid = PHYSICS_GRIDS[p][lo:hi]
            profiles[p] = [loss_at(point({p: g})) for g in grid]
            index[p] = lo + int(np.argmin(profiles[p]))
    values = point({})
    for p in fitted:
        lo, hi = span[p]
        values[p] = _refine(p, PHYSICS_GRIDS[p][lo:hi], index[p] - lo, profiles[p])
        if flat is not None:
            a, b = _flat_run(profiles[p], index[p] - lo)
            grid = PHYSICS_GRIDS[p][lo:hi]
            flat[p] = 0.5 * abs(_grid_coord(p, grid[b]) - _grid_coord(p, grid[a]))
    return values


def fit_physics(shapes_at: Callable[[dict], Sequence[ShapeRun]], fitted: Sequence[str], *,
                max_offset_s: float = DEFAULT_MAX_OFFSET_S, window_s: float = DEFAULT_WINDOW_S,
                order: int = DEFAULT_ORDER, progress: Callable[[int, int], None] | None = None,
                offset_floor_mm: float = 0.0) -> PhysicsFit:
    """Fit print physics and the constant-rate scales together, with leave-one-out and uncertainties.

    Each candidate parameter value is scored by the section 4.3 loss of the scales fitted at it (the
    time scale and the drop offsets refitted for every value, the mass scale pooled), summed over shapes;
    the parameters minimise it (:func:`_physics_search`). Leave-one-out refits the physics and the scales
    without each shape and predicts it from its weighed mass; the spread of those refits gives each
    parameter's jackknife standard error.

    Parameters
    ----------
    shapes_at : callable
        ``shapes_at(values)``: the calibration shapes (same order and names every call) simulated with the
        parameter values ``values`` (a dict over `PHYSICS_PARAMETERS`).
    fitted : sequence of str
        Parameters to fit (a subset of `FIT_PARAMETERS`; empty: the identity physics). The wetting lag `LAG`
        is fitted with the time scale inside every loss evaluation (:func:`_fit_time`), not searched on a grid;
        its standard error is the jackknife over the leave-one-out refits, at least `LAG_FLOOR_S`.
    max_offset_s, window_s, order
        As in :func:`fit_simcal`.
    progress : callable, optional
        ``progress(done, total)`` after the full fit and each left-out shape.
    offset_floor_mm : float
        Least standard error of the offset and of the swelling width, mm: a voxelised surface is placed, and a
        channel's width measured, only to within its voxels (the caller passes half the simulations' voxel edge).

    Returns
    -------
    PhysicsFit
    """
    unknown = [p for p in fitted if p not in FIT_PARAMETERS]
    if unknown:
        raise AnalysisError(f"unknown print physics {unknown}; known: {', '.join(FIT_PARAMETERS)}")
    lag = LAG in fitted
    simulated = [p for p in fitted if p in PHYSICS_PARAMETERS]
    prepared: dict[tuple, list[_Prepared]] = {}
    base = _prepare(shapes_at(dict(PHYSICS_IDENTITY)), window_s, order)   # the measured curves, smoothed once
    around = _fit_prepared(base, "constant", max_offset_s).cal.seconds_per_mm

    def prep(values: dict) -> list[_Prepared]:
        key = tuple(round(values[p], 9) for p in PHYSICS_PARAMETERS)
        if key not in prepared:
            prepared[key] = [b.with_simulation(sh) for b, sh in zip(base, shapes_at(values))]
        return prepared[key]

    def loss_without(skip: int | None) -> Callable[[dict], float]:
        def loss_at(values: dict) -> float:
            sub = [p for j, p in enumerate(prep(values)) if j != skip]
            return _fit_prepared(sub, "constant", max_offset_s, around, lag=lag).loss
        return loss_at

    n = len(base)
    if n < 2:
        raise AnalysisError("fitting print physics needs at least two shapes (leave-one-out)")
    flat: dict[str, float] = {}
    values = _physics_search(loss_without(None), simulated, flat=flat) if simulated else dict(PHYSICS_IDENTITY)
    full = _fit_prepared(prep(values), "constant", max_offset_s, lag=lag)
    values = {**values, LAG: full.cal.lag_s}
    if progress is not None:
        progress(1, n + 1)
    loo, loo_values = [], []
    for i in range(n):
        v = _physics_search(loss_without(i), simulated, near=values) if simulated else dict(PHYSICS_IDENTITY)
        shapes = prep(v)
        cal = _fit_prepared(shapes[:i] + shapes[i + 1:], "constant", max_offset_s, lag=lag).cal
        v = {**v, LAG: cal.lag_s}
        sh = shapes[i].shape
        predicted = cal.to_physical(sh.tau_mm, sh.released_mm3, sh.t_s, sh.water_g, mass_g=sh.mass_g)
        measured = np.asarray(sh.released_g, float)
        rel = float(np.sqrt(np.mean((predicted - measured) ** 2)) / sh.mass_g)
        loo.append(LooShape(sh.name, cal, np.asarray(sh.t_s, float), measured, predicted, rel))
        loo_values.append(v)
        log.info("leave-one-out %s (physics %s): %s, rel_rmse %.2f%%", sh.name, "+".join(fitted) or "none", v, 100 * rel)
        if progress is not None:
            progress(i + 2, n + 1)
    uncertainty = {}
    for p in fitted:
        coords = np.array([_grid_coord(p, v[p]) for v in loo_values])
        jack = math.sqrt((n - 1) / n * float(np.sum((coords - coords.mean()) ** 2)))
        if p == LAG:   # continuous, no grid: at least the search's resolution
            uncertainty[p] = float(max(jack, LAG_FLOOR_S))
            continue
        step = abs(_grid_coord(p, PHYSICS_GRIDS[p][1]) - _grid_coord(p, PHYSICS_GRIDS[p][0]))
        # a flat minimum of half-width a: any value in it fits alike (uniform: standard error a / sqrt(3))
        se = max(jack, 0.1 * step, flat.get(p, 0.0) / math.sqrt(3.0))
        # anisotropy is searched in log: its standard error is relative, reported in its own unit
        uncertainty[p] = float(values[p] * se) if p == "anisotropy" else float(max(se, offset_floor_mm))
    return PhysicsFit(tuple(fitted), values, uncertainty, full.loss, tuple(loo), tuple(loo_values))


DISCRETISATION_FACTOR = 1.5
"""The second resolution of the discretisation term, as a multiple of the calibration's (:func:`refit_physics`)."""


def refit_physics(shapes_at: Callable[[dict], Sequence[ShapeRun]], fitted: Sequence[str], near: dict, *,
                  max_offset_s: float = DEFAULT_MAX_OFFSET_S, window_s: float = DEFAULT_WINDOW_S,
                  order: int = DEFAULT_ORDER) -> dict:
    """The print physics fitted to all shapes again, on other simulations of them (the calibration meshes at a
    second resolution): the same loss and search as :func:`fit_physics`, within `_LOO_WINDOW` grid points of
    ``near`` (the first fit), without leave-one-out. Returns every parameter's value."""
    if not fitted:
        return dict(FIT_IDENTITY)
    lag = LAG in fitted
    simulated = [p for p in fitted if p in PHYSICS_PARAMETERS]
    base = _prepare(shapes_at(dict(PHYSICS_IDENTITY)), window_s, order)
    around = _fit_prepared(base, "constant", max_offset_s).cal.seconds_per_mm
    prepared: dict[tuple, list[_Prepared]] = {}

    def prep(values: dict) -> list[_Prepared]:
        key = tuple(round(values[p], 9) for p in PHYSICS_PARAMETERS)
        if key not in prepared:
            prepared[key] = [b.with_simulation(sh) for b, sh in zip(base, shapes_at(values))]
        return prepared[key]

    values = (_physics_search(lambda v: _fit_prepared(prep(v), "constant", max_offset_s, around, lag=lag).loss,
                              simulated, near=near) if simulated else dict(PHYSICS_IDENTITY))
    return {**values, LAG: _fit_prepared(prep(values), "constant", max_offset_s, lag=lag).cal.lag_s}


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
