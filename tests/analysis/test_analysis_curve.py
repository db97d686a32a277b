"""Savitzky-Golay smoothing on time stamps and steady-state detection."""
import numpy as np
import pytest
from scipy.signal import savgol_filter

from analysis import AnalysisError, smooth_curve, steady_state


def test_uniform_samples_match_scipy_savgol():
    rng = np.random.default_rng(0)
    t = np.arange(200) * 11.0
    c = 3.5 * (1 - np.exp(-t / 600)) + 0.02 * rng.standard_normal(t.size)
    ours = smooth_curve(t, c, window_s=30 * 11.0, order=2)
    # A 330 s window holds 31 samples at 11 s spacing.
    assert np.allclose(ours, savgol_filter(c, 31, 2, mode="interp"), atol=1e-10)


def test_a_gap_does_not_distort_a_polynomial():
    t = np.r_[np.arange(0, 500, 10.0), np.arange(800, 1500, 10.0)]
    c = 1e-6 * t ** 2 - 1e-3 * t + 2
    assert np.allclose(smooth_curve(t, c, window_s=200, order=2), c, atol=1e-9)


def test_nan_samples_are_filled_and_short_series_returned():
    t = np.arange(20.0)
    c = 2.0 * t
    c[7] = np.nan
    assert np.allclose(smooth_curve(t, c, window_s=6, order=1), 2.0 * t)
    assert np.array_equal(smooth_curve(t[:2], c[:2], order=2), c[:2])


def test_steady_state():
    t = np.arange(0, 7200, 11.0)
    rising = 3.5 * (1 - np.exp(-t / 1500))
    assert steady_state(t, 3.5 * (1 - np.exp(-t / 300)))
    assert not steady_state(t, rising)
    assert not steady_state(t[:100], 3.5 * np.ones(100))      # shorter than the 1800 s window
    assert not steady_state(t, np.zeros(t.size))              # nothing released yet
    assert steady_state(t, rising, tolerance=0.5)


def test_guards():
    with pytest.raises(AnalysisError, match="increase strictly"):
        smooth_curve(np.array([0.0, 2.0, 1.0]), np.zeros(3))
    with pytest.raises(AnalysisError, match="equal length"):
        steady_state(np.arange(3.0), np.zeros(4))
    with pytest.raises(AnalysisError, match="order"):
        smooth_curve(np.arange(3.0), np.zeros(3), order=9)


def test_smooth_curve_slope_matches_the_analytic_derivative_on_irregular_times():
    t = np.sort(np.random.default_rng(0).uniform(0.0, 3000.0, 300))
    slope = smooth_curve(t, 1.0 - np.exp(-t / 1000.0), deriv=1)
    # a quadratic over a 330 s window: the error is of order the third derivative, (165 s)^2 / 1000^3 x e^0
    np.testing.assert_allclose(slope * 1000.0, np.exp(-t / 1000.0), atol=0.02)
    with pytest.raises(AnalysisError, match="deriv=3"):
        smooth_curve(t, t, deriv=3)
