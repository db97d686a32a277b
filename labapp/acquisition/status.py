"""A one-line summary of a running procedure, built from engine events (CLI status line and GUI status bar).

The hotplate's part is a confirmed reading or says what it is not: ``LINK LOST since hh:mm:ss`` while the link is
down (heating and stirring unknown), ``stale Ns`` once the last reading is older than its freshness
(:attr:`labapp.acquisition.events.Reading.fresh_s`, wall seconds). Each procedure starts from a clean status (no
time, frames, concentration or warnings of the previous one).
"""
from __future__ import annotations

import math
import threading
import time

from labapp.acquisition.events import (
    Done,
    EngineEvent,
    FrameStored,
    Link,
    Message,
    Outcome,
    Phase,
    Prompt,
    Reading,
    StateChanged,
)

QUIET = ("preview",)
"""Procedures whose end leaves the status ``connected`` rather than ``done (outcome)`` (nothing is recorded)."""


def hms(t_s: float | None) -> str:
    """Seconds as ``H:MM:SS`` (``-:--:--`` when unknown)."""
    if t_s is None or math.isnan(t_s):
        return "-:--:--"
    sign, t = ("-" if t_s < 0 else ""), int(round(abs(t_s)))
    return f"{sign}{t // 3600}:{t // 60 % 60:02d}:{t % 60:02d}"


class RunStatus:
    """Subscribe :meth:`update` to an engine; :meth:`line` is the current status line."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.phase: str = "idle"        # shown first: "idle", the Phase, the prompt waited for, or the outcome
        self.folder = ""
        self.t_s: float | None = None
        self.frames = 0
        self.conc: float | None = None
        self.plate_c: float | None = None
        self.probe_c: float | None = None
        self.speed_rpm: float | None = None
        self.heating: bool | None = None
        self.setpoint_c: float | None = None
        self.last_error = ""
        self.warnings = 0
        self.outcome: Outcome | None = None
        self.procedure = ""
        self.link_ok = True
        self.link_lost_wall: float | None = None      # time.time() when the link was lost
        self.reading_mono: float | None = None        # time.monotonic() when the last reading arrived
        self.fresh_s = math.inf

    def _new_procedure(self, name: str) -> None:
        """Forget the previous procedure's time, frames, concentration, warnings and outcome."""
        self.procedure, self.folder, self.t_s, self.frames, self.conc = name, "", None, 0, None
        self.last_error, self.warnings, self.outcome = "", 0, None

    def reading_age_s(self) -> float | None:
        """Wall seconds since the last hotplate reading arrived (None before the first)."""
        return None if self.reading_mono is None else time.monotonic() - self.reading_mono

    def reading_stale(self) -> bool:
        """True when the last reading is older than its freshness, or the link is down."""
        age = self.reading_age_s()
        return not self.link_ok or (age is not None and age > self.fresh_s)

    def update(self, event: EngineEvent) -> None:
        """Fold one event into the status."""
        with self._lock:
            match event:
                case StateChanged():
                    if event.phase == Phase.STARTING:
                        self._new_procedure(event.procedure or "")
                    self.phase = event.phase
                    self.folder = event.folder or self.folder
                case FrameStored():
                    self.t_s, self.frames = event.t_s, event.n_frames
                    self.conc = self.conc if math.isnan(event.conc_g_per_kg) else event.conc_g_per_kg
                case Reading():
                    self.plate_c, self.probe_c, self.speed_rpm = event.plate_c, event.probe_c, event.speed_rpm
                    self.heating, self.setpoint_c = event.heating, event.setpoint_c
                    self.reading_mono, self.fresh_s, self.link_ok = time.monotonic(), event.fresh_s, True
                    if event.t_s is not None:
                        self.t_s = event.t_s
                case Link():
                    self.link_ok = event.ok
                    self.link_lost_wall = None if event.ok else time.time()
                case Message(level="warning" | "error"):
                    self.warnings += 1
                    self.last_error = event.message
                case Prompt():
                    self.phase = f"waiting: {event.prompt}"
                case Done():
                    self.outcome = event.outcome
                    quiet = self.procedure in QUIET and event.outcome == Outcome.COMPLETE
                    self.phase = "connected" if quiet else f"done ({event.outcome})"

    def plate_text(self) -> str:
        """The hotplate's part of the line: the reading with its heater state, or what it is not."""
        def num(v: float | None, fmt: str) -> str:
            return "-" if v is None else format(v, fmt)
        values = (f"plate {num(self.plate_c, '.1f')} C probe {num(self.probe_c, '.1f')} C "
                  f"{num(self.speed_rpm, '.0f')} rpm")
        age = self.reading_age_s()
        if not self.link_ok:
            since = time.strftime("%H:%M:%S", time.localtime(self.link_lost_wall or time.time()))
            last = "" if age is None else f"; last reading {age:.0f} s ago: {values}"
            return f"hotplate LINK LOST since {since}, retrying; heating and stirring unknown{last}"
        if age is not None and age > self.fresh_s:
            return f"{values} STALE ({age:.0f} s old); heating unknown"
        if self.heating is None:
            return values
        return values + (f" heating ON ({self.setpoint_c:g} C)" if self.heating else " heating OFF")

    def line(self, width: int | None = None) -> str:
        """``[phase] t=H:MM:SS frames N conc C g/kg plate P C probe Q C S rpm heating ON (70 C) | N warnings, last:
        ...`` (``heating OFF`` once the plate reports it off; ``LINK LOST`` or ``STALE`` instead of the heater's
        state when the reading is not current); cut to ``width`` characters when given (a terminal's)."""
        def num(v: float | None, fmt: str) -> str:
            return "-" if v is None else format(v, fmt)
        with self._lock:
            text = (f"[{self.phase}] t={hms(self.t_s)} frames {self.frames} conc {num(self.conc, '.3f')} g/kg "
                    + self.plate_text())
            if self.last_error:
                text += f" | {self.warnings} warnings, last: {self.last_error}"
        return text if width is None else text[:width]
