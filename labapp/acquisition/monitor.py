"""A background poller that keeps the hotplate's link alive and always has its latest reading.

The Heidolph unit shows "PC Err" after 10 s without a command while heating, and an 11 s frame interval
is longer than that, so the plate is polled on its own thread every ``poll_s`` wall seconds. Every
command to the plate goes through :meth:`HotplateMonitor.command` under one lock, so the poller and the
procedure never interleave bytes on the wire. A lost link is reported once, then retried with back-off
(``connect()`` again) until it comes back, which is reported too; so is a drop the driver repaired by
itself (a driver with a ``reconnects`` counter, like ``HeidolphHotplate``) and a plate that had stopped on its
own and was switched on again (a ``watchdog_trips`` counter).

A reading is the plate's current state only while it is fresh: younger than the poll interval plus the time one
read takes (:attr:`HotplateMonitor.fresh_s`). :meth:`HotplateMonitor.fresh` returns the latest reading only
then, so that a procedure never stores an old reading as a new measurement (a driver that retries a dead link
for 15 s inside ``read()`` leaves the last good reading in place all that time).
"""
from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from drivers.hotplate.base import Hotplate, HotplateError, HotplateReading

log = logging.getLogger(__name__)

GRACE_S = 0.5
"""Wall seconds of scheduling slack added to a reading's freshness (a loaded machine wakes the poller late)."""


class HotplateMonitor:
    """Poll ``hotplate`` every ``poll_s`` s (wall clock) in a daemon thread.

    Parameters
    ----------
    hotplate : Hotplate
        A connected hotplate.
    report : callable
        ``report(level, kind, message)``, called from the poller thread on link loss and recovery.
    poll_s : float
        Wall-clock seconds between polls (> 0).
    max_backoff_s : float
        Longest wait between reconnect attempts, s.
    on_reading : callable, optional
        Called with every good reading (from whichever thread polled).
    on_link : callable, optional
        ``on_link(ok, message)``: the link went down (False) or answers again (True).
    """

    def __init__(self, hotplate: Hotplate, report: Callable[[str, str, str], None], poll_s: float = 2.0,
                 max_backoff_s: float = 30.0,
                 on_reading: Callable[[HotplateReading], None] | None = None,
                 on_link: Callable[[bool, str], None] | None = None) -> None:
        if not poll_s > 0:
            raise ValueError(f"poll_s must be > 0 s, got {poll_s}")
        self.hotplate = hotplate
        self._report = report
        self.poll_s = poll_s
        self.max_backoff_s = max_backoff_s
        self._lock = threading.RLock()
        self._latest: HotplateReading | None = None
        self._link_ok = True
        self._on_reading = on_reading
        self._on_link = on_link
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.failures = 0
        self._reconnects = getattr(hotplate, "reconnects", 0)
        self._trips = getattr(hotplate, "watchdog_trips", 0)
        self._latest_mono: float | None = None     # time.monotonic() when the latest reading arrived
        self._read_s = 0.0                          # how long the latest good read took, wall s

    @property
    def fresh_s(self) -> float:
        """Wall seconds a reading stays fresh: the poll interval, plus the time a read takes, plus
        :data:`GRACE_S`."""
        return self.poll_s + self._read_s + GRACE_S

    def age_s(self) -> float | None:
        """Wall seconds since the latest good reading arrived (None before the first)."""
        return None if self._latest_mono is None else time.monotonic() - self._latest_mono

    def fresh(self) -> HotplateReading | None:
        """The latest reading while it is fresh (see :attr:`fresh_s`) and the link is up, else None."""
        age = self.age_s()
        if not self._link_ok or age is None or age > self.fresh_s:
            return None
        return self._latest

    @property
    def latest(self) -> HotplateReading | None:
        """The last good reading (None before the first one)."""
        return self._latest

    @property
    def link_ok(self) -> bool:
        """False between a failed poll and the next good one."""
        return self._link_ok

    def command(self, fn: Callable[..., Any], *args: Any) -> Any:
        """Call a hotplate method under the wire lock (e.g. ``command(hp.set_temperature, 70)``)."""
        with self._lock:
            return fn(*args)

    def poll(self) -> HotplateReading | None:
        """Read the plate now; on failure report (once per outage) and return None."""
        started = time.monotonic()
        try:
            reading = self.command(self.hotplate.read)
        except HotplateError as exc:
            self.failures += 1
            if self._link_ok:
                self._link_ok = False
                message = (f"hotplate link lost ({exc}); retrying until it answers (at least every "
                           f"{self.max_backoff_s:g} s); heating and stirring are unknown until then")
                self._report("warning", "hotplate-link", message)
                if self._on_link is not None:
                    self._on_link(False, message)
            return None
        self._read_s = time.monotonic() - started
        if not self._link_ok:
            self._link_ok = True
            message = (f"hotplate link restored: the plate reads heating {'on' if reading.heating else 'OFF'}, "
                       f"stirring {'on' if reading.stirring else 'OFF'}")
            self._report("info", "hotplate-link", message)
            if self._on_link is not None:
                self._on_link(True, message)
        reconnects = getattr(self.hotplate, "reconnects", 0)
        if reconnects > self._reconnects:
            self._report("warning", "hotplate-link", f"hotplate link dropped and re-established by the driver "
                         f"({reconnects} reconnects so far)")
            self._reconnects = reconnects
        trips = getattr(self.hotplate, "watchdog_trips", 0)
        if trips > self._trips:
            self._report("warning", "hotplate-restart", "the plate had stopped heating and stirring on its own (its "
                         "connection check, 'PC Err') and was switched on again: it now reads heating "
                         f"{'on' if reading.heating else 'OFF'}, stirring {'on' if reading.stirring else 'OFF'}")
            self._trips = trips
        self._latest, self._latest_mono = reading, time.monotonic()
        if self._on_reading is not None:
            self._on_reading(reading)
        return reading

    def _reconnect(self) -> None:
        try:
            with self._lock:
                self.hotplate.close()
                self.hotplate.connect()
        except HotplateError as exc:
            log.debug("hotplate reconnect failed: %s", exc)

    def _loop(self) -> None:
        backoff = self.poll_s
        while not self._stop.is_set():
            if self.poll() is None:
                self._stop.wait(backoff)
                self._reconnect()
                backoff = min(backoff * 2, self.max_backoff_s)
                continue
            backoff = self.poll_s
            self._stop.wait(self.poll_s)

    def start(self) -> None:
        """Start polling (idempotent)."""
        if self._thread is None or not self._thread.is_alive():
            self._stop.clear()
            self._thread = threading.Thread(target=self._loop, name="hotplate-monitor", daemon=True)
            self._thread.start()

    def stop(self) -> None:
        """Stop polling and wait for the poller to finish."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10 + self.poll_s)
            self._thread = None

    def wait_stable(self, setpoint_c: float, tolerance_c: float, hold_s: float, timeout_s: float, step_s: float,
                    now: Callable[[], float], sleep: Callable[[float], None],
                    should_stop: Callable[[], bool],
                    progress: Callable[[HotplateReading], None] | None = None) -> bool:
        """Wait until the water (probe, else plate) stays within ``tolerance_c`` of ``setpoint_c`` for ``hold_s``.

        Polls every ``step_s``; times in s on the procedure's clock (``now``/``sleep``), so a simulated
        clock drives the wait too; ``progress(reading)`` is called with each good reading. Returns False on
        timeout or stop.
        """
        start, since = now(), None
        while not should_stop():
            reading = self.poll()
            if reading is not None and progress is not None:
                progress(reading)
            if reading is not None:
                temp = reading.probe_c if reading.probe_c is not None else reading.plate_c
                if abs(temp - setpoint_c) <= tolerance_c:
                    since = now() if since is None else since
                    if now() - since >= hold_s:
                        return True
                else:
                    since = None
            if now() - start > timeout_s:
                return False
            sleep(step_s)
        return False
