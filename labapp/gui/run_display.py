"""What the bench window shows of the procedure in progress: each stored run frame on the plots (with the drop,
a resume, steady state, gaps and frames that could not be analysed marked) and counted in the Runs list, the
bath's readings while it heats, preview and calibration frames, the run's reference frame with its crop before the
drop, and at the window's refresh the newest frame in the live view, the recording run's progress and the large
state word of the Run tab.

A new run starts from a clean view (:meth:`RunDisplay.prepare`): empty plots with their axes fitted anew, an empty
live view, and the status's previous warnings gone. A resumed run's stored frames arrive first (the procedure
publishes them again), so its plots show the whole run with the gap marked."""
from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QObject

from labapp.acquisition.events import (
    CalibrationLevel,
    Done,
    EngineEvent,
    FrameStored,
    Message,
    Phase,
    Preview,
    Reading,
    ReferenceStored,
    StateChanged,
)
from labapp.acquisition.procedures import RunConfig, RunProcedure
from labapp.acquisition.status import RunStatus
from labapp.gui.live_view import LiveView
from labapp.gui.plots import PlotsPanel
from labapp.gui.run_browser import RunBrowser
from labapp.gui.window_layout import RunProgress

GAP_FACTOR, GAP_MIN_S = 5.0, 120.0
"""A frame arriving more than this many intervals, and at least this long, after the previous one marks a gap
on the plots (an accelerated simulation may lag its interval a little: that is no gap)."""


_WORDS = {Phase.STARTING: "STARTING", Phase.CONNECTING: "STARTING", Phase.OPENED: "STARTING", Phase.HEATING: "HEATING",
          Phase.WAITING_DROP: "WAITING FOR DROP", Phase.ACQUIRING: "RECORDING", Phase.CALIBRATING: "CALIBRATING"}


def state_of(status: RunStatus, running: bool, stopping: bool = False) -> tuple[str, str]:
    """The Run tab's state word (``HEATING``, ``WAITING FOR DROP``, ``RECORDING``, ``LINK LOST``, ...) and a line
    of detail, from the status and whether the engine runs (``stopping``: a stop was asked)."""
    phase = status.phase
    if running and not status.link_ok:
        return "LINK LOST", status.plate_text()
    if running and stopping:
        return "STOPPING", "heating off, devices closing"
    if running:
        word = "WAITING FOR DROP" if phase.startswith("waiting: drop") else _WORDS.get(phase, phase.upper())
        if word == "WAITING FOR DROP":
            return word, "drop the object into the beaker, then press Object dropped (F7)"
        if word == "HEATING" and status.setpoint_c is not None:
            return word, f"bath to {status.setpoint_c:g} C: {status.plate_text()}"
        return word, status.plate_text()
    if not status.link_ok:
        return "LINK LOST", status.plate_text()
    if status.outcome is not None and phase.startswith("done"):
        return f"ENDED: {str(status.outcome).upper()}", ""
    return ("CONNECTED", status.plate_text()) if phase == "connected" else ("IDLE", "")


class RunDisplay(QObject):
    """Feeds the live view, the plots, the progress bar and the Runs list's frame counts from engine events
    (its ``on_*`` methods are slots for the :class:`~labapp.gui.bridge.EngineBridge`'s signals).

    Parameters
    ----------
    status : RunStatus
        The engine's status, current when a signal lands.
    live, plots, progress, browser : LiveView, PlotsPanel, RunProgress, RunBrowser
        The widgets it shows the procedure in.
    """

    def __init__(self, status: RunStatus, live: LiveView, plots: PlotsPanel, progress: RunProgress,
                 browser: RunBrowser, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.status, self.live, self.plots, self.progress, self.browser = status, live, plots, progress, browser
        self.run_config: RunConfig | None = None
        """The settings of the run being shown (None: not a run, or a resumed run without a record of them)."""
        self.latest_frame: str | None = None
        """The newest stored frame not shown yet (shown at the next :meth:`refresh`)."""
        self._last_frame_t: float | None = None
        self._resumed = False
        self._before_drop = False          # a run's readings before its drop go on the bath plot

    def prepare(self, config: RunConfig | None) -> None:
        """A clean view for a run with ``config``: empty plots (its water, object mass and setpoint band), an empty
        live view."""
        self.run_config = config
        self._last_frame_t = None
        self.latest_frame = None
        self._before_drop = config is not None
        self.plots.clear()
        self.live.clear("waiting for the reference frame (clear water) ...")
        if config is not None:
            self.plots.set_water(config.bath.water_g)
            self.plots.set_object_mass(config.object_mass_g)
            self.plots.set_setpoint_band(config.bath.setpoint_c, config.bath.tolerance_c)
            self.plots.set_duration(config.max_duration_s)

    def on_frame(self, frame: FrameStored) -> None:
        """A run frame was stored: plot it, remember it for the live view."""
        self.latest_frame = frame.path
        interval = self.run_config.interval_s if self.run_config is not None else None
        if self._last_frame_t is not None and interval and \
                frame.t_s - self._last_frame_t > max(GAP_FACTOR * interval, GAP_MIN_S):
            self.plots.mark("gap", self._last_frame_t, "", end_s=frame.t_s)
        self._last_frame_t = frame.t_s
        self.plots.add_frame(frame.t_s, frame.conc_g_per_kg)
        self.browser.show_frames(Path(frame.path).parent, frame.n_frames)     # the Runs list counts live
        # the bath plot shows the reading logged with each frame: one time base with the release curve
        self.plots.add_reading(frame.t_s, frame.plate_c, frame.probe_c, frame.speed_rpm)

    def on_event(self, event: EngineEvent) -> None:
        """Marks on the plots: the drop, a resume, steady state and a frame that could not be analysed (faults and
        excursions: the alarm banner's); the bath's readings before the drop."""
        t = self.status.t_s
        if isinstance(event, StateChanged) and event.phase == Phase.OPENED:
            self._resumed = event.resumed
        if isinstance(event, Done):
            self._before_drop = False
        if isinstance(event, StateChanged) and event.phase == Phase.ACQUIRING:
            self._before_drop = False
            self.plots.set_drop(event.t0_unix_s)
            if self._resumed:
                now = self.plots.t_now(event.t_unix_s, event.t0_unix_s, t)
                if self._last_frame_t is not None and now > self._last_frame_t:
                    self.plots.mark("gap", self._last_frame_t, "", end_s=now)     # the time nothing was recorded
                    self.plots.add_reading(self._last_frame_t, None, None, None)   # no bath line across it
                    self._last_frame_t = now
                self.plots.mark("resume", now, "resumed")
            else:
                self.plots.mark("drop", 0.0, "drop")
        elif isinstance(event, Reading) and event.t_s is None and self._before_drop:
            self.plots.add_heating_reading(event.t_unix_s, event.plate_c, event.probe_c, event.speed_rpm)
        elif isinstance(event, Message) and t is not None and event.topic == "steady":
            self.plots.mark("steady", t, "steady state")
        elif isinstance(event, Message) and t is not None and event.topic == "analysis" and ": could not" in event.message:
            self.plots.mark("fault", t, "frame not analysed")

    def on_reference(self, reference: ReferenceStored) -> None:
        """Show the run's reference frame with the crop: check it on today's beaker before the drop."""
        self.live.show_file(reference.path, "reference frame (clear water): check the crop before the drop")

    def on_level(self, level: CalibrationLevel) -> None:
        """A calibration-series frame was stored: show it in the live view."""
        self.latest_frame = level.path

    def on_preview(self, preview: Preview) -> None:
        """Show a preview frame."""
        self.live.show_jpeg(preview.data, f"preview {preview.file}")

    def refresh(self, running: bool, procedure: object) -> None:
        """The run's progress (``running``: the engine runs ``procedure``) and the newest frame."""
        self.show_progress(running, procedure)
        if self.latest_frame is not None:
            self.live.show_file(self.latest_frame)
            self.latest_frame = None

    def show_progress(self, running: bool, procedure: object) -> None:
        """Show the progress bar while a run records (``running``: the engine runs ``procedure``)."""
        config, t = self.run_config, self.status.t_s
        if isinstance(procedure, RunProcedure):
            config = procedure.config      # the engine's: a duration changed during the run included
        recording = running and config is not None and self.status.phase == Phase.ACQUIRING
        self.progress.setVisible(recording)
        if recording and t is not None:
            self.progress.show_time(t, config.max_duration_s, config.stop_on_steady)
