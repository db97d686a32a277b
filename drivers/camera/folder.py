"""`FolderCamera`: frames that another program (a vendor tether tool, a phone sync) writes into a folder."""
from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Callable

from drivers.camera.base import CameraError, CameraSettings, Capture, CaptureMissed

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".tif", ".tiff", ".png", ".nef", ".cr2", ".arw", ".dng")


class FolderCamera:
    """Each `capture` returns the next new image file in ``folder`` once its size has settled.

    Files present at `connect` are ignored; new files are taken oldest first (by modification time,
    then name). A file counts as complete when its size has not changed for ``settle_s``.

    Parameters
    ----------
    folder : str or Path
        Folder the other program writes into.
    deadline_s : float
        Real seconds `capture` waits for a new complete file before reporting the frame missed.
    settle_s : float
        Seconds a file's size must stay unchanged.
    poll_s : float
        Seconds between folder scans.
    clock, sleep : callable
        Monotonic clock and sleep, injectable for tests.
    """

    def __init__(self, folder: str | Path, *, deadline_s: float = 30.0, settle_s: float = 0.5,
                 poll_s: float = 0.2, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        if deadline_s <= 0 or settle_s < 0 or poll_s <= 0:
            raise ValueError(f"need deadline_s > 0, settle_s >= 0, poll_s > 0; got {deadline_s!r}, "
                             f"{settle_s!r}, {poll_s!r}")
        self.folder = Path(folder)
        self.deadline_s, self.settle_s, self.poll_s = deadline_s, settle_s, poll_s
        self._clock, self._sleep = clock, sleep
        self._seen: set[str] = set()
        self._sizes: dict[str, tuple[int, float]] = {}
        self._connected = False

    def connect(self) -> None:
        """Remember the files already there.

        Raises
        ------
        CameraError
            If ``folder`` is not an existing directory.
        """
        if not self.folder.is_dir():
            raise CameraError(f"camera folder {self.folder} does not exist or is not a directory")
        self._seen = {p.name for p in self._images()}
        self._connected = True
        log.info("watching %s (%d existing files ignored)", self.folder, len(self._seen))

    def configure(self, settings: CameraSettings) -> dict[str, str]:
        """Nothing can be set from here: every requested setting is reported as such."""
        return {key: "not controllable: the program writing the folder sets it"
                for key, value in vars(settings).items() if value is not None}

    def capture(self) -> Capture:
        """Wait for the next complete new file and return it.

        Raises
        ------
        CaptureMissed
            If no new complete file appears within ``deadline_s``.
        """
        if not self._connected:
            self.connect()
        end = self._clock() + self.deadline_s
        while True:
            path = self._next_complete()
            if path is not None:
                self._seen.add(path.name)
                self._sizes.pop(path.name, None)
                try:
                    data = path.read_bytes()
                    t_unix_s = path.stat().st_mtime
                except OSError as exc:
                    raise CameraError(f"cannot read {path}: {exc}") from exc
                return Capture(data=data, file_name=path.name, t_unix_s=t_unix_s)
            if self._clock() >= end:
                raise CaptureMissed(f"no new image in {self.folder} within {self.deadline_s:g} s")
            self._sleep(self.poll_s)

    def close(self) -> None:
        self._connected = False

    def _images(self) -> list[Path]:
        return [p for p in self.folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES]

    def _next_complete(self) -> Path | None:
        now = self._clock()
        candidates = []
        for path in self._images():
            if path.name in self._seen:
                continue
            try:
                stat = path.stat()
            except OSError:
                continue
            size, since = self._sizes.get(path.name, (-1, now))
            if size != stat.st_size:
                self._sizes[path.name] = (stat.st_size, now)
                since = now
            if stat.st_size > 0 and now - since >= self.settle_s:
                candidates.append((stat.st_mtime, path.name, path))
        return min(candidates)[2] if candidates else None
