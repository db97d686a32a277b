"""USB helpers for tethered cameras (pyusb): list still-image devices and reset a hung one."""
from __future__ import annotations

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


def _is_camera(dev) -> bool:
    return any(intf.bInterfaceClass == STILL_IMAGE_CLASS for cfg in dev for intf in cfg)


def list_cameras() -> list[UsbCamera]:
    """USB devices that expose a still-image interface; empty if libusb is unavailable."""
    import usb.core

    try:
        devices = list(usb.core.find(find_all=True, custom_match=_is_camera))
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
        return False
    import usb.core

    try:
        device = usb.core.find(bus=where[0], address=where[1], custom_match=_is_camera)
    except (usb.core.NoBackendError, usb.core.USBError) as exc:
        log.warning("cannot look for the camera on %s: %s", port, exc)
        return False
    if device is None:
        return False
    try:
        device.reset()
    except usb.core.USBError as exc:
        raise CameraError(f"USB reset of the camera on {port} failed: {exc} "
                          "(check write permission on /dev/bus/usb, e.g. a udev rule)") from exc
    log.warning("reset the USB camera on %s", port)
    return True
