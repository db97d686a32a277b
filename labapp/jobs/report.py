"""The run report: one PDF a scientist can file (`sfr report RUN --out report.pdf`, the run browser).

Page 1: the record (who, when, status, record hash), the method and settings, the sample and the devices,
the calibration, and the release curve in g and in % of the weighed mass over hours with its raw points.
Page 2: the metrics (MDT, DE, the model fits ranked by AIC), f2 against each reference under the named
regulator's rule, the method's acceptance criteria, and the warnings (integrity, analysis, event log).
Page 3: the audit trail and the signatures, each marked intact or BROKEN. Nothing in the record is
written: a run without a recorded analysis (``analysis/curve.csv``) is analysed in memory.
"""
from __future__ import annotations

import hashlib
import math
import textwrap
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from analysis import AnalysisError, BenchCalibration, analyze_run
from analysis.profile import ReleaseProfile, similarity
from analysis.regulatory import RULE_NAMES, get_rule
from labapp.acquisition.methods import MethodError, load_method
from labapp.errors import UsageError
from labapp.jobs.compare import DEFAULT_RULE, summarize
from labapp.jobs.verify import verify
from labapp.records import operators
from labapp.records.audit import check_trail
from labapp.records.curvefiles import check_same_unit, read_header, read_physical_curve
from labapp.records.fileio import StorageError, atomic_file, sha256_file
from labapp.records.manifests import EVENTS_LOG, read_run
from labapp.records.outpaths import check_out
from labapp.records.runrecord import RecordKind
from labapp.records.signatures import check_signatures, record_hash

__all__ = ["DEFAULT_RULE", "ReportData", "collect", "write_report"]

RECORDED_CURVE = Path("analysis") / "curve.csv"
_PAGE = (8.27, 11.69)       # A4 portrait, inches
_MONO = {"family": "monospace", "size": 6.6}
_WRAP = 118                 # characters of a monospace line at that size


@dataclass
class ReportData:
    """Everything the report shows, gathered without writing anything (see :func:`collect`)."""

    folder: Path
    record: Any
    status: str
    record_hash: str
    curve_source: str
    t_s: np.ndarray
    released_g: np.ndarray
    raw_g: np.ndarray | None
    mass_g: float | None
    summary: Any
    method: Any = None
    method_note: str = ""
    calibration: BenchCalibration | None = None
    calibration_sha: str | None = None
    comparisons: list[dict[str, Any]] = field(default_factory=list)
    acceptance: list[tuple[str, str, str]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    integrity: list[str] = field(default_factory=list)
    audit: Any = None
    signatures: list[Any] = field(default_factory=list)
    references: list[tuple[str, np.ndarray, np.ndarray]] = field(default_factory=list)
    n_frames: int = 0
    metrics_error: str = ""


def _read_curve(folder: Path, curve: Path | None, calibration: BenchCalibration | None):
    """(source text, t_s, released_g, raw_g or None, analysis warnings) of the run's release curve."""
    path = curve or (folder / RECORDED_CURVE if (folder / RECORDED_CURVE).is_file() else None)
    if path is not None:
        if path.is_dir():
            raise UsageError(f"--curve {path} is a folder; give the curve CSV (sfr analyze's curve.csv)")
        read = read_physical_curve(path)       # the checks of sfr compare and sfr design: values, rows, units
        raw = None
        if "released_raw_g" in read_header(path):
            raw = read_physical_curve(path, column="released_raw_g").released_g
        source = f"{path} (SHA-256 {sha256_file(path)[:16]})"
        return source, read.t_s, read.released_g, raw, []
    if calibration is None:
        raise UsageError(f"{folder} holds no calibration.json and no {RECORDED_CURVE}; give --curve CURVE.csv "
                         "(from sfr analyze)")
    try:
        run_curve = analyze_run(folder, calibration, cache_dir=None)
    except AnalysisError as exc:
        raise UsageError(f"{folder}: the run cannot be analysed for its report ({exc})") from exc
    return ("analysed for this report from the frames with the run's calibration.json (not written)",
            run_curve.t_s, run_curve.released_g, run_curve.released_raw_g, list(run_curve.warnings))


def _hundred(mass_g: float | None, released_g: np.ndarray) -> float:
    """The 100 % of a curve, g: the weighed mass, else the final release (its maximum; never 0)."""
    return mass_g if mass_g else max(float(np.max(released_g)), 1e-12)


def _percent_profile(t_s: np.ndarray, released_g: np.ndarray, mass_g: float | None, label: str) -> ReleaseProfile:
    total = _hundred(mass_g, released_g)
    return ReleaseProfile(t_s, 100.0 * released_g / total, "s", "%", 100.0, label)


def collect(folder: str | Path, *, references: tuple[str | Path, ...] = (), rule: str = DEFAULT_RULE,
            curve: str | Path | None = None) -> ReportData:
    """Gather a run's report: record, method, calibration, curve, metrics, f2, criteria, warnings, audit trail
    and signatures. Reads only.

    Raises
    ------
    UsageError
        For a folder that is not an acquisition run, an unknown rule, or a run whose curve cannot be had; a
        curve with a bad value or times in another unit (as ``sfr compare`` and ``sfr design`` refuse it).
    """
    folder = Path(folder)
    if rule not in RULE_NAMES:
        raise UsageError(f"--rule {rule!r}: expected one of {', '.join(RULE_NAMES)}")
    try:
        snap = read_run(folder)
    except StorageError as exc:
        raise UsageError(f"{folder} is not a run folder ({exc}); a report is made of an acquisition run") from None
    if snap.record.kind != RecordKind.RUN:
        raise UsageError(f"{folder} is a {snap.record.kind}, not an acquisition run; a report is made of a run")
    cal_file = folder / "calibration.json"
    calibration = BenchCalibration.load(cal_file) if cal_file.is_file() else None
    source, t_s, released, raw, warnings = _read_curve(folder, Path(curve) if curve else None, calibration)
    if curve and snap.frames:           # a curve given for the run: in the unit of the run's own frames
        check_same_unit([(str(curve), float(t_s[-1])),
                         (f"the run's frames ({folder / 'frames.csv'})", float(snap.frames[-1].t_s))])
    mass = snap.record.object_mass_g
    try:
        summary, metrics_error = summarize(ReleaseProfile(t_s, released, "s", "g", mass, snap.record.name or folder.name)), ""
    except AnalysisError as exc:        # a curve the metrics refuse (e.g. no release yet): said, not fatal
        summary, metrics_error = None, str(exc)
    data = ReportData(folder, snap.record, str(snap.status), record_hash(folder), source, t_s, released, raw, mass,
                      summary, calibration=calibration,
                      calibration_sha=sha256_file(cal_file) if cal_file.is_file() else None)
    data.n_frames, data.metrics_error = len(snap.frames), metrics_error
    data.warnings = warnings + [f"event log: {line.split(chr(9), 4)[-1]}" for line in snap.events()
                                if "\tWARNING\t" in line or "\tERROR\t" in line]
    if mass is None:
        data.warnings.insert(0, "no weighed mass recorded: percent released is of the final release")
    _method(data)
    cut = get_rule(rule).cut
    for ref in references:
        ref_curve = read_physical_curve(ref)
        data.references.append((str(ref), ref_curve.t_s, ref_curve.released_g))
        entry: dict[str, Any] = {"reference": str(ref), "rule": get_rule(rule)}
        try:
            sim = similarity(_percent_profile(ref_curve.t_s, ref_curve.released_g, ref_curve.object_mass_g, str(ref)),
                             _percent_profile(t_s, released, mass, "this run"), rule=cut)
            entry.update(f1=sim.f1, f2=sim.f2, points=sim.points_used, reason=sim.reason, notes=sim.notes)
        except AnalysisError as exc:
            entry.update(f1=None, f2=None, points=0, reason=str(exc), notes=())
        data.comparisons.append(entry)
    _acceptance(data, t_s, 100.0 * released / _hundred(mass, released))
    report = verify(folder)
    data.integrity = [f"sfr verify: {'OK' if report.ok else 'FAILED: ' + report.reason}"] + \
        [f"problem: {p}" for p in report.problems if p != report.reason]
    data.audit = check_trail(folder)
    data.signatures = check_signatures(folder)
    return data


def _method(data: ReportData) -> None:
    cited = data.record.method
    if not cited:
        return
    path = Path(str(cited.get("path", "")))
    try:
        method = load_method(path)
    except MethodError as exc:
        data.method_note = f"method file not readable now ({exc}); the run cites SHA-256 {cited.get('sha256')}"
        data.warnings.append(data.method_note)
        return
    data.method = method
    if method.sha256 != cited.get("sha256"):
        data.method_note = f"the method file changed after the run (SHA-256 {method.sha256[:16]} now, " \
                           f"{str(cited.get('sha256'))[:16]} cited); its criteria are not applied"
        data.warnings.append(data.method_note)
        data.method = None


def _acceptance(data: ReportData, t_s: np.ndarray, percent: np.ndarray) -> None:
    if data.method is None:
        return
    hours = t_s / 3600.0
    for criterion in data.method.acceptance:
        if criterion.metric == "released_percent":
            if criterion.at_h > hours[-1]:
                data.acceptance.append((criterion.text(), "not measured", f"the run ends at {hours[-1]:.2f} h"))
                continue
            value = float(np.interp(criterion.at_h, hours, percent))
            data.acceptance.append((criterion.text(), "PASS" if criterion.holds(value) else "FAIL", f"{value:.1f} %"))
        else:
            f2s = [c["f2"] for c in data.comparisons if c["f2"] is not None]
            if not f2s:
                data.acceptance.append((criterion.text(), "not evaluated", "no reference given (--reference)"))
            for c in data.comparisons:
                if c["f2"] is not None:
                    data.acceptance.append((criterion.text(), "PASS" if criterion.holds(c["f2"]) else "FAIL",
                                            f"f2 {c['f2']:.1f} vs {Path(c['reference']).name}"))


# ------------------------------------------------------------------------------------------------- drawing
class _Page:
    """A text cursor down an A4 figure, in figure fractions."""

    def __init__(self, pdf, number: int, total: int, footer: str) -> None:
        import matplotlib.pyplot as plt

        self.pdf, self.fig = pdf, plt.figure(figsize=_PAGE)
        self.y = 0.955
        self.fig.text(0.06, 0.025, footer, fontsize=6.5, color="0.35")
        self.fig.text(0.94, 0.025, f"page {number} of {total}", fontsize=6.5, color="0.35", ha="right")

    def heading(self, text: str) -> None:
        self.y -= 0.012
        self.fig.text(0.06, self.y, text, fontsize=10, weight="bold")
        self.y -= 0.006
        self.fig.add_artist(_rule(self.fig, self.y))
        self.y -= 0.016

    def line(self, text: str, color: str = "black", bold: bool = False) -> None:
        for part in textwrap.wrap(text, _WRAP, subsequent_indent="    ") or [""]:
            self.fig.text(0.06, self.y, part, fontdict=_MONO, color=color, weight="bold" if bold else "normal")
            self.y -= 0.0125

    def pairs(self, rows: list[tuple[str, str]]) -> None:
        width = max(len(k) for k, _ in rows) + 2
        for key, value in rows:
            self.line(f"{key:<{width}}{value}")

    def close(self) -> None:
        self.pdf.savefig(self.fig)
        import matplotlib.pyplot as plt

        plt.close(self.fig)


def _rule(fig, y: float):
    from matplotlib.lines import Line2D

    return Line2D([0.06, 0.94], [y, y], transform=fig.transFigure, color="0.6", linewidth=0.6)


def _utc(unix_s: float | None) -> str:
    return "-" if unix_s is None else time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(unix_s))


def _shown(value: Any, unit: str, fmt: str = "g") -> str:
    return "-" if value is None else f"{value:{fmt}} {unit}".strip()


def _page_one(page: _Page, d: ReportData) -> None:
    r, cfg = d.record, dict(d.record.config or {})
    page.fig.text(0.06, page.y, f"Release run report: {r.name or d.folder.name}", fontsize=14, weight="bold")
    page.y -= 0.022
    page.line(f"record {d.folder.resolve()}")
    page.line(f"status {d.status}; record SHA-256 {d.record_hash}")
    page.heading("Record")
    clock = " (simulated bench clock)" if r.simulated else ""
    page.pairs([("started by", r.operator or "not recorded"), ("folder created", _utc(r.created_unix_s)),
                ("time zero (drop)", _utc(r.t0_unix_s) + clock), ("finished", _utc(r.finished_unix_s)),
                ("frames", f"{d.n_frames} recorded, {len(d.t_s)} on the curve; {len(r.gaps)} gap(s); resumed "
                           f"{r.resumed} time(s)")])
    page.heading("Method and settings")
    m = d.method
    rows = [("method", f"{m.name} ({m.path}, SHA-256 {m.sha256[:16]}...)" if m else (d.method_note or "none"))]
    rows += [("bath", f"setpoint {_shown(cfg.get('setpoint_c'), 'C')}, tolerance {_shown(cfg.get('tolerance_c'), 'C')}"
                      f" held {_shown(cfg.get('hold_s'), 's')}, stirring {_shown(cfg.get('speed_rpm'), 'rpm')}"),
             ("water", _shown(r.water_g, "g")),
             ("frame interval", _shown(r.interval_s, "s")),
             ("stop rule", f"at most {_shown((cfg.get('max_duration_s') or 0) / 3600, 'h', '.2f')}; "
                           + ("at steady state after " + _shown((cfg.get("min_duration_s") or 0) / 60, "min", ".0f")
                              if cfg.get("stop_on_steady", True) else "no steady-state stop"))]
    page.pairs(rows)
    page.heading("Sample, devices and calibration")
    cal = d.calibration
    rows = [("object", f"{r.object_name or '-'}, weighed mass {_shown(d.mass_g, 'g', '.4f')}"),
            ("bench", f"{r.bench or '-'}{' (simulated)' if r.simulated else ''}")]
    if cal is not None:
        rows.append(("bench calibration", f"calibration.json SHA-256 {d.calibration_sha[:16]}..., {cal.water_g:g} g "
                                          f"water, {len(cal.conc_levels_g_per_kg)} levels up to "
                                          f"{max(cal.conc_levels_g_per_kg):.3g} g/kg, {int(np.count_nonzero(cal.good))}"
                                          f"/{cal.good.size} good cells, made {cal.created or '-'}"))
    else:
        rows.append(("bench calibration", "none recorded in the run"))
    rows.append(("curve", d.curve_source))
    page.pairs(rows)
    page.heading("Release")
    _plot(page, d)


def _plot(page: _Page, d: ReportData) -> None:
    height = page.y - 0.07
    ax = page.fig.add_axes([0.1, 0.07, 0.78, height - 0.02])
    hours = d.t_s / 3600.0
    total = _hundred(d.mass_g, d.released_g)
    ax.plot(hours, d.released_g, "-", lw=1.3, color="C0", label="release (smoothed)", zorder=2)
    if d.raw_g is not None:
        ax.plot(hours, d.raw_g, "o", ms=1.6, mew=0, color="0.2", alpha=0.55, label="measured points (raw)", zorder=3)
    for k, (name, t_ref, g_ref) in enumerate(d.references):
        ax.plot(t_ref / 3600.0, g_ref, "--", lw=1.2, color=f"C{k + 1}", label=f"reference {Path(name).name}")
    if d.mass_g:
        ax.axhline(d.mass_g, color="0.3", lw=0.8, ls=":", label=f"weighed mass {d.mass_g:.4f} g")
    ax.set_xlabel("time since drop (h)")
    ax.set_ylabel("released (g)")
    ax.set_xlim(left=0.0)
    ax.set_ylim(bottom=min(0.0, float(np.nanmin(d.raw_g if d.raw_g is not None else d.released_g))))
    ax.grid(alpha=0.3)
    secondary = ax.secondary_yaxis("right", functions=(lambda g: 100.0 * g / total, lambda p: p * total / 100.0))
    secondary.set_ylabel("released (% of the weighed mass)" if d.mass_g else "released (% of the final release)")
    ax.legend(loc="lower right", fontsize=7)


def _fit_rows(summary) -> list[str]:
    rows = [f"{'rank':<5}{'model':<22}{'R^2':>8}{'AIC':>9}  parameters"]
    for fit in sorted(summary.fits, key=lambda f: (f.rank is None, f.rank or 0)):
        params = ", ".join(f"{k} = {v:.4g}{' ' + fit.units[k] if fit.units.get(k) else ''}"
                           for k, v in fit.params.items()) if math.isfinite(fit.r2) else fit.note
        rank = "-" if fit.rank is None else str(fit.rank)
        r2 = "-" if not math.isfinite(fit.r2) else f"{fit.r2:.4f}"
        aic = "-" if not math.isfinite(fit.aic) else f"{fit.aic:.1f}"
        rows.append(f"{rank:<5}{fit.model:<22}{r2:>8}{aic:>9}  {params}"
                    + (f" ({fit.note})" if fit.note and math.isfinite(fit.r2) else ""))
    return rows


def _page_two(page: _Page, d: ReportData, rule: str) -> None:
    s = d.summary
    page.heading("Metrics")
    basis = "the weighed mass" if d.mass_g else "the final release"
    total = _hundred(d.mass_g, d.released_g)
    if s is None:
        page.line(f"final release {d.released_g[-1]:.4f} g = {100 * d.released_g[-1] / total:.1f} % of {basis} at "
                  f"{d.t_s[-1] / 3600:.2f} h")
        page.line(f"MDT, DE and model fits not computed: {d.metrics_error}", color="firebrick")
    else:
        _metrics(page, s, d, basis)
    _rest_of_page_two(page, d, rule)


def _metrics(page: _Page, s, d: ReportData, basis: str) -> None:
    page.pairs([("mean dissolution time", f"{s.mdt_s / 60:.1f} min ({s.mdt_s / 3600:.2f} h; to {s.until_s / 3600:.2f} h)"),
                ("dissolution efficiency", f"{s.de_pct:.1f} % (to {s.until_s / 3600:.2f} h)"),
                ("final release", f"{d.released_g[-1]:.4f} g = {100 * d.released_g[-1] / s.total_g:.1f} % of {basis}"
                                  f" at {d.t_s[-1] / 3600:.2f} h")])
    page.line("")
    page.line(f"model fits of % released over time (t in s), ranked by AIC; 100 % = {basis}:", bold=True)
    for row in _fit_rows(s):
        page.line(row)


def _rest_of_page_two(page: _Page, d: ReportData, rule: str) -> None:
    page.heading(f"Similarity to a reference (f2, {get_rule(rule).agency} rule)")
    if not d.comparisons:
        page.line("no reference given (sfr report RUN --reference REF_RUN)")
    for c in d.comparisons:
        f2 = "not reported" if c["f2"] is None else f"{c['f2']:.1f} (f1 {c['f1']:.1f}), {c['points']} time points; " + \
            ("similar (f2 >= 50)" if c["f2"] >= 50 else "NOT similar (f2 < 50)")
        page.line(f"{c['reference']}: f2 {f2}")
        if c["reason"]:
            page.line(f"  reason: {c['reason']}", color="firebrick")
        page.line(f"  rule: {c['rule'].agency}: at most one point after 85 % ({c['rule'].cut} curve); one curve per "
                  "product, so the rule's CV limits cannot be checked; source: " + c["rule"].source)
        for note in c["notes"]:
            page.line(f"  note: {note}")
    page.heading("Acceptance criteria")
    if d.method is None:
        page.line("no method with acceptance criteria cited by the run")
    elif not d.acceptance:
        page.line(f"method {d.method.name!r} states no acceptance criteria")
    for text, verdict, value in d.acceptance:
        page.line(f"{verdict:<14}{text}: {value}", color="firebrick" if verdict == "FAIL" else "black",
                  bold=verdict in ("PASS", "FAIL"))
    page.heading("Integrity and warnings")
    for line in d.integrity:
        page.line(line, color="black" if line.endswith("OK") else "firebrick")
    shown = d.warnings[:18]
    for w in shown:
        page.line(f"warning: {w}")
    if len(d.warnings) > len(shown):
        page.line(f"... and {len(d.warnings) - len(shown)} more in {EVENTS_LOG}")
    if not d.warnings:
        page.line("no warnings")


def _page_three(page: _Page, d: ReportData) -> None:
    trail = d.audit
    page.heading("Audit trail")
    if not trail.exists:
        page.line("no audit trail (audit.jsonl): the record does not name its operators", color="firebrick")
    else:
        page.line(f"{'seq':<4}{'UTC':<25}{'operator':<24}{'action':<15}detail / reason", bold=True)
        for e in trail.entries[-40:]:
            reason = f" [reason: {e['reason']}]" if e.get("reason") else ""
            page.line(f"{e['seq']!s:<4}{str(e['utc'])[:23]:<25}{str(e['operator'])[:23]:<24}{e['action']:<15}"
                      f"{e['detail']}{reason}")
        page.line(f"chain {'intact' if trail.ok else 'BROKEN'}: {len(trail.entries)} entries" +
                  ("" if trail.ok else "; " + "; ".join(trail.problems)), color="black" if trail.ok else "firebrick",
                  bold=True)
    page.heading("Electronic signatures")
    if not d.signatures:
        page.line("not signed")
    for state in d.signatures:
        s = state.signature
        page.line(f"{str(s.get('meaning', '?')).upper()} by {s.get('signer')} at {s.get('utc')}"
                  + (f"; reason: {s['reason']}" if s.get("reason") else ""), bold=True)
        page.line(f"  bound to record SHA-256 {s.get('record_hash')}: "
                  + ("INTACT" if state.intact else f"BROKEN ({state.why})"),
                  color="black" if state.intact else "firebrick")
    page.line("")
    page.line("A signature is intact while every file of the record (all but audit.jsonl and signatures.jsonl) "
              "hashes to the record SHA-256 it was bound to; 'sfr verify RECORD' checks it again.")


def write_report(folder: str | Path, out: str | Path, *, references: tuple[str | Path, ...] = (),
                 rule: str = DEFAULT_RULE, curve: str | Path | None = None) -> Path:
    """Write the report of the run ``folder`` to the PDF ``out`` (three A4 pages); returns its path.

    Raises
    ------
    UsageError
        As :func:`collect`, or an ``out`` that exists or lies inside a record.
    labapp.records.fileio.WriteError
        A full, read-only or forbidden disk (exit code 2); the PDF is written whole or not at all.
    """
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.backends.backend_pdf import PdfPages

    out = check_out(out, "report", [folder, *references], file=True)
    data = collect(folder, references=references, rule=rule, curve=curve)
    who = operators.current()
    stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    footer = f"{data.folder.name} | record {data.record_hash[:16]} | generated {stamp}" + \
        (f" by {who}" if who else "") + " | sfr report"
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(out) as fh, PdfPages(fh, metadata={"Title": f"Release run report: {data.folder.name}",
                                                        "Creator": "sfr report",
                                                        "Subject": f"record SHA-256 {data.record_hash}"}) as pdf:
        for number, draw in enumerate((lambda p: _page_one(p, data), lambda p: _page_two(p, data, rule),
                                       lambda p: _page_three(p, data)), start=1):
            page = _Page(pdf, number, 3, footer)
            draw(page)
            page.close()
    return out


def report_digest(path: str | Path) -> str:
    """SHA-256 (hex) of a written report (printed by ``sfr report`` so that the filed copy can be checked)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()
