"""Device panel: pick the camera and hotplate (real ports or simulated), camera settings, the bath, connect,
readouts."""
from __future__ import annotations

from PySide6.QtWidgets import QComboBox, QFormLayout, QGroupBox, QHBoxLayout, QLabel, QLineEdit, QPushButton, QVBoxLayout, QWidget

from drivers.camera.base import CameraSettings
from labapp.acquisition.devices import CAMERA_SPECS
from labapp.acquisition.events import Reading
from labapp.acquisition.settings import BATH_SETTINGS, BathSettings
from labapp.gui.fields import add_rows

SIMULATED = "simulated"
NO_HOTPLATE = "none"


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
        self.readouts = {key: QLabel("-") for key in ("plate_c", "probe_c", "speed_rpm", "setpoint_c", "state")}
        devices = QGroupBox("devices")
        form = QFormLayout(devices)
        form.addRow("camera", self.camera)
        form.addRow("hotplate", self.hotplate)
        settings = QGroupBox("camera settings (paper: f/22, 1/125 s, ISO 160)")
        sform = QFormLayout(settings)
        sform.addRow("aperture", self.aperture)
        sform.addRow("shutter", self.shutter)
        sform.addRow("ISO", self.iso)
        sform.addRow("format", self.image_format)
        bath = QGroupBox("bath (runs and calibration series)")
        self.bath_fields = add_rows(QFormLayout(bath), tuple(s for s in BATH_SETTINGS if s.flag))
        readout = QGroupBox("hotplate")
        rform = QFormLayout(readout)
        for key, label in (("plate_c", "plate (C)"), ("probe_c", "probe (C)"), ("speed_rpm", "stirring (rpm)"),
                           ("setpoint_c", "setpoint (C)"), ("state", "heating / stirring")):
            rform.addRow(label, self.readouts[key])
        buttons = QHBoxLayout()
        buttons.addWidget(self.connect_button)
        layout = QVBoxLayout(self)
        for w in (devices, settings, bath, readout):
            layout.addWidget(w)
        layout.addLayout(buttons)
        layout.addStretch(1)

    def camera_spec(self) -> str:
        """The chosen camera (``simulated`` or a spec of :data:`labapp.acquisition.devices.CAMERA_SPECS`)."""
        return self.camera.currentText().strip()

    def hotplate_spec(self) -> str | None:
        """The chosen hotplate port, ``simulated``, or None for no hotplate."""
        text = self.hotplate.currentText().strip()
        return None if text in ("", NO_HOTPLATE) else text

    def bath(self) -> BathSettings:
        """The bath settings of the fields (the others: their defaults; UsageError for a bad value)."""
        return BathSettings(**{name: box.stored() for name, box in self.bath_fields.items()})

    def settings(self) -> CameraSettings:
        """Camera settings from the fields (empty: leave the camera's own)."""
        def val(edit: QLineEdit) -> str | None:
            return edit.text().strip() or None
        return CameraSettings(val(self.aperture), val(self.shutter), val(self.iso), val(self.image_format))

    def show_reading(self, reading: Reading) -> None:
        """Slot: show one hotplate reading (an engine :class:`labapp.acquisition.events.Reading`)."""
        def fmt(v: float | None, spec: str) -> str:
            return "no probe" if v is None else format(v, spec)
        self.readouts["plate_c"].setText(fmt(reading.plate_c, ".1f"))
        self.readouts["probe_c"].setText(fmt(reading.probe_c, ".1f"))
        self.readouts["speed_rpm"].setText(fmt(reading.speed_rpm, ".0f"))
        self.readouts["setpoint_c"].setText(fmt(reading.setpoint_c, ".1f"))
        self.readouts["state"].setText(f"{'on' if reading.heating else 'off'} / "
                                       f"{'on' if reading.stirring else 'off'}")
