"""The records the engine publishes: one frozen dataclass per kind.

Subscribers tell kinds apart by type (``isinstance`` or ``match``), never by which keys are present.
``t_unix_s`` is stamped by :meth:`labapp.acquisition.engine.Engine.emit` with the engine's clock (simulated time on
an accelerated bench). Times from the drop in s, temperatures in degrees C, speeds in rpm,
concentrations in g/kg, masses in g.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Literal

__all__ = ["Alarm", "AlarmKind", "CalibrationLevel", "Done", "EngineEvent", "FrameStored", "Link", "Message", "Outcome",
           "Phase", "Preview", "Prompt", "PromptKind", "Reading", "ReferenceStored", "StateChanged"]

Level = Literal["info", "warning", "error"]


class Phase(enum.StrEnum):
    """The step a procedure is in (:class:`StateChanged`)."""

    STARTING = "starting"
    CONNECTING = "connecting"
    OPENED = "opened"
    """The run folder exists (new or resumed)."""
    HEATING = "heating"
    WAITING_DROP = "waiting-drop"
    ACQUIRING = "acquiring"
    CALIBRATING = "calibrating"


class PromptKind(enum.StrEnum):
    """What the operator is asked (:class:`Prompt`); the answer goes to ``Engine.answer`` under the same name."""

    DROP = "drop"
    """Confirm that the object is in the beaker (time zero)."""
    ADDED_MASS = "added_mass_g"
    """The cumulative filament mass of the next calibration level, g; empty to finish the series."""


class Outcome(enum.StrEnum):
    """How a procedure ended (:class:`Done`); a run's final status in ``run.json`` has the same value."""

    COMPLETE = "complete"
    STOPPED = "stopped"
    """Stopped on request (the data so far is kept and finalised)."""
    ABORTED = "aborted"
    FAILED = "failed"
    INTERRUPTED = "interrupted"
    """Interrupted by a signal (SIGINT, SIGTERM) or by closing the window: heating off, the run folder left
    resumable (``run.json`` reads ``interrupted``)."""


class AlarmKind(enum.StrEnum):
    """What the operator must see, not only read in the log (:class:`Alarm`): failures, and changes that need
    them (the drop, a link back, a heater switched on again, the end of a run)."""

    HEAT_TIMEOUT = "heat-timeout"
    """The bath did not become stable within the heating timeout."""
    FIT_FAILED = "fit-failed"
    """The calibration series' fit failed."""
    CAMERA_FAULT = "camera-fault"
    """A capture was missed or failed."""
    LINK_FAULT = "link-fault"
    """The hotplate's link was lost (or dropped and re-established by the driver)."""
    TEMPERATURE_EXCURSION = "temperature-excursion"
    """The bath left setpoint +/- the run's excursion tolerance during acquisition."""
    REFERENCE_OFFSET = "reference-offset"
    """The reference frame does not read as clear water on the calibration's zero level."""
    LINK_RESTORED = "link-restored"
    """The hotplate answers again after a lost link (check what it does now)."""
    HEATER_RESTARTED = "heater-restarted"
    """The plate had stopped heating and stirring on its own (its connection check) and was switched on again."""
    NOT_CONFIRMED_OFF = "not-confirmed-off"
    """At the end of a procedure the plate did not confirm that heating and stirring are off."""
    DROP = "drop"
    """The bath is stable and the reference taken: drop the object now, then confirm."""
    RUN_ENDED = "run-ended"
    """A run or calibration series ended (its outcome)."""


@dataclass(frozen=True)
class EngineEvent:
    """Base of every published record."""

    t_unix_s: float = field(default=0.0, kw_only=True)


@dataclass(frozen=True)
class StateChanged(EngineEvent):
    """A procedure entered ``phase``; ``folder`` once the run folder exists."""

    phase: Phase
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
    fresh_s: float = 6.0
    """Wall seconds for which this reading counts as the plate's current state: its poll interval plus the time
    one read takes (:attr:`labapp.acquisition.monitor.HotplateMonitor.fresh_s`); older, it is stale."""


@dataclass(frozen=True)
class Link(EngineEvent):
    """The hotplate's link went down (``ok`` False: no reading arrives, heating and stirring are unknown; the
    monitor keeps retrying) or answers again (``ok`` True)."""

    ok: bool
    message: str


@dataclass(frozen=True)
class ReferenceStored(EngineEvent):
    """The run's reference frame (clear water, before the drop) was stored at ``path``."""

    path: str


@dataclass(frozen=True)
class Preview(EngineEvent):
    """One frame from the camera, not stored (the device panel's connect check); ``data`` is the file."""

    data: bytes
    file: str
    capture_t_unix_s: float


@dataclass(frozen=True)
class Prompt(EngineEvent):
    """The operator is asked ``text``; answer with ``Engine.answer(prompt, value)``; ``auto`` answers itself."""

    prompt: PromptKind
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
class Alarm(EngineEvent):
    """A failure the operator must acknowledge: ``kind``, the text, and ``t_s`` (s since the drop; None
    before it). The same text is also published as a :class:`Message` and written to ``events.log``."""

    kind: AlarmKind
    message: str
    t_s: float | None = None


@dataclass(frozen=True)
class Done(EngineEvent):
    """A procedure ended with ``outcome``; ``reason`` is the engine's stop reason."""

    outcome: Outcome
    reason: str = ""
