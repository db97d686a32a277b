"""Run controls: the run's settings, start / object dropped / stop, abort kept apart, and the active calibration.

Start stays disabled, with the reason shown under it, while a field holds a value outside its range or the
settings cannot work together (a steady-state stop without a calibration); Stop and Abort ask first
(:mod:`labapp.gui.dialogs`), naming the run and what cannot be undone. While a run records, its settings are
locked except the ones declared changeable during a run (the maximum and minimum duration): "Change
duration..." asks for them and a reason. A large state word at the top (HEATING, WAITING FOR DROP, RECORDING,
LINK LOST, ...) can be read from across the room.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from PySide6.QtCore import Signal
from PySide6.QtGui import QFont
from PySide6.QtWidgets import (
    QCheckBox,
    QFileDialog,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from labapp.acquisition.events import Phase, StateChanged
from labapp.acquisition.procedures import RunConfig
from labapp.acquisition.settings import EXCURSION, INTERVAL, MAX_DURATION, OBJECT_MASS, BathSettings
from labapp.gui import dialogs
from labapp.gui.fields import SettingBox, narrow_form, problems

NO_CALIBRATION_STEADY = ("stop at steady state needs a bench calibration (the live concentration decides it): "
                         "choose a calibration, or untick it")
ABORT_STYLE = ("QPushButton { color: white; background-color: #a01010; font-weight: bold; padding: 4px 12px; } "
               "QPushButton:disabled { color: #8a8a8a; background-color: #dcdcdc; font-weight: normal; }")
STATE_POINT_SIZE = 26
"""Point size of the state word: about 9 mm high on a 96-dpi screen, readable from 2 m."""
STATE_COLOURS = {"IDLE": "#e0e0e0", "CONNECTED": "#e0e0e0", "STARTING": "#cfe3ff", "HEATING": "#ffb347",
                 "WAITING FOR DROP": "#ffe14d", "RECORDING": "#5cd65c", "LINK LOST": "#c00000", "CALIBRATING": "#cfe3ff",
                 "STOPPING": "#cfe3ff"}
"""The state word's background (anything else: light grey)."""


class RunControls(QWidget):
    """Settings form and buttons. Emits ``start_requested``, ``drop_confirmed``, and ``stop_requested`` /
    ``abort_requested`` once the operator confirmed; the main window wires them to the engine, calls
    :meth:`set_running`, feeds :meth:`follow` with the engine's state changes (the run's name for the
    questions) and adds the device panel's checks with :meth:`watch`. The bath (water, temperature,
    stirring, the alarm band) is set in the device panel."""

    start_requested = Signal()
    drop_confirmed = Signal()
    stop_requested = Signal()
    abort_requested = Signal()
    change_requested = Signal()

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
        self.simulate = simulate
        self.calibration = QLineEdit("")
        self.calibration.setPlaceholderText("bench calibration JSON (live concentration)")
        browse = QPushButton("...")
        browse.clicked.connect(self._browse)
        self.notes = QLineEdit("")
        self.band_label = QLabel("")
        self.band_label.setWordWrap(True)
        self.state_label = QLabel("IDLE")
        font = QFont(self.state_label.font())
        font.setPointSize(STATE_POINT_SIZE)
        font.setBold(True)
        self.state_label.setFont(font)
        self.state_label.setWordWrap(True)
        self.state_detail = QLabel("")
        self.state_detail.setWordWrap(True)
        self.show_state("IDLE")
        form_box = QGroupBox("run")
        form = narrow_form(form_box)
        form.addRow("name", self.name)
        form.addRow("object", self.object_name)
        for box in (self.object_mass, self.interval, self.max_hours):
            box.add_to(form, box.setting.label)
        form.addRow(self.stop_on_steady)
        form.addRow(self.auto_drop)
        cal_row = QHBoxLayout()
        cal_row.addWidget(self.calibration, 1)
        cal_row.addWidget(browse)
        form.addRow("calibration", cal_row)
        form.addRow("notes", self.notes)
        form.addRow("temperature alarm", self.band_label)
        self.start_button = QPushButton("Start")
        self.drop_button = QPushButton("Object dropped")
        self.stop_button = QPushButton("Stop")
        self.stop_button.setToolTip("finish the run cleanly: heating off, the run finalised as 'stopped' (asks first)")
        self.abort_button = QPushButton("Abort")
        self.abort_button.setStyleSheet(ABORT_STYLE)
        self.abort_button.setToolTip("end at once: heating off, the run marked 'aborted' (asks first)")
        self.change_button = QPushButton("Change duration...")
        self.change_button.setToolTip("while a run records: change its maximum or minimum duration, with a reason "
                                      "for the audit trail (the other settings stay as the run started)")
        self.change_button.clicked.connect(self.change_requested)
        self.start_reason = QLabel("")
        self.start_reason.setStyleSheet("color: #b00000;")
        self.start_reason.setWordWrap(True)
        self.start_button.clicked.connect(self.start_requested)
        self.drop_button.clicked.connect(self.drop_confirmed)
        self.stop_button.clicked.connect(self.ask_stop)
        self.abort_button.clicked.connect(self.ask_abort)
        row = QHBoxLayout()
        for b in (self.start_button, self.drop_button, self.stop_button):
            row.addWidget(b)
        abort_box = QGroupBox("end at once")
        abort_row = QHBoxLayout(abort_box)
        abort_row.addStretch(1)
        abort_row.addWidget(self.abort_button)
        layout = QVBoxLayout(self)
        layout.addWidget(self.state_label)
        layout.addWidget(self.state_detail)
        layout.addWidget(form_box)
        layout.addLayout(row)
        layout.addWidget(self.change_button)
        layout.addWidget(self.start_reason)
        layout.addStretch(1)                   # Abort at the far end of the panel, away from Stop
        layout.addWidget(abort_box)
        self.checks: list[Callable[[], list[str]]] = []
        """Further checks before Start (each returns the problems it finds): the device panel's bath."""
        self.procedure, self.run_name = "", ""
        self._running, self._waiting_drop, self._recording = False, False, False
        for box in (self.object_mass, self.interval, self.max_hours):
            box.problem_changed.connect(self.update_start)
        self.stop_on_steady.toggled.connect(self.update_start)
        self.calibration.textChanged.connect(self.update_start)
        self.set_running(False)

    def show_state(self, word: str, detail: str = "") -> None:
        """Show the state word (e.g. ``RECORDING``) in large letters, and a line of detail under it."""
        colour = STATE_COLOURS.get(word, "#e0e0e0")
        text_colour = "white" if word == "LINK LOST" else "black"
        if self.state_label.text() != word or not self.state_label.styleSheet():
            self.state_label.setText(word)
            self.state_label.setStyleSheet(f"QLabel {{ background-color: {colour}; color: {text_colour}; "
                                           "padding: 6px; border-radius: 4px; }")
        if self.state_detail.text() != detail:
            self.state_detail.setText(detail)

    def _browse(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "bench calibration", "", "JSON (*.json)")
        if path:
            self.calibration.setText(path)

    def apply(self, config: RunConfig, calibration: str, name: bool = True) -> None:
        """Show ``config``'s run settings (not the object's; its name if ``name``) and ``calibration`` (kept out
        when the file does not exist)."""
        if name:
            self.name.setText(config.name)
        self.interval.set_stored(config.interval_s)
        self.max_hours.set_stored(config.max_duration_s)
        self.stop_on_steady.setChecked(config.stop_on_steady)
        if not calibration or Path(calibration).is_file():
            self.calibration.setText(calibration)

    def calibration_path(self) -> str | None:
        """The active bench calibration's path as typed (None: none)."""
        return self.calibration.text().strip() or None

    def set_calibration_path(self, path: str | Path) -> None:
        """Make ``path`` the active bench calibration."""
        self.calibration.setText(str(path))

    def set_locked(self, locked: bool) -> None:
        """Make the run's settings read-only while a procedure records (auto drop: only ever on a simulated
        bench)."""
        for widget in (self.name, self.object_name, self.object_mass, self.interval, self.max_hours, self.notes,
                       self.calibration):
            widget.setReadOnly(locked)
        self.stop_on_steady.setEnabled(not locked)
        self.auto_drop.setEnabled(not locked and self.simulate)
        tip = "locked while a procedure records" if locked else ""
        for widget in (self.name, self.interval, self.max_hours):
            widget.setStatusTip(tip)

    def config(self, bath: BathSettings) -> RunConfig:
        """The run settings with ``bath`` as a :class:`RunConfig` (UsageError on a bad value)."""
        return RunConfig(name=self.name.text() or RunConfig.name, interval_s=self.interval.stored(),
                         max_duration_s=self.max_hours.stored(), stop_on_steady=self.stop_on_steady.isChecked(),
                         object_mass_g=self.object_mass.stored(), object_name=self.object_name.text(),
                         notes=self.notes.text(), auto_drop=self.auto_drop.isChecked(), bath=bath)

    # -- checks before Start ----------------------------------------------------------------------------------
    def watch(self, boxes: dict[str, SettingBox]) -> None:
        """Check ``boxes`` (the device panel's bath) before Start too, and show their alarm band here."""
        self.checks.append(lambda: problems(boxes))
        for box in boxes.values():
            box.problem_changed.connect(self.update_start)
        setpoint, band = boxes.get("setpoint_c"), boxes.get(EXCURSION.name)
        if setpoint is not None and band is not None:
            def show() -> None:
                if setpoint.is_none():
                    self.band_label.setText("none: the bath is not heated (no setpoint)")
                else:
                    self.band_label.setText(f"an alarm when the bath leaves {setpoint.value():g} +/- {band.value():g} "
                                            "C after the drop (set in Devices, bath)")
            setpoint.valueChanged.connect(show)
            band.valueChanged.connect(show)
            show()
        self.update_start()

    def start_problems(self) -> list[str]:
        """Why Start cannot be pressed now (empty: it can): values out of range, a calibration file that does
        not exist, a steady-state stop without a calibration."""
        found = problems([self.object_mass, self.interval, self.max_hours])
        for check in self.checks:
            found += check()
        cal = self.calibration.text().strip()
        if cal and not Path(cal).is_file():
            found.append(f"the calibration {cal} does not exist")
        if self.stop_on_steady.isChecked() and not cal:
            found.append(NO_CALIBRATION_STEADY)
        return found

    def hold_start(self, held: bool) -> None:
        """Keep Start disabled while ``held`` (a bench being built); when released it shows what it can again."""
        if held:
            self.start_button.setEnabled(False)
        else:
            self.update_start()

    def update_start(self, *_args) -> None:
        """Enable Start when nothing runs and nothing is wrong; say why not under it."""
        found = [] if self._running else self.start_problems()
        self.start_button.setEnabled(not self._running and not found)
        self.start_reason.setText("Start is disabled: " + "; ".join(found) if found else "")
        self.start_reason.setVisible(bool(found))

    # -- running ----------------------------------------------------------------------------------------------
    def follow(self, state: StateChanged) -> None:
        """Slot for the engine's state changes: which procedure runs and its folder's name."""
        if state.phase == Phase.STARTING:
            self.procedure, self.run_name = state.procedure or "", ""
        if state.folder:
            self.run_name = Path(state.folder).name
        self._recording = self._running and self.procedure == "run" and state.phase == Phase.ACQUIRING
        self.change_button.setEnabled(self._recording)

    def ask_stop(self) -> None:
        """Stop, once the operator confirmed."""
        if dialogs.confirm(self, dialogs.stop_question(self.procedure, self.run_name)):
            self.stop_requested.emit()

    def ask_abort(self) -> None:
        """Abort, once the operator confirmed."""
        if dialogs.confirm(self, dialogs.abort_question(self.procedure, self.run_name)):
            self.abort_requested.emit()

    def set_running(self, running: bool, waiting_drop: bool = False) -> None:
        """Enable the buttons that make sense now."""
        self._running, self._waiting_drop = running, waiting_drop
        self._recording = self._recording and running
        self.change_button.setEnabled(self._recording)      # a run after its drop (see follow)
        self.drop_button.setEnabled(running and waiting_drop)
        self.stop_button.setEnabled(running)
        self.abort_button.setEnabled(running)
        self.update_start()
