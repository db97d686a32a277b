"""The records the engine publishes: one frozen dataclass per kind.

Subscribers tell kinds apart by type (``isinstance`` or ``match``), never by which keys are present.
``t_unix_s`` is stamped by :meth:`labapp.acquisition.engine.Engine.emit` with the engine's clock (simulated time on
an accelerated bench). Times from the drop in s, temperatures in degrees C, speeds in rpm,
concentrations in g/kg, masses in g.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

__all__ = ["CalibrationLevel", "Done", "EngineEvent", "FrameStored", "Message", "Preview", "Prompt", "Reading",
           "StateChanged"]

Level = Literal["info", "warning", "error"]


@dataclass(frozen=True)
class EngineEvent:
    """Base of every published record."""

    t_unix_s: float = field(default=0.0, kw_only=True)


@dataclass(frozen=True)
class StateChanged(EngineEvent):
    """A procedure entered ``phase`` (``starting``, ``connecting``, ``opened``, ``heating``, ``waiting-drop``,
    ``acquiring``, ``calibrating``); ``folder`` once the run folder exists."""

    phase: str
    folder: str | None = None
    procedure: str | None = None
    resumed: bool = False
    setpoint_c: float | None = None
    t0_unix_s: float | None = None


@dataclass(frozen=True)
class FrameStored(EngineEvent):
    """A release-run frame was stored (and analysed live when a calibration is active)."""

    index: int
    file: str
    path: str
    t_s: float
    n_frames: int
    capture_t_unix_s: float | None = None
    conc_g_per_kg: float = math.nan
    uncertainty_g_per_kg: float = math.nan
    released_g: float = math.nan
    plate_c: float | None = None
    probe_c: float | None = None
    speed_rpm: float | None = None
    last_error: str = ""


@dataclass(frozen=True)
class CalibrationLevel(EngineEvent):
    """A calibration-series frame was stored at a known cumulative added mass."""

    index: int
    file: str
    path: str
    t_s: float | None
    added_mass_g: float
    conc_g_per_kg: float
    n_frames: int


@dataclass(frozen=True)
class Reading(EngineEvent):
    """A hotplate poll; ``t_s`` None before the drop."""

    plate_c: float
    probe_c: float | None
    speed_rpm: float
    setpoint_c: float
    setpoint_rpm: float
    heating: bool
    stirring: bool
    t_s: float | None = None


@dataclass(frozen=True)
class Preview(EngineEvent):
    """One frame from the camera, not stored (the device panel's connect check); ``data`` is the file."""

    data: bytes
    file: str
    capture_t_unix_s: float


@dataclass(frozen=True)
class Prompt(EngineEvent):
    """The operator is asked ``text``; answer with ``Engine.answer(prompt, value)``; ``auto`` answers itself."""

    prompt: str
    text: str
    auto: bool = False


@dataclass(frozen=True)
class Message(EngineEvent):
    """A note for the event log: ``level`` info, warning or error; ``topic`` what it is about; ``fatal``
    for the error that ended a procedure."""

    level: Level
    message: str
    topic: str = ""
    fatal: bool = False


@dataclass(frozen=True)
class Done(EngineEvent):
    """A procedure ended with ``outcome`` (``complete``, ``stopped``, ``aborted``, ``failed``)."""

    outcome: str
    reason: str = ""
