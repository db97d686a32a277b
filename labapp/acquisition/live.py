"""Live analysis of frames as they arrive: cells -> concentration with the active bench calibration."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis import BenchCalibration, estimate_concentration, read_cells, smooth_curve, steady_state
from analysis.curve import DEFAULT_ORDER, DEFAULT_WINDOW_S


@dataclass(frozen=True)
class LivePoint:
    """One analysed frame: concentration in g/kg (NaN when the frame could not be read) and its uncertainty."""

    conc_g_per_kg: float
    uncertainty_g_per_kg: float
    rejected_cells: int


class LiveAnalyzer:
    """Turns frame files into concentrations, re-anchored on the run's reference frame when there is one.

    Parameters
    ----------
    calibration : BenchCalibration
        The active bench calibration (its geometry gives crop, grid and mirror axis).

    Frames are decoded at the calibration's own reduced size (``calibration.reduce``), as offline analysis does.
    """

    def __init__(self, calibration: BenchCalibration) -> None:
        self.calibration = calibration
        self.reference_cells: np.ndarray | None = None

    def set_reference(self, path: Path) -> None:
        """Use the clear-water frame at ``path`` as the zero-concentration anchor."""
        self.reference_cells = self._cells(path)

    def analyze(self, path: Path) -> LivePoint:
        """Concentration of one frame file.

        Raises
        ------
        Exception
            ``analysis.AnalysisError`` for a corrupt or wrong-sized frame; the caller logs it and goes on.
        """
        est = estimate_concentration(self._cells(path), self.calibration, reference_cells=self.reference_cells)
        return LivePoint(est.conc_g_per_kg, est.uncertainty_g_per_kg, len(est.rejected_cells))

    def _cells(self, path: Path) -> np.ndarray:
        cal = self.calibration
        return read_cells(path, cal.geometry, reduce=cal.reduce, expect_shape=cal.image_shape)


def is_steady(t_s: list[float], conc: list[float], min_duration_s: float) -> bool:
    """The analysis package's steady-state criterion on the Savitzky-Golay smoothed curve (the window the
    live plot and ``sfr analyze`` use, ``analysis.curve.DEFAULT_WINDOW_S``), applied only
    after ``min_duration_s`` s of run (times in s, concentrations in g/kg, NaN frames ignored)."""
    pairs = [(t, c) for t, c in zip(t_s, conc) if not math.isnan(c)]
    if len(pairs) < 10 or pairs[-1][0] < min_duration_s:
        return False
    t, c = np.array(pairs).T
    return bool(steady_state(t, smooth_curve(t, c, window_s=DEFAULT_WINDOW_S, order=DEFAULT_ORDER)))
