"""A background poller that keeps the hotplate's link alive and always has its latest reading.

The Heidolph unit shows "PC Err" after 10 s without a command while heating, and an 11 s frame interval
is longer than that, so the plate is polled on its own thread every ``poll_s`` wall seconds. Every
command to the plate goes through :meth:`HotplateMonitor.command` under one lock, so the poller and the
procedure never interleave bytes on the wire. A lost link is reported once, then retried with back-off
(``connect()`` again) until it comes back, which is reported too; so is a drop the driver repaired by
itself (a driver with a ``reconnects`` counter, like ``HeidolphHotplate``).
"""
from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

from drivers.hotplate.base import Hotplate, HotplateError, HotplateReading

log = logging.getLogger(__name__)


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
    """

    def __init__(self, hotplate: Hotplate, report: Callable[[str, str, str], None], poll_s: float = 2.0,
                 max_backoff_s: float = 30.0,
                 on_reading: Callable[[HotplateReading], None] | None = None) -> None:
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
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.failures = 0
        self._reconnects = getattr(hotplate, "reconnects", 0)

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
        try:
            reading = self.command(self.hotplate.read)
        except HotplateError as exc:
            self.failures += 1
            if self._link_ok:
                self._link_ok = False
                self._report("warning", "hotplate-link", f"hotplate link lost: {exc}")
            return None
        if not self._link_ok:
            self._link_ok = True
            self._report("info", "hotplate-link", "hotplate link restored")
        reconnects = getattr(self.hotplate, "reconnects", 0)
        if reconnects > self._reconnects:
            self._report("warning", "hotplate-link", f"hotplate link dropped and re-established by the driver "
                         f"({reconnects} reconnects so far)")
            self._reconnects = reconnects
        self._latest = reading
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
                    should_stop: Callable[[], bool]) -> bool:
        """Wait until the water (probe, else plate) stays within ``tolerance_c`` of ``setpoint_c`` for ``hold_s``.

        Polls every ``step_s``; times in s on the procedure's clock (``now``/``sleep``), so a simulated
        clock drives the wait too. Returns False on timeout or stop.
        """
        start, since = now(), None
        while not should_stop():
            reading = self.poll()
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
