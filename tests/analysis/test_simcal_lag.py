"""analysis.simcal: the wetting lag, one delay after the drop shared by every run, fitted with the time scale.

Synthetic runs of four analytic shapes (exact releases: a uniformly receding surface) on a hidden truth, each
print with its own 1.5% rate and 2% density draw, 0.2%-of-mass noise, a frame every 30 s, and each run's logged
drop off by its own jitter (standard deviation 20 s). Tolerances: the lag within 30 s of the truth (one frame)
and within 3 of its stated standard errors; the time scale within 2% of the prints' mean.
"""
import numpy as np
import pytest

from analysis import ShapeRun, SimCal, fit_simcal
from analysis.physics_fit import choose_physics, fit_physics
from analysis.physics_grid import LAG, PHYSICS_SETS
from tests.analysis.test_analysis_simcal import SHAPES, TRUTH


def _runs(lag_s: float, seed: int = 3, jitter_s: float = 20.0) -> list[ShapeRun]:
    """The runs; ``_runs.seconds_per_mm`` is their prints' mean time scale."""
    rng = np.random.default_rng(seed)
    runs, scales = [], []
    for name, (tau, vol) in SHAPES.items():
        cal = SimCal("constant", TRUTH.seconds_per_mm * (1 + 0.015 * rng.standard_normal()),
                     TRUTH.g_per_mm3 * (1 + 0.02 * rng.standard_normal()), lag_s=lag_s)
        mass = cal.g_per_mm3 * vol[-1]
        scales.append(cal.seconds_per_mm)
        end = cal.clock_s(tau, vol * cal.g_per_mm3, 500.0)[-1] + lag_s
        t = np.arange(30.0, 1.15 * end, 30.0)
        grams = cal.to_physical(tau, vol, t, 500.0) + 0.002 * mass * rng.standard_normal(t.size)
        runs.append(ShapeRun(name, tau, vol, t + jitter_s * rng.standard_normal(), grams, mass, 500.0))
    _runs.seconds_per_mm = float(np.mean(scales))
    return runs


def test_the_map_delays_a_prediction_by_the_lag_and_a_measured_curve_back():
    tau, vol = SHAPES["sphere"]
    cal, lagged = SimCal("constant", 1450.0, 1.27e-3), SimCal("constant", 1450.0, 1.27e-3, lag_s=300.0)
    t = np.linspace(0.0, 4e4, 201)
    assert np.array_equal(lagged.to_physical(tau, vol, t, 500.0), cal.to_physical(tau, vol, t - 300.0, 500.0))
    assert np.all(lagged.to_physical(tau, vol, t[t <= 300.0], 500.0) == 0.0)
    back_tau, _ = lagged.to_simulation(t[t >= 300.0], lagged.to_physical(tau, vol, t[t >= 300.0], 500.0), 500.0)
    assert back_tau == pytest.approx((t[t >= 300.0] - 300.0) / 1450.0)
    with pytest.raises(Exception, match="lag_s"):
        SimCal("constant", 1450.0, 1.27e-3, lag_s=-1.0)


@pytest.mark.parametrize("lag_s", [120.0, 450.0])
def test_a_known_lag_is_recovered_with_its_uncertainty(lag_s):
    runs = _runs(lag_s)
    fit = fit_physics(lambda values: runs, PHYSICS_SETS["lag"])
    assert fit.values[LAG] == pytest.approx(lag_s, abs=30.0)
    assert abs(fit.values[LAG] - lag_s) < 3.0 * fit.uncertainty[LAG]
    assert 1.0 <= fit.uncertainty[LAG] < 60.0
    # every leave-one-out refit carries its own lag, and predicts with it
    assert all(s.cal.lag_s == pytest.approx(v[LAG]) for s, v in zip(fit.loo, fit.loo_values))
    assert fit_simcal(runs, lag=True).cal.seconds_per_mm == pytest.approx(_runs.seconds_per_mm, rel=0.02)
    none = fit_physics(lambda values: runs, PHYSICS_SETS["none"])
    assert fit.loo_rel_rmse_mean < 0.6 * none.loo_rel_rmse_mean
    assert choose_physics({"none": none, "lag": fit}) == "lag"


def test_auto_does_not_keep_a_lag_the_truth_has_not():
    runs = _runs(0.0)
    fit = fit_physics(lambda values: runs, PHYSICS_SETS["lag"])
    none = fit_physics(lambda values: runs, PHYSICS_SETS["none"])
    assert fit.values[LAG] < 30.0
    assert choose_physics({"none": none, "lag": fit}) == "none"
