"""Per-cell Beer-Lambert bench calibration and robust concentration estimates (paper section 4.2).

Each cell's transmittance follows ``T = T0 * exp(-k * c)`` with ``c`` in g/kg. A calibration series of
frames at known concentrations fixes ``T0`` and ``k`` per cell by nonlinear least squares (Gauss-Newton
from the log-linear solution), with their covariance. A frame is then read by inverting every cell's law
and averaging the cells' concentrations, weighted by their uncertainty, after rejecting cells that
disagree with the robust consensus (an object piece or a bubble in the crop).
"""
from __future__ import annotations

import datetime as _dt
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analysis.errors import AnalysisError
from analysis.geometry import CropGeometry

log = logging.getLogger(__name__)

FORMAT = "sfr-bench-calibration/1"
WATER_RANGE_G = (100.0, 5000.0)
"""The water masses a bath plausibly holds, g: from 100 g (a 150 mL beaker; less and the camera's crop is no
longer below the surface, above a stirring magnet) to 5000 g (a 5 L beaker). The paper's bath is 500 g in a
600 mL beaker (section 4.2). A water mass outside is a typing or unit error: 0.5 (kg typed as g) makes every
concentration a thousand times too high, 1e9 every level 0.000 g/kg."""
_MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True, eq=False)
class BenchCalibration:
    """Fitted per-cell laws ``T = t0 * exp(-k * c)`` and the setup they hold for.

    Attributes
    ----------
    geometry : CropGeometry
    water_g : float
        Water mass of the calibration, g.
    t0, t0_sigma : (g, g) ndarray of float
        Zero-concentration transmittance and its standard error.
    k, k_sigma : (g, g) ndarray of float, kg/g
        Attenuation per g/kg and its standard error.
    cov_t0_k : (g, g) ndarray of float
        Covariance of ``t0`` and ``k``.
    rms_rel : (g, g) ndarray of float
        RMS relative fit residual (residual / T) of each cell: its noise level per frame.
    good : (g, g) ndarray of bool
        Cells whose fit is usable (finite, k > 0, residual not an outlier).
    conc_levels_g_per_kg : tuple of float
        Concentrations of the calibration frames.
    image_shape : (H, W) or None
        Full-resolution size of the calibration images, px.
    reduce : int
        Decode downscaling the cells were measured with.
    camera : dict
        Camera settings the calibration holds for (free-form strings).
    created : str
        ISO 8601 time of the fit.
    """

    geometry: CropGeometry
    water_g: float
    t0: np.ndarray
    t0_sigma: np.ndarray
    k: np.ndarray
    k_sigma: np.ndarray
    cov_t0_k: np.ndarray
    rms_rel: np.ndarray
    good: np.ndarray
    conc_levels_g_per_kg: tuple[float, ...]
    image_shape: tuple[int, int] | None = None
    reduce: int = 1
    camera: dict = field(default_factory=dict)
    created: str = ""

    def __post_init__(self) -> None:
        g = self.geometry.grid
        for name in ("t0", "t0_sigma", "k", "k_sigma", "cov_t0_k", "rms_rel", "good"):
            if np.shape(getattr(self, name)) != (g, g):
                raise AnalysisError(f"calibration field {name} has shape {np.shape(getattr(self, name))}, "
                                    f"expected ({g}, {g}) for grid={g}")
        if not WATER_RANGE_G[0] <= self.water_g <= WATER_RANGE_G[1]:
            raise AnalysisError(f"calibration water_g={self.water_g!r} g: {water_range_text()}")

    def save(self, path: str | Path) -> None:
        """Write the calibration as JSON (format in docs/formats.md)."""
        data = {"format": FORMAT, "created": self.created, "water_g": self.water_g,
                "geometry": self.geometry.to_dict(), "image_shape": self.image_shape, "reduce": self.reduce,
                "camera": self.camera, "conc_levels_g_per_kg": list(self.conc_levels_g_per_kg),
                "model": "T = t0 * exp(-k * conc_g_per_kg)",
                "cells": {name: np.asarray(getattr(self, name)).tolist()
                          for name in ("t0", "t0_sigma", "k", "k_sigma", "cov_t0_k", "rms_rel", "good")}}
        path = Path(path)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(data, indent=1))
        except OSError as exc:
            raise AnalysisError(f"cannot write calibration {path}: {exc.strerror or exc}") from exc

    @classmethod
    def load(cls, path: str | Path) -> BenchCalibration:
        """Read a calibration written by :meth:`save`.

        Raises
        ------
        AnalysisError
            Missing file, not JSON, or not a bench calibration.
        """
        try:
            data = json.loads(Path(path).read_text())
        except OSError as exc:
            raise AnalysisError(f"cannot read calibration {path}: {exc.strerror or exc}") from exc
        except ValueError:
            raise AnalysisError(f"{path} is not a bench calibration JSON (not JSON text; a calibration is the file "
                                f"'sfr calibrate-bench' writes)") from None
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise AnalysisError(f"{path} is not a bench calibration (expected format {FORMAT!r})")
        try:
            cells = {k: np.asarray(v, dtype=bool if k == "good" else float) for k, v in data["cells"].items()}
            shape = data.get("image_shape")
            _check_finite(path, data, cells)
            return cls(CropGeometry.from_dict(data["geometry"]), float(data["water_g"]),
                       conc_levels_g_per_kg=tuple(float(c) for c in data["conc_levels_g_per_kg"]),
                       image_shape=None if shape is None else (int(shape[0]), int(shape[1])),
                       reduce=int(data.get("reduce", 1)), camera=dict(data.get("camera") or {}),
                       created=str(data.get("created", "")), **cells)
        except (KeyError, TypeError, ValueError) as exc:
            raise AnalysisError(f"calibration {path} is incomplete or malformed: {exc}") from exc


def water_range_text() -> str:
    """What a water mass must be, and why (`WATER_RANGE_G`)."""
    low, high = WATER_RANGE_G
    return (f"expected a water mass in [{low:g}, {high:g}] g, a beaker's bath (the paper's is 500 g): a mass outside "
            f"is a typing or unit error that scales every concentration")


def _check_finite(path: str | Path, data: dict, cells: dict[str, np.ndarray]) -> None:
    """NaN/inf is refused in ``water_g``, the levels and every field of a cell marked good (a cell that is
    not good may hold NaN from a failed fit: it is never used)."""
    water = float(data["water_g"])
    if not (np.isfinite(water) and WATER_RANGE_G[0] <= water <= WATER_RANGE_G[1]):
        raise AnalysisError(f"calibration {path}: water_g is {data['water_g']!r}; {water_range_text()}")
    levels = np.asarray(data["conc_levels_g_per_kg"], dtype=float)
    if not np.all(np.isfinite(levels)):
        i = int(np.flatnonzero(~np.isfinite(levels))[0])
        raise AnalysisError(f"calibration {path}: conc_levels_g_per_kg[{i}] is {levels[i]}; expected a finite g/kg")
    good = cells.get("good")
    for key in ("t0", "k"):
        if key not in cells or good is None or cells[key].shape != good.shape:
            raise AnalysisError(f"calibration {path}: cells.{key} is missing or not the shape of cells.good")
    for key, values in cells.items():
        if key == "good" or values.shape != good.shape:
            continue
        bad = np.argwhere(good & ~np.isfinite(values))
        if bad.size:
            r, c = (int(v) for v in bad[0])
            raise AnalysisError(f"calibration {path}: cells.{key} of cell (row {r}, col {c}) is {values[r, c]} but "
                                f"the cell is marked good; expected a finite number ({len(bad)} such cells)")


def fit_bench_calibration(cells: np.ndarray, conc_g_per_kg: np.ndarray, geometry: CropGeometry, water_g: float,
                          camera: dict | None = None, *, image_shape: tuple[int, int] | None = None,
                          reduce: int = 1, outlier_factor: float = 5.0) -> BenchCalibration:
    """Fit ``T = t0 * exp(-k * c)`` per cell by nonlinear least squares.

    Parameters
    ----------
    cells : (L, g, g) ndarray of float
        Cell transmittances of L frames.
    conc_g_per_kg : (L,) ndarray of float
        Known concentration of each frame, g/kg; at least 3 distinct levels.
    geometry : CropGeometry
    water_g : float
        Water mass, g.
    camera : dict, optional
        Camera settings to record.
    image_shape : (H, W), optional
        Full-resolution image size, px.
    reduce : int
        Decode downscaling used for ``cells``.
    outlier_factor : float
        A cell whose residual exceeds this multiple of the median cell residual is marked not good, as
        is a cell whose attenuation ``k`` is not positive by 3 standard errors.

    Returns
    -------
    BenchCalibration

    Raises
    ------
    AnalysisError
        Shapes disagree, fewer than 3 levels, non-positive transmittances, or fewer than half the cells respond.
    """
    cells = np.asarray(cells, dtype=float)
    conc = np.asarray(conc_g_per_kg, dtype=float)
    g = geometry.grid
    if cells.ndim != 3 or cells.shape[1:] != (g, g) or cells.shape[0] != conc.shape[0]:
        raise AnalysisError(f"cells shape {cells.shape} does not match {conc.shape[0]} concentrations "
                            f"and a {g}x{g} grid")
    levels = np.unique(conc)
    if levels.size < 3:
        raise AnalysisError(f"a calibration needs at least 3 distinct concentration levels, got {levels.size} "
                            f"({', '.join(f'{c:g}' for c in levels)} g/kg)")
    if np.any(conc < 0) or not np.all(np.isfinite(conc)):
        raise AnalysisError("calibration concentrations must be finite and >= 0 g/kg")
    if not np.all(np.isfinite(cells)) or np.any(cells <= 0):
        raise AnalysisError("calibration cell transmittances must be finite and positive")
    t0, k, cov, rms_rel = _gauss_newton(cells.reshape(len(conc), -1), conc)
    k_sigma = np.sqrt(cov[:, 1, 1])
    good = np.isfinite(t0) & np.isfinite(k) & (k > 3 * k_sigma)
    if good.sum() < good.size / 2:
        raise AnalysisError(f"only {int(good.sum())} of {good.size} cells' transmittance falls significantly with "
                            "concentration (k > 3 sigma); is the crop inside the beaker, and do the images match "
                            "masses.csv?")
    median_rms = float(np.median(rms_rel[good])) if good.any() else np.inf
    good &= rms_rel <= outlier_factor * max(median_rms, 1e-6)
    bad = [divmod(int(i), g) for i in np.flatnonzero(~good)]
    if bad:
        log.warning("calibration: %d cells fit poorly and are not used: %s", len(bad), bad)
    shape2 = (g, g)
    return BenchCalibration(geometry, float(water_g), t0.reshape(shape2), np.sqrt(cov[:, 0, 0]).reshape(shape2),
                            k.reshape(shape2), k_sigma.reshape(shape2), cov[:, 0, 1].reshape(shape2),
                            rms_rel.reshape(shape2), good.reshape(shape2), tuple(float(c) for c in conc),
                            image_shape, reduce, dict(camera or {}),
                            _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))


def _gauss_newton(t: np.ndarray, conc: np.ndarray, iterations: int = 30):
    """Vectorised least squares of t[:, j] = a_j exp(-k_j conc) for all columns j."""
    design = np.stack([np.ones_like(conc), -conc], axis=1)
    coef, *_ = np.linalg.lstsq(design, np.log(t), rcond=None)
    a, k = np.exp(coef[0]), coef[1]
    for _ in range(iterations):
        e = np.exp(-np.outer(conc, k))
        r = t - a * e
        j = np.stack([e, -conc[:, None] * a * e], axis=-1)          # (L, n, 2)
        jtj = np.einsum("lni,lnj->nij", j, j)
        step = np.linalg.solve(jtj, np.einsum("lni,ln->ni", j, r)[..., None])[..., 0]
        a, k = a + step[:, 0], k + step[:, 1]
        if np.all(np.abs(step[:, 0]) <= 1e-12 * np.abs(a)) and np.all(np.abs(step[:, 1]) <= 1e-12 + 1e-10 * np.abs(k)):
            break
    e = np.exp(-np.outer(conc, k))
    fit = a * e
    dof = max(len(conc) - 2, 1)
    s2 = ((t - fit) ** 2).sum(axis=0) / dof
    j = np.stack([e, -conc[:, None] * a * e], axis=-1)
    cov = np.linalg.inv(np.einsum("lni,lnj->nij", j, j)) * s2[:, None, None]
    rms_rel = np.sqrt((((t - fit) / fit) ** 2).sum(axis=0) / dof)
    return a, k, cov, rms_rel


@dataclass(frozen=True, eq=False)
class ConcentrationEstimate:
    """One frame read against a calibration.

    Attributes
    ----------
    conc_g_per_kg : float
        Weighted mean over the accepted cells, g/kg.
    uncertainty_g_per_kg : float
        Its standard error, g/kg.
    rejected_cells : list of (row, col)
        Cells that disagreed with the consensus (object, bubble) and were left out.
    cell_conc_g_per_kg : (g, g) ndarray of float
        Every cell's own estimate (NaN where the cell is unusable).
    n_used : int
        Cells in the average.
    """

    conc_g_per_kg: float
    uncertainty_g_per_kg: float
    rejected_cells: list[tuple[int, int]]
    cell_conc_g_per_kg: np.ndarray
    n_used: int


def estimate_concentration(cells: np.ndarray, calibration: BenchCalibration, *,
                           reference_cells: np.ndarray | None = None,
                           reject_sigma: float = 5.0) -> ConcentrationEstimate:
    """Concentration of one frame from its cell transmittances.

    Parameters
    ----------
    cells : (g, g) ndarray of float
        Cell transmittances of the frame.
    calibration : BenchCalibration
    reference_cells : (g, g) ndarray of float, optional
        Cells of the run's clear-water reference frame; replaces ``t0`` per cell (see
        :func:`reanchor_t0`).
    reject_sigma : float
        Cells farther than this many combined standard deviations from the median are rejected.

    Returns
    -------
    ConcentrationEstimate

    Raises
    ------
    AnalysisError
        Wrong shape, or no usable cell.
    """
    g = calibration.geometry.grid
    cells = np.asarray(cells, dtype=float)
    if cells.shape != (g, g):
        raise AnalysisError(f"cells shape {cells.shape} does not match the calibration's {g}x{g} grid")
    t0 = calibration.t0 if reference_cells is None else reanchor_t0(reference_cells, calibration)
    lnt0_var = (calibration.t0_sigma / calibration.t0) ** 2 if reference_cells is None else calibration.rms_rel ** 2
    usable = calibration.good & np.isfinite(cells) & (cells > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        conc = np.where(usable, np.log(t0 / cells) / calibration.k, np.nan)
        k = calibration.k
        cov_lnt0_k = 0.0 if reference_cells is not None else calibration.cov_t0_k / calibration.t0
        var = ((calibration.rms_rel ** 2 + lnt0_var) / k ** 2 + (conc * calibration.k_sigma / k) ** 2
               - 2 * conc / k ** 2 * cov_lnt0_k)
    var = np.maximum(var, 1e-18)
    if not usable.any():
        raise AnalysisError("no usable cell: every cell is marked bad in the calibration or non-positive")
    median = float(np.median(conc[usable]))
    spread = _MAD_TO_SIGMA * float(np.median(np.abs(conc[usable] - median)))
    accepted = usable & (np.abs(conc - median) <= reject_sigma * np.sqrt(spread ** 2 + var))
    rejected = [divmod(int(i), g) for i in np.flatnonzero(usable & ~accepted)]
    w = np.where(accepted, 1.0 / var, 0.0)
    mean = float((w * np.nan_to_num(conc)).sum() / w.sum())
    n = int(accepted.sum())
    chi2 = float((w * np.nan_to_num(conc - mean) ** 2).sum()) / max(n - 1, 1)
    sigma = float(np.sqrt(1.0 / w.sum() * max(chi2, 1.0)))
    if len(rejected) > usable.sum() // 2:
        log.warning("%d of %d cells rejected; the estimate %.4g g/kg rests on a minority", len(rejected),
                    int(usable.sum()), mean)
    return ConcentrationEstimate(mean, sigma, rejected, conc, n)


def reanchor_t0(reference_cells: np.ndarray, calibration: BenchCalibration,
                reject_sigma: float = 5.0) -> np.ndarray:
    """Zero-concentration transmittances taken from a clear-water reference frame.

    Cells where the reference disagrees with the calibration's ``t0`` far more than the others (an
    object or bubble in the reference frame) keep ``t0`` scaled by the median ratio instead.

    Returns
    -------
    (g, g) ndarray of float
    """
    ref = np.asarray(reference_cells, dtype=float)
    if ref.shape != calibration.t0.shape:
        raise AnalysisError(f"reference cells shape {ref.shape} does not match the calibration's "
                            f"{calibration.t0.shape}")
    ok = np.isfinite(ref) & (ref > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_ratio = np.where(ok, np.log(ref / calibration.t0), np.nan)
    median = float(np.nanmedian(log_ratio)) if ok.any() else 0.0
    spread = _MAD_TO_SIGMA * float(np.nanmedian(np.abs(log_ratio - median))) if ok.any() else 0.0
    noise = np.hypot(calibration.rms_rel, calibration.t0_sigma / calibration.t0)
    keep = ok & (np.abs(log_ratio - median) <= reject_sigma * np.hypot(spread, noise))
    return np.where(keep, ref, calibration.t0 * np.exp(median))


def reference_offset(reference_cells: np.ndarray, calibration: BenchCalibration,
                     n_sigma: float = 3.0) -> tuple[ConcentrationEstimate, str | None]:
    """How far a clear-water reference frame reads from the calibration's zero level.

    Returns
    -------
    estimate : ConcentrationEstimate
        The reference read against the calibration's own ``t0``.
    warning : str or None
        A message when the offset exceeds ``n_sigma`` times the fit's uncertainty, else None.
    """
    est = estimate_concentration(reference_cells, calibration)
    if abs(est.conc_g_per_kg) > n_sigma * est.uncertainty_g_per_kg:
        return est, (f"the reference frame reads {est.conc_g_per_kg:+.4f} +/- {est.uncertainty_g_per_kg:.4f} g/kg "
                     f"on the calibration's zero level (more than {n_sigma:g} sigma): light, camera or beaker "
                     "changed since the calibration; the reference re-anchors each cell")
    return est, None
