"""The bootstrap of f2 over units, with the five f2 estimators and four interval types of bootf2.

Estimators on the P points the rule keeps (Shah et al. 1998, Pharm. Res. 15:889, table 7; Mendyk et al.
2013, Dissolution Technol. 20:13), with mean differences d_i, unit variances S_T,i^2, S_R,i^2 and unit
counts n_T, n_R:

- ``est.f2``     f2 = 100 - 25 log10(1 + sum d_i^2 / P)
- ``exp.f2``     100 - 25 log10(1 + (sum d_i^2 + sum (S_T^2/n_T + S_R^2/n_R)) / P)        (expected)
- ``bc.f2``      100 - 25 log10(1 + (sum d_i^2 - sum (S_T^2/n_T + S_R^2/n_R)) / P)        (bias-corrected)
- ``vc.exp.f2``  as exp.f2 with each variance weighted by w = 0.5 + S^2 / (S_T^2 + S_R^2)   (variance-corrected)
- ``vc.bc.f2``   as bc.f2 with the weighted variances
  (the bias-corrected ones are undefined, NaN, when the bracket falls to 0 or below).

Each bootstrap sample draws n_T test and n_R reference units with replacement, recomputes the means, the
points the rule keeps, and every estimator. Intervals at two-sided level 1 - 2 alpha (Davison and Hinkley
1997, ch. 5; Efron and Tibshirani 1993, ch. 14), from the finite bootstrap values f*:

- ``normal``      2 f2 - mean(f*) -/+ sd(f*) z(1 - alpha)
- ``basic``       2 f2 - q*(1 - alpha), 2 f2 - q*(alpha)
- ``percentile``  q*(alpha), q*(1 - alpha)
- ``bca``         q*(alpha_1), q*(alpha_2), alpha_k = Phi(z0 + (z0 + z_k) / (1 - a (z0 + z_k))),
  z0 = Phi^-1(#{f* < f2} / B), the acceleration a from the jackknife over all n_T + n_R units
  (``bca``, Shah 1998) or from the regression of f* on the resampling frequencies (``bca.boot``, as R's
  boot package and bootf2BCA do)

where q*(p) is the order statistic of f* interpolated on the normal scale (Davison and Hinkley eq. 5.8).

The units are drawn with R's own generator (Mersenne twister seeded by ``set.seed``, ``sample`` with
rejection sampling), so that a seed gives the very bootstrap samples bootf2 draws with that seed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import norm

from analysis.errors import AnalysisError
from analysis.profile import CUTOFF_PCT, MIN_POINTS
from analysis.regulatory import Rule, get_rule, points_used
from analysis.replicates import ReplicateSet, check_same_times

ESTIMATORS = ("est.f2", "exp.f2", "bc.f2", "vc.exp.f2", "vc.bc.f2")
"""The f2 estimators, named as bootf2 names them."""
INTERVALS = ("normal", "basic", "percentile", "bca", "bca.boot")
"""The confidence intervals: bca takes its acceleration from the jackknife, bca.boot from regression."""
DEFAULT_SEED = 306
"""bootf2's default seed."""
DEFAULT_N_BOOT = 10000


# ---------------------------------------------------------------- R's generator
def _r_seed_state(seed: int) -> np.ndarray:
    """The 624 Mersenne-twister words R's ``set.seed(seed)`` leaves (R's RNG.c: 50 scrambling steps of the
    LCG 69069 s + 1, then one step per word)."""
    s = int(seed) & 0xFFFFFFFF
    for _ in range(50):
        s = (69069 * s + 1) & 0xFFFFFFFF
    words = np.empty(625, dtype=np.uint32)
    for j in range(625):
        s = (69069 * s + 1) & 0xFFFFFFFF
        words[j] = s
    return words[1:]  # the first word is the position, reset to 624 by R


class RSampler:
    """Uniform draws and ``sample.int(n, size, replace = TRUE)`` as R (>= 3.6) produces them for a seed."""

    def __init__(self, seed: int) -> None:
        self._bits = np.random.MT19937()
        self._bits.state = {"bit_generator": "MT19937", "state": {"key": _r_seed_state(seed), "pos": 624}}

    def unif(self, size: int) -> np.ndarray:
        """``runif(size)``: 32-bit words times 2^-32, kept inside (0, 1) as R's fixup does."""
        u = self._bits.random_raw(size).astype(np.float64) * 2.3283064365386963e-10
        return np.clip(u, 0.5 * 2.328306437080797e-10, 1.0 - 0.5 * 2.328306437080797e-10)

    def sample_int(self, n: int, size: int) -> np.ndarray:
        """``sample.int(n, size, replace = TRUE)`` consuming exactly the words R consumes."""
        bits = int(math.ceil(math.log2(n))) if n > 1 else 0
        if bits >= 16:
            raise AnalysisError(f"{n} units: the R-compatible sampler draws from at most 32768 units")
        out = []
        have = 0
        while have < size:
            need = size - have
            state = self._bits.state
            chunk = max(need + need // 2 + 16, 64)
            v = np.floor(self.unif(chunk) * 65536).astype(np.int64) & ((1 << bits) - 1)
            ok = np.flatnonzero(v < n)
            if ok.size >= need:
                last = int(ok[need - 1])
                self._bits.state = state
                self._bits.random_raw(last + 1)  # consume exactly the words up to the last accepted draw
                out.append(v[ok[:need]])
                have = size
            else:
                out.append(v[ok])
                have += ok.size
        return np.concatenate(out) + 1


# ---------------------------------------------------------------- estimators
def _estimators(mt: np.ndarray, mr: np.ndarray, vt: np.ndarray, vr: np.ndarray, nt: int, nr: int,
                used: np.ndarray, min_points: int) -> np.ndarray:
    """(B, 5) estimators of (B, T) means and variances with ``used`` (B,) leading points."""
    mask = np.arange(mt.shape[-1])[None, :] < used[:, None]
    p = used.astype(float)
    sq = np.sum(np.where(mask, (mt - mr) ** 2, 0.0), axis=-1)
    var = np.sum(np.where(mask, vt / nt + vr / nr, 0.0), axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        tot = vt + vr
        wvt = np.where(tot > 0, (0.5 + vt / tot) * vt, 0.0)
        wvr = np.where(tot > 0, (0.5 + vr / tot) * vr, 0.0)
    wvar = np.sum(np.where(mask, wvt / nt + wvr / nr, 0.0), axis=-1)

    def f2(x):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(x > -p, 100.0 - 25.0 * np.log10(1.0 + x / p), np.nan)

    out = np.column_stack([f2(sq), f2(sq + var), f2(sq - var), f2(sq + wvar), f2(sq - wvar)])
    out[used < min_points] = np.nan
    return out


def _stats(ut: np.ndarray, ur: np.ndarray) -> tuple[np.ndarray, ...]:
    """Means and sample variances over the unit axis (-2) of (..., n, T) arrays."""
    return ut.mean(axis=-2), ur.mean(axis=-2), ut.var(axis=-2, ddof=1), ur.var(axis=-2, ddof=1)


def f2_estimators(test: ReplicateSet, reference: ReplicateSet, rule: str | Rule = "ema", *,
                  both_tr_85: bool = False, min_points: int = MIN_POINTS, cutoff_pct: float = CUTOFF_PCT) -> dict:
    """The five f2 estimators of two replicate sets (points by ``rule``'s 85 % cut; no CV check).

    Returns
    -------
    dict of str to float
        Keyed by ``ESTIMATORS``; NaN where undefined; plus ``"points"``, the points used.
    """
    rule = rule if isinstance(rule, Rule) else get_rule(rule)
    ut, ur = _units(test, reference)
    mt, mr, vt, vr = _stats(ut, ur)
    used = np.atleast_1d(points_used(mt, mr, rule.cut, both_tr_85=both_tr_85, cutoff_pct=cutoff_pct))
    values = _estimators(mt[None], mr[None], vt[None], vr[None], ut.shape[0], ur.shape[0], used, min_points)[0]
    return dict(zip(ESTIMATORS, (float(v) for v in values))) | {"points": int(used[0])}


def _units(test: ReplicateSet, reference: ReplicateSet) -> tuple[np.ndarray, np.ndarray]:
    check_same_times(test, reference)
    keep = test.times > 0
    for s in (test, reference):
        if s.n_units < 2:
            raise AnalysisError(f"{s.label}: {s.n_units} unit; the f2 estimators and the bootstrap need at least 2 "
                                f"units per product (the guidelines ask for 12)")
    return test.units[:, keep], reference.units[:, keep]


# ---------------------------------------------------------------- intervals
def _quantile_normal_scale(sorted_values: np.ndarray, alphas) -> np.ndarray:
    """Order statistics at (B + 1) alpha, interpolated on the normal scale (Davison and Hinkley eq. 5.8)."""
    x = sorted_values
    n = x.size
    out = []
    for a in np.atleast_1d(alphas):
        rk = (n + 1) * a
        k = int(math.trunc(rk))
        if k == rk and 1 <= k <= n:
            out.append(x[k - 1])
        elif k <= 0:
            out.append(x[0])
        elif k >= n:
            out.append(x[-1])
        else:
            z, z1, z2 = norm.ppf(a), norm.ppf(k / (n + 1)), norm.ppf((k + 1) / (n + 1))
            out.append(x[k - 1] + (z - z1) / (z2 - z1) * (x[k] - x[k - 1]))
    return np.array(out, dtype=float)


def _bca(boot: np.ndarray, f2: float, a: float, alpha: float) -> tuple[float, float]:
    finite = np.sort(boot[np.isfinite(boot)])
    if not finite.size or not math.isfinite(f2) or not math.isfinite(a):
        return math.nan, math.nan
    z0 = norm.ppf(np.sum(finite < f2) / boot.size)
    if not math.isfinite(z0):
        return math.nan, math.nan
    zs = norm.ppf([alpha, 1.0 - alpha])
    levels = norm.cdf(z0 + (z0 + zs) / (1.0 - a * (z0 + zs)))
    if not np.all(np.isfinite(levels)):
        return math.nan, math.nan
    lo, hi = _quantile_normal_scale(finite, levels)
    return float(lo), float(hi)


def _acceleration(values: np.ndarray) -> float:
    d = np.nanmean(values) - values
    d = d[np.isfinite(d)]
    den = 6.0 * np.sum(d * d) ** 1.5
    return float(np.sum(d ** 3) / den) if den > 0 else 0.0


@dataclass(frozen=True, eq=False)
class BootstrapF2:
    """The bootstrap of f2 between two replicate sets.

    Attributes
    ----------
    estimates : dict of str to float
        Each estimator of the original data (NaN where undefined).
    boot_mean, boot_median : dict of str to float
        Of the finite bootstrap values of each estimator.
    boot_na : dict of str to int
        Bootstrap samples where an estimator was undefined (fewer than ``min_points`` points, or a
        bias correction below its bound).
    intervals : dict of (str, str) to (float, float)
        ``(estimator, interval)`` to (lower, upper); NaN when not computable.
    level : float
        Two-sided level, 1 - 2 alpha (0.90 for alpha = 0.05).
    n_boot, seed : int
    rule : str
    points : int
        Points used with the original data.
    values : (n_boot, 5) ndarray of float
        The bootstrap values, one column per estimator.
    """

    estimates: dict
    boot_mean: dict
    boot_median: dict
    boot_na: dict
    intervals: dict
    level: float
    n_boot: int
    seed: int
    rule: str
    points: int
    n_test: int
    n_reference: int
    values: np.ndarray = field(repr=False)

    def interval(self, estimator: str = "est.f2", kind: str = "percentile") -> tuple[float, float]:
        if estimator not in ESTIMATORS or kind not in INTERVALS:
            raise AnalysisError(f"interval {estimator!r}, {kind!r}: expected an estimator of {', '.join(ESTIMATORS)} "
                                f"and an interval of {', '.join(INTERVALS)}")
        return self.intervals[(estimator, kind)]

    def similar(self, estimator: str = "est.f2", kind: str = "percentile") -> bool | None:
        """The lower bound of the interval at or above 50; None when it is not computable."""
        lo = self.interval(estimator, kind)[0]
        return None if not math.isfinite(lo) else lo >= 50.0

    def to_dict(self) -> dict:
        clean = (lambda v: None if not math.isfinite(v) else float(v))
        return {"rule": self.rule, "n_boot": self.n_boot, "seed": self.seed, "level": self.level,
                "points": self.points, "n_test": self.n_test, "n_reference": self.n_reference,
                "estimators": {e: {"estimate": clean(self.estimates[e]), "boot_mean": clean(self.boot_mean[e]),
                                   "boot_median": clean(self.boot_median[e]), "boot_na": self.boot_na[e],
                                   "intervals": {k: [clean(x) for x in self.intervals[(e, k)]] for k in INTERVALS}}
                               for e in ESTIMATORS}}


def bootstrap_f2(test: ReplicateSet, reference: ReplicateSet, rule: str | Rule = "ema", *,
                 n_boot: int = DEFAULT_N_BOOT, seed: int = DEFAULT_SEED, alpha: float = 0.05,
                 min_points: int = MIN_POINTS, both_tr_85: bool = False, cutoff_pct: float = CUTOFF_PCT) -> BootstrapF2:
    """The bootstrap of the five f2 estimators with normal, basic, percentile and BCa intervals.

    Parameters
    ----------
    test, reference : ReplicateSet
        At least 2 units each, the same time points.
    rule : str or Rule
        Chooses the points in every sample (the 85 % cut; the CV rule is not applied, as in bootf2).
    n_boot : int
        Bootstrap samples, >= 100.
    seed : int
        R's ``set.seed`` value: the same seed draws the same samples as bootf2 (default 306, bootf2's).
    alpha : float
        One-sided error; the intervals are two-sided at 1 - 2 alpha.
    min_points : int
        An estimator is undefined in a sample with fewer points (bootf2's ``min.points``).
    both_tr_85 : bool
        The conventional reading of the FDA's 85 % sentence (fda only).

    Returns
    -------
    BootstrapF2

    Raises
    ------
    AnalysisError
        Fewer than 2 units in a set, different time points, a bad setting.
    """
    rule = rule if isinstance(rule, Rule) else get_rule(rule)
    if both_tr_85 and rule.name != "fda":
        raise AnalysisError(f"both_tr_85 applies to the fda rule only, not to {rule.name}")
    if int(n_boot) < 100:
        raise AnalysisError(f"n_boot={n_boot!r}; use at least 100 bootstrap samples")
    if not 0 < alpha < 0.5:
        raise AnalysisError(f"alpha={alpha!r} must lie in (0, 0.5)")
    ut, ur = _units(test, reference)
    nt, nr = ut.shape[0], ur.shape[0]
    n_boot = int(n_boot)

    def estimate(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        mt, mr, vt, vr = _stats(a, b)
        if mt.ndim == 1:
            mt, mr, vt, vr = mt[None], mr[None], vt[None], vr[None]
        used = np.atleast_1d(points_used(mt, mr, rule.cut, both_tr_85=both_tr_85, cutoff_pct=cutoff_pct))
        return _estimators(mt, mr, vt, vr, a.shape[-2], b.shape[-2], used, min_points)

    original = estimate(ut, ur)[0]
    mt0, mr0 = ut.mean(axis=0), ur.mean(axis=0)
    points = int(points_used(mt0, mr0, rule.cut, both_tr_85=both_tr_85, cutoff_pct=cutoff_pct))
    sampler = RSampler(seed)
    it = sampler.sample_int(nt, n_boot * nt).reshape(nt, n_boot).T - 1  # R fills bt.array by columns
    ir = sampler.sample_int(nr, n_boot * nr).reshape(nr, n_boot).T - 1
    values = np.empty((n_boot, len(ESTIMATORS)))
    for start in range(0, n_boot, 2000):
        sl = slice(start, start + 2000)
        values[sl] = estimate(ut[it[sl]], ur[ir[sl]])
    # acceleration: jackknife over every unit of both products (bootf2's "nt+nr")
    jack = np.array([estimate(np.delete(ut, i, axis=0), ur)[0] for i in range(nt)]
                    + [estimate(ut, np.delete(ur, j, axis=0))[0] for j in range(nr)])
    # acceleration: regression of the bootstrap values on the resampling frequencies
    freq = np.zeros((n_boot, nt + nr))
    np.add.at(freq, (np.repeat(np.arange(n_boot), nt), it.ravel()), 1.0 / nt)
    np.add.at(freq, (np.repeat(np.arange(n_boot), nr), nt + ir.ravel()), 1.0 / nr)
    design = np.delete(freq, [0, nt], axis=1)
    group = np.r_[np.zeros(nt, int), np.ones(nr, int)]
    z = norm.ppf(1.0 - alpha)
    intervals, boot_mean, boot_median, boot_na = {}, {}, {}, {}
    for k, name in enumerate(ESTIMATORS):
        f2, boot = float(original[k]), values[:, k]
        finite = np.sort(boot[np.isfinite(boot)])
        boot_na[name] = int(n_boot - finite.size)
        boot_mean[name] = float(finite.mean()) if finite.size else math.nan
        boot_median[name] = float(np.median(finite)) if finite.size else math.nan
        nan2 = (math.nan, math.nan)
        if finite.size < 2 or not math.isfinite(f2):
            for kind in INTERVALS:
                intervals[(name, kind)] = nan2
            continue
        sd = float(finite.std(ddof=1))
        intervals[(name, "normal")] = (float(2 * f2 - boot_mean[name] - sd * z), float(2 * f2 - boot_mean[name] + sd * z))
        hi_q, lo_q = _quantile_normal_scale(finite, [1.0 - alpha, alpha])
        intervals[(name, "basic")] = (float(2 * f2 - hi_q), float(2 * f2 - lo_q))
        lo, hi = _quantile_normal_scale(finite, [alpha, 1.0 - alpha])
        intervals[(name, "percentile")] = (float(lo), float(hi))
        intervals[(name, "bca")] = _bca(boot, f2, _acceleration(jack[:, k]), alpha)
        ok = np.isfinite(boot)
        x = np.column_stack([np.ones(int(ok.sum())), design[ok]])
        beta = np.linalg.lstsq(x, boot[ok], rcond=None)[0][1:]
        lvec = np.insert(beta, [0, nt - 1], 0.0)
        lvec = lvec - np.array([lvec[group == g].mean() for g in (0, 1)])[group]
        den = 6.0 * np.sum(lvec ** 2) ** 1.5
        intervals[(name, "bca.boot")] = _bca(boot, f2, float(np.sum(lvec ** 3) / den) if den > 0 else 0.0, alpha)
    return BootstrapF2(dict(zip(ESTIMATORS, (float(v) for v in original))), boot_mean, boot_median, boot_na,
                       intervals, 1.0 - 2.0 * alpha, n_boot, int(seed), rule.name, points, nt, nr, values)
