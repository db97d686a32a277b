"""Device panel: pick the camera and hotplate (real ports or simulated), camera settings, the bath, connect,
readouts.

The hotplate's readouts come from polls of the plate off the GUI thread, every ``keepalive_s`` of the engine's
clock, whenever a bench is connected: by the procedure's monitor while a procedure holds the bench (its last
reading is taken after the heating was switched off), and by the window's idle poller between procedures
(:mod:`labapp.gui.plate_poller`). The heater's state (heating ON or OFF, setpoint, bath, stirring) is shown in one
prominent line only while the reading is current: every readout turns grey with "stale since hh:mm:ss" once the
last reading is older than its freshness (its poll interval plus the time a read takes,
:attr:`labapp.acquisition.events.Reading.fresh_s`), and a lost link (:class:`labapp.acquisition.events.Link`) shows
"LINK LOST" in red, with heating and stirring unknown, until the plate answers again.
"""
from __future__ import annotations

import time

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QComboBox, QGroupBox, QHBoxLayout, QLabel, QLineEdit, QPushButton, QVBoxLayout, QWidget

from drivers.camera.base import CameraSettings
from labapp.acquisition.devices import CAMERA_SPECS
from labapp.acquisition.events import Link, Reading
from labapp.acquisition.settings import BATH_SETTINGS, KEEPALIVE, SETPOINT, BathSettings
from labapp.gui.fields import add_rows, narrow_form, problems

SIMULATED = "simulated"
NO_HOTPLATE = "none"
STALE_AFTER_S = 3 * KEEPALIVE.default
"""Wall-clock seconds without a hotplate reading after which the readouts are shown as stale when the reading does
not say its own freshness."""
STALE_CHECK_MS = 500
HEATING_ON_STYLE = "QLabel { background-color: #ffb347; color: black; font-weight: bold; padding: 4px; }"
HEATING_OFF_STYLE = "QLabel { background-color: #cfe3ff; color: black; font-weight: bold; padding: 4px; }"
STALE_STYLE = "QLabel { background-color: #dddddd; color: #555555; font-weight: bold; padding: 4px; }"
LINK_LOST_STYLE = "QLabel { background-color: #c00000; color: white; font-weight: bold; padding: 4px; }"


def serial_ports() -> list[str]:
    """Serial ports the OS lists (USB adapters of the hotplate among them)."""
    from serial.tools import list_ports

    return sorted(p.device for p in list_ports.comports())


class DevicePanel(QWidget):
    """Camera and hotplate choice, camera settings, the bath, a Connect button and live hotplate readouts.

    The main window reads :meth:`camera_spec`, :meth:`hotplate_spec` and :meth:`settings` when it builds
    the bench, and :meth:`bath` for a run or a calibration series; readouts are fed by :meth:`show_reading`
    (a slot for the bridge's ``reading`` signal).
    """

    def __init__(self, simulate: bool, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.camera = QComboBox()
        self.camera.setEditable(True)
        self.camera.addItems(([SIMULATED] if simulate else []) + ["gphoto2", "folder:"])
        self.camera.setToolTip(f"camera: {SIMULATED} | {CAMERA_SPECS}")
        self.hotplate = QComboBox()
        self.hotplate.setEditable(True)
        self.hotplate.addItems(([SIMULATED] if simulate else []) + serial_ports() + [NO_HOTPLATE])
        self.hotplate.setToolTip("hotplate serial port or URL (e.g. /dev/ttyUSB0, socket://host:4001)")
        defaults = CameraSettings()
        self.aperture = QLineEdit(defaults.aperture or "")
        self.shutter = QLineEdit(defaults.shutter_speed or "")
        self.iso = QLineEdit(defaults.iso or "")
        self.image_format = QLineEdit(defaults.image_format or "")
        self.connect_button = QPushButton("Connect / preview")
        self.connect_button.setToolTip("connect both devices, take one preview frame and one reading")
        self._connect_text = self.connect_button.text()
        self.readouts = {key: QLabel("-") for key in ("plate_c", "probe_c", "speed_rpm", "setpoint_c", "state")}
        self.heater = QLabel("hotplate: no reading yet (Connect)")
        self.heater.setWordWrap(True)
        self.heater.setStyleSheet(STALE_STYLE)
        self.stale_label = QLabel("")
        self.stale_label.setStyleSheet("color: #777777;")
        self.stale_label.setWordWrap(True)         # never wider than the dock
        self.stale_label.hide()
        self.stale_after_s: float | None = None
        """Wall seconds after which a reading is stale (None: the reading's own ``fresh_s``)."""
        self.last_reading: Reading | None = None
        self.link_ok = True
        self._link_lost_wall: float | None = None
        self._received_s: float | None = None          # time.monotonic() of the last reading
        self._received_wall: float | None = None       # time.time() of the last reading, for "stale since"
        self.stale = True
        self._look: tuple | None = None
        devices = QGroupBox("devices")
        form = narrow_form(devices)
        form.addRow("camera", self.camera)
        form.addRow("hotplate", self.hotplate)
        settings = QGroupBox("camera settings (paper: f/22, 1/125 s, ISO 160)")
        sform = narrow_form(settings)
        sform.addRow("aperture", self.aperture)
        sform.addRow("shutter", self.shutter)
        sform.addRow("ISO", self.iso)
        sform.addRow("format", self.image_format)
        bath = QGroupBox("bath (runs and calibration series)")
        self.bath_fields = add_rows(narrow_form(bath), tuple(s for s in BATH_SETTINGS if s.flag),
                                    none_text={SETPOINT.name: "no heating"})
        readout = QGroupBox("hotplate")
        rform = narrow_form(readout)
        rform.addRow(self.heater)
        rform.addRow(self.stale_label)
        for key, label in (("plate_c", "plate (\u00b0C)"), ("probe_c", "probe (\u00b0C)"), ("speed_rpm", "stirring (rpm)"),
                           ("setpoint_c", "setpoint (\u00b0C)"), ("state", "heating / stirring")):
            rform.addRow(label, self.readouts[key])
        buttons = QHBoxLayout()
        buttons.addWidget(self.connect_button)
        layout = QVBoxLayout(self)
        layout.addWidget(devices)
        layout.addLayout(buttons)                 # Connect under the device choice: in view on a small screen
        for w in (readout, bath, settings):       # the bath in view at 1280 x 800; the camera's settings last
            layout.addWidget(w)
        layout.addStretch(1)
        self.stale_timer = QTimer(self)
        self.stale_timer.timeout.connect(self.check_stale)
        self.stale_timer.start(STALE_CHECK_MS)

    def camera_spec(self) -> str:
        """The chosen camera (``simulated`` or a spec of :data:`labapp.acquisition.devices.CAMERA_SPECS`)."""
        return self.camera.currentText().strip()

    def hotplate_spec(self) -> str | None:
        """The chosen hotplate port, ``simulated``, or None for no hotplate."""
        text = self.hotplate.currentText().strip()
        return None if text in ("", NO_HOTPLATE) else text

    def problems(self) -> list[str]:
        """What is wrong in the bath's fields (empty: nothing)."""
        return problems(self.bath_fields)

    def bath(self) -> BathSettings:
        """The bath settings of the fields (the others: their defaults; UsageError for a bad value)."""
        return BathSettings(**{name: box.stored() for name, box in self.bath_fields.items()})

    def apply_bath(self, bath: BathSettings) -> None:
        """Show ``bath``'s settings in the fields."""
        for name, box in self.bath_fields.items():
            box.set_stored(getattr(bath, name))

    def set_locked(self, locked: bool) -> None:
        """Make the bath read-only and the device choice and Connect unavailable while a procedure records."""
        for box in self.bath_fields.values():
            box.setReadOnly(locked)
        for widget in (self.camera, self.hotplate, self.connect_button):
            widget.setEnabled(not locked)
        tip = "locked while a procedure records" if locked else ""
        for box in self.bath_fields.values():
            box.setStatusTip(tip)

    def set_connecting(self, busy: bool, doing: str = "connecting") -> None:
        """While ``busy``, Connect says what is being done (``doing...``) and is unavailable; then it is back."""
        if busy:
            self._connect_text = self.connect_button.text()
            self.connect_button.setText(f"{doing}...")
        else:
            self.connect_button.setText(self._connect_text)
        self.connect_button.setEnabled(not busy)

    def settings(self) -> CameraSettings:
        """Camera settings from the fields (empty: leave the camera's own)."""
        def val(edit: QLineEdit) -> str | None:
            return edit.text().strip() or None
        return CameraSettings(val(self.aperture), val(self.shutter), val(self.iso), val(self.image_format))

    def show_reading(self, reading: Reading) -> None:
        """Slot: show one hotplate reading (an engine :class:`labapp.acquisition.events.Reading`)."""
        def fmt(v: float | None, spec: str) -> str:
            return "no probe" if v is None else format(v, spec)
        self.last_reading, self.link_ok = reading, True
        self._received_s, self._received_wall = time.monotonic(), time.time()
        self.readouts["plate_c"].setText(fmt(reading.plate_c, ".1f"))
        self.readouts["probe_c"].setText(fmt(reading.probe_c, ".1f"))
        self.readouts["speed_rpm"].setText(fmt(reading.speed_rpm, ".0f"))
        self.readouts["setpoint_c"].setText(fmt(reading.setpoint_c, ".1f"))
        self.readouts["state"].setText(f"{'on' if reading.heating else 'off'} / "
                                       f"{'on' if reading.stirring else 'off'}")
        bath = reading.probe_c if reading.probe_c is not None else reading.plate_c
        where = "bath" if reading.probe_c is not None else "plate (no probe)"
        stirring = f"stirring {reading.speed_rpm:.0f} rpm" if reading.stirring else "stirring off"
        if reading.heating:
            self.heater.setText(f"HEATING ON: setpoint {reading.setpoint_c:.1f} C, {where} {bath:.1f} C, {stirring}")
        else:
            self.heater.setText(f"HEATING OFF: {where} {bath:.1f} C, {stirring}")
        self._current_text = self.heater.text()
        self._set_stale(False)

    def show_link(self, link: Link) -> None:
        """Slot: the hotplate's link went down (heating and stirring unknown) or answers again."""
        self.link_ok = link.ok
        self._link_lost_wall = None if link.ok else time.time()
        if link.ok:
            return                               # the reading that follows shows the plate as it is
        self._set_stale(True)

    def limit_s(self) -> float:
        """Wall seconds a reading stays current: :attr:`stale_after_s`, else the reading's own freshness."""
        if self.stale_after_s is not None:
            return self.stale_after_s
        return self.last_reading.fresh_s if self.last_reading is not None else STALE_AFTER_S

    def heater_text(self) -> str:
        """The heater's line as shown (with the stale note when it is)."""
        return self.heater.text() + (f" ({self.stale_label.text()})" if self.stale and self.last_reading else "")

    def check_stale(self) -> None:
        """Grey the readouts once the last reading is older than :meth:`limit_s` (wall clock); keep its age
        current while it is."""
        if self._received_s is not None and time.monotonic() - self._received_s > self.limit_s():
            self._set_stale(True)

    def _set_stale(self, stale: bool) -> None:
        age = None if self._received_s is None else time.monotonic() - self._received_s
        if stale and self._received_wall is not None:
            since = time.strftime("%H:%M:%S", time.localtime(self._received_wall))
            self.stale_label.setText(f"stale since {since} ({age:.0f} s): no reading for more than "
                                     f"{self.limit_s():g} s; the plate is polled while connected")
        elif not stale:
            self.stale_label.setText("")
        self.stale_label.setVisible(bool(self.stale_label.text()))     # no empty row: the bath stays in view
        heating = self.last_reading is not None and self.last_reading.heating
        look = (stale, heating, self.link_ok)
        if look == self._look:
            return
        self._look = look
        self.stale = stale
        if not self.link_ok:
            lost = time.strftime("%H:%M:%S", time.localtime(self._link_lost_wall or time.time()))
            self.heater.setText(f"LINK LOST since {lost}: heating and stirring UNKNOWN (retrying)")
            self.heater.setStyleSheet(LINK_LOST_STYLE)
        elif stale:
            last = getattr(self, "_current_text", "")
            self.heater.setText(f"heating UNKNOWN (reading stale); last: {last.lower()}" if last else
                                "hotplate: no current reading")
            self.heater.setStyleSheet(STALE_STYLE)
        else:
            self.heater.setStyleSheet(HEATING_ON_STYLE if heating else HEATING_OFF_STYLE)
        for label in self.readouts.values():
            label.setStyleSheet("color: #999999;" if stale else "")
