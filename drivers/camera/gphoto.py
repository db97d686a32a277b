"""`GPhotoCamera`: a tethered camera through python-gphoto2, every operation under a deadline.

libgphoto2 runs in a worker process (`drivers.camera.gphoto_worker`); this side sends one request at
a time and waits on the pipe with a deadline. Past it, the worker is killed, the USB device is reset
(pyusb, `drivers.camera.usb`), the capture is reported as `CaptureMissed`, and the camera is detected
and initialised again on the next call, so a run goes on. libgphoto2 errors map to a policy:

==========================================  =================================================
busy (-110), timeout (-10), I/O read/write   retry on the same session, after ``retry_delay_s``
I/O (-7), USB not found (-52), camera error  re-detect and re-initialise, then retry
(-113), no memory/store full (-3), generic
USB claimed (-53)                            CameraError saying how to free the device
anything else                                CameraError with libgphoto2's message
==========================================  =================================================
"""
from __future__ import annotations

import logging
import multiprocessing
import time
from dataclasses import asdict

from drivers.camera import usb
from drivers.camera.base import CameraError, CameraSettings, Capture, CaptureMissed

log = logging.getLogger(__name__)

RETRY_SAME_SESSION = {-110: "camera busy", -10: "timeout", -34: "I/O read error", -35: "I/O write error"}
RETRY_NEW_SESSION = {-7: "I/O error (camera disconnected?)", -52: "camera not found on USB",
                     -113: "camera error", -3: "out of memory / store full", -1: "unspecified error"}
USB_CLAIMED = -53
MODEL_NOT_FOUND = -105
CLAIM_MESSAGE = ("the camera's USB interface is claimed by another program, usually the desktop's photo "
                 "importer (gvfs-gphoto2-volume-monitor / gvfsd-gphoto2): unmount the camera in the file "
                 "manager or run `gio mount -s gphoto2`, close other camera programs, then reconnect")

_CONTEXT = multiprocessing.get_context("spawn")


class _GPhotoFailure(Exception):
    def __init__(self, op: str, code: int, message: str) -> None:
        super().__init__(f"{op}: libgphoto2 error {code} ({message})")
        self.code = code


class GPhotoCamera:
    """A camera found by libgphoto2; satisfies `drivers.camera.base.Camera`.

    Parameters
    ----------
    model : str, optional
        Substring of the model name to pick (case-insensitive); default the first camera found.
    port : str, optional
        libgphoto2 port (``usb:001,004``) to pick.
    deadline_s : float
        Real seconds each capture (with download and delete) may take before it is declared missed.
    connect_deadline_s : float
        Real seconds for starting the worker, detecting and initialising the camera.
    retries : int
        Extra attempts after a recoverable libgphoto2 error.
    retry_delay_s : float
        Pause before each retry, s.
    event_wait_ms : int
        How long to wait after a capture for companion files (NEF+JPEG), ms.
    """

    def __init__(self, model: str | None = None, port: str | None = None, *, deadline_s: float = 30.0,
                 connect_deadline_s: float = 30.0, retries: int = 2, retry_delay_s: float = 0.5,
                 event_wait_ms: int = 200) -> None:
        if deadline_s <= 0 or connect_deadline_s <= 0:
            raise ValueError(f"deadlines must be > 0 s, got deadline_s={deadline_s!r}, "
                             f"connect_deadline_s={connect_deadline_s!r}")
        if retries < 0 or retry_delay_s < 0 or event_wait_ms < 0:
            raise ValueError(f"retries, retry_delay_s and event_wait_ms must be >= 0, got "
                             f"{retries!r}, {retry_delay_s!r}, {event_wait_ms!r}")
        self.model, self.port = model, port
        self.deadline_s = deadline_s
        self.connect_deadline_s = connect_deadline_s
        self.retries = retries
        self.retry_delay_s = retry_delay_s
        self.event_wait_ms = event_wait_ms
        self.name: str | None = None
        self.address: str | None = None
        self.missed = 0
        self.resets = 0
        self._settings: CameraSettings | None = None
        self._proc = None
        self._conn = None

    @property
    def worker_pid(self) -> int | None:
        """Process id of the libgphoto2 worker, None when none is running."""
        return self._proc.pid if self._proc is not None else None

    # -- Camera protocol ------------------------------------------------------------------------------

    def connect(self) -> None:
        """Start the worker, detect the camera and initialise it.

        Raises
        ------
        CameraError
            No matching camera, the USB device is claimed, or initialisation ran past its deadline.
        """
        if self._proc is not None:
            return
        self._proc_start()
        try:
            self.name, self.address = self._call("open", (self.model, self.port), self.connect_deadline_s)
        except _GPhotoFailure as exc:
            self._kill()
            if exc.code == USB_CLAIMED:
                raise CameraError(CLAIM_MESSAGE) from exc
            wanted = " ".join(x for x in (self.model, self.port) if x) or "any camera"
            if exc.code == MODEL_NOT_FOUND:
                raise CameraError(f"no camera found on USB ({wanted}; libgphoto2 error {exc.code}): is it "
                                  "switched on and not claimed by another program?") from exc
            raise CameraError(f"cannot open {wanted} with libgphoto2: {exc}") from exc
        log.info("camera %s on %s", self.name, self.address)
        if self._settings is not None:
            try:
                self._call("configure", (asdict(self._settings),), self.connect_deadline_s)
            except _GPhotoFailure as exc:
                raise CameraError(f"re-applying settings to {self.name}: {exc}") from exc

    def configure(self, settings: CameraSettings) -> dict[str, str]:
        """Apply exposure settings and capture target internal RAM; report what could not be set.

        Returns
        -------
        dict of str to str
            ``{setting: outcome}``, e.g. ``{"iso": "not exposed by this camera"}``.
        """
        self.connect()
        try:
            outcome = self._call("configure", (asdict(settings),), self.deadline_s)
        except _GPhotoFailure as exc:
            raise CameraError(f"configuring {self.name}: {exc}") from exc
        self._settings = settings
        for key, text in outcome.items():
            (log.info if text.startswith("set to") else log.warning)("camera %s: %s", key, text)
        return outcome

    def capture(self) -> Capture:
        """Capture one frame, download it (and its companion files) and delete it from the camera.

        Raises
        ------
        CaptureMissed
            The capture ran past ``deadline_s``; the camera was reset and will be re-initialised.
        CameraError
            The capture failed after the allowed retries, or the camera cannot be reached.
        """
        last: Exception | None = None
        for attempt in range(self.retries + 1):
            if attempt:
                time.sleep(self.retry_delay_s)
            self.connect()
            t_unix_s = time.time()
            try:
                files = self._call("capture", (self.event_wait_ms,), self.deadline_s)
            except _GPhotoFailure as exc:
                last = exc
                if exc.code == USB_CLAIMED:
                    raise CameraError(CLAIM_MESSAGE) from exc
                if exc.code in RETRY_SAME_SESSION:
                    log.warning("capture attempt %d: %s; retrying", attempt + 1, exc)
                elif exc.code in RETRY_NEW_SESSION:
                    log.warning("capture attempt %d: %s; re-detecting the camera", attempt + 1, exc)
                    self._kill()
                else:
                    raise CameraError(f"capture on {self.name}: {exc}") from exc
                continue
            return _to_capture(files, t_unix_s)
        raise CameraError(f"capture on {self.name} failed after {self.retries + 1} attempts: {last}") from last

    def close(self) -> None:
        """Exit the camera session and stop the worker (killed if it does not answer in time)."""
        if self._proc is None:
            return
        try:
            self._call("quit", (), min(self.deadline_s, 5.0))
        except (CameraError, _GPhotoFailure) as exc:
            log.warning("camera did not close cleanly: %s", exc)
        self._kill()

    def __enter__(self) -> "GPhotoCamera":
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- worker ---------------------------------------------------------------------------------------

    def _proc_start(self) -> None:
        from drivers.camera import gphoto_worker

        parent, child = _CONTEXT.Pipe()
        proc = _CONTEXT.Process(target=gphoto_worker.serve, args=(child,), name="gphoto-worker", daemon=True)
        proc.start()
        child.close()
        self._proc, self._conn = proc, parent

    def _call(self, op: str, args: tuple, deadline_s: float):
        """Run ``op`` in the worker; kill it and raise if it does not answer within ``deadline_s``."""
        try:
            self._conn.send((op, args))
            ready = self._conn.poll(deadline_s)
            reply = self._conn.recv() if ready else None
        except (EOFError, OSError) as exc:
            self._kill()
            raise CameraError(f"camera worker died during {op}: {exc}") from exc
        if reply is None:
            self._hung(op, deadline_s)
        if reply[0] == "ok":
            return reply[1]
        if reply[0] == "gp":
            raise _GPhotoFailure(op, reply[1], reply[2])
        raise CameraError(f"camera {op} failed: {reply[1]}")

    def _hung(self, op: str, deadline_s: float) -> None:
        self._kill()
        self.resets += 1
        if self.address:
            try:
                usb.reset(self.address)
            except CameraError as exc:
                log.error("%s", exc)
        if op == "capture":
            self.missed += 1
            raise CaptureMissed(f"capture on {self.name} did not finish within {deadline_s:g} s; camera "
                                f"reset, frame missed ({self.missed} so far)")
        raise CameraError(f"camera {op} did not finish within {deadline_s:g} s; camera reset")

    def _kill(self) -> None:
        proc, conn = self._proc, self._conn
        self._proc = self._conn = None
        if proc is None:
            return
        if proc.is_alive():
            proc.kill()
        proc.join(timeout=5.0)
        conn.close()


def _to_capture(files: list[tuple[str, bytes]], t_unix_s: float) -> Capture:
    """The JPEG (if any) is the frame; every other file of the exposure goes to ``extra``."""
    if not files:
        raise CameraError("the camera reported a capture but no file")
    jpegs = [f for f in files if f[0].lower().endswith((".jpg", ".jpeg"))]
    name, data = (jpegs or files)[0]
    return Capture(data=data, file_name=name, t_unix_s=t_unix_s,
                   extra={n: d for n, d in files if n != name})


def detect_cameras(deadline_s: float = 20.0) -> list[tuple[str, str]]:
    """``(model, port)`` of every camera libgphoto2 finds, detected in a worker under a deadline.

    Raises
    ------
    CameraError
        If detection does not finish within ``deadline_s``.
    """
    camera = GPhotoCamera(connect_deadline_s=deadline_s, deadline_s=deadline_s)
    camera._proc_start()
    try:
        return camera._call("detect", (), deadline_s)
    finally:
        camera.close()
