"""USB helpers for tethered cameras (pyusb): list still-image devices and reset a hung one."""
from __future__ import annotations

import functools
import logging
import re
from dataclasses import dataclass

from drivers.camera.base import CameraError

log = logging.getLogger(__name__)

STILL_IMAGE_CLASS = 6
"""USB interface class of PTP cameras."""


@dataclass(frozen=True)
class UsbCamera:
    """A USB device with a still-image (PTP) interface."""

    bus: int
    address: int
    vendor_id: int
    product_id: int

    @property
    def gphoto_port(self) -> str:
        """The port string libgphoto2 uses for this device (``usb:BBB,AAA``)."""
        return f"usb:{self.bus:03d},{self.address:03d}"


NO_BACKEND_MESSAGE = ("no libusb backend for pyusb: USB cameras can be neither listed nor reset "
                      "(reinstall the project so 'libusb-package' is present, or install the system "
                      "libusb-1.0, e.g. 'apt-get install libusb-1.0-0')")


@functools.lru_cache(maxsize=1)
def _backend():
    """pyusb backend: libusb-package's bundled libusb-1.0 first, else pyusb's own lookup; None if neither.

    Looked up once per process (a library does not appear while the app runs); a missing backend is
    logged once, at error level, with what to install.
    """
    try:
        import libusb_package

        backend = libusb_package.get_libusb1_backend()
    except (ImportError, OSError) as exc:  # package missing, or its binary not loadable here
        log.debug("libusb-package unavailable: %s", exc)
        backend = None
    if backend is None:
        import usb.backend.libusb0
        import usb.backend.libusb1
        import usb.backend.openusb

        # pyusb's default order (usb.core.find with backend=None), made explicit to report a miss
        backend = (usb.backend.libusb1.get_backend() or usb.backend.openusb.get_backend()
                   or usb.backend.libusb0.get_backend())
    if backend is None:
        log.error(NO_BACKEND_MESSAGE)
    return backend


def _is_camera(dev) -> bool:
    """True if any configuration of ``dev`` has a still-image (PTP) interface."""
    import usb.core

    try:
        return any(intf.bInterfaceClass == STILL_IMAGE_CLASS for cfg in dev for intf in cfg)
    except usb.core.USBError as exc:  # descriptors unreadable: not ours to claim
        log.debug("skipping USB device %04x:%04x: %s", dev.idVendor, dev.idProduct, exc)
        return False


def list_cameras() -> list[UsbCamera]:
    """USB devices that expose a still-image interface; empty (and logged) if libusb is unavailable."""
    import usb.core

    backend = _backend()
    if backend is None:
        return []
    try:
        devices = list(usb.core.find(find_all=True, custom_match=_is_camera, backend=backend))
    except (usb.core.NoBackendError, usb.core.USBError) as exc:
        log.warning("cannot list USB devices: %s", exc)
        return []
    return [UsbCamera(d.bus, d.address, d.idVendor, d.idProduct) for d in devices]


def parse_port(port: str) -> tuple[int, int] | None:
    """Bus and address of a libgphoto2 ``usb:BBB,AAA`` port, or None for any other port."""
    match = re.fullmatch(r"usb:(\d+),(\d+)", port)
    return (int(match.group(1)), int(match.group(2))) if match else None


def reset(port: str) -> bool:
    """Reset the still-image USB device on a libgphoto2 port; return whether one was reset.

    Only a device that pyusb sees at that bus and address *with* a still-image interface is touched,
    so a virtual camera's port (or a hub) is never reset.

    Raises
    ------
    CameraError
        If the device exists but the reset fails (e.g. no permission on /dev/bus/usb).
    """
    where = parse_port(port)
    if where is None:
        log.info("not resetting %r: not a USB port of the form usb:BBB,AAA", port)
        return False
    import usb.core

    backend = _backend()
    if backend is None:
        log.warning("cannot reset the camera on %s: %s", port, NO_BACKEND_MESSAGE)
        return False
    try:
        device = usb.core.find(bus=where[0], address=where[1], custom_match=_is_camera, backend=backend)
    except (usb.core.NoBackendError, usb.core.USBError) as exc:
        log.warning("cannot look for the camera on %s: %s", port, exc)
        return False
    if device is None:
        log.warning("not resetting %s: no USB device with a still-image interface at bus %d, address %d",
                    port, *where)
        return False
    try:
        device.reset()
    except usb.core.USBError as exc:
        raise CameraError(f"USB reset of the camera on {port} failed: {exc} "
                          "(check write permission on /dev/bus/usb, e.g. a udev rule)") from exc
    log.warning("reset the USB camera on %s", port)
    return True
