"""A one-line summary of a running procedure, built from engine events (CLI status line and GUI status bar)."""
from __future__ import annotations

import math
import threading

from labapp.acquisition.events import Done, EngineEvent, FrameStored, Message, Outcome, Prompt, Reading, StateChanged


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

    def update(self, event: EngineEvent) -> None:
        """Fold one event into the status."""
        with self._lock:
            match event:
                case StateChanged():
                    self.phase = event.phase
                    self.folder = event.folder or self.folder
                case FrameStored():
                    self.t_s, self.frames = event.t_s, event.n_frames
                    self.conc = self.conc if math.isnan(event.conc_g_per_kg) else event.conc_g_per_kg
                case Reading():
                    self.plate_c, self.probe_c, self.speed_rpm = event.plate_c, event.probe_c, event.speed_rpm
                    self.heating, self.setpoint_c = event.heating, event.setpoint_c
                    if event.t_s is not None:
                        self.t_s = event.t_s
                case Message(level="warning" | "error"):
                    self.warnings += 1
                    self.last_error = event.message
                case Prompt():
                    self.phase = f"waiting: {event.prompt}"
                case Done():
                    self.phase, self.outcome = f"done ({event.outcome})", event.outcome

    def line(self, width: int = 160) -> str:
        """``[phase] t=H:MM:SS frames N conc C g/kg plate P C probe Q C S rpm heating ON (70 C) | last error``
        (``heating OFF`` once the plate reports it off, e.g. after the run switched it off)."""
        def num(v: float | None, fmt: str) -> str:
            return "-" if v is None else format(v, fmt)
        with self._lock:
            text = (f"[{self.phase}] t={hms(self.t_s)} frames {self.frames} conc {num(self.conc, '.3f')} g/kg "
                    f"plate {num(self.plate_c, '.1f')} C probe {num(self.probe_c, '.1f')} C "
                    f"{num(self.speed_rpm, '.0f')} rpm")
            if self.heating is not None:
                text += f" heating ON ({self.setpoint_c:g} C)" if self.heating else " heating OFF"
            if self.last_error:
                text += f" | {self.warnings} warnings, last: {self.last_error}"
        return text[:width]
