"""Release-profile metrics of dissolution testing: f1/f2 of two curves with the regulatory time-point rules,
mean dissolution time (MDT) and dissolution efficiency (DE). Replicate units, the regulators' CV rules, the
bootstrap of f2 and the multivariate tests are in :mod:`analysis.replicates`, :mod:`analysis.regulatory`,
:mod:`analysis.bootstrap` and :mod:`analysis.msd`.

Definitions (Moore and Flanner 1996; FDA guidance "Dissolution testing of immediate release solid oral
dosage forms", 1997; EMA "Guideline on the investigation of bioequivalence", 2010, appendix I; Costa and
Sousa Lobo 2001, "Modeling and comparison of dissolution profiles", Eur. J. Pharm. Sci. 13:123):

- with R_j, T_j the percent released of the reference and the test at n common time points,
  f1 = 100 sum|R_j - T_j| / sum R_j  and  f2 = 50 log10(100 / sqrt(1 + sum (R_j - T_j)^2 / n));
  f2 >= 50 (an average difference of at most about 10 %) is read as "similar";
- both curves are expressed in percent of the reference's total (its weighed mass when known, else its
  final value), at the same time points, time zero excluded, at most one point after 85 % released in
  either curve (EMA and FDA; ``rule="reference"``: in the reference, the WHO's; ``rule="both"``: in both,
  the conventional reading of the FDA text), and at least 3 points (:mod:`analysis.regulatory` holds each
  regulator's rule with its CV limits, for replicate units);
- MDT = sum t_mid,j dM_j / sum dM_j and DE(T) = int_0^T M dt / (M_total T), both from the piecewise
  linear curve through the samples, joined to (0, 0) when it starts after time 0; an amount already
  released at time 0 is a burst at time 0 (it enters sum dM_j with t = 0, and the area of DE).

When the rules leave too few points, :func:`similarity` returns a result whose ``reason`` says why and
whose f1/f2 are None.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from analysis.errors import AnalysisError

CUTOFF_PCT = 85.0
"""Percent released after which at most one time point may enter f1/f2."""
MIN_POINTS = 3
"""Fewest time points f1/f2 may use."""
SIMILAR_F2 = 50.0
"""f2 at or above which two profiles are called similar."""
MAX_SAMPLED_POINTS = 30
"""A curve with at most this many samples is a sampled dissolution test: its own times are the f2 points."""
GRID_POINTS = 8
"""Time points aimed for up to the reference's 85 % time when both curves are densely sampled."""
DECREASE_TOLERANCE = 0.02
"""Largest drop of a cumulative curve below its running maximum accepted as noise, fraction of its maximum."""
RULES = ("either", "both", "reference")
_NICE_STEPS_S = (1, 2, 5, 10, 15, 20, 30, 60, 120, 300, 600, 900, 1200, 1800, 3600, 7200, 10800, 21600, 43200)


@dataclass(frozen=True, eq=False)
class ReleaseProfile:
    """A cumulative release curve with its units, checked on construction.

    Attributes
    ----------
    t : (N,) ndarray of float
        Strictly increasing sample times, in ``time_unit``.
    released : (N,) ndarray of float
        Cumulative amount released, in ``amount_unit``; may dip below its running maximum by at most
        ``DECREASE_TOLERANCE`` of its maximum (measurement noise).
    time_unit, amount_unit : str
        E.g. ``"s"`` and ``"g"`` (physical) or ``"mm"`` and ``"mm3"`` (simulation).
    total : float or None
        The amount that is 100 % (the weighed mass), in ``amount_unit``; default the final value.
    label : str
        Named in error messages.

    Raises
    ------
    AnalysisError
        Shapes, NaN/infinite values, non-increasing times, a decreasing curve, or a non-positive total.
    """

    t: np.ndarray
    released: np.ndarray
    time_unit: str = "s"
    amount_unit: str = "g"
    total: float | None = None
    label: str = "curve"

    def __post_init__(self) -> None:
        t = np.array(self.t, dtype=float)
        m = np.array(self.released, dtype=float)
        name = self.label
        if t.ndim != 1 or t.shape != m.shape:
            raise AnalysisError(f"{name}: times {t.shape} and amounts {m.shape} must be 1-D of equal length")
        if t.size < 2:
            raise AnalysisError(f"{name}: {t.size} samples; a release curve needs at least 2")
        for what, values in (("time", t), ("released amount", m)):
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                raise AnalysisError(f"{name}: sample {bad[0]}: {what} = {values[bad[0]]} is not a finite number")
        steps = np.flatnonzero(np.diff(t) <= 0)
        if steps.size:
            i = int(steps[0]) + 1
            raise AnalysisError(f"{name}: sample {i}: time {t[i]:g} {self.time_unit} does not increase "
                                f"(sample {i - 1} has {t[i - 1]:g}); times must increase strictly")
        peak = float(np.max(np.abs(m)))
        drop = np.maximum.accumulate(m) - m
        if peak > 0 and drop.max() > DECREASE_TOLERANCE * peak:
            i = int(np.argmax(drop > DECREASE_TOLERANCE * peak))
            raise AnalysisError(f"{name}: sample {i}: released {m[i]:.6g} {self.amount_unit} at t = {t[i]:g} "
                                f"{self.time_unit} is {drop[i]:.4g} below an earlier value; a cumulative release "
                                f"curve must not decrease by more than {DECREASE_TOLERANCE:.0%} of its maximum")
        if self.total is not None and not (math.isfinite(self.total) and self.total > 0):
            raise AnalysisError(f"{name}: total {self.total!r} {self.amount_unit} must be a positive number")
        t.flags.writeable = False
        m.flags.writeable = False
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "released", m)

    @property
    def amount_total(self) -> float:
        """The amount that is 100 %: ``total`` if given, else the final value, in ``amount_unit``."""
        return float(self.total) if self.total is not None else float(self.released[-1])

    def at(self, times: np.ndarray) -> np.ndarray:
        """Linear interpolation of the curve at ``times`` (inside its time span), in ``amount_unit``."""
        return np.interp(times, self.t, self.released)


@dataclass(frozen=True, eq=False)
class Similarity:
    """f1 and f2 of a test profile against a reference, with the points they came from.

    Attributes
    ----------
    f1, f2 : float or None
        Difference and similarity factors; None when the rules cannot be met (see ``reason``).
    times : (n,) ndarray of float
        Time points used, in the curves' time unit.
    reference_pct, test_pct : (n,) ndarray of float, %
        Both curves at ``times``, in percent of the reference's total.
    reason : str or None
        Why f1/f2 are not reported.
    notes : tuple of str
        How the points were chosen (interpolation, exclusions).
    """

    f1: float | None
    f2: float | None
    times: np.ndarray
    reference_pct: np.ndarray
    test_pct: np.ndarray
    reason: str | None = None
    notes: tuple[str, ...] = ()

    @property
    def points_used(self) -> int:
        """Number of time points in f1/f2."""
        return int(self.times.size)

    @property
    def similar(self) -> bool | None:
        """f2 >= 50, or None when f2 is not reported."""
        return None if self.f2 is None else self.f2 >= SIMILAR_F2


def f1_f2(reference_pct: np.ndarray, test_pct: np.ndarray) -> tuple[float, float]:
    """f1 and f2 of two profiles already on common points (no rules applied).

    Parameters
    ----------
    reference_pct, test_pct : (n,) or (B, n) ndarray of float, %
        Percent released at the same n time points (rows of a batch are independent profiles).

    Returns
    -------
    f1, f2 : float or (B,) ndarray of float
    """
    r = np.asarray(reference_pct, dtype=float)
    d = np.asarray(test_pct, dtype=float) - r
    f1 = 100.0 * np.abs(d).sum(axis=-1) / r.sum(axis=-1)
    f2 = 50.0 * np.log10(100.0 / np.sqrt(1.0 + np.mean(d * d, axis=-1)))
    return f1, f2


def _check_pair(reference: ReleaseProfile, test: ReleaseProfile) -> tuple[float, float]:
    """Same units and a common time span; return that span."""
    if (reference.time_unit, reference.amount_unit) != (test.time_unit, test.amount_unit):
        raise AnalysisError(f"{reference.label} is in {reference.time_unit} and {reference.amount_unit} but "
                            f"{test.label} in {test.time_unit} and {test.amount_unit}; compare curves in the same "
                            f"units (convert simulation units with a calibration first)")
    lo, hi = max(reference.t[0], test.t[0]), min(reference.t[-1], test.t[-1])
    if lo >= hi:
        raise AnalysisError(f"{reference.label} ({reference.t[0]:g}..{reference.t[-1]:g} {reference.time_unit}) and "
                            f"{test.label} ({test.t[0]:g}..{test.t[-1]:g} {test.time_unit}) do not overlap in time")
    return float(lo), float(hi)


def _reference_total(reference: ReleaseProfile, total: float | None) -> float:
    m = reference.amount_total if total is None else float(total)
    if not (math.isfinite(m) and m > 0):
        raise AnalysisError(f"{reference.label}: the reference releases {m:g} {reference.amount_unit} in total; "
                            f"percent released needs a reference with a positive release")
    return m


def _nice_step(span: float, time_unit: str) -> float:
    """A round step near span / GRID_POINTS (minutes and hours for seconds, 1-2-5 otherwise)."""
    raw = span / GRID_POINTS
    if time_unit == "s" and _NICE_STEPS_S[0] <= raw <= _NICE_STEPS_S[-1]:
        candidates = np.array(_NICE_STEPS_S, dtype=float)
    else:
        decade = 10.0 ** math.floor(math.log10(raw))
        candidates = decade * np.array([0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0])
    return float(candidates[np.argmin(np.abs(np.log(candidates / raw)))])


def _time_points(reference: ReleaseProfile, test: ReleaseProfile, span: tuple[float, float],
                 total: float, cutoff_pct: float) -> tuple[np.ndarray, str]:
    lo, hi = span
    sparse = min((reference, test), key=lambda p: p.t.size)
    if sparse.t.size <= MAX_SAMPLED_POINTS:
        other = test if sparse is reference else reference
        inside = sparse.t[(sparse.t >= lo) & (sparse.t <= hi)]
        if other.t.shape == sparse.t.shape and np.allclose(other.t, sparse.t, rtol=0, atol=1e-9 * abs(hi)):
            return inside, "both curves share their time points"
        return inside, (f"{other.label} interpolated linearly onto the {inside.size} time points of "
                        f"{sparse.label} inside the common span")
    pct = 100.0 * reference.released / total
    reached = np.flatnonzero(pct >= cutoff_pct)
    t_cut = min(float(reference.t[reached[0]]) if reached.size else hi, hi)
    start = max(lo, 0.0)
    step = _nice_step((t_cut if t_cut > start else hi) - start, reference.time_unit)
    times = np.arange(1, int(math.floor(hi / step + 1e-9)) + 1) * step
    times = times[times >= lo]
    return times, (f"both curves interpolated linearly onto a regular grid every {step:g} {reference.time_unit} "
                   f"(both are densely sampled)")


def sampling_times(reference: ReleaseProfile, test: ReleaseProfile, *, reference_total: float | None = None,
                   cutoff_pct: float = CUTOFF_PCT) -> tuple[np.ndarray, str]:
    """The time points f2 is computed on when none are given, before any rule cuts them, and how they
    were chosen: the samples of the sparser curve when it has at most ``MAX_SAMPLED_POINTS`` (a sampled
    dissolution test), else a regular grid of round steps with about ``GRID_POINTS`` points up to the
    reference's 85 % time, over the common span. Points at time zero or before are left out.

    Raises
    ------
    AnalysisError
        Different units, no common time span, a reference with no release.
    """
    span = _check_pair(reference, test)
    total = _reference_total(reference, reference_total)
    pts, how = _time_points(reference, test, span, total, cutoff_pct)
    return pts[pts > 0], how


def similarity(reference: ReleaseProfile, test: ReleaseProfile, *, times: Sequence[float] | None = None,
               reference_total: float | None = None, cutoff_pct: float = CUTOFF_PCT,
               rule: str = "either") -> Similarity:
    """f1 and f2 of ``test`` against ``reference`` under the regulatory time-point rules.

    Parameters
    ----------
    reference, test : ReleaseProfile
        Same units, overlapping in time.
    times : sequence of float, optional
        Time points to use (both curves interpolated onto them). Default: the points of the sparser curve
        when it has at most ``MAX_SAMPLED_POINTS`` samples (the other curve interpolated onto them unless
        it has the same points); else, for two densely sampled curves, a regular grid of round steps with
        about ``GRID_POINTS`` points up to the reference's 85 % time.
    reference_total : float, optional
        The reference's 100 % (weighed mass), in its amount unit; default ``reference.amount_total``.
    cutoff_pct : float
        At most one point after this percent released (default 85).
    rule : {"either", "both", "reference"}
        The point after the cut-off is the first at which either curve (EMA, FDA, Canada, ANVISA), the
        reference (WHO), or both curves (the conventional reading of the FDA text) exceed it.

    Returns
    -------
    Similarity

    Raises
    ------
    AnalysisError
        Different units, no common time span, a reference with no release, bad ``times`` or ``rule``.
    """
    if rule not in RULES:
        raise AnalysisError(f"rule={rule!r}; expected one of {', '.join(RULES)}")
    if not 0 < cutoff_pct <= 100:
        raise AnalysisError(f"cutoff_pct={cutoff_pct!r} must lie in (0, 100]")
    span = _check_pair(reference, test)
    total = _reference_total(reference, reference_total)
    notes = []
    if times is None:
        pts, how = _time_points(reference, test, span, total, cutoff_pct)
    else:
        pts = np.asarray(times, dtype=float)
        if pts.ndim != 1 or not np.all(np.isfinite(pts)) or np.any(np.diff(pts) <= 0):
            raise AnalysisError(f"times must be finite and strictly increasing, got {list(np.ravel(pts))}")
        inside = (pts >= span[0]) & (pts <= span[1])
        if not inside.all():
            notes.append(f"{int((~inside).sum())} requested time points outside the common span "
                         f"{span[0]:g}..{span[1]:g} {reference.time_unit} dropped")
        pts = pts[inside]
        how = f"both curves interpolated linearly onto the {pts.size} requested time points"
    notes.append(how)
    if np.any(pts <= 0):
        notes.append(f"{int((pts <= 0).sum())} point(s) at time zero or before excluded")
        pts = pts[pts > 0]
    ref_pct = 100.0 * reference.at(pts) / total
    test_pct = 100.0 * test.at(pts) / total
    if rule == "either":
        over = (ref_pct > cutoff_pct) | (test_pct > cutoff_pct)
    elif rule == "reference":
        over = ref_pct > cutoff_pct
    else:
        over = (ref_pct > cutoff_pct) & (test_pct > cutoff_pct)
    if over.any():
        last = int(np.flatnonzero(over)[0])
        if last + 1 < pts.size:
            which = {"either": "either curve", "reference": "the reference", "both": "both curves"}[rule]
            notes.append(f"{pts.size - last - 1} point(s) after the first point above {cutoff_pct:g} % in {which} "
                         f"dropped")
        pts, ref_pct, test_pct = pts[:last + 1], ref_pct[:last + 1], test_pct[:last + 1]
    if not (100.0 * reference.at(span[1]) / total >= cutoff_pct):
        notes.append(f"the reference never reaches {cutoff_pct:g} % in the common span; "
                     f"all points up to {span[1]:g} {reference.time_unit} are used")
    reason = None
    if pts.size < MIN_POINTS:
        if pts.size and ref_pct[0] > cutoff_pct and test_pct[0] > cutoff_pct:
            reason = (f"both curves exceed {cutoff_pct:g} % at the first time point ({pts[0]:g} "
                      f"{reference.time_unit}): f2 does not apply (very rapid release in both)")
        else:
            reason = (f"only {pts.size} usable time point(s) under the rules; f1/f2 need at least {MIN_POINTS}")
    if reason is not None:
        return Similarity(None, None, pts, ref_pct, test_pct, reason, tuple(notes))
    f1, f2 = f1_f2(ref_pct, test_pct)
    return Similarity(float(f1), float(f2), pts, ref_pct, test_pct, None, tuple(notes))


def mean_profile(curves: Sequence[ReleaseProfile], label: str = "mean") -> ReleaseProfile:
    """The mean of replicate curves over their common time span.

    Parameters
    ----------
    curves : sequence of ReleaseProfile
        Same units; each interpolated linearly onto the union of their sample times inside the span.
    label : str

    Returns
    -------
    ReleaseProfile
        Mean amounts, with the mean of the curves' totals as its total.
    """
    curves = list(curves)
    if not curves:
        raise AnalysisError("a mean profile needs at least one curve")
    for curve in curves[1:]:
        _check_pair(curves[0], curve)
    lo = max(c.t[0] for c in curves)
    hi = min(c.t[-1] for c in curves)
    if lo >= hi:
        raise AnalysisError(f"the replicate curves {', '.join(c.label for c in curves)} have no time span in common")
    grid = np.unique(np.concatenate([c.t for c in curves]))
    grid = grid[(grid >= lo) & (grid <= hi)]
    values = np.array([c.at(grid) for c in curves]).mean(axis=0)
    total = float(np.mean([c.amount_total for c in curves]))
    return ReleaseProfile(grid, values, curves[0].time_unit, curves[0].amount_unit, total, label)


def _from_zero(profile: ReleaseProfile, until: float | None) -> tuple[np.ndarray, np.ndarray]:
    """The piecewise linear curve from time 0 to ``until`` (default its last time); a curve that starts
    after time 0 is joined to (0, 0)."""
    t, m = profile.t, profile.released
    end = float(t[-1]) if until is None else float(until)
    if not (math.isfinite(end) and 0 < end <= t[-1]):
        raise AnalysisError(f"{profile.label}: until = {until!r} {profile.time_unit} must lie in "
                            f"(0, {t[-1]:g}], the curve's span")
    inside = (t > 0) & (t < end)
    start = float(np.interp(0.0, t, m)) if t[0] <= 0 else 0.0
    tt = np.concatenate([[0.0], t[inside], [end]])
    mm = np.concatenate([[start], m[inside], [float(np.interp(end, t, m))]])
    return tt, mm


def mean_dissolution_time(profile: ReleaseProfile, *, until: float | None = None) -> float:
    """Mean dissolution time, MDT = sum t_mid,j dM_j / sum dM_j (Costa and Sousa Lobo 2001, eq. 16).

    Parameters
    ----------
    profile : ReleaseProfile
        Released amount; a curve that starts after time 0 is joined linearly to (0, 0); an amount already
        released at time 0 (a burst) counts as released at time 0.
    until : float, optional
        Use the curve up to this time (default: its end), in ``profile.time_unit``.

    Returns
    -------
    float
        MDT in ``profile.time_unit``: the mean time at which the amount released by ``until`` left.

    Examples
    --------
    Half released at once, the other half evenly over 10 min: MDT = (0 x 50 + 5 x 50) / 100 = 2.5 min.

    >>> round(mean_dissolution_time(ReleaseProfile([0.0, 10.0], [50.0, 100.0], "min", "%")), 6)
    2.5
    >>> round(mean_dissolution_time(ReleaseProfile([1e-9, 10.0], [50.0, 100.0], "min", "%")), 6)
    2.5

    Raises
    ------
    AnalysisError
        ``until`` outside the curve, or nothing released by ``until``.
    """
    t, m = _from_zero(profile, until)
    dm = np.diff(m)
    # an amount already out at t = 0 (m[0], a burst) left at time 0: it adds nothing to the sum of
    # t dM and all of itself to the sum of dM, so that a first sample at t = 0 and one at t -> 0+
    # (joined linearly to (0, 0)) give the same MDT
    released = float(m[-1])
    if not released > 0:
        raise AnalysisError(f"{profile.label}: nothing released by {t[-1]:g} {profile.time_unit}; MDT is undefined")
    return float(np.sum(0.5 * (t[1:] + t[:-1]) * dm) / released)


def dissolution_efficiency(profile: ReleaseProfile, *, until: float | None = None) -> float:
    """Dissolution efficiency, DE(T) = int_0^T M dt / (M_total T) in percent (Khan 1975).

    Parameters
    ----------
    profile : ReleaseProfile
        Its ``amount_total`` is 100 %.
    until : float, optional
        T, in ``profile.time_unit`` (default: the curve's end).

    Returns
    -------
    float, %
        The area under the curve up to T as a percent of the rectangle of complete release.
    """
    t, m = _from_zero(profile, until)
    total = profile.amount_total
    if not total > 0:
        raise AnalysisError(f"{profile.label}: total release {total:g} {profile.amount_unit}; DE needs a positive total")
    area = float(np.sum(0.5 * (m[1:] + m[:-1]) * np.diff(t)))
    return 100.0 * area / (total * t[-1])
