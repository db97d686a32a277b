"""analysis.replicates and analysis.regulatory: mean, SD and CV per time point, and each regulator's f2
rule at its edges (hand-computed sets of 12 units whose CVs are set exactly), with Shah et al.'s f2."""
import math

import numpy as np
import pytest

from analysis import AnalysisError
from analysis.regulatory import RULE_NAMES, check_rule, points_used
from analysis.replicates import ReplicateSet
from tests.analysis.published import shah1998

Z = np.array([-1.5, -1.2, -0.9, -0.6, -0.3, -0.1, 0.1, 0.3, 0.6, 0.9, 1.2, 1.5])
Z = (Z - Z.mean()) / Z.std(ddof=1)  # 12 offsets with mean 0 and sample SD 1: units = mean (1 + cv Z)


def units(means, cvs_pct):
    means, cvs = np.asarray(means, float), np.asarray(cvs_pct, float) / 100.0
    return means[None, :] * (1.0 + cvs[None, :] * Z[:, None])


def sets(times, test_means, ref_means, test_cv, ref_cv=None):
    ref_cv = test_cv if ref_cv is None else ref_cv
    return (ReplicateSet(times, units(test_means, test_cv), "min", "test"),
            ReplicateSet(times, units(ref_means, ref_cv), "min", "reference"))


TIMES = [5, 10, 15, 20, 30, 45]
TEST = [20, 40, 60, 75, 88, 95]
REF = [22, 42, 62, 77, 90, 96]


def test_mean_sd_cv_per_time_point_are_the_textbook_ones():
    s = ReplicateSet([0, 10, 20], [[0, 10, 30], [0, 14, 34], [0, 12, 38]], "min", "x")
    assert s.mean.tolist() == pytest.approx([0, 12, 34])
    assert s.sd.tolist() == pytest.approx([0, 2, 4])  # sample SD, n - 1
    assert s.cv_pct.tolist() == pytest.approx([0, 100 * 2 / 12, 100 * 4 / 34])  # 0 where the mean is 0
    assert s.table()[1] == pytest.approx({"time": 10.0, "mean_pct": 12.0, "sd_pct": 2.0, "cv_pct": 100 / 6})
    t, r = sets(TIMES, TEST, REF, [25, 5, 5, 5, 5, 5])
    assert t.cv_pct == pytest.approx([25, 5, 5, 5, 5, 5]) and t.mean == pytest.approx(TEST)


def test_a_25_percent_cv_at_the_first_point_is_refused_by_all_but_the_fda_which_warns():
    t, r = sets(TIMES, TEST, REF, [25, 5, 5, 5, 5, 5])
    # 85 % rule: the first point above 85 % in either mean is 30 min: 5 points, each differing by 2 %
    f2 = 100 - 25 * math.log10(1 + 4)  # 82.52575
    for name in RULE_NAMES:
        c = check_rule(t, r, name)
        assert c.used == 5 and c.cv_failures == ("test CV 25.00 % at 5 min exceeds 20 %",
                                                 "reference CV 25.00 % at 5 min exceeds 20 %"), name
        if name == "fda":
            assert c.refused is None and c.f2 == pytest.approx(f2) and c.similar
            assert any("CV rule of the FDA not strictly met" in w for w in c.warnings)
        else:
            assert c.f2 is None and "CV rule" in c.refused and "bootstrap" in c.refused, name


def test_the_early_points_differ_10_min_15_min_and_the_first_40_percent():
    # CV 18 % at 5 and 10 min, 15 % at 15 min, 5 % after: only the FDA counts 15 min as early
    t, r = sets(TIMES, TEST, REF, [18, 18, 15, 5, 5, 5])
    got = {n: check_rule(t, r, n) for n in RULE_NAMES}
    assert got["fda"].refused is None and got["fda"].early == 3 and got["fda"].warnings == ()
    for n in ("ema", "who", "canada"):
        assert got[n].early == 2 and "CV 15.00 % at 15 min exceeds 10 %" in got[n].refused
    assert got["anvisa"].early == 2  # floor(0.4 x 6) = 2 of the 6 points
    # ten points: ANVISA's first floor(0.4 x 10) = 4 points (to 20 min) are early; CV 15 % at 20 min
    times = [5, 10, 15, 20, 25, 30, 35, 40, 45, 60]
    means = [10, 20, 30, 40, 50, 60, 70, 75, 80, 84]
    t, r = sets(times, means, means, [15, 15, 15, 15, 5, 5, 5, 5, 5, 5])
    assert check_rule(t, r, "anvisa").refused is None and check_rule(t, r, "anvisa").early == 4
    assert check_rule(t, r, "anvisa").f2 == pytest.approx(100.0)
    fda = check_rule(t, r, "fda")
    assert fda.f2 == pytest.approx(100.0) and "20 min exceeds 10 %" in fda.warnings[0]
    assert "20 min exceeds 10 %" in check_rule(t, r, "ema").refused


def test_cv_limits_apply_to_the_cv_rounded_to_two_decimals():
    ok = sets(TIMES, TEST, REF, [20.004, 5, 5, 5, 5, 5])
    bad = sets(TIMES, TEST, REF, [20.006, 5, 5, 5, 5, 5])
    assert check_rule(*ok, "ema").refused is None
    assert "CV 20.01 % at 5 min exceeds 20 %" in check_rule(*bad, "ema").refused
    assert "CV rule" in check_rule(*sets(TIMES, TEST, REF, [5, 5, 5, 5, 10.006, 5]), "ema").refused
    assert check_rule(*sets(TIMES, TEST, REF, [5, 5, 5, 5, 5, 10.006]), "ema").refused is None  # after the cut


def test_the_who_cuts_where_the_reference_passes_85_percent():
    test = [40, 70, 86, 92, 96, 98]  # the test passes 85 % at 15 min, the reference at 30 min
    ref = [30, 55, 70, 80, 88, 95]
    t, r = sets(TIMES, test, ref, [5] * 6)
    assert check_rule(t, r, "ema").used == 3 and check_rule(t, r, "who").used == 5
    d = np.array(test) - np.array(ref)
    assert check_rule(t, r, "who").f2 == pytest.approx(100 - 25 * math.log10(1 + np.mean(d[:5] ** 2)))
    assert check_rule(t, r, "ema").f2 == pytest.approx(100 - 25 * math.log10(1 + np.mean(d[:3] ** 2)))
    assert points_used(np.array([test, test]), np.array([ref, ref]), "reference").tolist() == [5, 5]


def test_fewer_than_three_points_is_similar_without_f2_only_when_both_pass_85_by_15_min():
    times = [10, 15, 30, 45]
    t, r = sets(times, [80, 90, 97, 99], [82, 91, 98, 99], [5, 3, 2, 2])
    c = check_rule(t, r, "ema")
    assert c.used == 2 and c.similar_without_f2 and c.similar and c.f2 is None and "similar without f2" in c.refused
    # Canada asks every unit above 85 % at 15 min: a unit at 84 % leaves f2 refused for too few points
    low = t.units.copy()
    low[0, 1] = 84.0
    t84 = ReplicateSet(times, low, "min", "test")
    assert check_rule(t84, r, "ema").similar_without_f2  # the mean is still above 85 %
    canada = check_rule(t84, r, "canada")
    assert not canada.similar_without_f2 and canada.similar is None and "only 2 usable" in canada.refused
    slow = sets([20, 30, 45], [86, 95, 99], [87, 96, 99], [3, 2, 2])
    assert "only 1 usable" in check_rule(*slow, "ema").refused  # above 85 % only after 15 min


def test_few_units_and_mean_profiles_are_warned_about():
    t, r = sets(TIMES, TEST, REF, [5] * 6)
    six = ReplicateSet(TIMES, t.units[:6], "min", "test")
    assert "test: 6 units; the guidelines ask for 12" in check_rule(six, r, "ema").warnings
    mean_only = ReplicateSet(TIMES, [TEST], "min", "test")
    c = check_rule(mean_only, ReplicateSet(TIMES, [REF], "min", "reference"), "ema")
    assert c.f2 == pytest.approx(100 - 25 * math.log10(1 + 4)) and "CV not checked" in c.warnings[0]


@pytest.mark.parametrize("batch, f2", [("test1", 60.03), ("test2", 51.08), ("test3", 51.19),
                                       ("test4", 50.07), ("test5", 48.05)])
def test_shah_1998_f2_under_the_conventional_fda_reading_as_bootf2_prints_it(batch, f2):
    # bootf2 tests/testthat/test_bootf2.R: calcf2(test, ref, regulation = "FDA", both.TR.85 = TRUE)
    c = check_rule(shah1998(batch), shah1998("ref"), "fda", both_tr_85=True)
    assert round(c.f2, 2) == f2
    assert "conventional reading" in c.warnings[0]


def test_bad_input_is_named():
    t, r = sets(TIMES, TEST, REF, [5] * 6)
    with pytest.raises(AnalysisError, match="rule 'eu'; expected one of ema, fda, who, canada, anvisa"):
        check_rule(t, r, "eu")
    with pytest.raises(AnalysisError, match="fda rule only"):
        check_rule(t, r, "ema", both_tr_85=True)
    with pytest.raises(AnalysisError, match="not sampled at the same time points"):
        check_rule(ReplicateSet([5, 10, 15, 20, 30, 40], t.units, "min", "test"), r)
    with pytest.raises(AnalysisError, match="time 5 min .* does not increase"):
        ReplicateSet([10, 5], [[1, 2]], "min", "x")
    with pytest.raises(AnalysisError, match="percent released at index"):
        ReplicateSet([5, 10], [[1, np.nan]], "min", "x")
