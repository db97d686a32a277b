"""The camera interface every camera implementation satisfies."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

from drivers.errors import DriverError


class CameraError(DriverError):
    """A camera could not be reached, configured or read; the message says which and why."""


class CaptureMissed(CameraError):
    """A capture did not complete before its deadline; the camera was reset, the frame is lost."""


@dataclass(frozen=True)
class CameraSettings:
    """Exposure settings to apply (None leaves the camera's own value). Paper section 4.2 defaults."""

    aperture: str | None = "22"
    shutter_speed: str | None = "1/125"
    iso: str | None = "160"
    image_format: str | None = "JPEG Fine"


DSLR_FRAME_BYTES = 15_000_000
"""Bytes of one tethered DSLR capture (a JPEG Fine and its companion raw), for disk-space estimates."""


@dataclass(frozen=True)
class Capture:
    """One captured frame: encoded image bytes as the camera wrote them.

    ``t_unix_s`` is the capture time (seconds since the epoch, host clock);
    ``extra`` holds companion files of the same exposure (e.g. the NEF of a NEF+JPEG pair)
    as ``{file_name: bytes}``.
    """

    data: bytes
    file_name: str
    t_unix_s: float
    extra: dict[str, bytes] = field(default_factory=dict)


@runtime_checkable
class Camera(Protocol):
    """connect -> configure -> capture ... -> close. Every call returns or raises within its deadline."""

    def connect(self) -> None: ...

    def configure(self, settings: CameraSettings) -> dict[str, str]:
        """Apply settings; return {setting: outcome} naming those the camera does not expose."""
        ...

    def capture(self) -> Capture: ...

    def close(self) -> None: ...
