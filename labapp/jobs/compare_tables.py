"""The tables and pictures of ``sfr compare``: two curves (:class:`labapp.jobs.compare.Comparison`) or two
replicate sets (:class:`labapp.jobs.compare.SetComparison`) as the text the command prints and as a PNG."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from analysis.bootstrap import ESTIMATORS, INTERVALS
from analysis.replicates import TIME_UNITS_MIN
from labapp.jobs.compare import Comparison, SetComparison, basis_text

__all__ = ["format_set_table", "format_table", "plot_comparison", "plot_sets"]


def format_table(c: Comparison) -> str:
    """The short table ``sfr compare A B`` prints."""
    s = c.similarity
    lines = [f"A (reference): {c.a.source}  [100 % = {c.a.total_g:.4g} g]",
             f"B (test):      {c.b.source}  [100 % = {c.b.total_g:.4g} g]", basis_text(c.percent_basis)]
    if s.f2 is None:
        lines.append(f"f2: not reported: {s.reason}")
    else:
        verdict = "similar (f2 >= 50)" if s.similar else "not similar (f2 < 50)"
        lines.append(f"f2 = {s.f2:.2f}, f1 = {s.f1:.2f}: {verdict}; {s.points_used} points "
                     f"{', '.join(f'{t:g}' for t in s.times)} s")
    lines += [f"  note: {n}" for n in s.notes]
    lines.append(f"{'':24}{'A':>14}{'B':>14}")
    lines.append(f"{'MDT (s)':24}{c.a.mdt_s:>14.1f}{c.b.mdt_s:>14.1f}")
    lines.append(f"{f'DE to {c.a.until_s:g} s (%)':24}{c.a.de_pct:>14.2f}{c.b.de_pct:>14.2f}")
    for name, summary in (("A", c.a), ("B", c.b)):
        best = summary.best
        lines.append(f"best model fit {name}: {best.describe() if best else 'none could be ranked'}")
    return "\n".join(lines)


def _num(v: float | None, fmt: str = ".2f") -> str:
    return "n/a" if v is None or not math.isfinite(v) else format(v, fmt)


def format_set_table(c: SetComparison) -> str:
    """The table ``sfr compare --reference ... --test ...`` prints: one row per time point, the rule's verdict,
    the bootstrap, the multivariate tests and the mean curves' MDT, DE and best fit."""
    k = c.check
    r, t = c.reference.without_time_zero(), c.test.without_time_zero()
    unit = r.time_unit
    lines = [f"reference: {r.n_units} unit(s)  ({', '.join(c.sources_reference)})",
             f"test:      {t.n_units} unit(s)  ({', '.join(c.sources_test)})",
             basis_text(c.percent_basis),
             f"rule: {k.rule.agency} ({k.rule.source})"]
    lines += [f"  note: {n}" for n in c.notes]
    minutes = unit != "min"  # the CV rules name their early points in minutes
    head = (f"{'time (' + unit + ')':>10}" + (f" {'min':>7}" if minutes else "")
            + f" | {'ref mean':>8} {'SD':>6} {'CV %':>6} | {'test mean':>9} {'SD':>6} {'CV %':>6} | f2 point")
    lines += [head, "-" * len(head)]
    for i, time in enumerate(r.times):
        used = ("early (CV <= 20 %)" if i < k.early else "yes") if i < k.used else "-"
        lines.append(f"{time:>10g}" + (f" {r.times_min[i]:>7.4g}" if minutes else "")
                     + f" | {r.mean[i]:>8.2f} {r.sd[i]:>6.2f} {r.cv_pct[i]:>6.2f} | "
                     f"{t.mean[i]:>9.2f} {t.sd[i]:>6.2f} {t.cv_pct[i]:>6.2f} | {used}")
    if k.f2 is not None:
        verdict = "similar (f2 >= 50)" if k.similar else "not similar (f2 < 50)"
        lines.append(f"f2 = {k.f2:.2f}, f1 = {k.f1:.2f} on the means: {verdict}; {k.used} points")
    elif k.similar_without_f2:
        lines.append(f"similar without f2: {k.refused}")
    else:
        lines.append(f"f2 refused: {k.refused}")
    lines += [f"  warning: {w}" for w in k.warnings]
    if c.bootstrap is not None:
        b = c.bootstrap
        lines.append(f"bootstrap of f2: {b.n_boot} samples over units, seed {b.seed} (R's set.seed), "
                     f"{b.level:.0%} intervals; similar when the lower bound >= 50")
        lines.append(f"{'estimator':>10} {'value':>7} {'boot mean':>9} | "
                     + " | ".join(f"{kind:^16}" for kind in INTERVALS))
        for e in ESTIMATORS:
            cells = " | ".join(f"{_num(lo):>7}..{_num(hi):<7}" for lo, hi in (b.interval(e, kind) for kind in INTERVALS))
            lines.append(f"{e:>10} {_num(b.estimates[e]):>7} {_num(b.boot_mean[e]):>9} | {cells}")
    if c.msd is not None:
        m = c.msd
        lines.append(f"MSD (Tsong, MIMCR) on {m.times.size} points, MTAD {m.mtad:g} %, alpha {m.signif:g}: "
                     f"D_M = {m.dm:.3f}, {1 - m.signif:.0%} region up to {m.obs_upper:.3f}, limit {m.sim_limit:.3f}: "
                     f"{'similar' if m.tsong_similar else 'not similar'}")
        lines.append(f"T^2 equivalence (Hoffelder): T^2 = {m.t2:.4g}, F = {m.f:.4g}, p = {m.p_hoffelder:.4g}: "
                     f"{'equivalent' if m.hoffelder_similar else 'not shown equivalent'} (p < {m.signif:g})")
    else:
        lines.append(f"MSD and T^2: not computed: {c.msd_error}")
    for name, s in (("reference", c.mean_reference), ("test", c.mean_test)):
        if s is not None:
            best = s.best
            lines.append(f"mean {name}: MDT {s.mdt_s:.4g} {unit}, DE {s.de_pct:.2f} %; best fit "
                         f"{best.describe() if best else 'none could be ranked'}")
    return "\n".join(lines)


def plot_comparison(c: Comparison, path: str | Path) -> None:
    """Both curves in percent of their 100 %, the f2 points marked, and the best fits dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
    for profile, summary, colour, name in ((c.profile_a, c.a, "C0", "A"), (c.profile_b, c.b, "C1", "B")):
        ax.plot(profile.t / 60.0, 100 * profile.released / profile.amount_total, color=colour,
                label=f"{name}: {Path(summary.source).name}")
        best = summary.best
        if best is not None:
            t = np.linspace(0, profile.t[-1], 300)
            ax.plot(t / 60.0, best.percent_at(t), "--", color=colour, lw=0.9, label=f"{name} {best.model} fit")
    s = c.similarity
    ax.plot(s.times / 60.0, s.reference_pct, "o", color="C0", ms=4)
    ax.plot(s.times / 60.0, s.test_pct, "o", color="C1", ms=4)
    ax.axhline(85, color="0.6", lw=0.6, ls=":")
    title = f"f2 = {s.f2:.1f}, f1 = {s.f1:.1f}" if s.f2 is not None else f"f2 not reported: {s.reason}"
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("time (min)")
    ax.set_ylabel(f"released (% of each curve's {c.percent_basis})")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def plot_sets(c: SetComparison, path: str | Path) -> None:
    """Every unit thin, the means with SD bars, the f2 points filled."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
    scale = TIME_UNITS_MIN[c.reference.time_unit]
    for s, colour in ((c.reference, "C0"), (c.test, "C1")):
        tm = s.times * scale
        for row in s.units:
            ax.plot(tm, row, color=colour, lw=0.5, alpha=0.35)
        ax.errorbar(tm, s.mean, yerr=s.sd, color=colour, lw=1.4, capsize=2, label=f"{s.label} ({s.n_units} units)")
    k = c.check
    ax.plot(k.used_times * scale, k.reference_mean[:k.used], "o", color="C0", ms=4)
    ax.plot(k.used_times * scale, k.test_mean[:k.used], "o", color="C1", ms=4)
    ax.axhline(85, color="0.6", lw=0.6, ls=":")
    ax.set_title(f"{k.rule.agency}: " + (f"f2 = {k.f2:.1f}" if k.f2 is not None else k.refused), fontsize=8)
    ax.set_xlabel("time (min)")
    ax.set_ylabel("released (%)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
