"""A design run's result in a few lines of text, read from its ``summary.json``: what `sfr design` prints and
the design launcher shows (`summary_lines`), and the phrases of its figures."""
from __future__ import annotations

from pathlib import Path

from design.files.records import DesignSummary
from design.inverse.status import DesignStatus

RESULT_FILES = ("design.stl", "density.npz", "curves.csv", "curves_physical.csv", "report.png", "history.csv",
                "summary.json", "design.ini")
"""The files a finished design run's result lines name, where they exist (`summary_lines`)."""


def percent_text(value: float | None, digits: int = 2) -> str:
    """A summary's fraction as a percentage with ``digits`` decimals, "-" for a figure not computed (None)."""
    return "-" if value is None else f"{value:.{digits}%}"


def enclosed_voids_text(summary: dict) -> str:
    """The enclosed-void fact of a run's summary as a phrase ("no enclosed voids", "2 enclosed voids, 12.5 mm^3")."""
    count = summary.get("enclosed_voids")
    if count is None:  # a summary written before the fact was recorded
        return "enclosed voids not assessed"
    if count == 0:
        return "no enclosed voids"
    return f"{count} enclosed void{'s' if count > 1 else ''}, {summary['enclosed_void_mm3']:.4g} mm^3"


def print_fit_text(summary: DesignSummary) -> str:
    """The headline fit of a summary as text: "0.412% (+/- 0.050%)", "-" when not computed."""
    fit = summary.get("rel_rmse_print")
    if fit is None:
        return "-"
    error = summary.get("rel_rmse_print_error")
    return f"{fit:.3%}" + ("" if error is None else f" (+/- {error:.3%})")


def summary_lines(summary: DesignSummary, out_dir: Path) -> list[str]:
    """The result of a design run in a few lines of text, from its summary: what `sfr design` prints and the
    design launcher shows.

    Parameters
    ----------
    summary : DesignSummary
        The run's summary (with the physical prediction, ``simcal`` and ``rel_rmse_physical``, when it has one).
    out_dir : Path
        The run folder; the last line names the result files it holds.
    """
    s = summary
    lines = [f"{DesignStatus(s['status']).text} after {s['iterations']} evaluations ({s['seconds']:.1f} s, "
             f"{s['seconds_per_iteration'] or 0:.3f} s each)",
             f"fit of the print: rel. RMSE {print_fit_text(s)} (design.stl by exact surface distances, "
             "against the target's physical release)",
             f"design grid (diagnostics): rel. RMSE density {s['rel_rmse_density']:.3%}, binary solid "
             f"{percent_text(s['rel_rmse_design_grid_binary'], 3)}"]
    dev = {k: percent_text(v) for k, v in s["rate_dev_mid80"].items()}
    lines.append(f"rate deviation, middle 80% of the release: print {dev['print']}; design grid: density "
                 f"{dev['density']}, binary solid {dev['design_grid_binary']}")
    lines.append(f"pieces {s['pieces']}, print mass {s['print_mass_g']:.3f} g, narrowest channel "
                 f"{'none' if s['min_channel_mm'] is None else format(s['min_channel_mm'], '.2f') + ' mm'}, "
                 f"{enclosed_voids_text(s)}")
    lines.append(f"overhangs along +z: {s['overhang_fraction']:.1%} of the solid, longest run "
                 f"{s['max_overhang_run_mm']:.2f} mm" + (f"; preset {s['preset']}" if s.get("preset") else ""))
    if s.get("ico"):
        ico = s["ico"]
        share = percent_text(ico["fab_time_share"], 0)
        lines.append(f"ICO J_fab {ico['J_fab']:.4g} of the start design's, {ico['layers']} layers, {share} of the time")
    physics = s.get("print_physics")
    if physics and (physics["anisotropy"], physics["offset_mm"], physics["swelling_mm"]) != (1.0, 0.0, 0.0):
        constraint = s.get("min_channel_constraint")
        lines.append(f"designed for the print: anisotropy {physics['anisotropy']:.3g}, offset {physics['offset_mm']:+.3g} mm "
                     f"(design.stl is the solid to print; the print, grown by the offset, is what the figures are of)"
                     + ("" if constraint is None else f", minimum open channel {constraint['width_mm']:.2f} mm "
                        f"{'met' if constraint['met'] else 'NOT met'}"))
    if "simcal" in s:
        lines.append(f"physical prediction ({s['simcal']['model']} model, {s['simcal']['seconds_per_mm']:.1f} s/mm): "
                     f"rel. RMSE {s['rel_rmse_physical']:.3%} of the target's final grams (curves_physical.csv)")
        band = s.get("band")
        if band:
            lines.append(f"its {band['level']:.0%} band (calibration uncertainty and leave-one-out residuals, "
                         f"{', '.join(band['columns'])}): mean half-width {band['mean_half_width_g']:.3g} g, "
                         f"{band['target_inside_fraction']:.0%} of the target inside")
    lines += [f"warning: {w}" for w in s["warnings"]]
    lines.append(f"results in {out_dir}: {', '.join(n for n in RESULT_FILES if (out_dir / n).exists())}")
    return lines
