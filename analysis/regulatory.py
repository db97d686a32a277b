"""The regulators' rules for comparing dissolution profiles with f2, one declaration per regulator.

Every guideline asks for the same time points in both products (time zero excluded), at least three of
them, 12 units per product, and at most one mean value above 85 % dissolved; they differ in which curve
the 85 % cut follows, in which points count as "early" for the coefficient of variation (at most 20 % there,
at most 10 % at the other points), and in what follows when the CV rule is not met. The rules are read
as the R package bootf2 (Xu and Zhang, ``calcf2``) reads them, and named as it names them:

======  ==================================  ===========================  ================  ==========
rule    85 % cut                            early points (CV <= 20 %)    CV not met        guideline
======  ==================================  ===========================  ================  ==========
ema     first point > 85 % in either mean   up to 10 min                 f2 refused        EMA 2010
fda     first point > 85 % in either mean   up to 15 min                 warning           FDA 1997
who     first point > 85 % in the reference up to 10 min                 f2 refused        WHO 2017
canada  first point > 85 % in either mean   up to 10 min                 f2 refused        HC 2018
anvisa  first point > 85 % in either mean   the first 40 % of the points f2 refused        ANVISA 2010
======  ==================================  ===========================  ================  ==========

The FDA's sentence "only one measurement should be considered after 85 % dissolution of both the
products" was long read as "up to the first point where both exceed 85 %"; bootf2 reports the FDA's own
reading (the same as the EMA's) and keeps the old one behind ``both_tr_85`` to check published values.

When fewer than three points remain and both means (for Canada every unit) exceed 85 % by 15 min, the
profiles are similar without f2 (rapidly dissolving immediate-release products); otherwise f2 is refused.
A set of a single curve (mean only) cannot be checked for CV: f2 is given with a warning that says so.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from analysis.errors import AnalysisError
from analysis.profile import CUTOFF_PCT, MIN_POINTS, f1_f2
from analysis.replicates import ReplicateSet, check_same_times

UNITS_REQUIRED = 12
"""Units per product the guidelines ask for."""
CV_EARLY_PCT = 20.0
"""Largest CV at the early time points, %."""
CV_LATE_PCT = 10.0
"""Largest CV at the other time points, %."""
RAPID_MIN = 15.0
"""Both products above 85 % by this time (min): similar without f2."""
CV_DIGITS = 2
"""CVs are rounded to this many decimals before the limits are applied (as bootf2 does)."""


@dataclass(frozen=True)
class Rule:
    """One regulator's f2 rule.

    Attributes
    ----------
    name : str
        ``ema``, ``fda``, ``who``, ``canada`` or ``anvisa``.
    agency : str
    cut : {"either", "reference"}
        The last point used is the first at which either mean (or the reference mean) exceeds 85 %.
    early_until_min : float or None
        Points at or before this time (min) are early (CV <= 20 %).
    early_fraction : float or None
        Else the first ``floor(fraction * n_points)`` points are early (ANVISA: 40 %).
    cv_fail : {"refuse", "warn"}
        What happens when a CV limit is exceeded.
    source : str
        The guideline the rule comes from.
    """

    name: str
    agency: str
    cut: str
    early_until_min: float | None
    early_fraction: float | None
    cv_fail: str
    source: str

    def early_text(self) -> str:
        if self.early_until_min is not None:
            return f"points up to {self.early_until_min:g} min"
        return f"the first {self.early_fraction:.0%} of the points"


RULES = {
    "ema": Rule("ema", "EMA", "either", 10.0, None, "refuse",
                "EMA, Guideline on the investigation of bioequivalence, CPMP/EWP/QWP/1401/98 Rev. 1 (2010), "
                "Appendix I"),
    "fda": Rule("fda", "FDA", "either", 15.0, None, "warn",
                "U.S. FDA, Guidance for Industry: Dissolution testing of immediate release solid oral dosage "
                "forms (1997); SUPAC-IR (1995)"),
    "who": Rule("who", "WHO", "reference", 10.0, None, "refuse",
                "WHO, Multisource (generic) pharmaceutical products: guidelines on registration requirements to "
                "establish interchangeability, TRS 1003 Annex 6 (2017)"),
    "canada": Rule("canada", "Health Canada", "either", 10.0, None, "refuse",
                   "Health Canada, Guidance Document: Use of a foreign-sourced reference product as a Canadian "
                   "reference product (2017)"),
    "anvisa": Rule("anvisa", "ANVISA", "either", None, 0.4, "refuse",
                   "ANVISA, RDC 31/2010: pharmaceutical equivalence studies and comparative dissolution profile "
                   "(2010)"),
}
"""The rules by name, as bootf2's ``regulation`` names them (lower case)."""
RULE_NAMES = tuple(RULES)


@dataclass(frozen=True, eq=False)
class RuleCheck:
    """A pair of replicate sets checked against one rule, with f1/f2 when the rule allows it.

    Attributes
    ----------
    rule : Rule
    times : (T,) ndarray of float
        All time points after time zero, in the sets' time unit.
    used : int
        The first ``used`` points enter f2 (the 85 % rule).
    test_mean, reference_mean, test_cv, reference_cv : (T,) ndarray of float, %
    early : int
        The first ``early`` points are held to the 20 % CV limit, the rest of the used ones to 10 %.
    cv_failures : tuple of str
        Each point and product whose CV exceeds its limit.
    f1, f2 : float or None
        On the means at the used points; None when refused.
    refused : str or None
        Why the rule does not allow f2.
    similar_without_f2 : bool
        Both products dissolve more than 85 % by 15 min with fewer than 3 points: similar, no f2 needed.
    warnings : tuple of str
    """

    rule: Rule
    times: np.ndarray
    used: int
    test_mean: np.ndarray
    reference_mean: np.ndarray
    test_cv: np.ndarray
    reference_cv: np.ndarray
    early: int
    cv_failures: tuple[str, ...]
    f1: float | None
    f2: float | None
    refused: str | None
    similar_without_f2: bool
    warnings: tuple[str, ...]
    n_test: int
    n_reference: int

    @property
    def used_times(self) -> np.ndarray:
        return self.times[:self.used]

    @property
    def similar(self) -> bool | None:
        """f2 >= 50 (True also when similar without f2); None when f2 is refused."""
        if self.similar_without_f2:
            return True
        return None if self.f2 is None else self.f2 >= 50.0

    def to_dict(self) -> dict:
        return {"rule": self.rule.name, "agency": self.rule.agency, "source": self.rule.source,
                "times": self.times.tolist(), "points_used": self.used, "early_points": self.early,
                "test_mean": self.test_mean.tolist(), "reference_mean": self.reference_mean.tolist(),
                "test_cv": self.test_cv.tolist(), "reference_cv": self.reference_cv.tolist(),
                "cv_failures": list(self.cv_failures), "f1": self.f1, "f2": self.f2, "similar": self.similar,
                "refused": self.refused, "similar_without_f2": self.similar_without_f2,
                "warnings": list(self.warnings), "n_test": self.n_test, "n_reference": self.n_reference}


def get_rule(name: str) -> Rule:
    """The rule called ``name`` (case-insensitive)."""
    rule = RULES.get(str(name).lower())
    if rule is None:
        raise AnalysisError(f"rule {name!r}; expected one of {', '.join(RULE_NAMES)}")
    return rule


def points_used(test_mean: np.ndarray, reference_mean: np.ndarray, cut: str, *, both_tr_85: bool = False,
                cutoff_pct: float = CUTOFF_PCT) -> np.ndarray:
    """How many leading points the 85 % rule keeps, for one pair or a batch of mean profiles.

    Parameters
    ----------
    test_mean, reference_mean : (T,) or (B, T) ndarray of float, %
        Means at the points after time zero.
    cut : {"either", "reference"}
        The last point kept is the first where either mean (or the reference mean) exceeds ``cutoff_pct``.
    both_tr_85 : bool
        The conventional reading of the FDA text: the first point where both exceed it.

    Returns
    -------
    int or (B,) ndarray of int
        All points when no point exceeds the cut-off.
    """
    t, r = np.asarray(test_mean, dtype=float), np.asarray(reference_mean, dtype=float)
    if both_tr_85:
        over = (t > cutoff_pct) & (r > cutoff_pct)
    elif cut == "reference":
        over = r > cutoff_pct
    else:
        over = (t > cutoff_pct) | (r > cutoff_pct)
    n = over.shape[-1]
    first = np.where(over.any(axis=-1), np.argmax(over, axis=-1) + 1, n)
    return first if first.ndim else int(first)


def _early_count(rule: Rule, times_min: np.ndarray, used: int) -> int:
    if rule.early_until_min is not None:
        return int(np.sum(times_min[:used] <= rule.early_until_min + 1e-9))
    k = int(math.floor(times_min.size * rule.early_fraction))
    if k == 0:
        return 0
    return int(np.sum(times_min[:used] <= times_min[k - 1] + 1e-9))


def _rapid(test: ReplicateSet, reference: ReplicateSet, rule: Rule, cutoff_pct: float) -> bool:
    """Both products above 85 % at the last point at or before 15 min (Canada: every unit)."""
    early = np.flatnonzero(test.times_min <= RAPID_MIN + 1e-9)
    if not early.size:
        return False
    i = int(early[-1])
    if rule.name == "canada":
        return bool(np.all(test.units[:, i] > cutoff_pct) and np.all(reference.units[:, i] > cutoff_pct))
    return bool(test.mean[i] > cutoff_pct and reference.mean[i] > cutoff_pct)


def check_rule(test: ReplicateSet, reference: ReplicateSet, rule: str | Rule = "ema", *, both_tr_85: bool = False,
               cutoff_pct: float = CUTOFF_PCT, min_points: int = MIN_POINTS) -> RuleCheck:
    """Apply one regulator's rule to a test and a reference set and compute f2 where it allows.

    Parameters
    ----------
    test, reference : ReplicateSet
        Same time points and time unit; points at time zero are dropped.
    rule : str or Rule
        One of ``RULE_NAMES``.
    both_tr_85 : bool
        The conventional (not the FDA's own) reading of the 85 % rule, for checks against old literature;
        only with ``rule="fda"``.
    cutoff_pct, min_points
        The 85 % and the three-point rules.

    Returns
    -------
    RuleCheck

    Raises
    ------
    AnalysisError
        Sets at different time points, an unknown rule, ``both_tr_85`` with another rule.
    """
    rule = rule if isinstance(rule, Rule) else get_rule(rule)
    if both_tr_85 and rule.name != "fda":
        raise AnalysisError(f"both_tr_85 (the conventional reading of the FDA's 85 % sentence) applies to the fda "
                            f"rule only, not to {rule.name}")
    check_same_times(test, reference)
    test, reference = test.without_time_zero(), reference.without_time_zero()
    if test.times.size == 0:
        raise AnalysisError(f"{test.label}: no time point after time zero")
    times, times_min = test.times, test.times_min
    mt, mr = test.mean, reference.mean
    cvt, cvr = test.cv_pct, reference.cv_pct
    used = points_used(mt, mr, rule.cut, both_tr_85=both_tr_85, cutoff_pct=cutoff_pct)
    early = _early_count(rule, times_min, used)
    warnings = []
    if both_tr_85:
        warnings.append("points up to the first at which both products exceed 85 %: the conventional reading of "
                        "the FDA text, not the FDA's own; for checks against published values only")
    failures = []
    checkable = test.n_units > 1 and reference.n_units > 1
    if checkable:
        for i in range(used):
            limit = CV_EARLY_PCT if i < early else CV_LATE_PCT
            for name, cv in ((test.label, cvt), (reference.label, cvr)):
                if round(float(cv[i]), CV_DIGITS) > limit:
                    failures.append(f"{name} CV {cv[i]:.2f} % at {times[i]:g} {test.time_unit} exceeds {limit:g} %")
    else:
        warnings.append("CV not checked: only mean profiles were given (the guidelines ask for "
                        f"{UNITS_REQUIRED} individual units per product)")
    for s in (test, reference):
        if 1 < s.n_units < UNITS_REQUIRED:
            warnings.append(f"{s.label}: {s.n_units} units; the guidelines ask for {UNITS_REQUIRED}")
    refused = None
    rapid = False
    if used < min_points:
        rapid = _rapid(test, reference, rule, cutoff_pct)
        if rapid:
            who = "every unit of both products" if rule.name == "canada" else "both mean profiles"
            refused = (f"{who} exceed {cutoff_pct:g} % by {RAPID_MIN:g} min: similar without f2 "
                       f"(immediate-release products)")
        else:
            refused = f"only {used} usable time point(s) under the {rule.agency} rule; f2 needs at least {min_points}"
    elif failures:
        text = "; ".join(failures)
        if rule.cv_fail == "refuse":
            refused = (f"CV rule of the {rule.agency} not met ({text}; at most {CV_EARLY_PCT:g} % at "
                       f"{rule.early_text()}, {CV_LATE_PCT:g} % after): f2 cannot be applied; use the bootstrap f2")
        else:
            warnings.append(f"CV rule of the {rule.agency} not strictly met ({text}); f2 is given, and an "
                            f"alternative such as the bootstrap f2 may be considered")
    f1 = f2 = None
    if refused is None:
        a, b = f1_f2(mr[:used], mt[:used])
        f1, f2 = float(a), float(b)
    return RuleCheck(rule, times, int(used), mt, mr, cvt, cvr, early, tuple(failures), f1, f2, refused, rapid,
                     tuple(warnings), test.n_units, reference.n_units)
