"""Comparing two release curves the way dissolution scientists do: f1/f2, MDT, DE and model fits.

The job behind ``sfr compare`` and the run browser's f2: any two physical curve files of the project
(read by :mod:`labapp.records.curvefiles`) in, a :class:`Comparison` out. The first curve is the reference: both
are expressed in percent of its weighed mass (its final release when the mass is not recorded).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis.errors import AnalysisError
from analysis.profile import (
    F2Interval,
    ReleaseProfile,
    Similarity,
    bootstrap_f2,
    dissolution_efficiency,
    mean_dissolution_time,
    mean_profile,
    similarity,
)
from analysis.release_models import ModelFit, best_fit, fit_release_models
from labapp.records.curvefiles import PhysicalCurve, read_physical_curve


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
    """The result of :func:`compare_curves`: the two (mean) curves, their summaries, f1/f2 and the optional
    bootstrap interval of f2."""

    profile_a: ReleaseProfile
    profile_b: ReleaseProfile
    a: CurveSummary
    b: CurveSummary
    similarity: Similarity
    interval: F2Interval | None = None

    def to_dict(self) -> dict:
        """The JSON of ``sfr compare --json``."""
        s = self.similarity
        out = {
            "reference": self.a.source, "test": self.b.source,
            "f1": s.f1, "f2": s.f2, "similar": s.similar, "reason": s.reason,
            "points_used": s.points_used, "times_s": s.times.tolist(),
            "reference_pct": [round(x, 4) for x in s.reference_pct.tolist()],
            "test_pct": [round(x, 4) for x in s.test_pct.tolist()], "notes": list(s.notes),
            "mdt_a": self.a.mdt_s, "mdt_b": self.b.mdt_s, "de_a": self.a.de_pct, "de_b": self.b.de_pct,
            "until_s": self.a.until_s, "total_g_a": self.a.total_g, "total_g_b": self.b.total_g,
            "best_fit_a": fit_dict(self.a.best), "best_fit_b": fit_dict(self.b.best),
            "fits_a": [fit_dict(f) for f in self.a.fits], "fits_b": [fit_dict(f) for f in self.b.fits],
        }
        if self.interval is not None:
            i = self.interval
            out["f2_bootstrap"] = {"lower": i.lower, "upper": i.upper, "level": i.level, "mean": i.boot_mean,
                                   "n_boot": i.n_boot, "seed": i.seed, "n_a": i.n_reference, "n_b": i.n_test}
        return out


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


def _read_group(paths: Sequence[str | Path], calibration, name: str) -> list[ReleaseProfile]:
    return [profile_of(read_physical_curve(p, calibration=calibration), f"{name}: {p}" if len(paths) > 1 else str(p))
            for p in paths]


def compare_profiles(a: Sequence[ReleaseProfile], b: Sequence[ReleaseProfile], *, until_s: float | None = None,
                     times_s: Sequence[float] | None = None, rule: str = "either", n_boot: int = 0,
                     seed: int = 0) -> Comparison:
    """Compare a reference (``a``) with a test (``b``), each one curve or several replicates.

    Parameters
    ----------
    a, b : sequence of ReleaseProfile
        Replicates are averaged (:func:`analysis.mean_profile`) for f1/f2, MDT, DE and the fits.
    until_s : float, optional
        MDT and DE up to this time, s (default: the end of the shorter curve, the same for both).
    times_s, rule
        As for :func:`analysis.similarity`.
    n_boot : int
        With replicates, the bootstrap samples of the f2 confidence interval (0: none).
    seed : int
        Seed of the bootstrap.
    """
    ref = a[0] if len(a) == 1 else mean_profile(a, "mean of A")
    test = b[0] if len(b) == 1 else mean_profile(b, "mean of B")
    sim = similarity(ref, test, times=times_s, rule=rule)
    until = min(ref.t[-1], test.t[-1]) if until_s is None else until_s
    interval = bootstrap_f2(a, b, n_boot=n_boot, seed=seed, times=times_s, rule=rule) if n_boot else None
    return Comparison(ref, test, summarize(ref, until), summarize(test, until), sim, interval)


def compare_curves(a: str | Path | Sequence[str | Path], b: str | Path | Sequence[str | Path], *,
                   calibration=None, **options) -> Comparison:
    """Read two curve files (or two groups of replicate files) and compare them; see :func:`compare_profiles`.

    Raises
    ------
    labapp.records.curvefiles.CurveFileError
        A file that cannot be read as a physical curve (named with its row).
    analysis.AnalysisError
        Curves that cannot be compared (no common time span, a reference without release, ...).
    """
    group_a = [a] if isinstance(a, (str, Path)) else list(a)
    group_b = [b] if isinstance(b, (str, Path)) else list(b)
    return compare_profiles(_read_group(group_a, calibration, "A"), _read_group(group_b, calibration, "B"), **options)


def format_table(c: Comparison) -> str:
    """The short table ``sfr compare`` prints."""
    s = c.similarity
    lines = [f"A (reference): {c.a.source}  [100 % = {c.a.total_g:.4g} g]", f"B (test):      {c.b.source}"]
    if s.f2 is None:
        lines.append(f"f2: not reported: {s.reason}")
    else:
        verdict = "similar (f2 >= 50)" if s.similar else "not similar (f2 < 50)"
        lines.append(f"f2 = {s.f2:.2f}, f1 = {s.f1:.2f}: {verdict}; {s.points_used} points "
                     f"{', '.join(f'{t:g}' for t in s.times)} s")
    if c.interval is not None:
        i = c.interval
        lines.append(f"f2 bootstrap {i.level:.0%} interval {i.lower:.2f} .. {i.upper:.2f} "
                     f"({i.n_boot} samples, seed {i.seed}, {i.n_reference} + {i.n_test} curves)")
    lines += [f"  note: {n}" for n in s.notes]
    lines.append(f"{'':24}{'A':>14}{'B':>14}")
    lines.append(f"{'MDT (s)':24}{c.a.mdt_s:>14.1f}{c.b.mdt_s:>14.1f}")
    lines.append(f"{f'DE to {c.a.until_s:g} s (%)':24}{c.a.de_pct:>14.2f}{c.b.de_pct:>14.2f}")
    for name, summary in (("A", c.a), ("B", c.b)):
        best = summary.best
        lines.append(f"best model fit {name}: {best.describe() if best else 'none could be ranked'}")
    return "\n".join(lines)


def plot_comparison(c: Comparison, path: str | Path) -> None:
    """Both curves in percent of A's total, the f2 points marked, and the best fits dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
    total = c.a.total_g
    for profile, summary, colour, name in ((c.profile_a, c.a, "C0", "A"), (c.profile_b, c.b, "C1", "B")):
        ax.plot(profile.t / 60.0, 100 * profile.released / total, color=colour, label=f"{name}: {Path(summary.source).name}")
        best = summary.best
        if best is not None:
            t = np.linspace(0, profile.t[-1], 300)
            ax.plot(t / 60.0, best.percent_at(t) * summary.total_g / total, "--", color=colour, lw=0.9,
                    label=f"{name} {best.model} fit")
    s = c.similarity
    ax.plot(s.times / 60.0, s.reference_pct, "o", color="C0", ms=4)
    ax.plot(s.times / 60.0, s.test_pct, "o", color="C1", ms=4)
    ax.axhline(85, color="0.6", lw=0.6, ls=":")
    title = f"f2 = {s.f2:.1f}, f1 = {s.f1:.1f}" if s.f2 is not None else f"f2 not reported: {s.reason}"
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("time (min)")
    ax.set_ylabel("released (% of A's mass)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
