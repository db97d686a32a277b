"""The rate-fit term J_rate and the rate-deviation metric of the zero-order requirement."""
import numpy as np
import pytest

from design.errors import DesignError
from design.files.rundir import run_design
from design.inverse.config import DesignConfig
from design.inverse.objective import DesignObjective
from design.inverse.rate import (
    lag_rate,
    lag_rate_adjoint,
    rate_deviation,
    rate_deviation_vs_target,
    rate_fit,
    rate_shape_fit,
    release_duration,
)
from design.inverse.settings import ANALYTIC_DEFAULTS, ANALYTIC_W_RATE, SPACE_DEFAULTS, W_CONNECT
from design.inverse.spaces import SpaceRequest, build_space


def test_lag_rate_adjoint_is_the_exact_transpose():
    rng = np.random.default_rng(0)
    c, g = rng.normal(size=50), rng.normal(size=50 - 7)
    assert np.dot(lag_rate(c, 7, 0.3), g) == pytest.approx(np.dot(c, lag_rate_adjoint(g, 7, 0.3)), rel=1e-12)


def test_rate_fit_value_and_gradient():
    tau = np.linspace(0.0, 2.0, 21)
    target = 3.0 * tau
    # a constant rate error of 1 mm^3/mm over the whole grid: J = t_s^2 * 1 * (K - L) dtau / T
    value, grad = rate_fit(4.0 * tau, target, 0.1, 2, 0.5)
    assert value == pytest.approx(0.25 * 19 * 0.1 / 2.0)
    rng = np.random.default_rng(1)
    c = target + rng.normal(size=21)
    value, grad = rate_fit(c, target, 0.1, 3, 0.7)
    for k in (0, 5, 20):
        e = np.zeros(21)
        e[k] = 1e-6
        fd = (rate_fit(c + e, target, 0.1, 3, 0.7)[0] - rate_fit(c - e, target, 0.1, 3, 0.7)[0]) / 2e-6
        assert grad[k] == pytest.approx(fd, rel=1e-6, abs=1e-9)


def test_rate_fit_span_counts_only_the_rates_inside_it():
    tau = np.linspace(0.0, 2.0, 21)
    target = 3.0 * tau
    # the same constant rate error, now over rates k = 4..9 only: J = t_s^2 * 1 * 6 dtau / T
    value, grad = rate_fit(4.0 * tau, target, 0.1, 2, 0.5, span=(4, 10))
    assert value == pytest.approx(0.25 * 6 * 0.1 / 2.0)
    rng = np.random.default_rng(2)
    c = target + rng.normal(size=21)
    value, grad = rate_fit(c, target, 0.1, 3, 0.7, span=(5, 12))
    assert np.all(grad[:5] == 0.0) and np.all(grad[15:] == 0.0)  # C_k enters rates k and k - L only
    for k in (5, 9, 14):
        e = np.zeros(21)
        e[k] = 1e-6
        fd = (rate_fit(c + e, target, 0.1, 3, 0.7, (5, 12))[0] - rate_fit(c - e, target, 0.1, 3, 0.7, (5, 12))[0]) / 2e-6
        assert grad[k] == pytest.approx(fd, rel=1e-6, abs=1e-9)


def test_rate_shape_fit_ignores_the_level_and_has_an_exact_gradient():
    tau = np.linspace(0.0, 2.0, 41)
    target = np.minimum(tau, 1.5) ** 1.5
    # the same profile at 80% of the level costs nothing; J_fit and J_rate would see it
    value, _ = rate_shape_fit(0.8 * target, target, 0.05, 2, 0.5, (3, 30))
    assert value == pytest.approx(0.0, abs=1e-20)
    rng = np.random.default_rng(3)
    c = target + 0.1 * rng.normal(size=41)
    value, grad = rate_shape_fit(c, target, 0.05, 2, 0.5, (3, 30))
    assert value > 0 and np.all(grad[:3] == 0.0) and np.all(grad[32:] == 0.0)
    for k in (3, 10, 31):
        e = np.zeros(41)
        e[k] = 1e-6
        fd = (rate_shape_fit(c + e, target, 0.05, 2, 0.5, (3, 30))[0]
              - rate_shape_fit(c - e, target, 0.05, 2, 0.5, (3, 30))[0]) / 2e-6
        assert grad[k] == pytest.approx(fd, rel=1e-6, abs=1e-9)


def test_rate_deviation_hand_computed():
    tau = np.linspace(0.0, 1.0, 1001)
    assert rate_deviation(tau, np.minimum(tau, 0.5)) == pytest.approx(0.0, abs=1e-9)
    # rate 1 then 2 with the switch at tau = 0.5: C = 1.5 at the end, 10% at 0.15, 90% at 0.925;
    # mean rate over [0.15, 0.925] is 1.2/0.775, sub-interval rates are 1 and 2
    c = np.where(tau < 0.5, tau, 0.5 + 2.0 * (tau - 0.5))
    mean = 1.2 / 0.775
    assert rate_deviation(tau, c) == pytest.approx(max(2.0 / mean - 1.0, 1.0 - 1.0 / mean), rel=1e-6)
    # against a reference rate over another curve's window
    assert rate_deviation(tau, 1.1 * np.minimum(tau, 0.5), window_from=np.minimum(tau, 0.5),
                          reference_rate=1.0) == pytest.approx(0.1)
    assert release_duration(tau, np.minimum(tau, 0.5), 1.0) == pytest.approx(0.5)
    with pytest.raises(DesignError, match="rising release"):
        rate_deviation(tau, np.zeros_like(tau))


def test_rate_deviation_reads_a_tail_that_varies_in_the_last_bit_like_a_flat_one():
    """A simulated release's flat tail varies by round-off (-1e-13 mm^3 steps on ~800 mm^3); the 10%
    and 90% times must still be interpolated, not snapped to the next sample (which moved a design's
    figure by 0.3 points). The curve's 10% and 90% fall between samples: 0.15 and 0.85 of a rate
    switching at 0.5, on samples 0.007 apart."""
    tau = np.linspace(0.0, 0.7, 101)
    c = np.minimum(np.where(tau < 0.5, tau, 0.5 + 2.0 * (tau - 0.5)), 0.6)
    rough = c.copy()
    rough[-20:] -= 1e-13 * (np.arange(20) % 2)
    assert np.any(np.diff(rough) < 0)
    assert rate_deviation(tau, rough) == rate_deviation(tau, c)
    assert rate_deviation(tau, c, window_from=rough) == rate_deviation(tau, c)


def test_rate_deviation_sees_a_rate_error_the_cumulative_fit_hardly_sees():
    """A 20% rate bump lasting 5% of the release: 1% cumulative error at most, 20% rate deviation."""
    tau = np.linspace(0.0, 1.0, 1001)
    bump = 0.2 * np.clip((tau - 0.5) / 0.05, 0.0, 1.0) * 0.05 - 0.2 * np.clip((tau - 0.6) / 0.05, 0.0, 1.0) * 0.05
    c = tau + bump
    assert np.abs(c - tau).max() <= 0.011
    assert rate_deviation(tau, c) == pytest.approx(0.2, abs=0.02)


@pytest.mark.slow
def test_rate_term_lowers_the_rate_deviation_on_a_tiny_problem(tmp_path):
    """A 12^3 octant, 80 evaluations: with J_rate the density's rate is closer to constant (J_rate alone:
    no connectivity term)."""
    devs = {}
    for w_rate, span in ((0.0, (0.0, 1.0)), (1.0, (0.0, 1.0)), (1.0, (0.05, 0.95))):
        config = DesignConfig(target="zero-order:final=0.1,duration=0.2", resolution=24, radius_vox=1.5,
                              max_iter=80, w_rate=w_rate, rate_span=span, allow_pieces=True, robust_eta=0.0)
        summary = run_design(config, tmp_path / f"w{w_rate}_{span[0]}").outputs.summary
        devs[w_rate, span] = summary["rate_dev_mid80"]["density"]
    # measured 1.15 without the term, 0.72 with it over the whole curve, 0.61 over the target's 5%-95%
    assert devs[1.0, (0.0, 1.0)] < 0.75 * devs[0.0, (0.0, 1.0)], devs
    assert devs[1.0, (0.05, 0.95)] < 0.85 * devs[0.0, (0.0, 1.0)], devs


def test_rate_weight_defaults_by_target_kind():
    assert DesignConfig(target="zero-order:final=0.1,duration=0.2").w_rate == ANALYTIC_W_RATE
    assert DesignConfig(target="sphere").w_rate == 0.0
    assert DesignConfig(target="sphere", w_rate=2.0).w_rate == 2.0
    with pytest.raises(DesignError, match="w_rate must be >= 0"):
        DesignConfig(target="sphere", w_rate=-1.0)
    assert DesignConfig(target="sphere").robust_eta == 0.0  # the paper's single design by default


def test_analytic_targets_default_to_the_robust_formulation_steep_beta_and_their_space_s_connectivity():
    for space in ("nfc", "extruded"):
        config = DesignConfig(target="accel:q=0.5", space=space)
        analytic = ANALYTIC_DEFAULTS[space]
        assert (config.robust_eta, config.beta_final) == (analytic["robust_eta"], analytic["beta_final"])
        assert config.w_connect == analytic.get("w_connect", W_CONNECT)
        sphere = DesignConfig(target="sphere", space=space)
        assert (sphere.robust_eta, sphere.beta_final, sphere.w_connect) == (0.0, SPACE_DEFAULTS[space]["beta_final"],
                                                                            W_CONNECT)
        preset = DesignConfig(target="zero-order", space=space, preset="paper:design-4")
        assert preset.beta_final == preset.beta  # a preset keeps the paper's fixed beta
    assert DesignConfig(target="zero-order", space="extruded").w_connect > W_CONNECT
    ico = DesignConfig(target="zero-order", space="ico")  # not measured there
    assert (ico.robust_eta, ico.beta_final, ico.w_connect) == (0.0, None, W_CONNECT)  # None: a fixed beta
    assert DesignConfig(target="zero-order", w_rate=0.0).robust_eta == 0.0  # it compares rates
    assert DesignConfig(target="zero-order", robust_eta=0.0).robust_eta == 0.0
    assert DesignConfig(target="zero-order", robust_eta=0.05).robust_eta == 0.05
    assert DesignConfig(target="zero-order", space="extruded", w_connect=2.0).w_connect == 2.0


def test_rate_span_and_robust_settings_are_checked():
    assert DesignConfig(target="sphere").rate_span == (0.05, 0.95)
    with pytest.raises(DesignError, match="rate_span must be two fractions"):
        DesignConfig(target="sphere", rate_span=(0.9, 0.1))
    with pytest.raises(DesignError, match=r"robust_eta must be in \[0, 0.4\]"):
        DesignConfig(target="sphere", robust_eta=0.5)
    with pytest.raises(DesignError, match="needs w_rate > 0"):
        DesignConfig(target="sphere", robust_eta=0.05)


def test_rate_weight_guard():
    space = build_space("nfc", SpaceRequest((8, 8, 8), 1.0))
    with pytest.raises(DesignError, match="w_rate >= 0"):
        DesignObjective(space, np.linspace(0, 1, 11), 4.0, radius_vox=2.0, beta=3.0, w_binary=1.0, w_rate=-1.0)
    with pytest.raises(DesignError, match="rate lag"):
        DesignObjective(space, np.linspace(0, 1, 11), 4.0, radius_vox=2.0, beta=3.0, w_binary=1.0, rate_lag=11)


def test_rate_deviation_vs_target_counts_a_constant_but_late_release():
    """A constant rate 10% below the target's over the target's window reads 10%; its own mean reads 0."""
    tau = np.linspace(0.0, 1.0, 1001)
    target = np.minimum(tau, 0.5)
    slow = np.minimum(0.9 * tau, 0.5)
    assert rate_deviation_vs_target(tau, slow, target) == pytest.approx(0.1, abs=1e-9)
    assert rate_deviation(tau, slow) == pytest.approx(0.0, abs=1e-9)
