"""analysis.msd: Tsong's MSD/MIMCR and Hoffelder's T^2 equivalence test against disprofas' published
values (its examples and tests, printed to 7 significant figures) and against independent computations."""
import math

import numpy as np
import pytest
from scipy.special import betainc

from analysis import AnalysisError
from analysis.msd import hotelling_two, msd_test, profile_portion
from analysis.replicates import ReplicateSet
from tests.analysis.published import dip

DIP1 = ["t.5", "t.10", "t.15", "t.20", "t.30", "t.60", "t.90", "t.120"]


def sig(x, n=7):
    return float(f"{x:.{n - 1}e}")


def printed(x, text):
    """``x`` rounded to as many decimals as the printed ``text`` has."""
    return round(x, len(text.split(".")[1])) == float(text)


def test_dip3_matches_hoffelder_2015_as_disprofas_prints_it():
    # disprofas examples_mimcr.R / test-mimcr.R: mimcr(dip3, tcol = 4:6, grouping = "batch")
    cols = ["x.15", "x.20", "x.25"]
    m = msd_test(dip("dip3", "batch", "blue", cols), dip("dip3", "batch", "white", cols))
    assert sig(m.dm) == 0.2384023 and (m.df1, m.df2) == (3, 20) and sig(m.kk) == 1.818182 and m.k == 6
    assert sig(m.t2) == 0.3410141 and sig(m.f) == 0.1033376 and sig(m.ncp) == 30.32296
    assert sig(m.f_crit) == 3.098391 and sig(m.f_crit_hoffelder) == 4.899274 and sig(m.p_f) == 0.9571526
    assert sig(m.sim_limit) == 2.248072 and sig(m.obs_lower) == 1.067015 and sig(m.obs_upper) == 1.543820
    assert m.tsong_similar and m.hoffelder_similar
    # R's pnbeta sums the Poisson mixture to an absolute error of 1e-9 and prints 2.890827e-08; the mixture
    # summed here to round-off gives 2.890994e-08, the value scipy returns
    assert m.p_hoffelder == pytest.approx(2.890827e-08, abs=1e-9)
    x = m.df1 * m.f / (m.df1 * m.f + m.df2)
    series = sum(math.exp(-m.ncp / 2 + j * math.log(m.ncp / 2) - math.lgamma(j + 1))
                 * betainc(m.df1 / 2 + j, m.df2 / 2, x) for j in range(400))
    assert m.p_hoffelder == pytest.approx(series, rel=1e-9)


@pytest.mark.parametrize("kw, p_h, sim_limit, obs_u, n_points", [
    ({"bounds": (1, 85)}, "0.740219", "11.328041", "31.679020", 7),
    ({"bounds": (1, 85), "mtad": 15}, "0.3559019", "16.9920622", "31.6790198", 7),
    ({"bounds": (1, 95), "signif": 0.1}, "0.1449045", "19.4271898", "33.3180044", 8),
])
def test_dip1_examples_of_mimcr(kw, p_h, sim_limit, obs_u, n_points):
    m = msd_test(dip("dip1", "type", "R", DIP1), dip("dip1", "type", "T", DIP1), **kw)
    assert m.times.size == n_points and m.times[-1] == (90 if n_points == 7 else 120)
    # disprofas examples_mimcr.R, res2 to res4
    assert printed(m.p_hoffelder, p_h) and printed(m.sim_limit, sim_limit) and printed(m.obs_upper, obs_u)
    assert not m.tsong_similar and not m.hoffelder_similar


def test_tsong_1996_region_boundary_points_match_the_newton_raphson_search():
    # test-mimcr.R "mimcr_results_match_Tsong_1996_two" and "_all"
    r, t = dip("dip1", "type", "R", ["t.15", "t.90"]), dip("dip1", "type", "T", ["t.15", "t.90"])
    m = msd_test(r, t, mtad=15, signif=0.1, bounds=(1, 100), nsf=(1, 3))
    assert [sig(v) for v in (m.dm, m.t2, m.f_crit, m.sim_limit, m.obs_lower, m.obs_upper)] == \
        [10.44045, 327.0089, 3.006452, 9.630777, 8.948135, 11.93276]
    assert [sig(v) for v in m.region_lower] == [-15.03433, 2.902591]
    assert [sig(v) for v in m.region_upper] == [-20.04900, 3.870743]
    assert m.s_pool[0].tolist() == pytest.approx([3.395808, 1.029870], abs=5e-7)
    m = msd_test(dip("dip1", "type", "R", DIP1), dip("dip1", "type", "T", DIP1), signif=0.1, bounds=(1, 100),
                 nsf=(1, 3))
    assert [sig(v) for v in (m.dm, m.kk, m.t2, m.f_crit, m.sim_limit, m.obs_lower, m.obs_upper)] == \
        [26.48562, 0.1125000, 2104.464, 5.251671, 19.42719, 19.65323, 33.31800]
    assert [sig(v) for v in m.region_lower] == [-17.58002, -15.22654, -13.01651, -10.97963, -7.432708,
                                                -0.5169504, 2.513022, 3.708933]
    # each point lies on the region's boundary: K (y - d)' S^-1 (y - d) = F_crit
    s_inv = np.linalg.inv(m.s_pool)
    for y in (m.region_lower, m.region_upper):
        assert m.kk * (y - m.mean_diff) @ s_inv @ (y - m.mean_diff) == pytest.approx(m.f_crit, rel=1e-9)
        assert math.sqrt(y @ s_inv @ y) in (pytest.approx(m.obs_lower), pytest.approx(m.obs_upper))


def test_hotelling_t2_agrees_with_its_textbook_formula():
    rng = np.random.default_rng(3)
    a, b = rng.normal(50, 3, (9, 3)), rng.normal(52, 3, (7, 3))
    h = hotelling_two(a, b, 0.05)
    s = ((8 * np.cov(a.T)) + 6 * np.cov(b.T)) / 14
    d = b.mean(0) - a.mean(0)
    assert h["T2"] == pytest.approx(9 * 7 / 16 * d @ np.linalg.solve(s, d))
    assert h["F"] == pytest.approx(h["T2"] * (16 - 3 - 1) / (14 * 3))


def test_profile_portion_keeps_the_first_point_above_the_bound_and_drops_below_1_percent():
    ok = profile_portion(np.array([0.4, 10, 50, 84, 90, 99]), np.array([0.6, 12, 55, 88, 95, 99]))
    assert ok.tolist() == [False, True, True, True, False, False]  # 0.4 rounds to 0.4 <= 1; 88 is the first > 85


def test_bad_input_is_named():
    r = ReplicateSet([15, 20], [[10, 20], [11, 22], [12, 21]], "min", "r")
    with pytest.raises(AnalysisError, match="mtad=60"):
        msd_test(r, r, mtad=60)
    with pytest.raises(AnalysisError, match="needs n_R \\+ n_T > p \\+ 1"):
        msd_test(ReplicateSet([5, 10, 15], [[5, 10, 20], [6, 11, 21]], "min", "a"),
                 ReplicateSet([5, 10, 15], [[5, 10, 20], [6, 12, 22]], "min", "b"))
    same = ReplicateSet([15, 20], [[10, 20], [11, 22], [12, 24]], "min", "s")
    with pytest.raises(AnalysisError, match="singular"):
        msd_test(same, same)
