"""Release curve (raw and Savitzky-Golay smoothed; g/kg left axis, released g or % of the weighed mass right axis)
and bath plots (plate, probe, stirring, the setpoint band), on a time axis in h:mm like the status line, with
marks for the drop, steady state, gaps, resumes and faults.

Data arrive by ``add_frame``/``add_reading`` (cheap appends, any rate); the plots redraw from a ~10 Hz
timer only when something changed, so a fast simulated run never floods the event loop. Before the drop the bath
plot draws the hotplate's readings as they arrive (``add_heating_reading``), at negative times: time zero is now
until the drop, and the drop itself from then on, so the heating stays on the plot before the release begins.
The stirring speed has its own right axis from 0 to twice its highest value, so read-out noise stays small.
"""
from __future__ import annotations

import math

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import QCheckBox, QHBoxLayout, QSplitter, QVBoxLayout, QWidget

from analysis import smooth_curve
from analysis.curve import DEFAULT_ORDER, DEFAULT_WINDOW_S
from labapp.acquisition.settings import WATER

REDRAW_MS = 100
DEGREES_C = "\u00b0C"
TIME_LABEL = "time since drop (h:mm)"
HEATING_LABEL = "time before now (h:mm)"
_STEPS_S = (1, 2, 5, 10, 15, 30, 60, 120, 300, 600, 900, 1800, 3600, 7200, 3 * 3600, 6 * 3600, 12 * 3600, 86400)
LEGEND_BRUSH = pg.mkBrush(0, 0, 0, 170)
LABEL_BRUSH = pg.mkBrush(0, 0, 0, 190)
"""A mark's label background."""
LABEL_ROWS = (0.92, 0.80, 0.68)
"""Heights (fraction of the plot) at which successive marks' labels sit, so that close marks do not overlap."""
"""A legend's background: dark enough to read its labels over the traces it may cover."""

#: Colour of each kind of mark (any other kind is drawn magenta).
MARK_COLOURS: dict[str, tuple[int, int, int]] = {
    "drop": (0, 170, 0), "steady": (30, 110, 255), "gap": (150, 150, 150), "resume": (0, 190, 190),
    "fault": (230, 0, 0), "alarm": (230, 0, 0), "excursion": (255, 140, 0),
}


def hmm(t_s: float, seconds: bool = False) -> str:
    """Seconds as ``H:MM`` (``H:MM:SS`` with ``seconds``), the units of the status line."""
    sign, t = ("-" if t_s < 0 else ""), int(round(abs(t_s)))
    text = f"{sign}{t // 3600}:{t // 60 % 60:02d}"
    return text + f":{t % 60:02d}" if seconds else text


class TimeAxis(pg.AxisItem):
    """A bottom axis in seconds whose ticks read ``H:MM`` (``H:MM:SS`` below a minute's spacing), at round
    steps of seconds, minutes or hours."""

    def __init__(self, **kwargs) -> None:
        super().__init__("bottom", **kwargs)
        self.enableAutoSIPrefix(False)

    def tickSpacing(self, minVal: float, maxVal: float, size: float):  # noqa: N802, N803 (pyqtgraph override)
        span = max(maxVal - minVal, 1e-9)
        fit = max(size / 90.0, 1.0)                # at most one label per ~90 px
        major = next((s for s in _STEPS_S if span / s <= fit), _STEPS_S[-1] * math.ceil(span / fit / _STEPS_S[-1]))
        minor = next((s for s in reversed(_STEPS_S) if s < major and major % s == 0), major / 2)
        return [(float(major), 0.0), (float(minor), 0.0)]

    def tickStrings(self, values, scale, spacing):  # noqa: N802 (pyqtgraph override)
        return [hmm(v, seconds=spacing < 60) for v in values]


def time_plot(title: str) -> pg.PlotWidget:
    """A plot whose x axis is time since the drop in ``H:MM``."""
    widget = pg.PlotWidget(title=title, axisItems={"bottom": TimeAxis()})
    widget.setLabel("bottom", TIME_LABEL)
    widget.setMinimumHeight(120)
    return widget


class PlotsPanel(QWidget):
    """Live plots of one run. ``water_g`` sets the released-mass axis (g = g/kg x kg of water). The smoothed
    curve uses the analysis' Savitzky-Golay window and order, the curve the steady-state stop judges.

    ``orientation``: the release and bath plots above each other (vertical) or side by side, in a splitter
    the operator can move.
    """

    def __init__(self, parent: QWidget | None = None, water_g: float = WATER.default,
                 smooth_window_s: float = DEFAULT_WINDOW_S, smooth_order: int = DEFAULT_ORDER,
                 orientation: Qt.Orientation = Qt.Orientation.Vertical) -> None:
        super().__init__(parent)
        self.smooth_window_s, self.smooth_order = smooth_window_s, smooth_order
        self.t_s: list[float] = []
        self.conc: list[float] = []
        self.bath: dict[str, list[float]] = {"t_s": [], "plate_c": [], "probe_c": [], "speed_rpm": []}
        self.heating: dict[str, list[float]] = {"t_unix_s": [], "plate_c": [], "probe_c": [], "speed_rpm": []}
        """Readings before the drop, on the engine's clock (drawn at ``t_unix_s - heating_zero``)."""
        self.heating_zero: float | None = None
        self.dropped = False
        self.marks: list[tuple[str, float, str]] = []
        self._mark_items: list[pg.GraphicsObject] = []
        self.object_mass_g: float | None = None
        self._dirty = False
        self.release_widget = time_plot("release")
        self.release = self.release_widget.getPlotItem()
        self.release.setLabel("left", "concentration (g/kg)")
        self.release.showAxis("right")
        self.release.addLegend(offset=(-10, -10), brush=LEGEND_BRUSH)   # bottom right: under a rising curve
        self.raw_curve = self.release.plot([], [], pen=None, symbol="o", symbolSize=4, symbolBrush=(120, 120, 255),
                                           name="measured")
        self.smooth_curve = self.release.plot([], [], pen=pg.mkPen("r", width=2), name="Savitzky-Golay")
        self.bath_widget = time_plot("bath")
        self.temps = self.bath_widget.getPlotItem()
        self.temps.setLabel("left", f"temperature ({DEGREES_C})")
        self.temps.addLegend(offset=(-10, -10), brush=LEGEND_BRUSH)     # bottom right: the bath runs along the top
        self.band = pg.LinearRegionItem(orientation="horizontal", movable=False, brush=pg.mkBrush(255, 140, 0, 40),
                                        pen=pg.mkPen((255, 140, 0, 120), style=Qt.PenStyle.DotLine))
        self.band.setZValue(-10)
        self.band.hide()
        self.temps.addItem(self.band, ignoreBounds=True)
        self.plate_curve = self.temps.plot([], [], pen=pg.mkPen((255, 140, 0), width=2), name="plate")
        self.probe_curve = self.temps.plot([], [], pen=pg.mkPen((0, 200, 0), width=2), name="probe")
        self.speed_view = pg.ViewBox()
        self.temps.showAxis("right")
        self.temps.scene().addItem(self.speed_view)
        self.temps.getAxis("right").linkToView(self.speed_view)
        self.temps.getAxis("right").setLabel("stirring (rpm)")
        self.speed_view.setXLink(self.temps)
        self.speed_curve = pg.PlotCurveItem(pen=pg.mkPen((150, 150, 150), width=1, style=Qt.PenStyle.DashLine))
        self.speed_view.addItem(self.speed_curve)
        self.speed_view.setMouseEnabled(y=False)
        self.speed_view.enableAutoRange(axis=pg.ViewBox.YAxis, enable=False)
        self.speed_view.setYRange(0.0, 300.0, padding=0.0)
        self.temps.legend.addItem(self.speed_curve, "stirring (rpm, right)")
        self.temps.vb.sigResized.connect(self._sync_views)
        for plot in (self.release, self.temps):
            for side in ("left", "right"):
                plot.getAxis(side).enableAutoSIPrefix(False)  # no "(x0.001)" rescaling of g/kg, g or s
        self.percent = QCheckBox("released as % of the weighed mass")
        self.percent.setToolTip("right axis in % of the object's weighed mass (needs the mass)")
        self.percent.setEnabled(False)
        self.percent.setVisible(False)                # shown once a weighed mass is known
        self.percent.toggled.connect(self._scale_right_axis)
        self.set_water(water_g)
        self.splitter = QSplitter(orientation)
        self.splitter.addWidget(self.release_widget)
        self.splitter.addWidget(self.bath_widget)
        self.splitter.setStretchFactor(0, 1)
        self.splitter.setStretchFactor(1, 1)
        self.splitter.setChildrenCollapsible(False)
        options = QHBoxLayout()
        options.setContentsMargins(4, 0, 4, 0)
        options.addWidget(self.percent)
        options.addStretch(1)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(0)
        layout.addWidget(self.splitter, 1)
        layout.addLayout(options)
        self.timer = QTimer(self)
        self.timer.timeout.connect(self.redraw)
        self.timer.start(REDRAW_MS)

    def set_water(self, water_g: float) -> None:
        """Scale the released-mass axis for ``water_g`` g of water."""
        self.water_g = water_g
        self._scale_right_axis()

    def set_object_mass(self, mass_g: float | None) -> None:
        """The object's weighed mass (None: not weighed), for the % axis."""
        self.object_mass_g = mass_g if mass_g else None
        self.percent.setEnabled(self.object_mass_g is not None)
        self.percent.setVisible(self.object_mass_g is not None)
        if self.object_mass_g is None:
            self.percent.setChecked(False)
        self._scale_right_axis()

    def _scale_right_axis(self) -> None:
        axis = self.release.getAxis("right")
        if self.percent.isChecked() and self.object_mass_g:
            axis.setScale(self.water_g / 1000.0 / self.object_mass_g * 100.0)
            axis.setLabel(f"released (% of {self.object_mass_g:g} g)")
        else:
            axis.setScale(self.water_g / 1000.0)
            axis.setLabel("released (g)")

    def set_duration(self, max_duration_s: float) -> None:
        """Show the release plot from the drop to the run's maximum duration (s) until data arrive, not the
        previous run's axes."""
        self.release.setXRange(0.0, max_duration_s, padding=0.02)
        self.release.setYRange(0.0, 0.1, padding=0.0)          # fitted to the data again from the first frame

    def set_setpoint_band(self, setpoint_c: float | None, tolerance_c: float | None) -> None:
        """Shade setpoint +- tolerance on the bath plot (None: no band)."""
        if setpoint_c is None or tolerance_c is None:
            self.band.hide()
            return
        self.band.setRegion((setpoint_c - tolerance_c, setpoint_c + tolerance_c))
        self.band.show()

    def mark(self, kind: str, t_s: float, text: str = "", end_s: float | None = None) -> None:
        """Mark time ``t_s`` (s since the drop) on both plots: a labelled vertical line, or a shaded span to
        ``end_s`` (a gap). ``kind``: drop, steady, gap, resume, fault, alarm, excursion or any other word."""
        colour = MARK_COLOURS.get(kind, (200, 0, 200))
        self.marks.append((kind, float(t_s), text))
        row = LABEL_ROWS[sum(1 for _, _, label in self.marks if label) % len(LABEL_ROWS)]
        for plot in (self.release, self.temps):
            if end_s is not None and end_s > t_s:
                item = pg.LinearRegionItem(values=(t_s, end_s), movable=False, brush=pg.mkBrush(*colour, 50),
                                           pen=pg.mkPen((*colour, 120)))
            else:
                item = pg.InfiniteLine(pos=t_s, angle=90, movable=False,
                                       pen=pg.mkPen(colour, width=1.5, style=Qt.PenStyle.DashLine))
            if plot is self.release and text:          # labelled on the release plot only
                # horizontal, near the top, on a dark ground: a label never longer than the plot is high; left of
                # the line (an alarm comes at the newest time, the right edge), right of it for the drop and a resume
                right = kind in ("drop", "resume")
                label = pg.InfLineLabel(item if isinstance(item, pg.InfiniteLine) else item.lines[0], text=text,
                                        position=row,
                                        anchor=(0 if right else 1, 0.5), color=colour, fill=LABEL_BRUSH)
                label.setZValue(20)
            plot.addItem(item, ignoreBounds=True)
            self._mark_items.append((plot, item))

    def clear(self) -> None:
        """Forget all data and marks (a new run), and fit the axes to the new data again."""
        self.t_s.clear()
        self.conc.clear()
        for values in (*self.bath.values(), *self.heating.values()):
            values.clear()
        self.heating_zero, self.dropped = None, False
        self.bath_widget.setLabel("bottom", TIME_LABEL)
        for plot in (self.release, self.temps):
            plot.enableAutoRange()
        for plot, item in self._mark_items:
            plot.removeItem(item)
        self._mark_items.clear()
        self.marks.clear()
        self._dirty = True

    def add_frame(self, t_s: float, conc_g_per_kg: float) -> None:
        """Append one analysed frame (NaN concentrations are kept out of the curve)."""
        if not math.isnan(conc_g_per_kg):
            self.t_s.append(t_s)
            self.conc.append(conc_g_per_kg)
            self._dirty = True
            if len(self.t_s) == 1:
                self.release.enableAutoRange()

    def add_reading(self, t_s: float, plate_c: float | None, probe_c: float | None, speed_rpm: float | None) -> None:
        """Append one hotplate reading (unknown values as NaN)."""
        for key, value in (("t_s", t_s), ("plate_c", plate_c), ("probe_c", probe_c), ("speed_rpm", speed_rpm)):
            self.bath[key].append(math.nan if value is None else value)
        self._dirty = True

    def add_heating_reading(self, t_unix_s: float, plate_c: float | None, probe_c: float | None,
                            speed_rpm: float | None) -> None:
        """Append one reading from before the drop (``t_unix_s`` on the engine's clock); until
        :meth:`set_drop`, the newest is time zero."""
        for key, value in (("t_unix_s", t_unix_s), ("plate_c", plate_c), ("probe_c", probe_c),
                           ("speed_rpm", speed_rpm)):
            self.heating[key].append(math.nan if value is None else value)
        if not self.dropped:
            self.heating_zero = t_unix_s
            self.bath_widget.setLabel("bottom", HEATING_LABEL)
        self._dirty = True

    def set_drop(self, t0_unix_s: float | None) -> None:
        """The drop happened at ``t0_unix_s`` (engine clock): the readings before it move to negative times."""
        self.dropped = True
        if t0_unix_s is not None:
            self.heating_zero = t0_unix_s
        self.bath_widget.setLabel("bottom", TIME_LABEL)
        self._dirty = True

    @staticmethod
    def t_now(t_unix_s: float, t0_unix_s: float | None, fallback: float | None) -> float:
        """Seconds since the drop at ``t_unix_s`` (``fallback``, else 0, without a drop time)."""
        if t0_unix_s is not None:
            return t_unix_s - t0_unix_s
        return fallback if fallback is not None else 0.0

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
        if self.heating["t_unix_s"] and self.heating_zero is not None:
            h = {k: np.asarray(v, dtype=float) for k, v in self.heating.items()}
            h["t_s"] = h.pop("t_unix_s") - self.heating_zero
            b = {k: np.concatenate([h[k], [math.nan], b[k]]) for k in b}     # NaN: no line across the drop
        self.plate_curve.setData(b["t_s"], b["plate_c"], connect="finite")
        self.probe_curve.setData(b["t_s"], b["probe_c"], connect="finite")
        self.speed_curve.setData(b["t_s"], b["speed_rpm"], connect="finite")
        speeds = b["speed_rpm"][np.isfinite(b["speed_rpm"])]
        top = 2.0 * float(speeds.max()) if speeds.size and speeds.max() > 0 else 300.0
        self.speed_view.setYRange(0.0, top, padding=0.0)

    def _sync_views(self) -> None:
        self.speed_view.setGeometry(self.temps.vb.sceneBoundingRect())
        self.speed_view.linkedViewChanged(self.temps.vb, self.speed_view.XAxis)
