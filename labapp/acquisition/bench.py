"""The devices of one bench and the steps every procedure shares (connect, heat, capture, shut down)."""
from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

from drivers.camera.base import DSLR_FRAME_BYTES, Camera, CameraError, CameraSettings, Capture, CaptureMissed
from drivers.hotplate.base import Hotplate, HotplateError, HotplateReading
from labapp.acquisition.engine import Engine
from labapp.acquisition.events import Alarm, AlarmKind, Link, Message, Phase, Reading, StateChanged
from labapp.acquisition.monitor import HotplateMonitor
from labapp.acquisition.settings import KEEPALIVE, BathSettings
from labapp.errors import LabError
from labapp.records.storage import RunFolder

log = logging.getLogger(__name__)
_LEVELS = {"info": logging.INFO, "warning": logging.WARNING, "error": logging.ERROR}
PUBLISHED = "published_as_event"
"""Attribute set on log records that are also published as engine events."""
HEAT_PROGRESS_S = 60.0
"""Seconds of the procedure's clock between two notes of the bath's progress while it heats."""
_REPORT_ALARMS = {("warning", "hotplate-link"): AlarmKind.LINK_FAULT, ("info", "hotplate-link"): AlarmKind.LINK_RESTORED,
                  ("warning", "hotplate-restart"): AlarmKind.HEATER_RESTARTED}
"""The alarm each report of the hotplate monitor raises (level, kind): every change the operator must see."""


def bath_c(reading: HotplateReading) -> float:
    """The bath's temperature of a reading, C: the probe's, else the plate's (no probe plugged in)."""
    return reading.probe_c if reading.probe_c is not None else reading.plate_c


def heat_timeout_text(setpoint_c: float, tolerance_c: float, hold_s: float, timeout_s: float,
                      last: HotplateReading | None) -> str:
    """The sentence that ends a procedure whose bath never became stable."""
    if last is None:
        now = "no reading of the hotplate arrived"
    else:
        now = (f"the last reading was {bath_c(last):.1f} C ({'probe' if last.probe_c is not None else 'plate, no probe'}), "
               f"heating {'on' if last.heating else 'OFF'} at a setpoint of {last.setpoint_c:g} C")
    return (f"the bath did not hold {setpoint_c:g} +/- {tolerance_c:g} C for {hold_s:g} s within the heating timeout of "
            f"{timeout_s:g} s; {now}. A hotplate only heats: a setpoint below the bath's room temperature is never "
            "reached (choose no heating)")


def monitor_poll_s(keepalive_s: float, clock_speed: float) -> float:
    """Wall seconds between two polls of the hotplate: every ``keepalive_s`` of the engine's clock, so that on an
    accelerated clock a reading is as recent as on the real bench (at most 20 polls a wall second; the serial
    link itself bounds the rate)."""
    return max(keepalive_s / max(clock_speed, 1.0), min(keepalive_s, 0.05))


class ProcedureError(LabError):
    """A procedure cannot go on (bath never stable, camera gone for good); the message says why."""


@dataclass
class Bench:
    """A camera, an optional hotplate, and hooks through which a simulated bench follows the procedure.

    ``on_drop(t_unix_s)`` is called when the object goes in (time zero, also again on resume);
    ``on_add_mass(total_g)`` when a calibration step adds filament (cumulative mass); ``on_new_beaker()`` when
    a new run or series starts with fresh water (a simulated bench empties its beaker). ``frame_bytes`` is
    what one capture takes on disk, bytes, for the disk-space check before a run.
    """

    camera: Camera
    hotplate: Hotplate | None = None
    camera_settings: CameraSettings = field(default_factory=CameraSettings)
    simulated: bool = False
    on_drop: Callable[[float], None] | None = None
    on_add_mass: Callable[[float], None] | None = None
    on_new_beaker: Callable[[], None] | None = None
    description: str = ""
    frame_bytes: int = DSLR_FRAME_BYTES


class BenchSession:
    """The live connection to a bench during one procedure: devices, hotplate monitor and run-folder logging.

    Every ``note`` goes both to the run's ``events.log`` and to the engine's subscribers; notes made before
    the run folder exists (while connecting) are written to it by :meth:`attach`.
    """

    def __init__(self, bench: Bench, engine: Engine, run: RunFolder | None,
                 keepalive_s: float = KEEPALIVE.default) -> None:
        self.bench, self.engine, self.run = bench, engine, run
        self.keepalive_s = keepalive_s
        self.monitor: HotplateMonitor | None = None
        self.t0_unix_s: float | None = None
        self.camera_failures = 0
        self.last_error = ""
        self._pending: list[tuple[str, str, str]] = []
        self._band: tuple[float, float] | None = None       # (setpoint, excursion) watched after the drop
        self._outside = False
        self.off_confirmed: bool | None = None
        """After :meth:`close`: True when the plate confirmed heating and stirring off, False when it did not,
        None without a hotplate."""

    def attach(self, run: RunFolder) -> None:
        """Log into ``run`` from now on, starting with the notes made before it existed."""
        self.run = run
        for level, kind, message in self._pending:
            run.event(level, kind, message, self.t_s())
        self._pending.clear()

    def t_s(self, t_unix_s: float | None = None) -> float | None:
        """Seconds since the drop (None before it)."""
        if self.t0_unix_s is None:
            return None
        return (self.engine.clock.now() if t_unix_s is None else t_unix_s) - self.t0_unix_s

    def note(self, level: str, kind: str, message: str, alarm: AlarmKind | None = None) -> None:
        """Record an event in ``events.log`` and publish it (``info``, ``warning`` or ``error``); with
        ``alarm``, also publish an :class:`labapp.acquisition.events.Alarm` of that kind."""
        # also published as a Message event: marked so that the GUI's log handler does not show it twice
        log.log(_LEVELS.get(level, logging.INFO), "%s: %s", kind, message, extra={PUBLISHED: True})
        if level in ("warning", "error"):
            self.last_error = message
        if self.run is not None:
            self.run.event(level, kind, message, self.t_s())
        else:
            self._pending.append((level, kind, message))
        self.engine.emit(Message(level if level in ("info", "warning", "error") else "info", message, topic=kind))
        if alarm is not None:
            self.engine.emit(Alarm(alarm, message, self.t_s()))

    def _monitor_report(self, level: str, kind: str, message: str) -> None:
        """The monitor's report, each with its alarm: a lost link, a link back, a plate switched on again."""
        self.note(level, kind, message, _REPORT_ALARMS.get((level, kind)))

    def _link(self, ok: bool, message: str) -> None:
        self.engine.emit(Link(ok, message))

    def fresh_reading(self) -> HotplateReading | None:
        """The hotplate's latest reading while it is fresh (:meth:`HotplateMonitor.fresh`), else None."""
        return self.monitor.fresh() if self.monitor is not None else None

    def connect(self, setpoint_c: float | None, speed_rpm: float | None) -> None:
        """Connect and configure the camera; connect the hotplate, set it up and start heating."""
        self.engine.emit(StateChanged(Phase.CONNECTING))
        self.bench.camera.connect()
        outcome = self.bench.camera.configure(self.bench.camera_settings)
        self.note("info", "camera", f"camera connected ({self.bench.description or type(self.bench.camera).__name__}); "
                  f"settings: {outcome}")
        hp = self.bench.hotplate
        if hp is None:
            return
        hp.connect()
        poll_s = monitor_poll_s(self.keepalive_s, self.engine.clock.speed)
        self.monitor = HotplateMonitor(hp, self._monitor_report, poll_s=poll_s, on_reading=self._publish_reading,
                                       on_link=self._link)
        if setpoint_c is not None:
            self.monitor.command(hp.set_temperature, setpoint_c)
            self.monitor.command(hp.start_heating)
        if speed_rpm is not None:
            self.monitor.command(hp.set_speed, speed_rpm)
        self.monitor.poll()
        self.monitor.start()
        self.note("info", "hotplate", "hotplate connected" + ("" if setpoint_c is None else
                  f"; setpoint {setpoint_c} C, {speed_rpm} rpm, heating on"))

    def _publish_reading(self, reading: HotplateReading) -> None:
        self.engine.emit(Reading(reading.plate_c, reading.probe_c, reading.speed_rpm, reading.setpoint_c,
                                 reading.setpoint_rpm, reading.heating, reading.stirring, self.t_s(),
                                 fresh_s=self.monitor.fresh_s))
        if self._band is not None:
            self._check_band(bath_c(reading))

    def watch_bath(self, setpoint_c: float | None, excursion_c: float) -> None:
        """From now on, raise a temperature-excursion alarm whenever the bath (probe, else plate) leaves
        ``setpoint_c`` +/- ``excursion_c`` (C), and note when it is back; nothing without a setpoint."""
        self._band = None if setpoint_c is None or self.monitor is None else (setpoint_c, excursion_c)
        self._outside = False

    def _check_band(self, temp_c: float) -> None:
        setpoint_c, excursion_c = self._band
        outside = abs(temp_c - setpoint_c) > excursion_c
        if outside and not self._outside:
            self.note("warning", "temperature", f"bath at {temp_c:.1f} C, outside the setpoint {setpoint_c:g} +/- "
                      f"{excursion_c:g} C", AlarmKind.TEMPERATURE_EXCURSION)
        elif self._outside and not outside:
            self.note("info", "temperature", f"bath back within {setpoint_c:g} +/- {excursion_c:g} C "
                      f"({temp_c:.1f} C)")
        self._outside = outside

    def wait_stable(self, setpoint_c: float, tolerance_c: float, hold_s: float, timeout_s: float,
                    step_s: float) -> None:
        """Wait until the bath holds the setpoint (see :meth:`HotplateMonitor.wait_stable`).

        Raises
        ------
        ProcedureError
            If it does not within ``timeout_s`` (s, procedure clock).
        """
        if self.monitor is None:
            return
        self.engine.emit(StateChanged(Phase.HEATING, setpoint_c=setpoint_c))
        clock = self.engine.clock
        ok = self.monitor.wait_stable(setpoint_c, tolerance_c, hold_s, timeout_s, step_s, clock.now,
                                      lambda dt: clock.sleep(dt, self.engine.should_stop), self.engine.should_stop,
                                      self._heat_progress(setpoint_c, tolerance_c, hold_s))
        if self.engine.should_stop():
            return
        if not ok:
            message = heat_timeout_text(setpoint_c, tolerance_c, hold_s, timeout_s, self.monitor.latest)
            self.engine.emit(Alarm(AlarmKind.HEAT_TIMEOUT, message))    # the error itself ends the procedure
            raise ProcedureError(message)
        self.note("info", "stable", f"bath stable at {setpoint_c} +/- {tolerance_c} C for {hold_s:.0f} s")

    def _heat_progress(self, setpoint_c: float, tolerance_c: float, hold_s: float) -> Callable[[HotplateReading], None]:
        """A progress callback for the heating wait: notes the bath's temperature, its rate and the time to the
        setpoint every :data:`HEAT_PROGRESS_S` of the procedure's clock."""
        clock, last = self.engine.clock, []

        def progress(reading: HotplateReading) -> None:
            now, temp = clock.now(), bath_c(reading)
            if last and now - last[0][0] < HEAT_PROGRESS_S:
                return
            rate = (temp - last[0][1]) / (now - last[0][0]) * 60.0 if last else None
            gap = setpoint_c - temp
            if abs(gap) <= tolerance_c:
                left = f"within +/- {tolerance_c:g} C: holding for {hold_s:g} s"
            elif rate is None:
                left = "the next note says how fast it rises"
            elif rate * gap > 0:
                left = f"about {gap / rate:.0f} min to the setpoint"
            else:
                left = "not approaching the setpoint"
            rising = "" if rate is None else f", {rate:+.1f} C/min"
            self.note("info", "heating", f"heating: bath {temp:.1f} C of {setpoint_c:g} C{rising}; {left}")
            last[:] = [(now, temp)]
        return progress

    def wait_bath(self, bath: BathSettings) -> None:
        """Wait until the bath holds ``bath.setpoint_c`` (:meth:`wait_stable`); no wait without a setpoint."""
        if bath.setpoint_c is not None:
            self.wait_stable(bath.setpoint_c, bath.tolerance_c, bath.hold_s, bath.heat_timeout_s, bath.stable_step_s)

    def start_stirring(self, speed_rpm: float | None = None, timeout_s: float = 120.0, step_s: float = 2.0) -> None:
        """Switch the stirrer on (no-op without a hotplate); with ``speed_rpm``, wait until the measured
        speed is within 5 % of it (at most ``timeout_s``, s on the procedure clock; a warning if not)."""
        if self.monitor is None:
            return
        self.monitor.command(self.bench.hotplate.start_stirring)
        self.note("info", "stirring", "stirring on")
        if speed_rpm is None:
            return
        clock = self.engine.clock
        deadline = clock.now() + timeout_s
        while not self.engine.should_stop():
            reading = self.monitor.poll()
            if reading is not None and abs(reading.speed_rpm - speed_rpm) <= 0.05 * speed_rpm:
                self.note("info", "stirring", f"stirring steady at {reading.speed_rpm:.0f} rpm")
                return
            if clock.now() >= deadline:
                self.note("warning", "stirring", f"stirrer not at {speed_rpm:.0f} rpm after {timeout_s:.0f} s "
                          f"(last reading: {reading}); going on")
                return
            clock.sleep(step_s, self.engine.should_stop)

    def capture(self) -> Capture | None:
        """One capture; a missed or failed frame is logged and returns None, the camera is re-initialised
        after three failures in a row."""
        try:
            cap = self.bench.camera.capture()
        except CaptureMissed as exc:
            self.camera_failures += 1
            self.note("warning", "camera-missed", f"frame missed: {exc}", AlarmKind.CAMERA_FAULT)
            return None
        except CameraError as exc:
            self.camera_failures += 1
            self.note("warning", "camera-error", f"capture failed: {exc}", AlarmKind.CAMERA_FAULT)
            if self.camera_failures >= 3:
                self._reinit_camera()
            return None
        self.camera_failures = 0
        return cap

    def _reinit_camera(self) -> None:
        try:
            self.bench.camera.close()
            self.bench.camera.connect()
            self.bench.camera.configure(self.bench.camera_settings)
            self.note("info", "camera", "camera re-initialised after repeated failures")
            self.camera_failures = 0
        except CameraError as exc:
            self.note("warning", "camera-error", f"camera re-initialisation failed: {exc}")

    def close(self) -> None:
        """Heating and stirring off, devices closed; every step best effort and logged. "Switched off" is
        recorded only when the plate confirms it: both commands answered and a last reading (published) shows
        heating and stirring off; otherwise an error and a :attr:`AlarmKind.NOT_CONFIRMED_OFF` alarm say that
        they could not be confirmed off (:attr:`off_confirmed`)."""
        self._band = None
        if self.monitor is not None:
            self.monitor.stop()
            failed = []
            for step in (self.bench.hotplate.stop_heating, self.bench.hotplate.stop_stirring):
                try:
                    self.monitor.command(step)
                except HotplateError as exc:
                    failed.append(step.__name__)
                    self.note("warning", "hotplate", f"{step.__name__} failed: {exc}")
            last = self.monitor.poll()
            self.off_confirmed = not failed and last is not None and not last.heating and not last.stirring
            if self.off_confirmed:
                self.note("info", "hotplate", "heating and stirring switched off (the plate confirms: heating off, "
                          "stirring off)")
            else:
                why = (f"{' and '.join(failed)} failed" if failed else "no reading after the commands" if last is None
                       else f"the plate still reads heating {'on' if last.heating else 'off'}, stirring "
                            f"{'on' if last.stirring else 'off'}")
                self.note("error", "hotplate", f"heating and stirring could NOT be confirmed off ({why}): check the "
                          "plate and switch it off by hand", AlarmKind.NOT_CONFIRMED_OFF)
        for device in (self.bench.hotplate, self.bench.camera):
            if device is None:
                continue
            try:
                device.close()
            except (CameraError, HotplateError, OSError) as exc:
                self.note("warning", "close", f"closing {type(device).__name__} failed: {exc}")
