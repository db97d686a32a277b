"""The barrier's relative speed s from runs of coated prints: each run's delay behind the drug's own curve.

A drug body inside a barrier coat of uniform thickness c (every point of the drug's surface c from the coat's
outer surface, as a box grown by c on every face or a convex body offset by c) releases exactly the uncoated
drug's curve delayed by c / s in tau (mm of drug): every straight path from the bath crosses at least c of barrier
at speed s, and c / s + (the drug's own distance) is reached along the coat's normal (paper eq. 5 with the
barrier's slowness 1 / s; docs/materials.md). On the bench, with the drug calibrated (seconds per mm k, density rho,
wetting lag), a coated print's measured mass is

    m(t) = rho_r C((t - lag) / k_r - c / s),

C the drug's simulated release (mm^3 against tau). Each run's print deviates a little from the material, so each run
is fitted for its own (k_r, rho_r, D_r) by least squares, and s_r = c / D_r. The barrier speed is the mean of the
runs' s_r. Its uncertainty has two terms in quadrature: the standard error of that mean (the runs' spread over
sqrt(n), which holds the prints' scatter and the fit's noise alike; one run: the fit's own, from its Jacobian), and
the rate term. The delay is measured in seconds, k_r D_r, and read in mm of drug through a rate: a run's own k_r
comes from the shape of its release after the coat, which small shape errors of a measurement shared by all runs
(the camera's concentration scale) move by a few percent; the calibration's k misses the print's own deviation. The
rate term is half the difference between s from the runs' own rates and s' = c k / (k_r D_r) from the calibration's,
and both are reported.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from analysis.errors import AnalysisError

ONSET_FRACTION = 0.02
"""A run's release starts, for the delay's first guess, where it passes this fraction of its final mass."""


@dataclass(frozen=True)
class BarrierFit:
    """The fitted barrier speed.

    Attributes
    ----------
    speed : float
        s, the barrier's erosion speed over the drug's.
    error : float
        Its standard uncertainty (standard error of the runs' mean; one run: the fit's own).
    per_run : tuple of float
        Each run's s_r.
    delays_mm : tuple of float
        Each run's delay D_r = c / s_r, mm of drug.
    rms_g : tuple of float
        Each run's RMS residual, g.
    standard_error : float
        The runs' standard error alone (one run: the fit's own).
    speed_at_calibrated_rate : float
        s' = mean of c k / (k_r D_r): the delays read through the calibration's rate k.
    """

    speed: float
    error: float
    per_run: tuple[float, ...]
    delays_mm: tuple[float, ...]
    rms_g: tuple[float, ...]
    standard_error: float = 0.0
    speed_at_calibrated_rate: float = 0.0


def _fit_run(t_s: np.ndarray, mass_g: np.ndarray, tau: np.ndarray, curve: np.ndarray, k0: float, rho0: float,
             lag_s: float) -> tuple[np.ndarray, float, float]:
    """(k, rho, D), the delay's standard error and the RMS residual of one run."""
    final = float(mass_g.max())
    onset = float(t_s[np.argmax(mass_g > ONSET_FRACTION * final)])
    d0 = max((onset - lag_s) / k0, 0.0)

    def residual(p):
        k, rho, d = p
        return rho * np.interp((t_s - lag_s) / k - d, tau, curve, left=0.0, right=curve[-1]) - mass_g

    fit = least_squares(residual, [k0, rho0, d0], x_scale=[k0, rho0, max(d0, 1e-3)],
                        bounds=([0.5 * k0, 0.5 * rho0, 0.0], [2.0 * k0, 2.0 * rho0, np.inf]))
    dof = max(t_s.size - 3, 1)
    sigma2 = float(np.sum(fit.fun ** 2)) / dof
    try:
        cov = np.linalg.inv(fit.jac.T @ fit.jac) * sigma2
        d_err = float(np.sqrt(max(cov[2, 2], 0.0)))
    except np.linalg.LinAlgError:
        d_err = float("inf")
    return fit.x, d_err, float(np.sqrt(np.mean(fit.fun ** 2)))


@dataclass(frozen=True)
class CoatedRun:
    """One run of a coated print, with its drug body's simulated release.

    Attributes
    ----------
    t_s, released_g : (K,) ndarray of float
        The measured drug mass against time since the drop, s and g.
    coat_mm : float
        The coat's thickness c, mm (as printed: every point of the drug's surface c from the bath).
    tau_mm, released_mm3 : (M,) ndarray of float
        The uncoated drug body's simulated release (the calibration's model), mm and mm^3.
    """

    t_s: np.ndarray
    released_g: np.ndarray
    coat_mm: float
    tau_mm: np.ndarray
    released_mm3: np.ndarray


def fit_barrier_runs(runs: list[CoatedRun], seconds_per_mm: float, g_per_mm3: float, lag_s: float = 0.0
                     ) -> BarrierFit:
    """Fit s from runs of coated prints, each with its own coat and drug body (module docstring).

    Parameters
    ----------
    runs : list of CoatedRun
    seconds_per_mm, g_per_mm3, lag_s : float
        The drug's calibration: each run's fit starts from these.

    Raises
    ------
    AnalysisError
        Without runs, for a coat <= 0, a run that releases nothing or one that shows no delay.
    """
    if not runs:
        raise AnalysisError("barrier fit: no runs of coated prints")
    speeds, delays, rms, errors, at_k = [], [], [], [], []
    for i, run in enumerate(runs):
        if not run.coat_mm > 0:
            raise AnalysisError(f"barrier fit: run {i}: coat thickness must be > 0 mm, got {run.coat_mm!r}")
        t_s, mass = np.asarray(run.t_s, float), np.asarray(run.released_g, float)
        if t_s.size < 5 or not np.any(mass > 0):
            raise AnalysisError(f"barrier fit: run {i} has {t_s.size} samples and {mass.max(initial=0):g} g released; "
                                "a coated print's run must release")
        (k_r, _, delay), d_err, r = _fit_run(t_s, mass, np.asarray(run.tau_mm, float),
                                             np.asarray(run.released_mm3, float), seconds_per_mm, g_per_mm3, lag_s)
        if delay <= 0:
            raise AnalysisError(f"barrier fit: run {i} shows no delay; its print releases at once (no coat?)")
        speeds.append(run.coat_mm / delay)
        at_k.append(run.coat_mm * seconds_per_mm / (k_r * delay))
        errors.append(run.coat_mm * d_err / delay ** 2)
        delays.append(delay)
        rms.append(r)
    s = np.asarray(speeds)
    standard = float(s.std(ddof=1) / np.sqrt(s.size)) if s.size > 1 else errors[0]
    rate_term = 0.5 * abs(float(s.mean()) - float(np.mean(at_k)))
    return BarrierFit(float(s.mean()), float(np.hypot(standard, rate_term)), tuple(speeds), tuple(delays), tuple(rms),
                      standard, float(np.mean(at_k)))
