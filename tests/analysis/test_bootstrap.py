"""analysis.bootstrap: R's generator reproduced, the five f2 estimators by their formulas, and bootf2's
published bootstrap of Shah et al.'s test 1 against the reference reproduced to its printed digits."""
import math

import numpy as np
import pytest
from scipy.stats import norm

from analysis import AnalysisError
from analysis.bootstrap import ESTIMATORS, INTERVALS, RSampler, bootstrap_f2, f2_estimators
from analysis.replicates import ReplicateSet
from tests.analysis.published import shah1998


def test_r_generator_gives_rs_numbers_for_a_seed():
    assert RSampler(1).unif(3) == pytest.approx([0.2655087, 0.3721239, 0.5728534], abs=5e-8)  # set.seed(1); runif(3)
    assert RSampler(42).unif(2) == pytest.approx([0.9148060, 0.9370754], abs=5e-8)  # set.seed(42); runif(2)
    draws = RSampler(7).sample_int(12, 5000)
    assert draws.min() == 1 and draws.max() == 12
    # rejection sampling consumes one word per try: the accepted draws are the words below 12 in order
    words = np.floor(RSampler(7).unif(20000) * 65536).astype(int) & 15
    assert draws.tolist() == (words[words < 12][:5000] + 1).tolist()


def test_estimators_follow_their_formulas():
    t, r = shah1998("test1"), shah1998("ref")
    got = f2_estimators(t, r, "ema")
    keep = 3  # EMA: the first point above 85 % in either mean is 90 min (test 87.4 %)
    assert got["points"] == keep
    d2 = np.sum((t.mean[:keep] - r.mean[:keep]) ** 2)
    var = np.sum(t.sd[:keep] ** 2 / 12 + r.sd[:keep] ** 2 / 12)
    vt, vr = t.sd[:keep] ** 2, r.sd[:keep] ** 2
    wvar = np.sum(((0.5 + vt / (vt + vr)) * vt + (0.5 + vr / (vt + vr)) * vr) / 12)
    f2 = (lambda x: 100 - 25 * math.log10(1 + x / keep))
    assert got["est.f2"] == pytest.approx(f2(d2)) and got["exp.f2"] == pytest.approx(f2(d2 + var))
    assert got["bc.f2"] == pytest.approx(f2(d2 - var)) and got["vc.exp.f2"] == pytest.approx(f2(d2 + wvar))
    assert got["vc.bc.f2"] == pytest.approx(f2(d2 - wvar))
    # a bias correction below its bound is undefined (Shah 1998): identical means, some variance
    same = ReplicateSet(t.times, t.units - t.mean + r.mean, "min", "same")
    assert math.isnan(f2_estimators(same, r)["bc.f2"]) and f2_estimators(same, r)["est.f2"] == pytest.approx(100)


def test_bootf2_published_bootstrap_of_shah_test1_to_its_printed_digits():
    # bootf2 0.4.1 tests/testthat/test_bootf2.R: bootf2(test1, ref, n.boots = 1000, min.points = 3),
    # defaults seed = 306, regulation = "EMA", alpha = 0.05 (compared there with Mendyk's bootf2BCA)
    b = bootstrap_f2(shah1998("test1"), shah1998("ref"), "ema", n_boot=1000, seed=306, min_points=3)
    assert round(b.estimates["exp.f2"], 2) == 56.83
    assert round(b.boot_mean["exp.f2"], 2) == 57.40
    assert [round(x, 2) for x in b.interval("exp.f2", "normal")] == [47.74, 64.79]
    assert [round(x, 2) for x in b.interval("exp.f2", "basic")] == [46.62, 63.64]
    assert [round(x, 2) for x in b.interval("exp.f2", "percentile")] == [50.03, 67.04]
    lo, hi = b.interval("exp.f2", "bca.boot")
    assert (round(lo, 2), round(hi, 3)) == (49.82, 66.695)
    assert b.level == pytest.approx(0.90) and b.points == 3 and (b.n_test, b.n_reference) == (12, 12)


def test_intervals_follow_their_definitions_from_the_bootstrap_values():
    b = bootstrap_f2(shah1998("test2"), shah1998("ref"), "fda", n_boot=400, seed=11)
    for k, name in enumerate(ESTIMATORS):
        f2, boot = b.estimates[name], b.values[:, k]
        fin = np.sort(boot[np.isfinite(boot)])
        z = norm.ppf(0.95)
        assert b.interval(name, "normal") == pytest.approx((2 * f2 - fin.mean() - z * fin.std(ddof=1),
                                                            2 * f2 - fin.mean() + z * fin.std(ddof=1)))
        # (B + 1) alpha = 20.05 for B = 400: between the 20th and 21st order statistics on the normal scale
        w = (norm.ppf(0.05) - norm.ppf(20 / 401)) / (norm.ppf(21 / 401) - norm.ppf(20 / 401))
        lo = fin[19] + w * (fin[20] - fin[19])
        assert b.interval(name, "percentile")[0] == pytest.approx(lo)
        assert b.interval(name, "basic")[1] == pytest.approx(2 * f2 - lo)
        for kind in ("bca", "bca.boot"):
            a, c = b.interval(name, kind)
            assert fin[0] <= a <= c <= fin[-1]


def test_seeded_and_identical_units_collapse_to_the_estimate():
    t, r = shah1998("test3"), shah1998("ref")
    one = bootstrap_f2(t, r, n_boot=200, seed=5)
    assert np.array_equal(one.values, bootstrap_f2(t, r, n_boot=200, seed=5).values)
    assert not np.array_equal(one.values, bootstrap_f2(t, r, n_boot=200, seed=6).values)
    flat_t = ReplicateSet(t.times, np.repeat(t.mean[None], 12, axis=0), "min", "t")
    flat_r = ReplicateSet(r.times, np.repeat(r.mean[None], 12, axis=0), "min", "r")
    b = bootstrap_f2(flat_t, flat_r, n_boot=100)
    assert b.interval("est.f2", "percentile") == pytest.approx((b.estimates["est.f2"],) * 2)
    assert set(b.to_dict()["estimators"]["est.f2"]["intervals"]) == set(INTERVALS)


def test_bad_input_is_named():
    t, r = shah1998("test1"), shah1998("ref")
    with pytest.raises(AnalysisError, match="test: 1 unit; .* at least 2 units"):
        bootstrap_f2(ReplicateSet(t.times, t.units[:1], "min", "test"), r)
    with pytest.raises(AnalysisError, match="at least 100 bootstrap samples"):
        bootstrap_f2(t, r, n_boot=50)
    with pytest.raises(AnalysisError, match="alpha=0.6"):
        bootstrap_f2(t, r, alpha=0.6)
