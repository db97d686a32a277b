"""A sweep's contact sheet: each design's release fit and a top view, best first.

Ranking (`rank`, documented in docs/scale.md): finished designs before unfinished ones, failures last;
among finished designs the printable ones first (one piece, no channel narrower than the run's
``warn_channel_mm``), as fabricability is the criterion hyperparameters are tuned for (section 5.2);
then by the print's fit (``rel_rmse_print``: relative RMSE of design.stl's release by exact surface
distances against the target's physical release; a run recorded before that figure, by its design grid's
binary fit), smallest first.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from design.errors import DesignError
from design.files.records import load_summary
from design.inverse.spaces import BUILD_AXIS
from design.inverse.status import FINISHED

TILES_PER_ROW = 3
MAX_PIXELS = 16000
"""Longest side of the contact sheet, pixels: large sweeps get a lower resolution."""
TILE_IN = (6.0, 3.0)
"""A design's tile (curve and views), inches: at 100 dpi the views span about 300 pixels, the design itself, cropped
to its solid (`crop_to_solid`), most of them."""
SCALE_BARS_MM = (0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0)
"""Lengths a view's scale bar takes, mm: the longest within a third of the top view's width."""


def _curves(folder: Path) -> dict[str, np.ndarray] | None:
    try:
        with open(folder / "curves.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
    except OSError:
        return None
    return {k: np.array([float(r[k]) for r in rows]) for k in (rows[0] if rows else {})} or None


def summary_row(folder: Path) -> dict:
    """sweep.csv fields from a design run folder (empty when it has no ``summary.json`` yet)."""
    try:
        s = load_summary(Path(folder))
    except (OSError, ValueError, DesignError):
        return {}
    row = {key: s.get(key) for key in ("status", "rel_rmse_print", "rel_rmse_print_error", "rel_rmse_density",
                                       "rel_rmse_design_grid_binary", "pieces", "min_channel_mm", "enclosed_void_mm3",
                                       "print_mass_g", "iterations", "seconds", "overhang_fraction",
                                       "rel_rmse_physical")}
    row["warn_channel_mm"] = s.get("config", {}).get("warn_channel_mm")
    for curve in ("print", "design_grid_binary"):
        row[f"rate_dev_{curve}"] = (s.get("rate_dev_mid80") or {}).get(curve)
    curves = _curves(Path(folder))
    if curves is not None:
        row["rmse_mm3"] = float(np.sqrt(np.mean((_achieved(curves) - curves["target_mm3"]) ** 2)))
    return {k: ("" if v is None else v) for k, v in row.items()}


def _achieved(curves: dict[str, np.ndarray]) -> np.ndarray:
    """The print's release of a run's curves.csv (the design grid's binary solid in a run recorded before it)."""
    return curves["print_mm3"] if "print_mm3" in curves else curves["binary_mm3"]


def fit_of(row: dict) -> float | None:
    """The fit a row is ranked and labelled by: the print's, else (a run recorded before it) the design grid's."""
    fit = _number(row.get("rel_rmse_print"))
    return fit if fit is not None else _number(row.get("rel_rmse_design_grid_binary"))


def _number(value) -> float | None:
    """A table value (number, numeric text, or "" / None for none)."""
    return None if value in ("", None) else float(value)


def printable(row: dict) -> bool:
    """One piece and no channel below the run's warning width (rows from summaries or sweep.csv)."""
    channel, limit = _number(row.get("min_channel_mm")), _number(row.get("warn_channel_mm"))
    narrow = channel is not None and limit is not None and channel < limit
    return _number(row.get("pieces")) == 1 and not narrow


def rank(rows: list[dict]) -> list[dict]:
    """Rows best first (module docstring)."""
    def key(row):
        status = row.get("status")
        group = 0 if status in FINISHED else 2 if status == "failed" else 1
        error = fit_of(row)
        return group, not printable(row), math.inf if error is None else error
    return sorted(rows, key=key)


def top_view(solid: np.ndarray, axis: int) -> np.ndarray:
    """Height map of a solid seen from +axis: the top solid voxel's height + 1 per column, 0 where empty.

    Parameters
    ----------
    solid : (X, Y, Z) ndarray of bool
    axis : int
        The viewing (build) axis.

    Returns
    -------
    (rows, cols) ndarray of int, voxels
    """
    solid = np.moveaxis(solid, axis, -1)
    n = solid.shape[-1]
    top = n - np.argmax(solid[..., ::-1], axis=-1)
    return np.where(solid.any(axis=-1), top, 0)


def views(solid: np.ndarray, build_axis: int) -> np.ndarray:
    """The top view (along the build axis) and a side view beside it, two voxels apart (0 = empty).

    Parameters
    ----------
    solid : (X, Y, Z) ndarray of bool
    build_axis : int

    Returns
    -------
    (rows, cols) ndarray of int, voxels
    """
    side_axis = next(a for a in range(3) if a != build_axis and a != 0) if build_axis != 0 else 1
    top, side = top_view(solid, build_axis), top_view(solid, side_axis)
    if top.shape[0] != side.shape[0]:
        return top
    return np.concatenate([top, np.zeros((top.shape[0], 2), dtype=top.dtype), side], axis=1)


def crop_to_solid(solid: np.ndarray, margin: int = 1) -> np.ndarray:
    """The solid's bounding box with ``margin`` empty voxels around it (the grid unchanged when it holds none)."""
    if not solid.any():
        return solid
    box = []
    for axis in range(solid.ndim):
        filled = np.flatnonzero(solid.any(axis=tuple(a for a in range(solid.ndim) if a != axis)))
        box.append(slice(max(0, filled[0] - margin), filled[-1] + 1 + margin))
    return solid[tuple(box)]


def _picture(folder: Path) -> tuple[np.ndarray, float | None, int] | None:
    """A run's views of its solid cropped to it, its voxel edge (mm; None when not recorded) and the top view's
    width, voxels."""
    try:
        with np.load(folder / "density.npz") as data:
            solid = crop_to_solid(data["solid"].astype(bool))
            dx = float(data["dx_mm"]) if "dx_mm" in data else None
    except (OSError, KeyError, ValueError):
        return None
    across = [a for a in range(3) if a != BUILD_AXIS][1]       # the top view's columns
    return views(solid, BUILD_AXIS), dx, int(solid.shape[across])


def _scale_bar(ax, dx_mm: float, top_width_vox: int) -> None:
    """A bar of a round length in mm under the top view, labelled."""
    length = max((mm for mm in SCALE_BARS_MM if mm / dx_mm <= top_width_vox / 3), default=SCALE_BARS_MM[0])
    ax.plot([0.5, 0.5 + length / dx_mm], [-1.5, -1.5], "-", color="k", lw=2, solid_capstyle="butt")
    ax.text(0.5 + 0.5 * length / dx_mm, -2.2, f"{length:g} mm", ha="center", va="top", fontsize=7)


def _label(rank_no: int, row: dict) -> str:
    err = fit_of(row)
    fit = f"fit {err:.1%}" if err is not None else row.get("error", "")[:40] or "no result"
    channel = row.get("min_channel_mm")
    facts = f"{row.get('pieces', '-')} pc, ch {float(channel):.2f} mm" if channel not in ("", None) else \
        f"{row.get('pieces', '-')} pc"
    return f"#{rank_no} {row['name']}\n{row.get('status')} | {fit} | {facts}"


def draw_contact_sheet(rows: list[dict], path: str | Path, sweep_dir: str | Path | None = None) -> Path:
    """Draw ranked rows (sweep.csv rows with ``folder`` relative to `sweep_dir`, default: beside `path`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    base = Path(sweep_dir) if sweep_dir is not None else path.parent
    n_rows = math.ceil(len(rows) / TILES_PER_ROW)
    width_in, height_in = TILE_IN[0] * TILES_PER_ROW, TILE_IN[1] * n_rows
    dpi = min(100.0, MAX_PIXELS / max(width_in, height_in))
    fig, axes = plt.subplots(n_rows, 2 * TILES_PER_ROW, figsize=(width_in, height_in), dpi=dpi, squeeze=False,
                             gridspec_kw={"width_ratios": [1.0, 1.4] * TILES_PER_ROW})
    for ax in axes.ravel():
        ax.set_axis_off()
    for i, row in enumerate(rows):
        curve_ax, pic_ax = axes[i // TILES_PER_ROW, 2 * (i % TILES_PER_ROW):2 * (i % TILES_PER_ROW) + 2]
        curve_ax.set_axis_on()
        curve_ax.set_title(_label(i + 1, row), fontsize=7, loc="left")
        curve_ax.tick_params(labelsize=6)
        folder = base / row["folder"]
        curves = _curves(folder)
        if curves is not None:
            curve_ax.plot(curves["tau_mm"], curves["target_mm3"], "-", color="g", lw=1.5)
            curve_ax.plot(curves["tau_mm"], _achieved(curves), "--", color="m", lw=1.2)
        picture = _picture(folder)
        if picture is not None:
            image, dx_mm, top_width = picture
            pic_ax.imshow(np.ma.masked_equal(image, 0), cmap="viridis", origin="lower", interpolation="nearest")
            if dx_mm:
                _scale_bar(pic_ax, dx_mm, top_width)
                pic_ax.set_ylim(-4.0, image.shape[0])
    fig.suptitle("sweep: target (green) vs the print (magenta dashed), tau (mm) vs released (mm^3); "
                 "top view | side view of the design, coloured by height, with a scale bar", fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.3 / height_in))
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp)
    plt.close(fig)
    tmp.replace(path)
    return path
