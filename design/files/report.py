"""The report picture of a design run: the target against the print's release (and the design grid's
diagnostic curves), density and solid slices.

Uses matplotlib's object API with the Agg canvas (no pyplot state), so it is safe in worker
threads and headless runs.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure


def _rate(tau: np.ndarray, c: np.ndarray, points: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """Release rate by differences over ~``points`` intervals (per-sample differences of a voxel
    release are dominated by voxel-layer ripple)."""
    step = max(1, (len(tau) - 1) // points)
    t, v = tau[::step], c[::step]
    return 0.5 * (t[1:] + t[:-1]), np.diff(v) / np.diff(t)


def report_figure(tau_mm: np.ndarray, target_mm3: np.ndarray, print_mm3: np.ndarray, density_mm3: np.ndarray,
                  binary_mm3: np.ndarray, rho_full: np.ndarray, solid_full: np.ndarray, title: str) -> Figure:
    """Build the report figure.

    Parameters
    ----------
    tau_mm : (K,) ndarray of float, mm
    target_mm3, print_mm3, density_mm3, binary_mm3 : (K,) ndarrays of float, mm^3
        Cumulative release of the (physical) target, of the printed solid by the reference evaluator
        (`design.forward.reference`), and on the design grid of the optimised density and of the
        re-voxelised binary solid.
    rho_full : (D, H, W) ndarray of float
        Full optimised density.
    solid_full : (D, H, W) ndarray of bool
        Full re-voxelised solid.
    title : str
    """
    fig = Figure(figsize=(13, 7.5), layout="constrained")
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(2, 4)
    ax_c = fig.add_subplot(grid[0, 0:2])
    ax_r = fig.add_subplot(grid[0, 2:4])
    styles = (("target", target_mm3, "-", "tab:green"), ("print (exact distances)", print_mm3, "-", "tab:red"),
              ("density, design grid", density_mm3, "--", "tab:blue"),
              ("binary solid, design grid", binary_mm3, ":", "tab:gray"))
    # a release that ends early (zero-order targets) is shown zoomed, with rates over 1/100 of the view
    t_end = float(tau_mm[np.argmax(target_mm3 >= 0.999 * target_mm3[-1])])
    view = min(float(tau_mm[-1]), 1.5 * t_end) if t_end < 0.5 * tau_mm[-1] else float(tau_mm[-1])
    points = max(1, int(round(100 * tau_mm[-1] / view)))
    for label, curve, ls, color in styles:
        ax_c.plot(tau_mm, curve, ls, color=color, label=label, lw=2)
        ax_r.plot(*_rate(tau_mm, curve, points), ls, color=color, label=label, lw=1.5)
    for ax in (ax_c, ax_r):
        ax.set_xlim(0.0, view)
    ax_c.set(xlabel="tau (mm dissolved)", ylabel="released (mm^3)", title="cumulative release")
    ax_r.set(xlabel="tau (mm dissolved)", ylabel="rate (mm^3 per mm)", title="release rate")
    ax_c.legend()
    mids = [n // 2 for n in rho_full.shape]
    names = ("axis 0", "axis 1", "axis 2")
    for col, ax_idx in enumerate((0, 2)):
        sl = [slice(None)] * 3
        sl[ax_idx] = mids[ax_idx]
        a = fig.add_subplot(grid[1, col])
        a.imshow(rho_full[tuple(sl)], cmap="gray_r", vmin=0, vmax=1, origin="lower")
        a.set_title(f"density, mid-slice {names[ax_idx]}")
        a.axis("off")
        b = fig.add_subplot(grid[1, 2 + col])
        b.imshow(solid_full[tuple(sl)], cmap="Greens", vmin=0, vmax=1, origin="lower")
        b.set_title(f"binary solid, mid-slice {names[ax_idx]}")
        b.axis("off")
    fig.suptitle(title)
    return fig


def save_report(path: str | Path, *args, **kwargs) -> Path:
    """Render `report_figure` to a PNG file; returns its path."""
    path = Path(path)
    report_figure(*args, **kwargs).savefig(path, dpi=100)
    return path
