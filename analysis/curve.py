"""Release curves: Savitzky-Golay smoothing on real time stamps and steady-state detection.

The smoother is the Savitzky-Golay filter (a local least-squares polynomial, evaluated at each sample)
written on time in seconds rather than sample index, so a dropped frame or an irregular interval does not
distort it; on uniform samples it equals ``scipy.signal.savgol_filter(..., mode="interp")``.
"""
from __future__ import annotations

import math

import numpy as np

from analysis.errors import AnalysisError

DEFAULT_WINDOW_S = 330.0    # 30 frames at the paper's 11 s interval
DEFAULT_ORDER = 2
DEFAULT_STEADY_WINDOW_S = 1800.0
DEFAULT_STEADY_TOLERANCE = 0.01


def _check_series(t_s: np.ndarray, conc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(t_s, dtype=float)
    c = np.asarray(conc, dtype=float)
    if t.ndim != 1 or t.shape != c.shape:
        raise AnalysisError(f"t_s {t.shape} and conc {c.shape} must be 1-D arrays of equal length")
    if t.size > 1 and np.any(np.diff(t) <= 0):
        i = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise AnalysisError(f"times must increase strictly: t_s[{i + 1}]={t[i + 1]:g} s follows t_s[{i}]={t[i]:g} s")
    return t, c


def smooth_curve(t_s: np.ndarray, conc: np.ndarray, *, window_s: float = DEFAULT_WINDOW_S,
                 order: int = DEFAULT_ORDER, deriv: int = 0) -> np.ndarray:
    """Savitzky-Golay smoothing of a curve sampled at times ``t_s`` (or its time derivative).

    Parameters
    ----------
    t_s : (N,) ndarray of float, s
        Strictly increasing sample times.
    conc : (N,) ndarray of float
        Values (any unit, e.g. g/kg); NaN samples are ignored by the fits and get a smoothed value.
    window_s : float
        Width of the fitting window, s (default 330 s = 30 frames at 11 s). Near the ends the window
        is shifted to stay inside the data.
    order : int
        Polynomial order (default 2), below the number of samples in a window.
    deriv : int
        0 for the smoothed values, 1 for the slope of the local fits (unit of ``conc`` per s), up to ``order``.

    Returns
    -------
    (N,) ndarray of float
        The smoothed curve (or its derivative); with too few samples for one fit, a copy of ``conc``
        (derivative: ``numpy.gradient`` of it).

    Raises
    ------
    AnalysisError
        Mismatched shapes, non-increasing times, bad window or order.
    """
    t, c = _check_series(t_s, conc)
    if not window_s > 0:
        raise AnalysisError(f"window_s={window_s!r} s must be positive")
    if not 0 <= order <= 6:
        raise AnalysisError(f"order={order!r} is outside 0..6")
    if not 0 <= deriv <= order:
        raise AnalysisError(f"deriv={deriv!r} is outside 0..order={order}")
    finite = np.isfinite(c)
    if finite.sum() <= order:
        return c.copy() if deriv == 0 or c.size < 2 else np.gradient(c, t)
    tf, cf = t[finite], c[finite]
    out = np.empty_like(c)
    half = 0.5 * window_s
    for i, ti in enumerate(t):
        lo = min(max(ti - half, tf[0]), max(tf[-1] - window_s, tf[0]))
        sel = (tf >= lo - 1e-9) & (tf <= lo + window_s + 1e-9)
        if sel.sum() <= order:
            nearest = np.argsort(np.abs(tf - ti))[: order + 1]
            sel = np.zeros_like(sel)
            sel[nearest] = True
        scale = max(half, 1e-9)
        x = (tf[sel] - ti) / scale
        vander = np.vander(x, order + 1, increasing=True)
        coef, *_ = np.linalg.lstsq(vander, cf[sel], rcond=None)
        out[i] = coef[deriv] * math.factorial(deriv) / scale ** deriv
    return out


def steady_state(t_s: np.ndarray, conc: np.ndarray, *, window_s: float = DEFAULT_STEADY_WINDOW_S,
                 tolerance: float = DEFAULT_STEADY_TOLERANCE, min_level: float = 0.0) -> bool:
    """Whether a (smoothed) release curve has levelled off, i.e. the run is over.

    True when the curve spans at least ``window_s`` and a straight line fitted to its last
    ``window_s`` seconds rises by less than ``tolerance`` times the current level over that window,
    and the level exceeds ``min_level``.

    Parameters
    ----------
    t_s : (N,) ndarray of float, s
    conc : (N,) ndarray of float, g/kg
    window_s : float
        Look-back window, s (default 1800 s).
    tolerance : float
        Allowed relative rise over the window (default 0.01 = 1 %).
    min_level : float
        Level below which the curve is never called steady (g/kg; default 0, i.e. any release).

    Returns
    -------
    bool
    """
    t, c = _check_series(t_s, conc)
    if not window_s > 0 or not tolerance > 0:
        raise AnalysisError(f"window_s={window_s!r} s and tolerance={tolerance!r} must be positive")
    ok = np.isfinite(c)
    t, c = t[ok], c[ok]
    if t.size < 3 or t[-1] - t[0] < window_s:
        return False
    sel = t >= t[-1] - window_s
    if sel.sum() < 3:
        return False
    slope, intercept = np.polyfit(t[sel], c[sel], 1)
    level = slope * t[-1] + intercept
    if level <= min_level or level <= 0:
        return False
    return bool(slope * window_s < tolerance * level)
