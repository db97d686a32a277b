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


TITLE_CHARS = 120
"""Characters of a title line: the figure's width at the suptitle's font size, with a margin on both edges."""
AXES = ("x", "y", "z")
"""The design grid's array axes (z, axis 2, the build direction)."""


def wrap_title(title: str, width: int = TITLE_CHARS) -> str:
    """``title`` broken into lines of at most ``width`` characters at its `` | `` separators (a longer part on a
    line of its own), so that no edge of the figure cuts it."""
    lines: list[str] = []
    for part in title.split(" | "):
        if lines and len(lines[-1]) + 3 + len(part) <= width:
            lines[-1] += " | " + part
        else:
            lines.append(part)
    return "\n".join(lines)


def _slice(ax, image: np.ndarray, across: int, dx_mm: float | None, cmap: str, what: str) -> None:
    """The mid-slice of a full (X, Y, Z) grid across axis ``across``, drawn with the remaining axes in mm (the
    first across the page, the second up it: z up for the vertical slice) and a 5 mm-class scale."""
    n = image.shape[across]
    sl = [slice(None)] * 3
    sl[across] = n // 2
    plane = image[tuple(sl)].T           # rows: the second remaining axis, drawn upwards
    first, second = (k for k in range(3) if k != across)
    step = dx_mm or 1.0
    unit = "mm" if dx_mm else "voxels"
    ax.imshow(plane, cmap=cmap, vmin=0, vmax=1, origin="lower", interpolation="nearest",
              extent=(0.0, plane.shape[1] * step, 0.0, plane.shape[0] * step))
    ax.set_xlabel(f"{AXES[first]} ({unit})")
    ax.set_ylabel(f"{AXES[second]} ({unit})")
    where = f"{AXES[across]} = {(n // 2 + 0.5) * step:.3g} {unit}"
    ax.set_title(f"{what}, mid-slice {where}", fontsize=10)
    ax.tick_params(labelsize=8)


def report_figure(tau_mm: np.ndarray, target_mm3: np.ndarray, print_mm3: np.ndarray, density_mm3: np.ndarray,
                  binary_mm3: np.ndarray, rho_full: np.ndarray, solid_full: np.ndarray, title: str,
                  dx_mm: float | None = None) -> Figure:
    """Build the report figure.

    Parameters
    ----------
    tau_mm : (K,) ndarray of float, mm
    target_mm3, print_mm3, density_mm3, binary_mm3 : (K,) ndarrays of float, mm^3
        Cumulative release of the (physical) target, of the printed solid by the reference evaluator
        (`design.forward.reference`), and on the design grid of the optimised density and of the
        re-voxelised binary solid.
    rho_full : (X, Y, Z) ndarray of float
        Full optimised density.
    solid_full : (X, Y, Z) ndarray of bool
        Full re-voxelised solid.
    title : str
        Parts separated by `` | ``; wrapped to the figure's width (`wrap_title`).
    dx_mm : float, optional
        Voxel edge, mm: the slices' axes in mm (else in voxels).
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
    for col, across in enumerate((0, 2)):      # a vertical slice (z up) and a horizontal one
        _slice(fig.add_subplot(grid[1, col]), rho_full, across, dx_mm, "gray_r", "density")
        _slice(fig.add_subplot(grid[1, 2 + col]), solid_full.astype(float), across, dx_mm, "Greens", "binary solid")
    fig.suptitle(wrap_title(title), fontsize=11)
    return fig


def save_report(path: str | Path, *args, **kwargs) -> Path:
    """Render `report_figure` to a PNG file; returns its path."""
    path = Path(path)
    report_figure(*args, **kwargs).savefig(path, dpi=100)
    return path
