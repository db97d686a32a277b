"""Clocks for the acquisition engine: real time, accelerated simulated time, and instant simulated time.

Every wait in a procedure goes through a clock, so a simulated 3-hour run can be replayed at N x speed
(``ScaledClock``) or as fast as frames can be rendered (``SteppedClock``: ``sleep`` advances time without
sleeping), while the real bench uses ``WallClock``. Times are seconds since the epoch.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Protocol

_SLICE_S = 0.05  # wall-clock granularity at which a sleep notices a stop request


class Clock(Protocol):
    """``now()`` in s since the epoch; ``sleep(dt_s, should_stop)`` returns early when a stop is requested."""

    speed: float

    def now(self) -> float: ...

    def sleep(self, dt_s: float, should_stop: Callable[[], bool] = lambda: False) -> None: ...


def _interruptible_sleep(wall_s: float, should_stop: Callable[[], bool]) -> None:
    end = time.monotonic() + wall_s
    while not should_stop():
        left = end - time.monotonic()
        if left <= 0:
            return
        time.sleep(min(left, _SLICE_S))


class WallClock:
    """Real time."""

    speed = 1.0

    def now(self) -> float:
        """Seconds since the epoch."""
        return time.time()

    def sleep(self, dt_s: float, should_stop: Callable[[], bool] = lambda: False) -> None:
        """Sleep ``dt_s`` seconds, returning early if ``should_stop()`` becomes true."""
        _interruptible_sleep(max(dt_s, 0.0), should_stop)


class ScaledClock:
    """Simulated time running ``speed`` times faster than the wall clock, starting at ``start_s``."""

    def __init__(self, speed: float, start_s: float | None = None) -> None:
        if not speed > 0:
            raise ValueError(f"clock speed must be > 0, got {speed}")
        self.speed = float(speed)
        self._start = time.time() if start_s is None else float(start_s)
        self._wall0 = time.monotonic()

    def now(self) -> float:
        """Simulated seconds since the epoch."""
        return self._start + (time.monotonic() - self._wall0) * self.speed

    def sleep(self, dt_s: float, should_stop: Callable[[], bool] = lambda: False) -> None:
        """Sleep ``dt_s`` simulated seconds (``dt_s / speed`` wall seconds)."""
        _interruptible_sleep(max(dt_s, 0.0) / self.speed, should_stop)


class SteppedClock:
    """Simulated time that only moves when someone sleeps: ``sleep(dt)`` advances it by ``dt`` at once.

    Thread-safe; ``speed`` is reported as infinite. Used by the demo and the tests to run hours of
    simulated acquisition as fast as the frames can be rendered.
    """

    speed = float("inf")

    def __init__(self, start_s: float | None = None) -> None:
        self._t = time.time() if start_s is None else float(start_s)
        self._lock = threading.Lock()

    def now(self) -> float:
        """Simulated seconds since the epoch."""
        with self._lock:
            return self._t

    def sleep(self, dt_s: float, should_stop: Callable[[], bool] = lambda: False) -> None:
        """Advance the clock by ``dt_s`` s (unless a stop is requested); yields the thread briefly."""
        if should_stop():
            return
        with self._lock:
            self._t += max(dt_s, 0.0)
        time.sleep(0)


def make_clock(speed: float | None) -> Clock:
    """``None`` or 1 -> :class:`WallClock`; ``inf`` -> :class:`SteppedClock`; else :class:`ScaledClock`."""
    if speed is None or speed == 1:
        return WallClock()
    if speed == float("inf"):
        return SteppedClock()
    return ScaledClock(speed)
