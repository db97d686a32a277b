"""The calibration-series wizard: clear water, then add filament / enter mass / capture, repeat, fit, save."""
from __future__ import annotations

import logging

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (QDoubleSpinBox, QFormLayout, QGroupBox, QHBoxLayout, QLabel, QLineEdit, QPushButton,
                               QVBoxLayout, QWidget)

log = logging.getLogger(__name__)


def parse_masses(text: str) -> tuple[float, ...]:
    """``"0.25, 0.5, 1"`` -> (0.25, 0.5, 1.0): cumulative masses in g (empty: ask the operator each time)."""
    return tuple(float(t) for t in text.replace(";", ",").split(",") if t.strip())


class CalibrationWizard(QWidget):
    """Guides a calibration series. Emits ``start_requested``; while the engine asks for a mass, the operator
    enters it and presses "Capture" (``mass_entered(value)``) or "Finish and fit" (``finish_requested``)."""

    start_requested = Signal()
    mass_entered = Signal(float)
    finish_requested = Signal()

    def __init__(self, simulate: bool, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.water = QDoubleSpinBox()
        self.water.setRange(1.0, 5000.0)
        self.water.setValue(500.0)
        self.water.setSuffix(" g")
        self.masses = QLineEdit("0.25, 0.5, 0.875, 1.25, 1.75" if simulate else "")
        self.masses.setToolTip("cumulative masses added by the simulated bench by itself; empty: ask each time")
        self.masses.setEnabled(simulate)
        self.mass = QDoubleSpinBox()
        self.mass.setRange(0.0, 100.0)
        self.mass.setDecimals(4)
        self.mass.setSuffix(" g")
        self.step_label = QLabel("1. set the crop in the live view  2. start: the clear-water frame is captured")
        self.step_label.setWordWrap(True)
        self.result_label = QLabel("")
        self.result_label.setWordWrap(True)
        self.start_button = QPushButton("Start series")
        self.capture_button = QPushButton("Capture")
        self.finish_button = QPushButton("Finish and fit")
        self.start_button.clicked.connect(self.start_requested)
        self.capture_button.clicked.connect(self._capture)
        self.finish_button.clicked.connect(self.finish_requested)
        box = QGroupBox("calibration series (paper section 4.2)")
        form = QFormLayout(box)
        form.addRow("water", self.water)
        form.addRow("simulated masses", self.masses)
        form.addRow("cumulative mass added", self.mass)
        row = QHBoxLayout()
        for b in (self.start_button, self.capture_button, self.finish_button):
            row.addWidget(b)
        layout = QVBoxLayout(self)
        layout.addWidget(box)
        layout.addLayout(row)
        layout.addWidget(self.step_label)
        layout.addWidget(self.result_label)
        layout.addStretch(1)
        self.set_asking(False, "")

    def _capture(self) -> None:
        self.mass_entered.emit(self.mass.value())

    def set_asking(self, asking: bool, text: str) -> None:
        """Enable the capture/finish buttons while the engine waits for a mass."""
        self.capture_button.setEnabled(asking)
        self.finish_button.setEnabled(asking)
        if text:
            self.step_label.setText(text)

    def show_result(self, text: str) -> None:
        """Show the outcome (calibration path or what went wrong)."""
        self.result_label.setText(text)
