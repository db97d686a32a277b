"""Overlay of release curves in physical units: several runs and simulated predictions, grams over hours."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pyqtgraph as pg
from PySide6.QtWidgets import QVBoxLayout, QWidget

from labapp.jobs.calibrate_sim import SimCalFile
from labapp.jobs.physical import predict_mesh
from labapp.records.curvefiles import PhysicalCurve, read_physical_curve


def run_curve(run: Path) -> PhysicalCurve:
    """A run's physical curve: its ``analysis/curve.csv`` when analysed, else the run analysed now with its
    own calibration."""
    analysed = Path(run) / "analysis" / "curve.csv"
    return read_physical_curve(analysed if analysed.is_file() else run)


class PhysicalOverlay(QWidget):
    """A plot of released grams over hours to which runs and predictions are added one by one."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.plot = pg.PlotWidget(title="overlay: released (g) over time since drop (h)")
        self.plot.setLabel("bottom", "time since drop (h)")
        self.plot.setLabel("left", "released (g)")
        self.plot.addLegend()
        self.curves: list[tuple[str, np.ndarray, np.ndarray]] = []
        QVBoxLayout(self).addWidget(self.plot)

    def add(self, label: str, t_s: np.ndarray, released_g: np.ndarray, dashed: bool = False) -> None:
        """Draw one curve (s, g)."""
        pen = pg.mkPen(pg.intColor(len(self.curves), hues=9), width=2,
                       style=pg.QtCore.Qt.PenStyle.DashLine if dashed else pg.QtCore.Qt.PenStyle.SolidLine)
        self.plot.plot(np.asarray(t_s) / 3600.0, np.asarray(released_g), pen=pen, name=label)
        self.curves.append((label, np.asarray(t_s), np.asarray(released_g)))

    def add_run(self, run: Path) -> None:
        """Overlay a run (analysed if it has no ``analysis/curve.csv`` yet)."""
        curve = run_curve(run)
        self.add(Path(run).name, curve.t_s, curve.released_g)

    def add_prediction(self, mesh: str, simcal: SimCalFile) -> None:
        """Overlay a mesh's release predicted through ``simcal`` (dashed)."""
        t, grams = predict_mesh(mesh, simcal)
        self.add(f"{Path(mesh).name} predicted ({simcal.cal.model})", t, grams, dashed=True)

    def clear(self) -> None:
        """Remove every curve."""
        self.plot.clear()
        self.curves.clear()
