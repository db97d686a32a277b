"""Comparing release curves the way dissolution scientists do: f1/f2 under a regulator's rule, MDT, DE, model
fits, and for replicate units the CV per time point, the bootstrap of f2 and the multivariate tests.

The job behind ``sfr compare`` and the run browser's f2. Two inputs:

- two curves (:func:`compare_curves`, a :class:`Comparison`): any physical curve files of the project, read by
  :mod:`labapp.records.curvefiles`; the first is the reference;
- two replicate sets (:func:`compare_sets`, a :class:`SetComparison`): several curves per product, or one CSV of
  unit columns per product (``t_min`` or ``t_s`` or ``t_h``, then one column of percent released per unit).

One rule for 100 %, stated in every table and JSON (``percent_basis``): each curve is in percent of its own
weighed mass when the mass is recorded for every curve compared, else in percent of its own final value. A
run given as its folder and as its ``curve.csv`` therefore gives the same numbers whenever both are compared
under the same basis.
"""
from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis.bootstrap import DEFAULT_SEED, BootstrapF2, bootstrap_f2
from analysis.errors import AnalysisError
from analysis.msd import BOUNDS_PCT, MTAD_PCT, SIGNIF, MsdResult, msd_test
from analysis.profile import (
    CUTOFF_PCT,
    MAX_SAMPLED_POINTS,
    ReleaseProfile,
    Similarity,
    dissolution_efficiency,
    mean_dissolution_time,
    mean_profile,
    sampling_times,
    similarity,
)
from analysis.regulatory import RULE_NAMES, RuleCheck, check_rule, get_rule
from analysis.release_models import ModelFit, best_fit, fit_release_models
from analysis.replicates import ReplicateSet
from labapp.records.curvefiles import CurveFileError, PhysicalCurve, check_same_unit, read_physical_curve

DEFAULT_RULE = "ema"
"""The regulator's rule ``sfr compare`` follows unless told otherwise."""
BASIS_MASS = "weighed mass"
BASIS_FINAL = "final value"


@dataclass(frozen=True, eq=False)
class CurveSummary:
    """MDT, DE and model fits of one curve up to a common time.

    Attributes
    ----------
    source : str
    mdt_s : float, s
    de_pct : float, %
    until_s : float, s
        The time MDT and DE run to.
    total_g : float, g
        The 100 % of the curve (weighed mass, else final release).
    fits : tuple of ModelFit
        Ranked by AIC (see :func:`analysis.release_models.fit_release_models`).
    """

    source: str
    mdt_s: float
    de_pct: float
    until_s: float
    total_g: float
    fits: tuple[ModelFit, ...]

    @property
    def best(self) -> ModelFit | None:
        return best_fit(self.fits)


@dataclass(frozen=True, eq=False)
class Comparison:
    """The result of :func:`compare_curves`: the two curves (g, with the 100 % of ``percent_basis``), their
    summaries and f1/f2 under the rule's 85 % cut.

    Attributes
    ----------
    profile_a, profile_b : ReleaseProfile
        The reference (A) and the test (B), in s and g; ``amount_total`` is each one's 100 %.
    a, b : CurveSummary
    similarity : Similarity
        f1/f2 with each curve in percent of its own 100 %.
    rule : str
        The regulator's rule (one of ``analysis.regulatory.RULE_NAMES``).
    percent_basis : str
        ``"weighed mass"`` or ``"final value"``: what 100 % is, for both curves.
    """

    profile_a: ReleaseProfile
    profile_b: ReleaseProfile
    a: CurveSummary
    b: CurveSummary
    similarity: Similarity
    rule: str = DEFAULT_RULE
    percent_basis: str = BASIS_FINAL

    def to_dict(self) -> dict:
        """The JSON of ``sfr compare A B --json``."""
        s = self.similarity
        return {
            "reference": self.a.source, "test": self.b.source, "rule": self.rule,
            "percent_basis": self.percent_basis, "percent_basis_text": basis_text(self.percent_basis),
            "f1": s.f1, "f2": s.f2, "similar": s.similar, "reason": s.reason,
            "points_used": s.points_used, "times_s": s.times.tolist(),
            "reference_pct": [round(x, 4) for x in s.reference_pct.tolist()],
            "test_pct": [round(x, 4) for x in s.test_pct.tolist()], "notes": list(s.notes),
            "mdt_a": self.a.mdt_s, "mdt_b": self.b.mdt_s, "de_a": self.a.de_pct, "de_b": self.b.de_pct,
            "until_s": self.a.until_s, "total_g_a": self.a.total_g, "total_g_b": self.b.total_g,
            "best_fit_a": fit_dict(self.a.best), "best_fit_b": fit_dict(self.b.best),
            "fits_a": [fit_dict(f) for f in self.a.fits], "fits_b": [fit_dict(f) for f in self.b.fits],
        }


def fit_dict(fit: ModelFit | None) -> dict | None:
    """A model fit as plain JSON values (NaN as None)."""
    if fit is None:
        return None
    clean = (lambda v: None if v is None or not math.isfinite(v) else v)
    return {"model": fit.model, "params": fit.params, "units": fit.units, "r2": clean(fit.r2),
            "r2_adj": clean(fit.r2_adj), "aic": clean(fit.aic), "n_points": fit.n_points, "rank": fit.rank,
            "note": fit.note}


def profile_of(curve: PhysicalCurve, label: str | None = None) -> ReleaseProfile:
    """A physical curve as a :class:`ReleaseProfile` in s and g, 100 % = its weighed mass when recorded."""
    return ReleaseProfile(curve.t_s, curve.released_g, "s", "g", curve.object_mass_g, label or curve.source)


def summarize(profile: ReleaseProfile, until_s: float | None = None) -> CurveSummary:
    """MDT, DE (up to ``until_s``, default the curve's end) and ranked model fits of one curve."""
    until = float(profile.t[-1]) if until_s is None else float(until_s)
    return CurveSummary(profile.label, mean_dissolution_time(profile, until=until),
                        dissolution_efficiency(profile, until=until), until, profile.amount_total,
                        fit_release_models(profile))


def release_summary(t_s: np.ndarray, released_g: np.ndarray, mass_g: float | None = None,
                    label: str = "curve") -> dict:
    """MDT, DE and the ranked model fits of one physical curve, as the JSON the analysis and design
    summaries carry (``{"error": ...}`` when the curve cannot be summarised, e.g. no release yet).

    Parameters
    ----------
    t_s : (N,) ndarray of float, s
    released_g : (N,) ndarray of float, g
    mass_g : float, optional
        The weighed mass (100 %); default the final release.
    label : str
        Named in error messages.
    """
    try:
        summary = summarize(ReleaseProfile(t_s, released_g, "s", "g", mass_g, label))
    except AnalysisError as exc:
        return {"error": str(exc)}
    best = summary.best
    return {"mdt_s": summary.mdt_s, "de_pct": summary.de_pct, "until_s": summary.until_s,
            "total_g": summary.total_g, "best_fit": fit_dict(best),
            "best_fit_text": best.describe() if best else None, "fits": [fit_dict(f) for f in summary.fits]}


def prediction_metrics(t_s: np.ndarray, reference_g: np.ndarray, predicted_g: np.ndarray,
                       mass_g: float | None = None) -> dict:
    """The release metrics a prediction carries: MDT, DE and model fits of the predicted curve and of its
    reference (a target or a measurement), and f1/f2 of the prediction against the reference.

    Parameters
    ----------
    t_s : (N,) ndarray of float, s
    reference_g, predicted_g : (N,) ndarray of float, g
    mass_g : float, optional
        The reference's 100 % (default its final release).
    """
    out = {"predicted": release_summary(t_s, predicted_g, None, "prediction"),
           "reference": release_summary(t_s, reference_g, mass_g, "reference")}
    try:
        sim = similarity(ReleaseProfile(t_s, reference_g, total=mass_g, label="reference"),
                         ReleaseProfile(t_s, predicted_g, label="prediction"))
    except AnalysisError as exc:
        out["f2_error"] = str(exc)
        return out
    out.update({"f1": sim.f1, "f2": sim.f2, "f2_reason": sim.reason, "f2_points": sim.points_used})
    return out


def basis_text(basis: str) -> str:
    """The sentence every table prints for the 100 % rule."""
    if basis == BASIS_MASS:
        return "100 % = each curve's weighed mass (recorded for every curve)"
    if basis == BASIS_FINAL:
        return "100 % = each curve's final value (the weighed mass is not recorded for every curve)"
    return "100 % as given in the units file (percent released per unit)"


def percent_basis(curves: Sequence[PhysicalCurve]) -> str:
    """The 100 % rule: every curve's weighed mass when all are known, else every curve's final value."""
    return BASIS_MASS if all(c.object_mass_g is not None for c in curves) else BASIS_FINAL


def _profile(curve: PhysicalCurve, basis: str, label: str) -> ReleaseProfile:
    return ReleaseProfile(curve.t_s, curve.released_g, "s", "g", curve.object_mass_g if basis == BASIS_MASS else None,
                          label)


def _percent(profile: ReleaseProfile) -> ReleaseProfile:
    """The curve in percent of its own 100 %."""
    total = profile.amount_total
    if not (math.isfinite(total) and total > 0):
        raise AnalysisError(f"{profile.label}: releases {total:g} {profile.amount_unit} in total; percent released "
                            f"needs a curve with a positive release")
    return ReleaseProfile(profile.t, 100.0 * profile.released / total, profile.time_unit, "%", 100.0, profile.label)


def _cut_of(rule: str) -> str:
    return "reference" if get_rule(rule).cut == "reference" else "either"


def compare_profiles(a: ReleaseProfile, b: ReleaseProfile, *, until_s: float | None = None,
                     times_s: Sequence[float] | None = None, rule: str = DEFAULT_RULE,
                     percent_basis: str = BASIS_FINAL) -> Comparison:
    """Compare a reference curve ``a`` with a test curve ``b``.

    Parameters
    ----------
    a, b : ReleaseProfile
        In s and g; each one's ``amount_total`` is its 100 % (see :func:`percent_basis`).
    until_s : float, optional
        MDT and DE up to this time, s (default: the end of the shorter curve, the same for both).
    times_s : sequence of float, optional
        f1/f2 time points (default: see :func:`analysis.profile.sampling_times`).
    rule : str
        The regulator whose 85 % cut applies (one curve per product: the CV rule cannot be checked).
    percent_basis : str
        Recorded in the result.
    """
    sim = similarity(_percent(a), _percent(b), times=times_s, rule=_cut_of(rule))
    sim = Similarity(sim.f1, sim.f2, sim.times, sim.reference_pct, sim.test_pct, sim.reason,
                     sim.notes + (f"{get_rule(rule).agency} rule; one curve per product: the CV rule is not checked",))
    until = min(a.t[-1], b.t[-1]) if until_s is None else until_s
    return Comparison(a, b, summarize(a, until), summarize(b, until), sim, get_rule(rule).name, percent_basis)


def compare_curves(a: str | Path, b: str | Path, *, calibration=None, until_s: float | None = None,
                   times_s: Sequence[float] | None = None, rule: str = DEFAULT_RULE) -> Comparison:
    """Read two curve files (the reference ``a``, the test ``b``) and compare them; see :func:`compare_profiles`.

    Raises
    ------
    labapp.records.curvefiles.CurveFileError
        A file that cannot be read as a physical curve (named with its row), or whose times are in another unit
        than the other's (named: :func:`labapp.records.curvefiles.check_same_unit`).
    analysis.AnalysisError
        Curves that cannot be compared (no common time span, a reference without release, ...).
    """
    curves = [read_physical_curve(p, calibration=calibration) for p in (a, b)]
    check_same_unit([(str(p), float(c.t_s[-1])) for p, c in zip((a, b), curves)])
    basis = percent_basis(curves)
    pa, pb = (_profile(c, basis, str(p)) for c, p in zip(curves, (a, b)))
    return compare_profiles(pa, pb, until_s=until_s, times_s=times_s, rule=rule, percent_basis=basis)


# ---------------------------------------------------------------- replicate sets
@dataclass(frozen=True, eq=False)
class SetComparison:
    """The result of :func:`compare_sets`.

    Attributes
    ----------
    reference, test : ReplicateSet
        Percent released of each unit at the common time points.
    check : RuleCheck
        Mean, CV per point, the rule's verdict and f1/f2 on the means.
    bootstrap : BootstrapF2 or None
        With ``n_boot``: the five estimators and four intervals.
    msd : MsdResult or None
        Tsong's MSD and Hoffelder's T^2 (None when they cannot be computed: ``msd_error`` says why).
    msd_error : str or None
    mean_reference, mean_test : CurveSummary or None
        MDT, DE and model fits of the mean curves (in %; None for a single time point).
    percent_basis : str
    sources_reference, sources_test : tuple of str
    notes : tuple of str
        How the time points were chosen.
    """

    reference: ReplicateSet
    test: ReplicateSet
    check: RuleCheck
    bootstrap: BootstrapF2 | None
    msd: MsdResult | None
    msd_error: str | None
    mean_reference: CurveSummary | None
    mean_test: CurveSummary | None
    percent_basis: str
    sources_reference: tuple[str, ...]
    sources_test: tuple[str, ...]
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        """The JSON of ``sfr compare --reference ... --test ... --json``."""
        def summary(s: CurveSummary | None) -> dict | None:
            return None if s is None else {"mdt": s.mdt_s, "de_pct": s.de_pct, "until": s.until_s,
                                           "best_fit": fit_dict(s.best), "fits": [fit_dict(f) for f in s.fits]}

        return {"reference": list(self.sources_reference), "test": list(self.sources_test),
                "percent_basis": self.percent_basis, "percent_basis_text": basis_text(self.percent_basis),
                "time_unit": self.reference.time_unit, "notes": list(self.notes),
                "reference_sd": self.reference.without_time_zero().sd.tolist(),
                "test_sd": self.test.without_time_zero().sd.tolist(),
                **self.check.to_dict(),
                "bootstrap": None if self.bootstrap is None else self.bootstrap.to_dict(),
                "msd": None if self.msd is None else self.msd.to_dict(), "msd_error": self.msd_error,
                "mean_reference": summary(self.mean_reference), "mean_test": summary(self.mean_test)}


UNIT_TIME_COLUMNS = {"t_s": "s", "t_min": "min", "t_h": "h"}
"""The first column of a units CSV and the time unit it names."""
UNIT_PERCENT_RANGE = (-10.0, 150.0)
"""The percent released a unit of a units CSV plausibly has, %: from a baseline's small negative error to half as
much again as the label claim (content uniformity allows units of 75-125 % of it). A value outside is another
unit (a fraction of 1, milligrams) or a sign error, and would make f2, MSD and T^2 meaningless."""


def read_units_csv(path: str | Path, label: str) -> ReplicateSet:
    """A CSV of unit columns: ``t_min`` (or ``t_s``, ``t_h``), then one column of percent released per unit.

    Raises
    ------
    CurveFileError
        An unreadable file, a first column that names no time unit, a cell that is not a number (row and
        column named), fewer than one unit.
    """
    path = Path(path)
    try:
        with open(path, newline="") as fh:
            rows = [r for r in csv.reader(fh) if any(c.strip() for c in r)]
    except (OSError, UnicodeDecodeError) as exc:
        raise CurveFileError(f"{path}: cannot read ({exc})") from exc
    if not rows:
        raise CurveFileError(f"{path}: empty file; expected a header t_min,unit1,unit2,...")
    header = [h.strip() for h in rows[0]]
    unit = UNIT_TIME_COLUMNS.get(header[0])
    if unit is None or len(header) < 2:
        raise CurveFileError(f"{path}: header {','.join(header)}; a units file starts with one of "
                             f"{', '.join(UNIT_TIME_COLUMNS)} and has one column of percent released per unit")
    values = np.empty((len(rows) - 1, len(header)))
    for r, row in enumerate(rows[1:], start=1):
        for c, name in enumerate(header):
            values[r - 1, c] = _unit_cell(path, row, r, c, name, unit)
    try:
        return ReplicateSet(values[:, 0], values[:, 1:].T, unit, label, tuple(header[1:]))
    except AnalysisError as exc:
        raise CurveFileError(f"{path}: {exc}") from exc


def _unit_cell(path: Path, row: list[str], r: int, c: int, name: str, unit: str) -> float:
    """The number in data row ``r`` (1 = the line after the header), column ``c`` of a units CSV; refused, naming
    the row, its line in the file and the column, if it is not a finite number, a negative time or a percentage
    outside `UNIT_PERCENT_RANGE`."""
    where = f"{path}: row {r} (line {r + 1}), column {c + 1} ({name})"
    cell = row[c].strip() if c < len(row) else "<missing>"
    try:
        value = float(cell)
    except ValueError:
        raise CurveFileError(f"{where}: {cell!r} is not a number") from None
    if not np.isfinite(value):
        raise CurveFileError(f"{where}: {cell!r} is not a finite number")
    if c == 0 and value < 0:
        raise CurveFileError(f"{where}: {value:g} {unit}; times count from the start of the test, never negative")
    low, high = UNIT_PERCENT_RANGE
    if c > 0 and not low <= value <= high:
        raise CurveFileError(f"{where}: {value:g} % released; a unit releases {low:g} to {high:g} % of its label "
                             f"claim (a fraction of 1 or a mass is another unit; give percent released)")
    return value


def _is_units_csv(path: Path) -> bool:
    if not (path.is_file() and path.suffix.lower() == ".csv"):
        return False
    try:
        with open(path, newline="") as fh:
            header = next(csv.reader(fh), [])
    except (OSError, UnicodeDecodeError):
        return False
    return bool(header) and header[0].strip() in UNIT_TIME_COLUMNS and "released_g" not in header


def _set_from_curves(curves: Sequence[PhysicalCurve], basis: str, times_s: np.ndarray, label: str) -> ReplicateSet:
    units = []
    for c in curves:
        if times_s[0] < c.t_s[0] - 1e-9 or times_s[-1] > c.t_s[-1] + 1e-9:
            raise AnalysisError(f"{c.source}: sampled {c.t_s[0]:g}..{c.t_s[-1]:g} s; the time points "
                                f"{times_s[0]:g}..{times_s[-1]:g} s lie outside it")
        units.append(_percent(_profile(c, basis, c.source)).at(times_s))
    return ReplicateSet(times_s, np.array(units), "s", label, tuple(c.source for c in curves))


def _common_times(ref: Sequence[PhysicalCurve], test: Sequence[PhysicalCurve], basis: str,
                  times_s: Sequence[float] | None) -> tuple[np.ndarray, str]:
    curves = list(ref) + list(test)
    lo, hi = max(float(c.t_s[0]) for c in curves), min(float(c.t_s[-1]) for c in curves)
    if lo >= hi:
        raise AnalysisError("the curves have no time span in common: "
                            + ", ".join(f"{c.source} {c.t_s[0]:g}..{c.t_s[-1]:g} s" for c in curves))
    if times_s is not None:
        pts = np.asarray(times_s, dtype=float)
        if pts.ndim != 1 or pts.size == 0 or np.any(np.diff(pts) <= 0) or not np.all(np.isfinite(pts)):
            raise AnalysisError(f"times {list(np.ravel(pts))}: expected finite, strictly increasing times in s")
        outside = pts[(pts < lo - 1e-9) | (pts > hi + 1e-9)]
        if outside.size:
            raise AnalysisError(f"time points {', '.join(f'{t:g}' for t in outside)} s lie outside the span "
                                f"{lo:g}..{hi:g} s that every curve covers")
        return pts, f"the {pts.size} requested time points"
    first = curves[0].t_s
    if first.size <= MAX_SAMPLED_POINTS and all(c.t_s.shape == first.shape and np.allclose(c.t_s, first)
                                                 for c in curves):
        return first.copy(), "every curve's own sampling times"
    mean_ref = mean_profile([_percent(_profile(c, basis, c.source)) for c in ref], "mean reference")
    mean_test = mean_profile([_percent(_profile(c, basis, c.source)) for c in test], "mean test")
    pts, how = sampling_times(mean_ref, mean_test)
    pts = pts[(pts >= lo) & (pts <= hi)]
    return pts, how.replace("both curves", "every curve")


def _read_set(sources: Sequence[str | Path], calibration, label: str) -> tuple[ReplicateSet | None,
                                                                               list[PhysicalCurve]]:
    paths = [Path(p) for p in sources]
    if not paths:
        raise CurveFileError(f"no {label} given")
    units = [p for p in paths if _is_units_csv(p)]
    if units:
        if len(paths) > 1:
            raise CurveFileError(f"{label}: a units file ({units[0]}) holds every unit of a product; give it alone, "
                                 f"not with other files")
        return read_units_csv(units[0], label), []
    return None, [read_physical_curve(p, calibration=calibration) for p in paths]


def _mean_summary(s: ReplicateSet, curves: Sequence[PhysicalCurve], basis: str, label: str) -> CurveSummary | None:
    try:
        if curves:
            mean = mean_profile([_percent(_profile(c, basis, c.source)) for c in curves], label)
        else:
            mean = ReleaseProfile(s.times, s.mean, s.time_unit, "%", 100.0, label)
        return summarize(mean)
    except AnalysisError:
        return None


def compare_sets(reference: Sequence[str | Path], test: Sequence[str | Path], *, calibration=None,
                 rule: str = DEFAULT_RULE, times_s: Sequence[float] | None = None, n_boot: int = 0,
                 seed: int = DEFAULT_SEED, mtad: float = MTAD_PCT, signif: float = SIGNIF,
                 both_tr_85: bool = False, cutoff_pct: float = CUTOFF_PCT,
                 bounds: tuple[float, float] = BOUNDS_PCT) -> SetComparison:
    """Compare the replicate units of a reference and a test product.

    Parameters
    ----------
    reference, test : sequence of str or Path
        Each product's curves (one per unit: run folders, curve CSVs), or one units CSV.
    calibration : analysis.BenchCalibration, optional
        For run folders without their own calibration.
    rule : str
        One of ``analysis.regulatory.RULE_NAMES``.
    times_s : sequence of float, optional
        Time points for curves, s (default: their common sampling times, or a regular grid); a units CSV
        brings its own.
    n_boot : int
        Bootstrap samples of f2 (0: none; else >= 100).
    seed : int
        R's ``set.seed`` value of the bootstrap (bootf2's default 306).
    mtad, signif : float
        Of Tsong's MSD and Hoffelder's T^2.
    both_tr_85 : bool
        The fda rule's older reading of its 85 % sentence (the published values of Shah et al. 1998; see
        :func:`analysis.regulatory.check_rule`), for f2 and its bootstrap.
    cutoff_pct : float
        The release after whose first point f2 stops, % (default 85).
    bounds : (float, float)
        The profile portion of the MSD and T^2 tests, % (disprofas' ``bounds``; default 1, 85).

    Raises
    ------
    labapp.records.curvefiles.CurveFileError
        A file that cannot be read.
    analysis.AnalysisError
        Sets that cannot be compared (different time points, no common span, a bad setting).
    """
    get_rule(rule)
    ref_set, ref_curves = _read_set(reference, calibration, "reference")
    test_set, test_curves = _read_set(test, calibration, "test")
    notes = []
    if (ref_set is None) != (test_set is None):
        raise CurveFileError("give both products as units files, or both as curves (one per unit)")
    if ref_set is None:
        check_same_unit([(c.source, float(c.t_s[-1])) for c in ref_curves + test_curves])
        basis = percent_basis(ref_curves + test_curves)
        pts, how = _common_times(ref_curves, test_curves, basis, times_s)
        notes.append(f"time points: {how}")
        ref_set = _set_from_curves(ref_curves, basis, pts, "reference")
        test_set = _set_from_curves(test_curves, basis, pts, "test")
    else:
        if times_s is not None:
            raise CurveFileError("--times applies to curves; a units file brings its own time points")
        basis = "units file"
    check = check_rule(test_set, ref_set, rule, both_tr_85=both_tr_85, cutoff_pct=cutoff_pct)
    boot = None
    if n_boot:
        boot = bootstrap_f2(test_set, ref_set, rule, n_boot=n_boot, seed=seed, both_tr_85=both_tr_85,
                            cutoff_pct=cutoff_pct)
    msd, msd_error = None, None
    try:
        msd = msd_test(ref_set, test_set, mtad=mtad, signif=signif, bounds=bounds)
    except AnalysisError as exc:
        msd_error = str(exc)
    return SetComparison(ref_set, test_set, check, boot, msd, msd_error,
                         _mean_summary(ref_set, ref_curves, basis, "mean reference"),
                         _mean_summary(test_set, test_curves, basis, "mean test"), basis,
                         tuple(str(p) for p in reference), tuple(str(p) for p in test), tuple(notes))


__all__ = ["BASIS_FINAL", "BASIS_MASS", "Comparison", "CurveSummary", "DEFAULT_RULE", "RULE_NAMES", "SetComparison",
           "basis_text", "compare_curves", "compare_profiles", "compare_sets", "fit_dict", "percent_basis",
           "prediction_metrics", "read_units_csv", "release_summary", "summarize"]
