"""A one-line summary of a running procedure, built from engine events (CLI status line and GUI status bar)."""
from __future__ import annotations

import logging
import math
import threading

from labapp.engine import Event

log = logging.getLogger(__name__)


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
        self.phase = "idle"
        self.folder = ""
        self.t_s: float | None = None
        self.frames = 0
        self.conc: float | None = None
        self.plate_c: float | None = None
        self.probe_c: float | None = None
        self.speed_rpm: float | None = None
        self.last_error = ""
        self.warnings = 0
        self.outcome: str | None = None

    def update(self, event: Event) -> None:
        """Fold one event into the status."""
        d = event.data
        with self._lock:
            if event.kind == "state":
                self.phase = d.get("phase", self.phase)
                self.folder = d.get("folder", self.folder)
            elif event.kind == "frame":
                self.t_s, self.frames = d.get("t_s"), d.get("n_frames", self.frames)
                conc = d.get("conc_g_per_kg")
                self.conc = conc if conc is not None and not math.isnan(conc) else self.conc
            elif event.kind == "reading":
                self.plate_c, self.probe_c, self.speed_rpm = d["plate_c"], d["probe_c"], d["speed_rpm"]
                if d.get("t_s") is not None:
                    self.t_s = d["t_s"]
            elif event.kind in ("warning", "error"):
                self.warnings += 1
                self.last_error = d.get("message", "")
            elif event.kind == "prompt":
                self.phase = f"waiting: {d.get('prompt')}"
            elif event.kind == "done":
                self.phase, self.outcome = f"done ({d.get('outcome')})", d.get("outcome")

    def line(self, width: int = 160) -> str:
        """``[phase] t=H:MM:SS frames N conc C g/kg plate P C probe Q C S rpm | last error``."""
        def num(v: float | None, fmt: str) -> str:
            return "-" if v is None else format(v, fmt)
        with self._lock:
            text = (f"[{self.phase}] t={hms(self.t_s)} frames {self.frames} conc {num(self.conc, '.3f')} g/kg "
                    f"plate {num(self.plate_c, '.1f')} C probe {num(self.probe_c, '.1f')} C "
                    f"{num(self.speed_rpm, '.0f')} rpm")
            if self.last_error:
                text += f" | {self.warnings} warnings, last: {self.last_error}"
        return text[:width]
