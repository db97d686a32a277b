"""The connected bench's hotplate, polled while no procedure holds it.

A procedure (preview, run, calibration series) connects the hotplate, polls it through its
:class:`labapp.acquisition.monitor.HotplateMonitor` and closes it at the end (heating and stirring off). Between
procedures the window keeps the bench it last used "connected": :class:`IdlePlatePoller` opens the hotplate again
and polls it with a monitor of its own, off the GUI thread, every ``keepalive_s`` of the engine's clock
(:func:`labapp.acquisition.bench.monitor_poll_s`), publishing each reading as the engine's
:class:`labapp.acquisition.events.Reading` (so the device panel and the status line show the plate as it is, not
as the last run left it) and a lost or restored link as a :class:`labapp.acquisition.events.Message`. It switches
nothing on; closing its connection switches heating and stirring off, as the driver always does.

A procedure takes the hotplate over through :class:`HeldProcedure`: in the engine's thread, before its own
startup, the idle poller stops and closes the hotplate; when it has shut down, the window hands the hotplate back
(:meth:`IdlePlatePoller.hold`). One lock orders the hand-over, so the poller never opens a port a procedure holds.
"""
from __future__ import annotations

import logging
import threading
import time

from drivers.hotplate.base import Hotplate, HotplateError, HotplateReading
from labapp.acquisition.bench import monitor_poll_s
from labapp.acquisition.engine import Engine, Procedure
from labapp.acquisition.events import Link, Message, Outcome, Reading
from labapp.acquisition.monitor import HotplateMonitor
from labapp.acquisition.settings import KEEPALIVE

log = logging.getLogger(__name__)
PORT_SETTLE_S = 0.5
"""Wall seconds between closing the hotplate's port and opening it again (by the idle poller or a procedure): a
serial adapter, like the emulator's pseudo-terminal, needs a moment to let go of the last connection."""


class IdlePlatePoller:
    """Poll a connected hotplate while the engine runs no procedure.

    Parameters
    ----------
    engine : Engine
        Readings and link messages are published through it; its clock sets the poll period.
    """

    def __init__(self, engine: Engine) -> None:
        self.engine = engine
        self._lock = threading.Lock()
        self._busy = False                  # a procedure holds the bench
        self._closed = False
        self.hotplate: Hotplate | None = None
        self.monitor: HotplateMonitor | None = None
        self._opener: threading.Thread | None = None
        self._stop = threading.Event()

    @property
    def polling(self) -> bool:
        """True while a hotplate is held for idle polling."""
        return self.hotplate is not None

    def hold(self, hotplate: Hotplate | None, keepalive_s: float = KEEPALIVE.default) -> None:
        """Poll ``hotplate`` from now on (opened off the calling thread), unless a procedure holds the bench or
        the poller is closed; a hotplate already polled is kept, another one replaces it."""
        if hotplate is None:
            return
        with self._lock:
            if self._busy or self._closed or hotplate is self.hotplate:
                return
            self._release_locked()
            self.hotplate = hotplate
            self._stop = threading.Event()
            poll_s = monitor_poll_s(keepalive_s, self.engine.clock.speed)
            self.monitor = HotplateMonitor(hotplate, self._report, poll_s=poll_s, on_reading=self._publish,
                                           on_link=self._link)
            self._opener = threading.Thread(target=self._open, args=(hotplate, self.monitor, self._stop),
                                            name="hotplate-idle", daemon=True)
            self._opener.start()

    def _open(self, hotplate: Hotplate, monitor: HotplateMonitor, stop: threading.Event) -> None:
        if stop.wait(PORT_SETTLE_S):         # the procedure has just closed the port
            return
        try:
            hotplate.connect()
        except Exception as exc:             # the monitor's first poll reports the lost link and retries
            log.debug("idle hotplate connect failed: %s", exc)
        if not stop.is_set():
            monitor.start()

    def _publish(self, reading: HotplateReading) -> None:
        monitor = self.monitor
        fresh = {} if monitor is None else {"fresh_s": monitor.fresh_s}
        self.engine.emit(Reading(reading.plate_c, reading.probe_c, reading.speed_rpm, reading.setpoint_c,
                                 reading.setpoint_rpm, reading.heating, reading.stirring, None, **fresh))

    def _link(self, ok: bool, message: str) -> None:
        self.engine.emit(Link(ok, f"{message} (polling while idle)"))

    def _report(self, level: str, kind: str, message: str) -> None:
        self.engine.emit(Message(level, f"{message} (polling while idle)", topic=kind))

    def release(self, hotplate: Hotplate | None = None) -> None:
        """Stop polling and close the hotplate (only if it is ``hotplate``, when given); blocks for one poll at
        most. The next :meth:`hold` opens it again."""
        with self._lock:
            if hotplate is None or hotplate is self.hotplate:
                self._release_locked()

    def _release_locked(self) -> None:
        hotplate, monitor, opener = self.hotplate, self.monitor, self._opener
        self.hotplate = self.monitor = self._opener = None
        if hotplate is None:
            return
        self._stop.set()
        if opener is not None:
            opener.join()
        monitor.stop()
        try:
            hotplate.close()
        except (HotplateError, OSError) as exc:
            log.warning("closing the idle hotplate connection failed: %s", exc)

    def begin_procedure(self) -> None:
        """A procedure takes the bench: stop polling and close the hotplate, and give the port
        :data:`PORT_SETTLE_S` before the procedure opens it (call it from the engine's thread)."""
        with self._lock:
            self._busy = True
            held = self.hotplate is not None
            self._release_locked()
        if held:
            time.sleep(PORT_SETTLE_S)

    def end_procedure(self) -> None:
        """The procedure has shut down its devices: :meth:`hold` may poll again."""
        with self._lock:
            self._busy = False

    def close(self) -> None:
        """Stop for good (the window closes)."""
        with self._lock:
            self._closed = True
            self._release_locked()


class HeldProcedure:
    """A procedure as the engine walks it when the window polls the plate while idle: the poller gives the
    hotplate up before the procedure's startup and may take it back after its shutdown."""

    def __init__(self, procedure: Procedure, poller: IdlePlatePoller) -> None:
        self.procedure, self.poller = procedure, poller
        self.name = procedure.name

    def startup(self, engine: Engine) -> None:
        """Release the idle poller's hotplate, then start the procedure."""
        self.poller.begin_procedure()
        self.procedure.startup(engine)

    def execute(self, engine: Engine) -> None:
        """The procedure's own."""
        self.procedure.execute(engine)

    def shutdown(self, engine: Engine, outcome: Outcome) -> None:
        """The procedure's own; then the bench is free for idle polling again."""
        try:
            self.procedure.shutdown(engine, outcome)
        finally:
            self.poller.end_procedure()
