"""Release curve (raw and Savitzky-Golay smoothed; g/kg left axis, released g right axis) and bath plots.

Data arrive by ``add_frame``/``add_reading`` (cheap appends, any rate); the plots redraw from a ~10 Hz
timer only when something changed, so a fast simulated run never floods the event loop.
"""
from __future__ import annotations

import math

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QVBoxLayout, QWidget

from analysis import smooth_curve
from analysis.curve import DEFAULT_ORDER, DEFAULT_WINDOW_S
from labapp.acquisition.settings import WATER

REDRAW_MS = 100


class PlotsPanel(QWidget):
    """Live plots of one run. ``water_g`` sets the released-mass axis (g = g/kg x kg of water). The smoothed
    curve uses the analysis' Savitzky-Golay window and order, the curve the steady-state stop judges."""

    def __init__(self, parent: QWidget | None = None, water_g: float = WATER.default,
                 smooth_window_s: float = DEFAULT_WINDOW_S, smooth_order: int = DEFAULT_ORDER) -> None:
        super().__init__(parent)
        self.smooth_window_s, self.smooth_order = smooth_window_s, smooth_order
        self.t_s: list[float] = []
        self.conc: list[float] = []
        self.bath: dict[str, list[float]] = {"t_s": [], "plate_c": [], "probe_c": [], "speed_rpm": []}
        self._dirty = False
        self.graphics = pg.GraphicsLayoutWidget()
        self.release = self.graphics.addPlot(row=0, col=0, title="release")
        self.release.setLabel("bottom", "time since drop", units="s")
        self.release.setLabel("left", "concentration (g/kg)")
        self.release.showAxis("right")
        self.release.setLabel("right", "released (g)")
        self.release.addLegend(offset=(10, 10))
        self.raw_curve = self.release.plot([], [], pen=None, symbol="o", symbolSize=4, symbolBrush=(120, 120, 255),
                                           name="measured")
        self.smooth_curve = self.release.plot([], [], pen=pg.mkPen("r", width=2), name="Savitzky-Golay")
        self.temps = self.graphics.addPlot(row=1, col=0, title="bath")
        self.temps.setLabel("bottom", "time since drop", units="s")
        self.temps.setLabel("left", "temperature (C)")
        self.temps.addLegend(offset=(10, 10))
        self.plate_curve = self.temps.plot([], [], pen=pg.mkPen((255, 140, 0), width=2), name="plate")
        self.probe_curve = self.temps.plot([], [], pen=pg.mkPen((0, 200, 0), width=2), name="probe")
        self.speed_view = pg.ViewBox()
        self.temps.showAxis("right")
        self.temps.scene().addItem(self.speed_view)
        self.temps.getAxis("right").linkToView(self.speed_view)
        self.temps.getAxis("right").setLabel("stirring (rpm)")
        self.speed_view.setXLink(self.temps)
        self.speed_curve = pg.PlotCurveItem(pen=pg.mkPen((150, 150, 150), width=1, style=pg.QtCore.Qt.PenStyle.DashLine))
        self.speed_view.addItem(self.speed_curve)
        self.temps.vb.sigResized.connect(self._sync_views)
        for plot in (self.release, self.temps):
            for side in ("left", "right", "bottom"):
                plot.getAxis(side).enableAutoSIPrefix(False)  # no "(x0.001)" rescaling of g/kg, g or s
        self.set_water(water_g)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.graphics)
        self.timer = QTimer(self)
        self.timer.timeout.connect(self.redraw)
        self.timer.start(REDRAW_MS)

    def set_water(self, water_g: float) -> None:
        """Scale the released-mass axis for ``water_g`` g of water."""
        self.water_g = water_g
        self.release.getAxis("right").setScale(water_g / 1000.0)

    def clear(self) -> None:
        """Forget all data (a new run)."""
        self.t_s.clear()
        self.conc.clear()
        for values in self.bath.values():
            values.clear()
        self._dirty = True

    def add_frame(self, t_s: float, conc_g_per_kg: float) -> None:
        """Append one analysed frame (NaN concentrations are kept out of the curve)."""
        if not math.isnan(conc_g_per_kg):
            self.t_s.append(t_s)
            self.conc.append(conc_g_per_kg)
            self._dirty = True

    def add_reading(self, t_s: float, plate_c: float | None, probe_c: float | None, speed_rpm: float | None) -> None:
        """Append one hotplate reading (unknown values as NaN)."""
        for key, value in (("t_s", t_s), ("plate_c", plate_c), ("probe_c", probe_c), ("speed_rpm", speed_rpm)):
            self.bath[key].append(math.nan if value is None else value)
        self._dirty = True

    def smoothed(self) -> np.ndarray:
        """The Savitzky-Golay smoothed concentrations (g/kg) of the current data (raw while too short)."""
        t, c = np.asarray(self.t_s), np.asarray(self.conc)
        try:
            return np.asarray(smooth_curve(t, c, window_s=self.smooth_window_s, order=self.smooth_order))
        except ValueError:
            return c

    def redraw(self) -> None:
        """Redraw if data changed since the last call (the timer calls this at ~10 Hz)."""
        if not self._dirty:
            return
        self._dirty = False
        self.raw_curve.setData(self.t_s, self.conc)
        self.smooth_curve.setData(self.t_s, self.smoothed() if self.t_s else [])
        b = {k: np.asarray(v, dtype=float) for k, v in self.bath.items()}
        self.plate_curve.setData(b["t_s"], b["plate_c"], connect="finite")
        self.probe_curve.setData(b["t_s"], b["probe_c"], connect="finite")
        self.speed_curve.setData(b["t_s"], b["speed_rpm"], connect="finite")

    def _sync_views(self) -> None:
        self.speed_view.setGeometry(self.temps.vb.sceneBoundingRect())
        self.speed_view.linkedViewChanged(self.temps.vb, self.speed_view.XAxis)
