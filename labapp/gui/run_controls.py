"""Run controls: the run's settings, start / object dropped / stop / abort, and the active calibration."""
from __future__ import annotations

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QCheckBox,
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
from labapp.acquisition.settings import INTERVAL, MAX_DURATION, OBJECT_MASS, BathSettings
from labapp.gui.fields import SettingBox


class RunControls(QWidget):
    """Settings form and buttons. Emits ``start_requested``, ``drop_confirmed``, ``stop_requested``,
    ``abort_requested``; the main window wires them to the engine and calls :meth:`set_running`. The bath
    (water, temperature, stirring) is set in the device panel."""

    start_requested = Signal()
    drop_confirmed = Signal()
    stop_requested = Signal()
    abort_requested = Signal()

    def __init__(self, simulate: bool, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        d = RunConfig()
        self.name = QLineEdit(d.name)
        self.object_name = QLineEdit("")
        self.object_mass = SettingBox(OBJECT_MASS, none_text="not weighed")
        self.interval = SettingBox(INTERVAL)
        self.max_hours = SettingBox(MAX_DURATION)
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
        for box in (self.object_mass, self.interval, self.max_hours):
            form.addRow(box.setting.label, box)
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

    def config(self, bath: BathSettings) -> RunConfig:
        """The run settings with ``bath`` as a :class:`RunConfig` (UsageError on a bad value)."""
        return RunConfig(name=self.name.text() or RunConfig.name, interval_s=self.interval.stored(),
                         max_duration_s=self.max_hours.stored(), stop_on_steady=self.stop_on_steady.isChecked(),
                         object_mass_g=self.object_mass.stored(), object_name=self.object_name.text(),
                         notes=self.notes.text(), auto_drop=self.auto_drop.isChecked(), bath=bath)

    def set_running(self, running: bool, waiting_drop: bool = False) -> None:
        """Enable the buttons that make sense now."""
        self.start_button.setEnabled(not running)
        self.drop_button.setEnabled(running and waiting_drop)
        self.stop_button.setEnabled(running)
        self.abort_button.setEnabled(running)
