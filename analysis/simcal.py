"""Simulation-to-bench calibration (paper section 4.3, Appendix B): grams per mm^3 and seconds per mm.

The forward model works in simulation units (tau = depth dissolved, mm; released solid, mm^3); the bench
measures seconds and grams. Two maps bridge them:

- mass: released grams per mm^3 of simulated solid, ``g_per_mm3 = weighed mass / simulated final volume``
  per shape, pooled over shapes as total weighed mass / total simulated volume;
- time: one ``seconds_per_mm`` shared by all shapes (tau = t / seconds_per_mm).

The second model (``saturation``, Appendix B) lets the bath slow the front as it fills:
d tau / dt = k (1 - c(t) / c_sat), with c(t) the bath concentration (g/kg) of the run's own water mass, so
runs with different water masses share one c_sat. Its clock is t(tau) = (1/k) int_0^tau dtau' / g(tau'),
g = 1 - m(tau') / (c_sat W) (trapezoid on the simulated tau grid).

This module holds the map (:class:`SimCal`) and the records around it: a calibration shape (:class:`ShapeRun`),
a fit (:class:`SimCalFit`) and a shape predicted without it (:class:`LooShape`). The scales are fitted by
:mod:`analysis.simcal_fit`, the print physics by :mod:`analysis.physics_fit`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from analysis.errors import AnalysisError

MODELS = ("constant", "saturation")
"""Calibration models: constant rate (Appendix A, eq. 11 with a constant bath) and the concentration-dependent
rate of Appendix B."""
DENSITY_RANGE_G_PER_CM3 = (0.8, 2.0)
"""Weighed mass / simulated volume outside this range means a wrong mesh, unit or mass."""
MIN_RELEASE_FRACTION = 0.05
"""A run whose measured release never reaches this fraction of its weighed mass shows no release."""


def check_weighed_run(name: str, mass_g: float, volume_mm3: float, released_g: np.ndarray, *,
                      volume_of: str = "the simulated") -> None:
    """Refuse a run whose weighed mass over ``volume_mm3`` (mm^3, ``volume_of`` names whose) is no plausible
    density, or whose measured release (g) never reaches `MIN_RELEASE_FRACTION` of that mass."""
    density = mass_g / volume_mm3 * 1000.0
    lo, hi = DENSITY_RANGE_G_PER_CM3
    if not lo <= density <= hi:
        raise AnalysisError(f"{name}: weighed {mass_g:g} g over {volume_of} {volume_mm3:.1f} mm^3 means "
                            f"{density:.3g} g/cm^3, outside {lo:g}-{hi:g} g/cm^3 (wrong mesh, mesh unit or mass?)")
    if np.max(released_g) < MIN_RELEASE_FRACTION * mass_g:
        raise AnalysisError(f"{name}: the run shows no release (at most {np.max(released_g):.3g} g of the weighed "
                            f"{mass_g:g} g); was the object dropped, and is it the right run?")


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
        check_weighed_run(self.name, self.mass_g, float(vol[-1]), rel)

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

    @classmethod
    def of(cls, cal: SimCal, shape: ShapeRun) -> LooShape:
        """``shape`` predicted from its weighed mass by ``cal`` (no offset: a drop-time error counts as
        prediction error)."""
        predicted = cal.to_physical(shape.tau_mm, shape.released_mm3, shape.t_s, shape.water_g, mass_g=shape.mass_g)
        measured = np.asarray(shape.released_g, float)
        rel = float(np.sqrt(np.mean((predicted - measured) ** 2)) / shape.mass_g)
        return cls(shape.name, cal, np.asarray(shape.t_s, float), measured, predicted, rel)
