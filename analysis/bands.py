"""Error bands of calibrated predictions: the calibration's parameter uncertainty and its leave-one-out residuals.

A prediction of a new print's release (grams over seconds, through :class:`analysis.simcal.SimCal`) is off
for two reasons: the print differs from the model in ways no calibrated parameter captures (shape to shape),
and the calibrated parameters themselves are uncertain. The band at each time is

    nominal +- q * sqrt(max(s_model(f), s_par(t))^2 + s_mass(t)^2)

- ``s_model(f)``: the leave-one-out residuals (each calibration run predicted by a calibration fitted without
  it, :func:`analysis.simcal_fit.leave_one_out`), as a root mean square per bin of the predicted released
  fraction f = predicted grams / mass (each run weighted equally in a bin), interpolated between bin
  centres, times the prediction's mass. They already hold the error of parameters fitted on one run fewer,
  so the parameter spread of the time scale and the print physics, ``s_par(t)``, is a floor, not an addend:
  it takes over where a prediction is more sensitive to those parameters than the calibration runs were.
- ``s_par(t)``: each parameter moved by its standard error (jackknife over the leave-one-out refits; the wetting
  lag moves the clock, the print physics are simulated again), the prediction's change at each time, added in
  quadrature (the linearised propagation
  sqrt(sum_p (dg/dp sigma_p)^2) with central differences, :func:`parameter_spread`).
- ``s_mass(t)``: the mass scale's predictive spread (how one more print's grams per simulated mm^3 differ from
  the pooled scale: the calibration prints' spread times sqrt(1 + 1/n)) times the predicted release, for a
  prediction whose mass is not weighed (leave-one-out predicts each run from its weighed mass, so its
  residuals lack this term).
- ``q``: Student's t quantile of the band's level with as many degrees of freedom as runs gave residuals
  (the residual mean square of k runs around a zero mean has k degrees of freedom): with few runs the
  band widens, as a prediction interval from a small sample must.

The coverage of a held-out run (:func:`loo_coverage`) is the fraction of its measured points inside the band
built from the other runs only: the residual model of the others and their quantile.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

from analysis.errors import AnalysisError
from analysis.physics_grid import LAG, PHYSICS_IDENTITY, PHYSICS_PARAMETERS
from analysis.simcal import LooShape, ShapeRun, SimCal

BAND_LEVEL = 0.90
"""Nominal coverage of the bands: the central 90% (the 5th and 95th percentiles)."""
FRACTION_EDGES = tuple(float(x) for x in np.concatenate([np.linspace(0.0, 0.95, 20), [0.995, 1.0]]))
"""Bins of the predicted released fraction the leave-one-out residuals are pooled in: 5% wide, and the
last 0.5% (a print predicted fully dissolved, where only the measurement's noise remains) on its own."""
SimulateAt = Callable[[dict], tuple[np.ndarray, np.ndarray]]
"""``simulate_at(physics)``: a shape's simulated release (tau_mm, released_mm3) with that print physics."""


@dataclass(frozen=True)
class ResidualModel:
    """Leave-one-out residuals as a root mean square per bin of the predicted released fraction.

    Attributes
    ----------
    fraction_edges : tuple of float
        Bin edges of the predicted fraction (0..1).
    rms : tuple of float
        Per bin, RMS of (predicted - measured) / mass; a bin no run reached takes its neighbours' value.
    runs : int
        Runs the residuals come from (the quantile's degrees of freedom).
    """

    fraction_edges: tuple[float, ...]
    rms: tuple[float, ...]
    runs: int

    def __post_init__(self) -> None:
        if len(self.rms) != len(self.fraction_edges) - 1 or self.runs < 1:
            raise AnalysisError(f"a residual model needs one RMS per bin and >= 1 run, got {len(self.rms)} RMS for "
                                f"{len(self.fraction_edges) - 1} bins and {self.runs} runs")
        if not all(math.isfinite(r) and r >= 0 for r in self.rms):
            raise AnalysisError(f"residual RMS must be finite and >= 0, got {self.rms}")

    def sigma(self, fraction: np.ndarray) -> np.ndarray:
        """The residual RMS at predicted fractions (fraction of mass), interpolated between bin centres."""
        edges = np.asarray(self.fraction_edges)
        centres = 0.5 * (edges[1:] + edges[:-1])
        return np.interp(np.clip(np.asarray(fraction, float), 0.0, 1.0), centres, np.asarray(self.rms))

    def to_dict(self) -> dict:
        return {"fraction_edges": list(self.fraction_edges), "rms": list(self.rms), "runs": self.runs}

    @classmethod
    def from_dict(cls, doc: dict) -> ResidualModel:
        return cls(tuple(float(x) for x in doc["fraction_edges"]), tuple(float(x) for x in doc["rms"]), int(doc["runs"]))


def quantile(level: float, runs: int) -> float:
    """Student's t quantile of a central ``level`` band with ``runs`` degrees of freedom.

    Examples
    --------
    >>> round(quantile(0.9, 10**6), 3)
    1.645
    """
    if not 0 < level < 1:
        raise AnalysisError(f"band level {level!r} must lie strictly between 0 and 1")
    return float(stats.t.ppf(0.5 + 0.5 * level, df=max(runs, 1)))


def residual_model(runs: Sequence[tuple[np.ndarray, np.ndarray, float]],
                   fraction_edges: Sequence[float] = FRACTION_EDGES) -> ResidualModel:
    """Pool leave-one-out residuals per bin of the predicted fraction.

    Parameters
    ----------
    runs : sequence of (predicted_g, measured_g, mass_g)
        Each held-out run's prediction and measurement at its sample times, g, and its mass, g.
    fraction_edges : sequence of float

    Returns
    -------
    ResidualModel
        Per bin, the mean over the runs with samples in it of each run's mean squared residual there, rooted.
    """
    if not runs:
        raise AnalysisError("a residual model needs at least one held-out run")
    edges = np.asarray(fraction_edges, float)
    nbins = edges.size - 1
    sums, counts = np.zeros(nbins), np.zeros(nbins)
    for predicted, measured, mass in runs:
        f = np.clip(np.asarray(predicted, float) / mass, 0.0, 1.0)
        r2 = ((np.asarray(predicted, float) - np.asarray(measured, float)) / mass) ** 2
        which = np.clip(np.searchsorted(edges, f, side="right") - 1, 0, nbins - 1)
        for b in np.unique(which):
            sums[b] += float(np.mean(r2[which == b]))
            counts[b] += 1
    filled = counts > 0
    centres = 0.5 * (edges[1:] + edges[:-1])
    ms = np.interp(centres, centres[filled], sums[filled] / counts[filled])
    return ResidualModel(tuple(float(x) for x in edges), tuple(float(x) for x in np.sqrt(ms)), len(runs))


def parameter_spread(nominal_g: np.ndarray, moved: Sequence[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """The linearised parameter spread of a prediction, g: sqrt(sum_p ((g(p + s_p) - g(p - s_p)) / 2)^2).

    Parameters
    ----------
    nominal_g : (Q,) ndarray of float
        The prediction at the fitted parameters (only its shape is used; an empty ``moved`` gives zeros).
    moved : sequence of ((Q,) ndarray, (Q,) ndarray)
        Per parameter, the prediction with that parameter one standard error up and one down.
    """
    spread = np.zeros_like(np.asarray(nominal_g, float))
    for up, down in moved:
        spread += (0.5 * (np.asarray(up, float) - np.asarray(down, float))) ** 2
    return np.sqrt(spread)


def band(nominal_g: np.ndarray, mass_g: float, residuals: ResidualModel, *, level: float = BAND_LEVEL,
         parameter_g: np.ndarray | None = None, mass_sd_g: np.ndarray | float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The band of a prediction (see the module docstring).

    Parameters
    ----------
    nominal_g : (Q,) ndarray of float
        The predicted release, g.
    mass_g : float
        The prediction's final mass, g (the residuals are fractions of it).
    residuals : ResidualModel
    level : float
        Nominal coverage.
    parameter_g : (Q,) ndarray of float, optional
        :func:`parameter_spread` of the time scale and the print physics, g.
    mass_sd_g : (Q,) ndarray of float or float
        The mass scale's spread, g (0 for a weighed mass).

    Returns
    -------
    lower_g, upper_g : (Q,) ndarray of float
        Clipped to [0, the upper end's mass]: a release is never negative.
    """
    nominal = np.asarray(nominal_g, float)
    if not (math.isfinite(mass_g) and mass_g > 0):
        raise AnalysisError(f"the band's mass {mass_g!r} must be a positive number of grams")
    model = residuals.sigma(nominal / mass_g) * mass_g
    floor = np.zeros_like(nominal) if parameter_g is None else np.asarray(parameter_g, float)
    half = quantile(level, residuals.runs) * np.sqrt(np.maximum(model, floor) ** 2 + np.asarray(mass_sd_g, float) ** 2)
    return np.maximum(nominal - half, 0.0), nominal + half


def inside(measured_g: np.ndarray, lower_g: np.ndarray, upper_g: np.ndarray) -> float:
    """Fraction of the measured points inside [lower, upper]."""
    m = np.asarray(measured_g, float)
    return float(np.mean((m >= np.asarray(lower_g)) & (m <= np.asarray(upper_g))))


@dataclass(frozen=True)
class Coverage:
    """How many held-out points fell inside their bands.

    Attributes
    ----------
    per_run : tuple of float
        Each held-out run's fraction of measured points inside the band from the other runs.
    points_inside, points : int
        Over all runs.
    level : float
        The bands' nominal coverage.
    """

    per_run: tuple[float, ...]
    points_inside: int
    points: int
    level: float

    @property
    def fraction(self) -> float:
        """Fraction of all held-out points inside their bands."""
        return self.points_inside / self.points if self.points else math.nan


def loo_bands(runs: Sequence[tuple[np.ndarray, np.ndarray, float]], *, level: float = BAND_LEVEL,
              parameter_g: Callable[[int], np.ndarray | None] | None = None,
              fraction_edges: Sequence[float] = FRACTION_EDGES) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each held-out run's band from the other runs (their residual model, their number its degrees of freedom).

    Parameters
    ----------
    runs : sequence of (predicted_g, measured_g, mass_g)
        Each run predicted by the calibration fitted without it (at least two runs).
    level : float
    parameter_g : callable, optional
        ``parameter_g(i)``: the parameter spread of run i's prediction (:func:`parameter_spread`), g, or None.
    fraction_edges : sequence of float

    Returns
    -------
    list of (lower_g, upper_g)
    """
    if len(runs) < 2:
        raise AnalysisError("the leave-one-out coverage needs at least two runs")
    out = []
    for i, (predicted, _, mass) in enumerate(runs):
        others = residual_model([r for j, r in enumerate(runs) if j != i], fraction_edges)
        out.append(band(predicted, mass, others, level=level, parameter_g=None if parameter_g is None else parameter_g(i)))
    return out


def loo_coverage(runs: Sequence[tuple[np.ndarray, np.ndarray, float]], *, level: float = BAND_LEVEL,
                 parameter_g: Callable[[int], np.ndarray | None] | None = None,
                 fraction_edges: Sequence[float] = FRACTION_EDGES) -> Coverage:
    """The leave-one-out coverage of the bands: the fraction of each held-out run's measured points inside its
    band from the other runs (:func:`loo_bands`; the arguments are its own).

    Returns
    -------
    Coverage
    """
    per_run, hits, total = [], 0, 0
    for (_, measured, _), (lower, upper) in zip(runs, loo_bands(runs, level=level, parameter_g=parameter_g,
                                                                 fraction_edges=fraction_edges)):
        m = np.asarray(measured, float)
        k = int(np.sum((m >= lower) & (m <= upper)))
        per_run.append(k / m.size)
        hits, total = hits + k, total + m.size
    return Coverage(tuple(per_run), hits, total, level)


# ---------------------------------------------------------------------------------------------------------
# The band block of a calibration: what a prediction's band needs, and the leave-one-out coverage.

def _jackknife_rel(values: Sequence[float]) -> float:
    """Jackknife standard error of a positive quantity from its leave-one-out values, relative (in log)."""
    logs = np.log(np.asarray(values, float))
    n = logs.size
    return float(math.sqrt((n - 1) / n * float(np.sum((logs - logs.mean()) ** 2))))


def _cal_moved(cal: SimCal, seconds_factor: float = 1.0, lag_s: float | None = None) -> SimCal:
    return dataclasses.replace(cal, seconds_per_mm=cal.seconds_per_mm * seconds_factor,
                               lag_s=cal.lag_s if lag_s is None else max(lag_s, 0.0))


def _moved_physics(physics: dict, sd: dict) -> list[tuple[dict, dict]]:
    """Per parameter with a standard error, the physics with it one standard error up and down."""
    out = []
    for p in PHYSICS_PARAMETERS:
        s = float(sd.get(p) or 0.0)
        if s > 0:
            up, down = dict(physics), dict(physics)
            if p == "anisotropy":    # a ratio, searched in log: its error is relative
                up[p], down[p] = physics[p] * math.exp(s / physics[p]), physics[p] * math.exp(-s / physics[p])
            else:   # a width cannot go below zero
                up[p], down[p] = physics[p] + s, physics[p] - s if p == "offset_mm" else max(physics[p] - s, 0.0)
            out.append((up, down))
    return out


def spread_g(cal: SimCal, tau_mm: np.ndarray, released_mm3: np.ndarray, t_s: np.ndarray, water_g: float,
             mass_g: float | None, seconds_rel_sd: float, physics: dict, physics_sd: dict,
             simulate_at: SimulateAt | None) -> np.ndarray:
    """The parameter spread (time scale and print physics) of one prediction, g (:func:`parameter_spread`)."""
    nominal = cal.to_physical(tau_mm, released_mm3, t_s, water_g, mass_g=mass_g)
    moved = [tuple(_cal_moved(cal, math.exp(sign * seconds_rel_sd)).to_physical(tau_mm, released_mm3, t_s, water_g,
                                                                                 mass_g=mass_g) for sign in (1, -1))]
    lag_sd = float(physics_sd.get(LAG) or 0.0)
    if lag_sd > 0:   # the wetting lag moves the clock, nothing is simulated again (a lag is never below 0)
        moved.append(tuple(_cal_moved(cal, lag_s=cal.lag_s + sign * lag_sd).to_physical(
            tau_mm, released_mm3, t_s, water_g, mass_g=mass_g) for sign in (1, -1)))
    if simulate_at is not None:
        for up, down in _moved_physics(physics, physics_sd):
            # with a weighed mass the moved print keeps it; without, its volume changes its mass
            moved.append(tuple(cal.to_physical(*simulate_at(values), t_s, water_g, mass_g=mass_g)
                               for values in (up, down)))
    return parameter_spread(nominal, moved)


def loo_parameter_spread(loo: Sequence[LooShape], shapes: Sequence[ShapeRun], loo_physics: Sequence[dict] | None,
                         physics_sd: dict, seconds_rel_sd: float,
                         simulate_at: Callable[[int, dict], tuple[np.ndarray, np.ndarray]]) -> Callable[[int], np.ndarray]:
    """``parameter_g(i)`` of :func:`loo_coverage`: held-out run i's parameter spread at its leave-one-out fit
    (its weighed mass, so no mass term)."""
    def parameter_g(i: int) -> np.ndarray:
        sh, s = shapes[i], loo[i]
        physics = dict(loo_physics[i]) if loo_physics else dict(PHYSICS_IDENTITY)
        tau, vol = simulate_at(i, physics)
        return spread_g(s.cal, tau, vol, s.t_s, sh.water_g, sh.mass_g, seconds_rel_sd, physics, physics_sd,
                        lambda values: simulate_at(i, values))
    return parameter_g


def band_block(loo: Sequence[LooShape], shapes: Sequence[ShapeRun], loo_physics: Sequence[dict] | None,
               physics_sd: dict, simulate_at: Callable[[int, dict], tuple[np.ndarray, np.ndarray]],
               level: float = BAND_LEVEL) -> dict:
    """The ``band`` block of ``simcal.json`` and the leave-one-out coverage.

    Parameters
    ----------
    loo : sequence of LooShape
        Each run predicted by the calibration fitted without it (with print physics: refitted without it).
    shapes : sequence of ShapeRun
        The calibration runs, in the same order (weighed mass, water, simulated volume).
    loo_physics : sequence of dict or None
        The print physics fitted without each run (None: the identity for all).
    physics_sd : dict
        Standard error of each fitted print physics parameter.
    simulate_at : callable
        ``simulate_at(i, physics)``: run i's mesh simulated with that physics (tau_mm, released_mm3).
    level : float
        Nominal coverage of the bands.
    """
    runs = [(s.predicted_g, s.measured_g, sh.mass_g) for s, sh in zip(loo, shapes)]
    residuals = residual_model(runs)
    seconds_sd = _jackknife_rel([s.cal.seconds_per_mm for s in loo])
    # a new print's own mass per simulated mm^3 differs from the pooled scale as the calibration prints' differ
    # (print density, surface offset over its area, voxelisation): the predictive spread of one more print,
    # sd * sqrt(1 + 1/n), not the standard error of the pooled mean
    ratios = np.log([sh.mass_g / sh.volume_mm3 for sh in shapes])
    mass_sd = float(np.std(ratios, ddof=1) * math.sqrt(1.0 + 1.0 / ratios.size)) if ratios.size > 1 else 0.0

    parameter_g = loo_parameter_spread(loo, shapes, loo_physics, physics_sd, seconds_sd, simulate_at)
    coverage = loo_coverage(runs, level=level, parameter_g=parameter_g)
    return {"level": level, "residuals": residuals.to_dict(), "seconds_per_mm_rel_sd": seconds_sd,
            "g_per_mm3_rel_sd": mass_sd, "physics_sd": {p: float(v) for p, v in physics_sd.items()},
            "loo_coverage": {"fraction": coverage.fraction, "points_inside": coverage.points_inside,
                             "points": coverage.points, "per_run": list(coverage.per_run),
                             "note": "each held-out run's band is built from the other runs' residuals"}}
