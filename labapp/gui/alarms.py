"""The alarm banner: failures the operator must not miss (a heat timeout, a failed fit, a camera or link fault,
a temperature excursion, a reference frame that is not clear water, a plate not confirmed off) and the changes
that need them (drop the object now, the link is back, the heater was switched on again, the run ended), shown
until acknowledged: red while any failure is listed, amber for changes only.

The engine publishes each as an :class:`labapp.acquisition.events.Alarm`; the bridge's ``alarm`` signal
calls :meth:`AlarmBanner.raise_alarm` in the GUI thread. The banner lists the alarms not yet acknowledged
(newest first, with their clock time and kind), marks each on the live plots at its time since the drop,
and beeps when "sound" is ticked (on by default).
"""
from __future__ import annotations

import time
from typing import Protocol

from PySide6.QtCore import Signal
from PySide6.QtWidgets import QApplication, QCheckBox, QFrame, QHBoxLayout, QLabel, QPushButton, QVBoxLayout, QWidget

from labapp.acquisition.events import Alarm, AlarmKind

__all__ = ["AlarmBanner", "TITLES"]

TITLES = {
    AlarmKind.HEAT_TIMEOUT: "heating timeout",
    AlarmKind.FIT_FAILED: "calibration fit failed",
    AlarmKind.CAMERA_FAULT: "camera fault",
    AlarmKind.LINK_FAULT: "hotplate link fault",
    AlarmKind.TEMPERATURE_EXCURSION: "temperature excursion",
    AlarmKind.REFERENCE_OFFSET: "reference frame is not clear water",
    AlarmKind.LINK_RESTORED: "hotplate link back",
    AlarmKind.HEATER_RESTARTED: "heater switched on again",
    AlarmKind.NOT_CONFIRMED_OFF: "heating not confirmed off",
    AlarmKind.DROP: "drop the object now",
    AlarmKind.RUN_ENDED: "run ended",
}
"""The banner's words for each kind."""
NOTICES = frozenset({AlarmKind.LINK_RESTORED, AlarmKind.HEATER_RESTARTED, AlarmKind.DROP, AlarmKind.RUN_ENDED})
"""Kinds that are changes needing the operator, not failures (the banner is amber while only these are listed)."""
MARK_KIND = {AlarmKind.TEMPERATURE_EXCURSION: "excursion", AlarmKind.LINK_RESTORED: "resume"}
"""The plot mark of each alarm kind (``PlotsPanel.mark`` colours): ``alarm`` unless listed."""
SHOWN = 4
"""Alarms listed in the banner at once (the rest are counted)."""
BANNER_STYLE = ("QFrame#alarms { background-color: #c00000; border: 2px solid #600000; } "
                "QFrame#alarms QLabel { color: white; font-weight: bold; } "
                "QFrame#alarms QCheckBox { color: white; }")
NOTICE_STYLE = ("QFrame#alarms { background-color: #ffd000; border: 2px solid #806000; } "
                "QFrame#alarms QLabel { color: black; font-weight: bold; } "
                "QFrame#alarms QCheckBox { color: black; }")


class Marker(Protocol):
    """What marks a time on the plots (``labapp.gui.plots.PlotsPanel``)."""

    def mark(self, kind: str, t_s: float, text: str = "", end_s: float | None = None) -> None: ...


class AlarmBanner(QFrame):
    """A red banner over the window while any alarm is unacknowledged; "Acknowledge" clears it.

    Parameters
    ----------
    plots : Marker, optional
        Where each alarm with a time since the drop is marked.

    Emits ``acknowledged(n)`` with the number of alarms acknowledged.
    """

    acknowledged = Signal(int)

    def __init__(self, plots: Marker | None = None, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("alarms")
        self.setStyleSheet(BANNER_STYLE)
        self.plots = plots
        self.pending: list[tuple[float, Alarm]] = []
        """The unacknowledged alarms with their wall-clock arrival time, oldest first."""
        self.history: list[Alarm] = []
        """Every alarm of the session."""
        self.text = QLabel("")
        self.text.setWordWrap(True)
        self.sound = QCheckBox("sound")
        self.sound.setToolTip("beep when an alarm is raised")
        self.sound.setChecked(True)
        self.ack_button = QPushButton("Acknowledge")
        self.ack_button.clicked.connect(self.acknowledge)
        side = QVBoxLayout()
        side.addWidget(self.ack_button)
        side.addWidget(self.sound)
        layout = QHBoxLayout(self)
        layout.addWidget(self.text, 1)
        layout.addLayout(side)
        self.hide()

    def raise_alarm(self, alarm: Alarm) -> None:
        """Slot: show ``alarm`` until acknowledged, mark it on the plots, beep if asked to."""
        self.pending.append((time.time(), alarm))
        self.history.append(alarm)
        if self.plots is not None and alarm.t_s is not None:
            self.plots.mark(MARK_KIND.get(alarm.kind, "alarm"), alarm.t_s, TITLES.get(alarm.kind, str(alarm.kind)))
        if self.sound.isChecked():
            QApplication.beep()
        self._show()

    def dismiss(self, kind: AlarmKind) -> None:
        """Take the alarms of ``kind`` off the banner (the operator answered them elsewhere, e.g. the drop)."""
        self.pending = [(at, a) for at, a in self.pending if a.kind != kind]
        self._show()

    def kinds(self) -> list[AlarmKind]:
        """The kinds of the unacknowledged alarms, oldest first."""
        return [alarm.kind for _, alarm in self.pending]

    def acknowledge(self) -> None:
        """The operator has seen the alarms: clear the banner."""
        n = len(self.pending)
        self.pending.clear()
        self._show()
        self.acknowledged.emit(n)

    def _show(self) -> None:
        if not self.pending:
            self.text.setText("")
            self.hide()
            return
        lines = [f"{time.strftime('%H:%M:%S', time.localtime(at))}  {TITLES.get(a.kind, str(a.kind)).upper()}: "
                 f"{a.message}" for at, a in reversed(self.pending[-SHOWN:])]
        more = len(self.pending) - SHOWN
        head = f"{len(self.pending)} alarm{'s' if len(self.pending) > 1 else ''} to acknowledge"
        notices = all(a.kind in NOTICES for _, a in self.pending)
        style = NOTICE_STYLE if notices else BANNER_STYLE
        if self.styleSheet() != style:
            self.setStyleSheet(style)
        self.text.setText("\n".join([head] + lines + ([f"... and {more} earlier"] if more > 0 else [])))
        self.show()
