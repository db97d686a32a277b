"""Overlay of release curves in physical units: several runs and simulated predictions, grams over hours."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pyqtgraph as pg
from PySide6.QtWidgets import QVBoxLayout, QWidget

from labapp.gui.plots import time_plot
from labapp.jobs.calibrate_sim import SimCalFile
from labapp.jobs.physical import predict_mesh
from labapp.records.curvefiles import PhysicalCurve, read_physical_curve


def physical_curve(run: Path) -> PhysicalCurve:
    """A run's physical curve: its ``analysis/curve.csv`` when analysed, else the run analysed now with its
    own calibration."""
    analysed = Path(run) / "analysis" / "curve.csv"
    return read_physical_curve(analysed if analysed.is_file() else run)


Curve = tuple[str, np.ndarray, np.ndarray, bool]
"""An overlay curve: label, time (s), released (g), dashed (a prediction)."""


def run_curve(run: Path) -> Curve:
    """A run as an overlay curve (slow for a run never analysed: call it off the GUI thread)."""
    curve = physical_curve(run)
    return Path(run).name, np.asarray(curve.t_s), np.asarray(curve.released_g), False


def prediction_curve(mesh: str, simcal: SimCalFile) -> Curve:
    """A mesh's release predicted through ``simcal`` as an overlay curve (a simulation: off the GUI thread)."""
    t, grams = predict_mesh(mesh, simcal)
    return f"{Path(mesh).name} predicted ({simcal.cal.model})", np.asarray(t), np.asarray(grams), True


class PhysicalOverlay(QWidget):
    """A plot of released grams over hours to which runs and predictions are added one by one."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.plot = time_plot("overlay: released (g) over time since drop")
        self.plot.setLabel("left", "released (g)")
        self.plot.addLegend()
        self.curves: list[tuple[str, np.ndarray, np.ndarray]] = []
        QVBoxLayout(self).addWidget(self.plot)

    def add(self, label: str, t_s: np.ndarray, released_g: np.ndarray, dashed: bool = False) -> None:
        """Draw one curve (s, g)."""
        pen = pg.mkPen(pg.intColor(len(self.curves), hues=9), width=2,
                       style=pg.QtCore.Qt.PenStyle.DashLine if dashed else pg.QtCore.Qt.PenStyle.SolidLine)
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
