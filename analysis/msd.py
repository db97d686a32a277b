"""Model-independent multivariate comparison of dissolution profiles: Tsong's multivariate statistical
distance (MSD, the model-independent multivariate confidence region procedure, MIMCR) and Hoffelder's
T^2 test for equivalence, as the R package disprofas (``mimcr``, ``get_T2_two``, ``get_sim_lim``)
computes them.

With n_R reference and n_T test units at p time points, mean difference d = mean_T - mean_R and pooled
covariance S (Tsong et al. 1996, Drug Inf. J. 30:1105; Hoffelder 2016, Stat. Papers / Hoffelder et al.
2015, AAPS J.):

- Mahalanobis distance D_M = sqrt(d' S^-1 d); k = n_R n_T / (n_R + n_T); Hotelling's T^2 = k D_M^2;
  df1 = p, df2 = n_R + n_T - p - 1, K = k df2 / ((n_R + n_T - 2) p), F = K D_M^2;
- the similarity limit for a largest tolerable average difference (MTAD, default 10 %) at every point,
  D_crit = sqrt(MTAD^2 1' S^-1 1);
- Tsong (MSD/MIMCR): the (1 - alpha) confidence region of the true difference is the ellipsoid
  K (y - d)' S^-1 (y - d) <= F_crit(1 - alpha; df1, df2). In the S^-1 metric it is a ball of radius
  r = sqrt(F_crit / K) around d, so its points nearest to and farthest from 0 lie on the line through d,
  at y = d (1 -/+ r / D_M), at distances |D_M - r| and D_M + r. The profiles are similar when that upper
  bound D_M + r is below D_crit. (disprofas finds the same two points by a Newton-Raphson search on the
  boundary; the closed form here is exact.)
- Hoffelder's T^2 test for equivalence: F follows a non-central F(df1, df2) with non-centrality
  k D_crit^2 on the boundary of the equivalence region; the profiles are equivalent when
  P(F' <= F) < alpha.

The time points are those with both means above ``bounds[0]`` and up to the first at which either mean
exceeds ``bounds[1]`` (that point included), means rounded to ``nsf`` significant figures for the tests,
as disprofas does; points after the first excluded one that follows the accepted run are dropped.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import f as f_dist
from scipy.stats import ncf

from analysis.errors import AnalysisError
from analysis.replicates import ReplicateSet, check_same_times

MTAD_PCT = 10.0
"""Largest tolerable average difference at each time point, %."""
SIGNIF = 0.05
BOUNDS_PCT = (1.0, 85.0)
NSF = (1, 2)
MAX_CONDITION = 1e10
"""Condition number of the pooled covariance above which it is taken as singular."""


def _signif(x: np.ndarray, digits: int) -> np.ndarray:
    """R's ``signif``: round to ``digits`` significant figures."""
    x = np.asarray(x, dtype=float)
    with np.errstate(divide="ignore"):
        mag = np.where(x != 0, np.floor(np.log10(np.abs(x))), 0.0)
    scale = 10.0 ** (digits - 1 - mag)
    return np.round(x * scale) / scale


def profile_portion(reference_mean: np.ndarray, test_mean: np.ndarray, bounds=BOUNDS_PCT, nsf=NSF) -> np.ndarray:
    """(T,) bool: the time points the multivariate tests use (see the module text)."""
    r, t = np.asarray(reference_mean, float), np.asarray(test_mean, float)
    over = (_signif(r, nsf[1]) > bounds[1]) | (_signif(t, nsf[1]) > bounds[1])
    if over.any():
        over[int(np.argmax(over))] = False  # the first point above the upper bound is kept
    ok = ~over & (_signif(r, nsf[0]) > bounds[0]) & (_signif(t, nsf[0]) > bounds[0])
    if ok.any():
        first = int(np.argmax(ok))
        gaps = np.flatnonzero(~ok[first:])
        if gaps.size:
            ok[first + int(gaps[0]):] = False
    return ok


@dataclass(frozen=True, eq=False)
class MsdResult:
    """Tsong's MSD/MIMCR and Hoffelder's T^2 equivalence test of a test against a reference set.

    Attributes
    ----------
    times : (p,) ndarray of float
        The time points used.
    mean_diff : (p,) ndarray of float, %
        Test mean minus reference mean.
    s_pool : (p, p) ndarray of float
        Pooled covariance matrix.
    dm, t2, f, f_crit, p_f : float
        Mahalanobis distance, Hotelling's T^2, its F value, the (1 - alpha) F quantile, P(F >= f).
    df1, df2 : int
    k, kk : float
        The scale factors k (of T^2) and K (of F).
    sim_limit : float
        D_crit, the Mahalanobis distance of an MTAD at every point.
    obs_lower, obs_upper : float
        Nearest and farthest distance of the confidence region from 0.
    region_lower, region_upper : (p,) ndarray of float, %
        The difference vectors at those two points.
    hotelling_ci : (p, 2) ndarray of float, %
        Simultaneous (Hotelling) confidence intervals of the difference at each point.
    ncp, f_crit_hoffelder, p_hoffelder : float
        Non-centrality k D_crit^2, the alpha quantile of the non-central F, and P(F' <= f).
    tsong_similar, hoffelder_similar : bool
    mtad, signif : float
    n_reference, n_test : int
    """

    times: np.ndarray
    mean_diff: np.ndarray
    s_pool: np.ndarray
    dm: float
    df1: int
    df2: int
    k: float
    kk: float
    t2: float
    f: float
    f_crit: float
    p_f: float
    sim_limit: float
    obs_lower: float
    obs_upper: float
    region_lower: np.ndarray
    region_upper: np.ndarray
    hotelling_ci: np.ndarray
    ncp: float
    f_crit_hoffelder: float
    p_hoffelder: float
    tsong_similar: bool
    hoffelder_similar: bool
    mtad: float
    signif: float
    n_reference: int
    n_test: int

    def to_dict(self) -> dict:
        return {"times": self.times.tolist(), "mean_diff": self.mean_diff.tolist(), "dm": self.dm, "df1": self.df1,
                "df2": self.df2, "k": self.k, "K": self.kk, "T2": self.t2, "F": self.f, "F_crit": self.f_crit,
                "p_F": self.p_f, "sim_limit": self.sim_limit, "obs_lower": self.obs_lower,
                "obs_upper": self.obs_upper, "ncp_hoffelder": self.ncp, "F_crit_hoffelder": self.f_crit_hoffelder,
                "p_hoffelder": self.p_hoffelder, "tsong_similar": self.tsong_similar,
                "hoffelder_similar": self.hoffelder_similar, "mtad": self.mtad, "signif": self.signif,
                "n_reference": self.n_reference, "n_test": self.n_test}


def hotelling_two(reference: np.ndarray, test: np.ndarray, signif: float = SIGNIF) -> dict:
    """Hotelling's two-sample T^2 of (n_R, p) and (n_T, p) unit matrices (disprofas' ``get_T2_two``).

    Returns
    -------
    dict
        ``dm, df1, df2, K, k, T2, F, F_crit, p_F, S_pool, mean_diff, hotelling_ci``.
    """
    m1, m2 = np.asarray(reference, float), np.asarray(test, float)
    if m1.ndim != 2 or m2.ndim != 2 or m1.shape[1] != m2.shape[1]:
        raise AnalysisError(f"reference {m1.shape} and test {m2.shape} must be (n, p) matrices with the same p")
    n1, n2, p = m1.shape[0], m2.shape[0], m1.shape[1]
    if n1 + n2 - p - 1 < 1:
        raise AnalysisError(f"{n1} + {n2} units for {p} time points: Hotelling's T^2 needs n_R + n_T > p + 1 "
                            f"(use fewer time points or more units)")
    s = ((n1 - 1) * np.cov(m1, rowvar=False, ddof=1).reshape(p, p)
         + (n2 - 1) * np.cov(m2, rowvar=False, ddof=1).reshape(p, p)) / (n1 + n2 - 2)
    if not np.all(np.isfinite(s)) or np.linalg.cond(s) > MAX_CONDITION:
        raise AnalysisError(f"the pooled covariance matrix of the units at the {p} time points is singular "
                            f"(units that differ only in proportion, or identical ones); the multivariate "
                            f"tests cannot be computed")
    s_inv = np.linalg.inv(s)
    d = m2.mean(axis=0) - m1.mean(axis=0)
    dm = float(math.sqrt(max(float(d @ s_inv @ d), 0.0)))
    df1, df2 = p, n1 + n2 - p - 1
    k = n1 * n2 / (n1 + n2)
    kk = k * df2 / ((n1 + n2 - 2) * df1)
    f_obs = kk * dm ** 2
    f_crit = float(f_dist.ppf(1.0 - signif, df1, df2))
    half = np.sqrt(f_crit / kk * np.diag(s))
    return {"dm": dm, "df1": df1, "df2": df2, "K": kk, "k": k, "T2": k * dm ** 2, "F": f_obs, "F_crit": f_crit,
            "p_F": float(f_dist.sf(f_obs, df1, df2)), "S_pool": s, "S_inv": s_inv, "mean_diff": d,
            "hotelling_ci": np.column_stack([d - half, d + half])}


def msd_test(reference: ReplicateSet, test: ReplicateSet, *, mtad: float = MTAD_PCT, signif: float = SIGNIF,
             bounds: tuple[float, float] = BOUNDS_PCT, nsf: tuple[int, int] = NSF,
             select: bool = True) -> MsdResult:
    """Tsong's MSD (MIMCR) and Hoffelder's T^2 equivalence test.

    Parameters
    ----------
    reference, test : ReplicateSet
        Units at the same time points.
    mtad : float
        Largest tolerable average difference at each point, % (0, 50].
    signif : float
        Significance level alpha (0, 1).
    bounds, nsf
        The points used (see the module text); ``select=False`` uses every point after time zero.

    Returns
    -------
    MsdResult

    Raises
    ------
    AnalysisError
        Different time points, a bad setting, fewer than 2 points, too few units, a singular covariance.
    """
    if not 0 < mtad <= 50:
        raise AnalysisError(f"mtad={mtad!r}; expected a percentage in (0, 50]")
    if not 0 < signif < 1:
        raise AnalysisError(f"signif={signif!r} must lie in (0, 1)")
    if not (0 <= bounds[0] <= bounds[1] <= 100):
        raise AnalysisError(f"bounds={bounds!r}; expected (lower, upper) within [0, 100]")
    check_same_times(test, reference)
    ref, tst = reference.without_time_zero(), test.without_time_zero()
    ok = profile_portion(ref.mean, tst.mean, bounds, nsf) if select else np.ones(ref.times.size, bool)
    if ok.sum() < 2:
        raise AnalysisError(f"{int(ok.sum())} time point(s) between {bounds[0]:g} % and the first above "
                            f"{bounds[1]:g} %; the multivariate tests need at least 2 (3 are expected)")
    h = hotelling_two(ref.units[:, ok], tst.units[:, ok], signif)
    ones = np.full(h["df1"], float(mtad))
    d_crit = float(math.sqrt(ones @ h["S_inv"] @ ones))
    ncp = h["k"] * d_crit ** 2
    f_crit_h = float(ncf.ppf(signif, h["df1"], h["df2"], ncp))
    p_h = float(ncf.cdf(h["F"], h["df1"], h["df2"], ncp))
    r = math.sqrt(h["F_crit"] / h["K"])
    dm, d = h["dm"], h["mean_diff"]
    direction = d / dm if dm > 0 else np.zeros_like(d)
    near, far = d - r * direction, d + r * direction
    return MsdResult(ref.times[ok], d, h["S_pool"], dm, h["df1"], h["df2"], h["k"], h["K"], h["T2"], h["F"],
                     h["F_crit"], h["p_F"], d_crit, abs(dm - r), dm + r, near, far, h["hotelling_ci"], ncp, f_crit_h,
                     p_h, dm + r < d_crit, p_h < signif, float(mtad), float(signif), ref.n_units, tst.n_units)
