"""Run controls: the run's settings, start / object dropped / stop / abort, and the active calibration."""
from __future__ import annotations

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QCheckBox,
    QDoubleSpinBox,
    QFileDialog,
    QFormLayout,
    QGridLayout,
    QGroupBox,
    QHBoxLayout,
    QLineEdit,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from labapp.acquisition.procedures import RunConfig


def _spin(value: float, lo: float, hi: float, decimals: int = 1, suffix: str = "") -> QDoubleSpinBox:
    box = QDoubleSpinBox()
    box.setRange(lo, hi)
    box.setDecimals(decimals)
    box.setValue(value)
    box.setSuffix(suffix)
    return box


class RunControls(QWidget):
    """Settings form and buttons. Emits ``start_requested``, ``drop_confirmed``, ``stop_requested``,
    ``abort_requested``; the main window wires them to the engine and calls :meth:`set_running`."""

    start_requested = Signal()
    drop_confirmed = Signal()
    stop_requested = Signal()
    abort_requested = Signal()

    def __init__(self, simulate: bool, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        d = RunConfig()
        self.name = QLineEdit("run")
        self.object_name = QLineEdit("")
        self.object_mass = _spin(1.75, 0.0, 100.0, 3, " g")
        self.water = _spin(d.water_g, 1.0, 5000.0, 1, " g")
        self.interval = _spin(d.interval_s, 1.0, 3600.0, 1, " s")
        self.setpoint = _spin(d.setpoint_c, 0.0, 100.0, 1, " C")
        self.rpm = _spin(d.speed_rpm, 0.0, 1400.0, 0, " rpm")
        self.max_hours = _spin(d.max_duration_s / 3600, 0.01, 48.0, 2, " h")
        self.stop_on_steady = QCheckBox("stop at steady state")
        self.stop_on_steady.setChecked(d.stop_on_steady)
        self.auto_drop = QCheckBox("drop by itself once stable (simulation)")
        self.auto_drop.setEnabled(simulate)
        self.calibration = QLineEdit("")
        self.calibration.setPlaceholderText("bench calibration JSON (live concentration)")
        browse = QPushButton("...")
        browse.clicked.connect(self._browse)
        self.notes = QLineEdit("")
        form_box = QGroupBox("run")
        form = QFormLayout(form_box)
        form.addRow("name", self.name)
        form.addRow("object", self.object_name)
        form.addRow("object mass", self.object_mass)
        form.addRow("water", self.water)
        form.addRow("interval", self.interval)
        form.addRow("setpoint", self.setpoint)
        form.addRow("stirring", self.rpm)
        form.addRow("max duration", self.max_hours)
        form.addRow("", self.stop_on_steady)
        form.addRow("", self.auto_drop)
        cal_row = QHBoxLayout()
        cal_row.addWidget(self.calibration, 1)
        cal_row.addWidget(browse)
        form.addRow("calibration", cal_row)
        form.addRow("notes", self.notes)
        self.start_button = QPushButton("Start")
        self.drop_button = QPushButton("Object dropped")
        self.stop_button = QPushButton("Stop")
        self.abort_button = QPushButton("Abort")
        self.start_button.clicked.connect(self.start_requested)
        self.drop_button.clicked.connect(self.drop_confirmed)
        self.stop_button.clicked.connect(self.stop_requested)
        self.abort_button.clicked.connect(self.abort_requested)
        grid = QGridLayout()
        for i, b in enumerate((self.start_button, self.drop_button, self.stop_button, self.abort_button)):
            grid.addWidget(b, i // 2, i % 2)
        layout = QVBoxLayout(self)
        layout.addWidget(form_box)
        layout.addLayout(grid)
        layout.addStretch(1)
        self.set_running(False)

    def _browse(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "bench calibration", "", "JSON (*.json)")
        if path:
            self.calibration.setText(path)

    def config(self) -> RunConfig:
        """The run settings as a :class:`RunConfig` (raises ValueError on a bad combination)."""
        return RunConfig(name=self.name.text() or "run", interval_s=self.interval.value(),
                         setpoint_c=self.setpoint.value(), speed_rpm=self.rpm.value(),
                         max_duration_s=self.max_hours.value() * 3600, stop_on_steady=self.stop_on_steady.isChecked(),
                         water_g=self.water.value(), object_mass_g=self.object_mass.value() or None,
                         object_name=self.object_name.text(), notes=self.notes.text(),
                         auto_drop=self.auto_drop.isChecked())

    def set_running(self, running: bool, waiting_drop: bool = False) -> None:
        """Enable the buttons that make sense now."""
        self.start_button.setEnabled(not running)
        self.drop_button.setEnabled(running and waiting_drop)
        self.stop_button.setEnabled(running)
        self.abort_button.setEnabled(running)
