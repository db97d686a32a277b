"""analysis.barrier_fit: s from coated prints' delays, with its two error terms (analytic box releases, no bench)."""
import numpy as np
import pytest

from analysis.barrier_fit import CoatedRun, fit_barrier_runs
from analysis.errors import AnalysisError

SIDES, K, RHO, S, COAT = (4.0, 4.0, 2.0), 1500.0, 1.3e-3, 0.4, 0.5


def _box(tau: np.ndarray) -> np.ndarray:
    """A box's release: its volume less the box shrunk by tau on every face, mm^3."""
    return float(np.prod(SIDES)) - np.prod([np.clip(s - 2.0 * tau, 0.0, None) for s in SIDES], axis=0)


def _run(rate_factor: float, coat: float = COAT) -> CoatedRun:
    tau = np.linspace(0.0, 1.2, 481)
    k = K * rate_factor
    t = np.arange(0.0, k * (coat / S + 1.1), 20.0)
    return CoatedRun(t, RHO * _box(np.clip(t / k - coat / S, 0.0, None)), coat, tau, _box(tau))


def test_each_runs_own_rate_gives_s_and_the_calibrations_rate_gives_the_rate_term():
    fit = fit_barrier_runs([_run(f) for f in (0.98, 1.0, 1.03)], K, RHO)
    # exact curves: every run's own rate and delay are found (to the tau grid's interpolation, 1e-4)
    assert fit.per_run == pytest.approx([S] * 3, rel=1e-4) and fit.speed == pytest.approx(S, rel=1e-4)
    assert fit.standard_error < 1e-4 * S
    # read through the calibration's rate, each delay k_r D / k is off by the print's own rate
    assert fit.speed_at_calibrated_rate == pytest.approx(np.mean([S / f for f in (0.98, 1.0, 1.03)]), rel=1e-4)
    assert fit.error == pytest.approx(np.hypot(fit.standard_error, 0.5 * abs(fit.speed - fit.speed_at_calibrated_rate)))


def test_one_run_takes_the_fits_own_error_and_bad_runs_are_refused():
    fit = fit_barrier_runs([_run(1.0)], K, RHO)
    assert fit.speed == pytest.approx(S, rel=1e-4) and np.isfinite(fit.standard_error)
    with pytest.raises(AnalysisError, match="no runs"):
        fit_barrier_runs([], K, RHO)
    with pytest.raises(AnalysisError, match="coat thickness must be > 0"):
        fit_barrier_runs([_run(1.0, coat=0.0)], K, RHO)
    with pytest.raises(AnalysisError, match="must release"):
        fit_barrier_runs([CoatedRun(np.arange(10.0), np.zeros(10), COAT, np.arange(3.0), np.arange(3.0))], K, RHO)
