"""analysis.profile: f1/f2 against published worked examples, the time-point rules at their edges,
bootstrap f2, MDT and DE against closed forms, and the input guards."""
import math

import numpy as np
import pytest

from analysis import AnalysisError
from analysis.profile import ReleaseProfile, dissolution_efficiency, f1_f2, mean_dissolution_time, similarity

# Tsong, Hammerstrom, Sathe and Shah, "Statistical assessment of mean differences between two dissolution
# data sets", Drug Inf. J. 30:1105-1112 (1996), table 1: % released of 6 reference and 6 test tablets.
# The same data set is `dip1` of the R package disprofas (P. Dahinden), whose f1/f2 examples give the
# values asserted below.
DIP1_MIN = np.array([5, 10, 15, 20, 30, 60, 90, 120], dtype=float)
DIP1_REF = np.array([
    [42.06, 59.91, 65.58, 71.81, 77.77, 85.67, 93.14, 94.23],
    [44.16, 60.18, 67.17, 70.82, 76.11, 83.27, 88.01, 89.59],
    [45.63, 55.77, 65.56, 70.50, 76.92, 83.91, 86.83, 90.12],
    [48.52, 60.39, 66.51, 73.06, 78.45, 84.99, 88.00, 93.43],
    [50.49, 61.82, 69.06, 72.85, 78.99, 86.86, 89.70, 90.79],
    [49.77, 62.73, 69.77, 72.88, 80.18, 84.20, 88.88, 90.47]])
DIP1_TEST = np.array([
    [19.99, 36.70, 47.77, 55.08, 65.69, 81.37, 92.39, 97.10],
    [22.08, 39.29, 49.46, 56.79, 67.22, 82.42, 89.93, 95.62],
    [21.93, 38.54, 47.76, 55.14, 65.25, 83.49, 90.19, 95.62],
    [22.44, 39.46, 49.72, 58.67, 69.21, 84.93, 94.12, 95.51],
    [25.67, 42.35, 52.68, 59.71, 71.51, 86.61, 93.80, 96.70],
    [26.37, 41.34, 51.01, 57.75, 69.44, 85.90, 94.45, 98.07]])


def _pct(t, values, label="curve", unit="min"):
    """A profile already in percent of the reference's 100 %."""
    return ReleaseProfile(np.asarray(t, float), np.asarray(values, float), unit, "%", 100.0, label)


def _f2_written_differently(r, t):
    # 50 log10(100 / sqrt(1 + m)) = 100 - 25 log10(1 + m), m the mean squared difference
    return 100.0 - 25.0 * math.log10(1.0 + float(np.mean((np.asarray(r) - np.asarray(t)) ** 2)))


def test_dip1_means_match_disprofas_under_the_ema_rule_and_on_fixed_points():
    ref = _pct(DIP1_MIN, DIP1_REF.mean(axis=0), "reference")
    test = _pct(DIP1_MIN, DIP1_TEST.mean(axis=0), "test")
    ema = similarity(ref, test)  # first point above 85 % is 90 min in both: 5..90 min, 7 points
    assert ema.points_used == 7 and ema.times[-1] == 90
    assert ema.f2 == pytest.approx(40.83405, abs=1e-5)
    assert ema.f1 == pytest.approx(18.19745, abs=1e-5)
    assert ema.similar is False
    every = similarity(ref, test, cutoff_pct=100.0)
    assert every.points_used == 8
    assert (every.f2, every.f1) == pytest.approx((42.11197, 16.22299), abs=1e-5)
    six = similarity(ref, test, times=DIP1_MIN[:6])
    assert (six.f2, six.f1) == pytest.approx((39.24385, 21.333), abs=1e-3)
    assert "share their time points" in ema.notes[0]


@pytest.mark.parametrize("test_means, expected", [
    # Shah, Tsong, Sathe and Liu, "In vitro dissolution profile comparison - statistics and analysis of the
    # similarity factor f2", Pharm. Res. 15:889-896 (1998), table 4 (dip2 of disprofas): batch b0 against
    # batches b1..b5 on the 4 points 30..180 min; the f2 values are those of disprofas' tests (test-f2.R).
    ([40.3392, 67.1458, 87.0083, 97.725], 60.03),
    ([49.3333, 65.3333, 86.75, 102.8333], 51.08),
    ([25.7917, 50.6333, 66.9917, 88.6], 51.19),
    ([15.0833, 59.5, 79.2667, 95.075], 50.07),
    ([43.3917, 77.9583, 86.325, 98.575], 48.05),
])
def test_dip2_batches_match_the_published_f2(test_means, expected):
    t = [0, 30, 60, 90, 180]
    ref = _pct(t, [0, 34.9167, 59.5, 79.2667, 95.075], "b0")
    result = similarity(ref, _pct(t, [0] + test_means, "batch"), cutoff_pct=100.0)
    assert result.points_used == 4 and result.times[0] == 30  # time zero excluded
    assert result.f2 == pytest.approx(expected, abs=0.01)
    assert any("time zero" in n for n in result.notes)


def test_f2_agrees_with_its_formula_written_differently():
    rng = np.random.default_rng(3)
    r = np.sort(rng.uniform(5, 80, 6))
    t = r + rng.normal(0, 7, 6)
    f1, f2 = f1_f2(r, t)
    assert f2 == pytest.approx(_f2_written_differently(r, t), rel=1e-12)
    assert f1 == pytest.approx(100 * np.abs(r - t).sum() / r.sum(), rel=1e-12)
    assert f1_f2(r, r)[1] == pytest.approx(100.0)
    # a uniform 10-point difference is the customary f2 = 50 boundary (just below it)
    assert f1_f2(r, r + 10)[1] == pytest.approx(100 - 25 * math.log10(101))


def test_a_point_after_85_in_one_curve_only_ends_the_points():
    t = [10, 20, 30, 40, 50, 60]
    ref = _pct(t, [20, 40, 60, 80, 90, 95], "reference")
    test = _pct(t, [30, 55, 75, 88, 95, 99], "test")
    ema = similarity(ref, test)  # test passes 85 % at 40 min: points 10..40
    np.testing.assert_array_equal(ema.times, [10, 20, 30, 40])
    assert ema.f2 == pytest.approx(_f2_written_differently([20, 40, 60, 80], [30, 55, 75, 88]), rel=1e-12)
    assert ema.f2 == pytest.approx(45.27679, abs=1e-5)  # by hand: 100 - 25 log10(1 + 614/4)
    assert any("2 point(s) after" in n for n in ema.notes)
    fda = similarity(ref, test, rule="both")  # both above 85 % only at 50 min
    np.testing.assert_array_equal(fda.times, [10, 20, 30, 40, 50])


def test_fewer_than_three_usable_points_gives_a_reason_not_a_number():
    t = [15, 30, 45, 60]
    result = similarity(_pct(t, [50, 90, 97, 99]), _pct(t, [40, 80, 92, 98]))
    assert result.f2 is None and result.f1 is None and result.similar is None
    assert result.points_used == 2
    assert "only 2 usable time point(s)" in result.reason
    rapid = similarity(_pct(t, [88, 97, 99, 100]), _pct(t, [91, 99, 100, 100]))
    assert rapid.f2 is None and "first time point" in rapid.reason


def test_a_reference_that_never_reaches_85_uses_every_point_and_says_so():
    t = [10, 20, 30, 40, 50]
    ref = _pct(t, [10, 25, 40, 55, 70])
    test = _pct(t, [12, 22, 45, 58, 66])
    result = similarity(ref, test)
    assert result.points_used == 5
    assert result.f2 == pytest.approx(_f2_written_differently([10, 25, 40, 55, 70], [12, 22, 45, 58, 66]))
    assert any("never reaches 85 %" in n for n in result.notes)


def test_percent_is_relative_to_the_reference_weighed_mass():
    t = np.array([0.0, 60, 120, 180])
    ref = ReleaseProfile(t, [0, 0.5, 1.0, 1.5], total=2.0, label="ref")  # weighed 2 g, 75 % released by 180 s
    test = ReleaseProfile(t, [0, 0.6, 1.1, 1.5], total=1.5, label="test")  # its own total does not matter
    result = similarity(ref, test)
    np.testing.assert_allclose(result.reference_pct, [25, 50, 75])
    np.testing.assert_allclose(result.test_pct, [30, 55, 75])


def test_a_dense_curve_is_interpolated_onto_a_sparse_ones_points():
    t_dense = np.linspace(0, 100, 1001)
    ref = _pct([0, 20, 40, 60, 80], [0, 30, 50, 70, 80], "sampled")
    test = _pct(t_dense, 0.9 * t_dense, "dense")
    result = similarity(ref, test)
    np.testing.assert_allclose(result.test_pct, [18, 36, 54, 72])
    assert "dense interpolated linearly onto the 5 time points of sampled" in result.notes[0]


def test_two_dense_curves_use_a_regular_grid_of_round_steps():
    t = np.arange(0, 4 * 3600 + 1, 11.0)
    ref = ReleaseProfile(t, 1.7 * (1 - np.exp(-t / 2400)), label="measured")
    test = ReleaseProfile(t + 3.0, 1.7 * (1 - np.exp(-(t + 3.0) / 2600)), label="simulated")
    result = similarity(ref, test)
    step = np.diff(result.times)
    assert np.allclose(step, step[0]) and step[0] % 60 == 0  # whole minutes
    assert 5 <= result.points_used <= 12
    assert "regular grid" in result.notes[0]


def test_mdt_and_de_match_closed_forms():
    k, end = 1 / 1200.0, 3600.0
    t = np.linspace(0, end, 20001)
    first = ReleaseProfile(t, 1 - np.exp(-k * t), total=1.0)
    released = 1 - math.exp(-k * end)
    area = end - released / k
    assert mean_dissolution_time(first) == pytest.approx((end * released - area) / released, rel=1e-7)
    assert dissolution_efficiency(first) == pytest.approx(100 * area / end, rel=1e-7)
    zero = ReleaseProfile([0, 100.0], [0, 2.0])  # zero order: MDT = T/2, DE = 50 %
    assert mean_dissolution_time(zero) == pytest.approx(50.0)
    assert dissolution_efficiency(zero) == pytest.approx(50.0)
    assert dissolution_efficiency(zero, until=50.0) == pytest.approx(25.0)  # area 50, rectangle 2 * 50
    assert mean_dissolution_time(zero, until=50.0) == pytest.approx(25.0)
    late = ReleaseProfile([10.0, 20.0], [1.0, 2.0])  # joined to (0, 0): a straight line through the origin
    assert mean_dissolution_time(late) == pytest.approx(10.0)


@pytest.mark.parametrize("build, message", [
    (lambda: similarity(ReleaseProfile([0, 1.0], [0, 1]), ReleaseProfile([0, 1.0], [0, 1], "mm", "mm3")),
     "in s and g but curve in mm and mm3"),
    (lambda: similarity(ReleaseProfile([0, 1.0], [0, 1], label="A"), ReleaseProfile([2, 3.0], [0, 1], label="B")),
     "do not overlap in time"),
    (lambda: similarity(ReleaseProfile([0, 1.0], [0, 0], label="A"), ReleaseProfile([0, 1.0], [0, 1])),
     "A: the reference releases 0 g in total"),
    (lambda: ReleaseProfile([0, 1, 2.0], [0, np.nan, 1], label="B"), r"B: sample 1: released amount = nan"),
    (lambda: ReleaseProfile([0, 2, 1.0], [0, 1, 2]), "sample 2: time 1 s does not increase"),
    (lambda: ReleaseProfile([0, 1, 2, 3.0], [0, 1.0, 0.5, 1.1]), r"sample 2: released 0.5 g .* below an earlier"),
    (lambda: mean_dissolution_time(ReleaseProfile([0, 1.0], [0, 0])), "nothing released"),
    (lambda: similarity(ReleaseProfile([0, 1.0], [0, 1]), ReleaseProfile([0, 1.0], [0, 1]), rule="fda"),
     "rule='fda'"),
])
def test_bad_input_is_named(build, message):
    with pytest.raises(AnalysisError, match=message):
        build()


def test_measurement_noise_below_the_tolerance_is_accepted():
    t = np.arange(0, 100.0)
    m = np.minimum(t / 50, 1) + 0.005 * np.sin(t)  # wiggles of 0.5 % of the maximum
    assert ReleaseProfile(t, m).released.shape == (100,)


@pytest.mark.parametrize("t0", [0.0, 1e-9, 1e-6])
def test_an_amount_out_at_time_zero_is_a_burst_at_time_zero_in_mdt_and_de(t0):
    # 50 % at once, then 50 % evenly over 10 min: MDT = (0 x 50 + 5 x 50) / 100 = 2.5 min by the definition
    # sum t_mid dM / sum dM; DE = area (50 x 10 + 50 x 10 / 2) / (100 x 10) = 75 %
    burst = ReleaseProfile([t0, 10.0], [50.0, 100.0], "min", "%", 100.0)
    assert mean_dissolution_time(burst) == pytest.approx(2.5, abs=1e-6)
    assert dissolution_efficiency(burst) == pytest.approx(75.0, abs=1e-5)
    # the same with samples in between and a later end: a burst of 30 %, then 70 % linearly over 20 min
    t = np.array([t0, 5.0, 10.0, 20.0])
    steady = ReleaseProfile(t, 30.0 + 70.0 * np.minimum(t, 20.0) / 20.0, "min", "%", 100.0)
    assert mean_dissolution_time(steady) == pytest.approx((0 * 30 + 10.0 * 70) / 100.0, abs=1e-6)
    assert mean_dissolution_time(steady, until=10.0) == pytest.approx((5.0 * 35) / 65.0, abs=1e-6)
