"""Release-rate measures: the rate-fit term of the objective and the rate-deviation metric.

J_fit of eq. (4) weighs the cumulative error, to which a rate error that lasts a short time
contributes little; a zero-order (constant-rate) target is judged on its rate. `rate_fit` is an
optional term that compares finite-difference rates of the simulated and target curves,

    J_rate = (1/T) sum_k (t_s (r_k - r*_k))^2 dtau,   r_k = (C_{k+L} - C_k) / (L dtau),

with a lag of L samples and a time scale t_s (the target's release duration), so that a relative
rate error e held over the release weighs like a relative cumulative error e in J_fit. It is linear
in C, so its adjoint is the transposed difference operator applied to the weighted residual. The sum
may be restricted to a span of k (`DesignObjective` uses the target's 5%-95% by default): where a
target's rate jumps, at its start and end, no solid can follow within a voxel's ramp, and matching
the jump there would pull the design's rate off within the release
(docs/design.md#analytic-targets-rate-term-robust-formulation-beta-64).

`rate_deviation` is the metric a zero-order requirement is judged by: the largest relative deviation
from the mean rate over the middle 80% of the release
(docs/design.md#from-density-to-print-designfabricationextractpy-designfilesoutputspy).
"""
from __future__ import annotations

import numpy as np

from design.errors import DesignError

MID_LO, MID_HI = 0.1, 0.9
"""The middle 80% of a release: from 10% to 90% of its final mass."""
MID_INTERVALS = 20
"""Sub-intervals the middle 80% is split into for the rate (each 4% of the 10%-90% time span)."""
RATE_SPAN_MIN_VOX = 10.0
"""Voxels of tau the middle 80% of a release should span for `rate_deviation` to be measured to
about a percentage point; below it `sfr design` warns. The grid's error against the span, on a plate
with an exact release: studies/rate_metric_grid.py (docs/benchmarks.md#studies)."""


def release_duration(tau_mm: np.ndarray, curve_mm3: np.ndarray, fraction: float = 0.999) -> float:
    """First tau at which the curve reaches ``fraction`` of its final value, mm (linear interpolation)."""
    c = np.asarray(curve_mm3, float)
    level = fraction * c[-1]
    k = int(np.argmax(c >= level))
    if k == 0:
        return float(tau_mm[0])
    t0, t1, c0, c1 = tau_mm[k - 1], tau_mm[k], c[k - 1], c[k]
    return float(t0 + (t1 - t0) * (level - c0) / (c1 - c0))


def lag_rate(curve: np.ndarray, lag: int, dtau_mm: float) -> np.ndarray:
    """``r_k = (C_{k+L} - C_k) / (L dtau)``, k = 0..K-1-L; (K-L,) array."""
    return (curve[lag:] - curve[:-lag]) / (lag * dtau_mm)


def lag_rate_adjoint(g_rate: np.ndarray, lag: int, dtau_mm: float) -> np.ndarray:
    """Transpose of `lag_rate`: the (K,) cotangent of C from the (K-L,) cotangent of r."""
    g = np.zeros(g_rate.size + lag)
    g[lag:] += g_rate
    g[:-lag] -= g_rate
    return g / (lag * dtau_mm)


def rate_fit(curve_mm3: np.ndarray, target_mm3: np.ndarray, dtau_mm: float, lag: int,
             time_scale_mm: float, span: tuple[int, int] | None = None) -> tuple[float, np.ndarray]:
    """J_rate (module docstring) of a curve against a target on the same tau grid, and dJ_rate/dC.

    Parameters
    ----------
    curve_mm3, target_mm3 : (K,) ndarray of float, mm^3
        Simulated and target cumulative release on ``tau_k = k dtau``.
    dtau_mm : float
    lag : int
        Finite-difference lag L in samples, 1 <= L < K.
    time_scale_mm : float
        t_s, mm.
    span : (int, int), optional
        Only rates r_k with ``span[0] <= k < span[1]`` count; default all.

    Returns
    -------
    value : float, mm^6
    grad : (K,) ndarray of float
    """
    k_count = curve_mm3.size
    total = dtau_mm * (k_count - 1)
    err = time_scale_mm * (lag_rate(curve_mm3, lag, dtau_mm) - lag_rate(target_mm3, lag, dtau_mm))
    if span is not None:
        err[:span[0]] = 0.0
        err[span[1]:] = 0.0
    value = float(np.sum(err ** 2) * dtau_mm / total)
    grad = lag_rate_adjoint(2.0 * err * time_scale_mm * dtau_mm / total, lag, dtau_mm)
    return value, grad


def rate_shape_fit(curve_mm3: np.ndarray, target_mm3: np.ndarray, dtau_mm: float, lag: int,
                   time_scale_mm: float, span: tuple[int, int]) -> tuple[float, np.ndarray]:
    """J_shape: like `rate_fit`, but against the target's rates scaled to the curve's own mean level.

    ``J_shape = (1/T) sum_{k in span} (t_s (r_k - (rbar / rbar*) r*_k))^2 dtau`` with rbar, rbar* the
    means of r, r* over the span: the rate profile must match the target's, whatever total it
    releases. The robust formulation (`design.inverse.objective`) asks this of its eroded and dilated designs,
    which hold less and more material than the target. Returns the value and dJ_shape/dC.
    """
    k_count = curve_mm3.size
    total = dtau_mm * (k_count - 1)
    a, b = span
    r = lag_rate(curve_mm3, lag, dtau_mm)[a:b]
    r_star = lag_rate(target_mm3, lag, dtau_mm)[a:b]
    n, mean_star = r.size, r_star.mean()
    if not mean_star > 0:
        raise DesignError("the target releases nothing over the rate span; J_shape is undefined")
    err = time_scale_mm * (r - r.mean() / mean_star * r_star)
    value = float(np.sum(err ** 2) * dtau_mm / total)
    # d err_k / d r_j = t_s (delta_kj - r*_k / (n rbar*))
    g_r = 2.0 * time_scale_mm * dtau_mm / total * (err - np.dot(err, r_star) / (n * mean_star))
    g_full = np.zeros(k_count - lag)
    g_full[a:b] = g_r
    return value, lag_rate_adjoint(g_full, lag, dtau_mm)


def middle_span_mm(tau_mm: np.ndarray, curve_mm3: np.ndarray) -> tuple[float, float]:
    """The tau at which a release first reaches 10% and 90% of its final value, mm.

    Linear interpolation on the curve's running maximum, so a curve that dips (a measured one, or a
    simulated one whose flat tail varies in the last bit) is read the same way as a rising one.
    """
    c = np.maximum.accumulate(np.asarray(curve_mm3, float))
    return tuple(float(np.interp(f * c[-1], c, tau_mm)) for f in (MID_LO, MID_HI))


def rate_deviation(tau_mm: np.ndarray, curve_mm3: np.ndarray, *, window_from: np.ndarray | None = None,
                   reference_rate: float | None = None) -> float:
    """Largest relative deviation of a release rate from constant over the middle 80% of the release.

    The middle 80% is ``[tau_10, tau_90]``, where the curve (or ``window_from``) first reaches 10%
    and 90% of its final value (linear interpolation between samples). That span is split into
    `MID_INTERVALS` equal sub-intervals; the rate on each is the finite difference
    ``(C(b) - C(a)) / (b - a)`` of the linearly interpolated curve, so the window is 4% of the
    span. Returns ``max_j |rate_j / reference - 1|`` with the reference the mean rate over the span
    (``(C(tau_90) - C(tau_10)) / (tau_90 - tau_10)``) unless ``reference_rate`` is given.

    Parameters
    ----------
    tau_mm, curve_mm3 : (K,) ndarray of float
        A cumulative release curve, tau increasing.
    window_from : (K,) ndarray of float, optional
        Take the 10%/90% times from this curve instead (e.g. the target's).
    reference_rate : float, optional
        Compare against this rate (mm^3 per mm) instead of the curve's own mean.

    Raises
    ------
    DesignError
        If the curve never rises, or its middle 80% lies within one tau sample (no rate to measure).
    """
    tau = np.asarray(tau_mm, float)
    c = np.asarray(curve_mm3, float)
    w = c if window_from is None else np.asarray(window_from, float)
    if tau.shape != c.shape or tau.shape != w.shape or tau.ndim != 1 or tau.size < 3 or not w[-1] > w[0]:
        raise DesignError(f"need matching 1D tau and rising release curves with >= 3 samples, got {tau.shape}, "
                          f"{c.shape}")
    lo, hi = middle_span_mm(tau, w)
    if not np.any((tau > lo) & (tau < hi)):
        raise DesignError(f"the middle 80% of the release ({lo:.6g} .. {hi:.6g} mm) lies within one tau sample: "
                          "no rate to measure")
    edges = np.linspace(lo, hi, MID_INTERVALS + 1)
    values = np.interp(edges, tau, c)
    rates = np.diff(values) / np.diff(edges)
    ref = (values[-1] - values[0]) / (hi - lo) if reference_rate is None else float(reference_rate)
    return float(np.max(np.abs(rates / ref - 1.0)))


def rate_deviation_vs_target(tau_mm: np.ndarray, curve_mm3: np.ndarray, target_mm3: np.ndarray) -> float:
    """`rate_deviation` of a curve over the target's middle 80%, against the target's mean rate there
    (a release that is constant but early or late also counts against it)."""
    lo, hi = middle_span_mm(tau_mm, target_mm3)
    reference = (MID_HI - MID_LO) * float(np.max(target_mm3)) / (hi - lo)
    return rate_deviation(tau_mm, curve_mm3, window_from=target_mm3, reference_rate=reference)
