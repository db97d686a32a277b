"""The hotplate interface every hotplate implementation satisfies."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from drivers.errors import DriverError


class HotplateError(DriverError):
    """The hotplate refused a command, replied garbage or lost its link; the message names the port."""


@dataclass(frozen=True)
class HotplateReading:
    """One poll of the plate. ``probe_c`` is None when no external probe is connected (999.9 on the wire)."""

    plate_c: float
    probe_c: float | None
    speed_rpm: float
    setpoint_c: float
    setpoint_rpm: float
    heating: bool
    stirring: bool
    t_unix_s: float


@runtime_checkable
class Hotplate(Protocol):
    """Temperature in degrees C, speed in rpm."""

    def connect(self) -> None: ...

    def set_temperature(self, temp_c: float) -> None: ...

    def set_speed(self, speed_rpm: float) -> None: ...

    def start_heating(self) -> None: ...

    def stop_heating(self) -> None: ...

    def start_stirring(self) -> None: ...

    def stop_stirring(self) -> None: ...

    def read(self) -> HotplateReading: ...

    def close(self) -> None:
        """Switch heating off (best effort) and release the port."""
        ...
