"""Concentration-dependent dissolution rate as a remapping of simulation time (Appendix B).

With the bulk concentration rising as solid dissolves, Noyes-Whitney (eq. 11) slows the dissolution
front: d tau / dt = r (1 - C(tau) / C_cap), where r is the rate into clean solvent (mm/s), C(tau) the
released solid volume (the curve of eq. 7, mm^3) and C_cap = V C_s / rho_0 the solid volume that would
saturate the solvent (Appendix B, with m_hat = rho_0 C). The curve C(tau) itself is unchanged; only
the clock is: t(tau) = (1/r) int_0^tau d tau' / (1 - C(tau') / C_cap). With C linear between the tau
samples the integral over each step is exact, dtau (ln g_k - ln g_k+1) / (g_k - g_k+1) with
g = 1 - C / C_cap, so the remapping and its derivative are exact for the sampled curve.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from design._validate import check_positive
from design.errors import DesignError

_SERIES = 1e-3
"""|g_k - g_k+1| / (g_k + g_k+1) below which the log-mean uses its series (error < 1e-12)."""


@dataclass(frozen=True)
class Saturation:
    """Dissolution into a finite solvent volume (Appendix B).

    Attributes
    ----------
    rate_mm_per_s : float
        Front speed d tau / dt into clean solvent, mm/s.
    capacity_mm3 : float
        Solid volume whose dissolution saturates the solvent, V C_s / rho_0, mm^3.
    """

    rate_mm_per_s: float
    capacity_mm3: float

    def __post_init__(self) -> None:
        check_positive("rate_mm_per_s", self.rate_mm_per_s)
        check_positive("capacity_mm3", self.capacity_mm3)

    @classmethod
    def from_solvent(cls, rate_mm_per_s: float, solvent_ml: float, saturation_g_per_ml: float,
                     solid_density_g_per_cm3: float) -> "Saturation":
        """Build from the solvent volume (ml), saturation concentration (g/ml) and solid density (g/cm^3)."""
        grams = check_positive("solvent_ml", solvent_ml) * check_positive("saturation_g_per_ml", saturation_g_per_ml)
        return cls(rate_mm_per_s, grams / check_positive("solid_density_g_per_cm3", solid_density_g_per_cm3) * 1000.0)


def _inverse_log_mean(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """L(a, b) = (ln a - ln b) / (a - b) and its partial derivatives, stable for a ~ b."""
    m = 0.5 * (a + b)
    d = 0.5 * (a - b)
    small = np.abs(d) < _SERIES * m
    safe_d = np.where(small, 1.0, d)
    exact = (np.log(a) - np.log(b)) / (2.0 * safe_d)
    value = np.where(small, (1.0 + d * d / (3.0 * m * m)) / m, exact)
    # exact partials: dL/da = (1/a - L) / (a - b), dL/db = (L - 1/b) / (a - b)
    da_exact = (1.0 / a - exact) / (2.0 * safe_d)
    db_exact = (exact - 1.0 / b) / (2.0 * safe_d)
    # series in d around m: L = 1/m + d^2 / (3 m^3); dL/dm = -1/m^2 - d^2/m^4, dL/dd = 2 d / (3 m^3)
    dm = -1.0 / (m * m) - d * d / m ** 4
    dd = 2.0 * d / (3.0 * m ** 3)
    da = np.where(small, 0.5 * (dm + dd), da_exact)
    db = np.where(small, 0.5 * (dm - dd), db_exact)
    return value, da, db


def _free_fraction(released_mm3: np.ndarray, saturation: Saturation) -> np.ndarray:
    g = 1.0 - np.asarray(released_mm3, dtype=np.float64) / saturation.capacity_mm3
    if np.any(g <= 0.0):
        raise DesignError(f"the solvent saturates: released volume reaches {float(np.max(released_mm3)):.4g} mm^3, "
                          f"capacity_mm3 = {saturation.capacity_mm3:.4g}; dissolution would never finish")
    return g


def remap_time(tau_mm: np.ndarray, released_mm3: np.ndarray, saturation: Saturation) -> np.ndarray:
    """Physical time at each tau sample under a concentration-dependent rate (Appendix B).

    Parameters
    ----------
    tau_mm : (K,) ndarray of float, mm
        Uniform tau grid starting at 0 (as in `Release.tau_mm`).
    released_mm3 : (K,) ndarray of float, mm^3
        Cumulative released solid volume at each tau.
    saturation : Saturation

    Returns
    -------
    (K,) ndarray of float, s
        t(tau_k), with t(0) = 0.
    """
    g = _free_fraction(released_mm3, saturation)
    step, _, _ = _inverse_log_mean(g[:-1], g[1:])
    return np.concatenate([[0.0], np.cumsum(step * np.diff(tau_mm))]) / saturation.rate_mm_per_s


def remap_time_vjp(tau_mm: np.ndarray, released_mm3: np.ndarray, saturation: Saturation,
                   t_bar: np.ndarray) -> np.ndarray:
    """Pull dJ/dt (per s, at each tau sample) back to dJ/dC (per mm^3) through :func:`remap_time`."""
    g = _free_fraction(released_mm3, saturation)
    _, da, db = _inverse_log_mean(g[:-1], g[1:])
    # t_k = sum_{j<k} dtau_j L_j / r, so L_j collects the t_bar of every later sample
    step_bar = np.cumsum(np.asarray(t_bar, dtype=np.float64)[::-1])[::-1][1:] * np.diff(tau_mm) / saturation.rate_mm_per_s
    g_bar = np.zeros_like(g)
    g_bar[:-1] += step_bar * da
    g_bar[1:] += step_bar * db
    return -g_bar / saturation.capacity_mm3


def release_at_times(t_s: np.ndarray, tau_mm: np.ndarray, released_mm3: np.ndarray,
                     saturation: Saturation) -> np.ndarray:
    """The released volume at given physical times, linear between the remapped samples.

    Parameters
    ----------
    t_s : (Q,) ndarray of float, s
        Query times; beyond the last sample the curve stays at its last value.
    tau_mm, released_mm3 : (K,) ndarray of float
        The simulated curve.
    saturation : Saturation

    Returns
    -------
    (Q,) ndarray of float, mm^3
    """
    return np.interp(t_s, remap_time(tau_mm, released_mm3, saturation), released_mm3)


def release_at_times_vjp(t_s: np.ndarray, tau_mm: np.ndarray, released_mm3: np.ndarray,
                         saturation: Saturation, out_bar: np.ndarray) -> np.ndarray:
    """Pull dJ/dC(t_q) back to dJ/dC_k through the interpolation and the time remapping.

    Returns
    -------
    (K,) ndarray of float
        dJ/d released_mm3, to pass to `release_gradient`.
    """
    c = np.asarray(released_mm3, dtype=np.float64)
    t = remap_time(tau_mm, c, saturation)
    q = np.asarray(t_s, dtype=np.float64)
    w = np.asarray(out_bar, dtype=np.float64)
    k = np.clip(np.searchsorted(t, q, side="right") - 1, 0, len(t) - 2)
    inside = (q >= t[0]) & (q < t[-1])
    span = t[k + 1] - t[k]
    frac = np.clip((q - t[k]) / span, 0.0, 1.0)
    c_bar = np.zeros_like(c)
    t_bar = np.zeros_like(c)
    np.add.at(c_bar, k, np.where(inside, w * (1.0 - frac), 0.0))
    np.add.at(c_bar, k + 1, np.where(inside, w * frac, 0.0))
    c_bar[-1] += np.sum(w[q >= t[-1]])
    c_bar[0] += np.sum(w[q < t[0]])
    # C_q = C_k + (C_k+1 - C_k)(q - t_k)/(t_k+1 - t_k): the breakpoints move with the remapping
    slope = (c[k + 1] - c[k]) / span
    np.add.at(t_bar, k, np.where(inside, w * slope * (frac - 1.0), 0.0))
    np.add.at(t_bar, k + 1, np.where(inside, -w * slope * frac, 0.0))
    return c_bar + remap_time_vjp(tau_mm, c, saturation, t_bar)
