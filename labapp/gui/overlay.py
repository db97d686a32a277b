"""Overlay of release curves in physical units: several runs and simulated predictions, grams over hours."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pyqtgraph as pg
from PySide6.QtGui import QColor
from PySide6.QtWidgets import QVBoxLayout, QWidget

from labapp.gui.plots import time_plot
from labapp.jobs.physical import predict_mesh_band
from labapp.records.curvefiles import PhysicalCurve, read_physical_curve
from labapp.records.simcal import SimCalFile


def physical_curve(run: Path) -> PhysicalCurve:
    """A run's physical curve: its ``analysis/curve.csv`` when analysed, else the run analysed now with its
    own calibration."""
    analysed = Path(run) / "analysis" / "curve.csv"
    return read_physical_curve(analysed if analysed.is_file() else run)


Curve = tuple[str, np.ndarray, np.ndarray, bool, tuple[np.ndarray, np.ndarray] | None]
"""An overlay curve: label, time (s), released (g), dashed (a prediction), its band (lower g, upper g) or None."""


def run_curve(run: Path) -> Curve:
    """A run as an overlay curve (slow for a run never analysed: call it off the GUI thread)."""
    curve = physical_curve(run)
    return Path(run).name, np.asarray(curve.t_s), np.asarray(curve.released_g), False, None


def prediction_curve(mesh: str, simcal: SimCalFile) -> Curve:
    """A mesh's release predicted through ``simcal`` with its band, as an overlay curve (simulations: off the GUI
    thread)."""
    t, grams, band = predict_mesh_band(mesh, simcal)
    return f"{Path(mesh).name} predicted ({simcal.cal.model})", np.asarray(t), np.asarray(grams), True, band


class PhysicalOverlay(QWidget):
    """A plot of released grams over hours to which runs and predictions are added one by one."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.plot = time_plot("overlay: released (g) over time since drop")
        self.plot.setLabel("left", "released (g)")
        self.plot.addLegend()
        self.curves: list[tuple[str, np.ndarray, np.ndarray]] = []
        self.bands = 0
        QVBoxLayout(self).addWidget(self.plot)

    def add(self, label: str, t_s: np.ndarray, released_g: np.ndarray, dashed: bool = False,
            band: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """Draw one curve (s, g), with its band shaded in the curve's colour."""
        colour = pg.intColor(len(self.curves), hues=9)
        pen = pg.mkPen(colour, width=2,
                       style=pg.QtCore.Qt.PenStyle.DashLine if dashed else pg.QtCore.Qt.PenStyle.SolidLine)
        if band is not None:
            lower, upper = (self.plot.plot(np.asarray(t_s), np.asarray(b), pen=pg.mkPen(None)) for b in band)
            fill = QColor(colour)
            fill.setAlpha(50)
            self.plot.addItem(pg.FillBetweenItem(lower, upper, brush=fill))
            self.bands += 1
        self.plot.plot(np.asarray(t_s), np.asarray(released_g), pen=pen, name=label)
        self.curves.append((label, np.asarray(t_s), np.asarray(released_g)))

    def add_run(self, run: Path) -> None:
        """Overlay a run (analysed if it has no ``analysis/curve.csv`` yet)."""
        self.add(*run_curve(run))

    def add_prediction(self, mesh: str, simcal: SimCalFile) -> None:
        """Overlay a mesh's release predicted through ``simcal`` (dashed)."""
        self.add(*prediction_curve(mesh, simcal))

    def clear(self) -> None:
        """Remove every curve."""
        self.plot.clear()
        self.curves.clear()
        self.bands = 0
