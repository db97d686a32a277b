"""The measured release curve drawn on a matplotlib axis (used by `sfr analyze` and `sfr demo`)."""
from __future__ import annotations


def draw_release(ax, curve) -> None:
    """Per-frame and Savitzky-Golay concentration (g/kg) vs minutes, released g on the right axis.

    ``curve`` is an `analysis.RunCurve` (t_s, conc_g_per_kg, conc_smooth_g_per_kg, water_g).
    """
    minutes = curve.t_s / 60.0
    ax.plot(minutes, curve.conc_g_per_kg, ".", ms=3, color="0.6", label="per frame")
    ax.plot(minutes, curve.conc_smooth_g_per_kg, "-", color="C0", lw=2, label="Savitzky-Golay")
    ax.set_ylabel("concentration (g/kg)")
    kg_water = curve.water_g / 1000.0
    right = ax.secondary_yaxis("right", functions=(lambda c: c * kg_water, lambda m: m / kg_water))
    right.set_ylabel("released (g)")
