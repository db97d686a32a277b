"""pyusb helpers: the libusb backend the project installs, the still-image filter, reset refusals."""
import logging
from types import SimpleNamespace

import pytest
import usb.core

from drivers.camera import usb as camusb
from drivers.camera.usb import UsbCamera, list_cameras, parse_port, reset


def _device(*interface_classes, bus=1, address=5, vendor=0x04B0, product=0x0437):
    """A stand-in for a pyusb Device: iterating it yields configurations, which yield interfaces."""
    config = [SimpleNamespace(bInterfaceClass=c) for c in interface_classes]

    class Device(SimpleNamespace):
        def __iter__(self):
            return iter([config])

    return Device(bus=bus, address=address, idVendor=vendor, idProduct=product)


def test_the_installed_backend_is_libusb_package():
    camusb._backend.cache_clear()
    backend = camusb._backend()
    assert backend is not None
    # enumerating through it works (the sandbox has no USB bus, so the list may be empty)
    assert isinstance(list(usb.core.find(find_all=True, backend=backend)), list)
    import libusb_package
    assert backend is libusb_package.get_libusb1_backend()


def test_list_cameras_works_without_a_backend_warning(caplog):
    caplog.set_level(logging.DEBUG, logger="drivers.camera.usb")
    cameras = list_cameras()
    assert isinstance(cameras, list) and all(isinstance(c, UsbCamera) for c in cameras)
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING], caplog.text
    # whatever this machine has, only still-image devices come back
    for cam in cameras:
        dev = usb.core.find(bus=cam.bus, address=cam.address, backend=camusb._backend())
        assert camusb._is_camera(dev)


def test_filter_keeps_only_still_image_interfaces():
    assert camusb._is_camera(_device(6))                       # a PTP camera
    assert camusb._is_camera(_device(255, 6))                  # vendor interface beside PTP (Nikon MTP/PTP)
    assert not camusb._is_camera(_device(8))                   # mass storage (a camera in MSC mode, a stick)
    assert not camusb._is_camera(_device(3, 3, vendor=0x04B0))  # a Nikon-made HID device: vendor alone is not enough
    assert not camusb._is_camera(_device(9))                   # a hub


def test_list_cameras_applies_the_filter_and_the_bundled_backend(monkeypatch):
    devices = [_device(6, bus=1, address=5), _device(8, bus=1, address=6), _device(9, bus=2, address=1),
               _device(255, 6, bus=3, address=17, vendor=0x04A9, product=0x32D1)]
    seen = {}

    def fake_find(find_all=False, custom_match=None, backend=None, **kw):
        seen["backend"] = backend
        return iter([d for d in devices if custom_match(d)])

    monkeypatch.setattr(usb.core, "find", fake_find)
    cameras = list_cameras()
    assert cameras == [UsbCamera(1, 5, 0x04B0, 0x0437), UsbCamera(3, 17, 0x04A9, 0x32D1)]
    assert [c.gphoto_port for c in cameras] == ["usb:001,005", "usb:003,017"]
    assert seen["backend"] is camusb._backend()


def test_no_backend_is_a_clear_message_not_an_exception(monkeypatch, caplog):
    monkeypatch.setattr(camusb, "_backend", lambda: None)
    with caplog.at_level(logging.WARNING, logger="drivers.camera.usb"):
        assert list_cameras() == []
        assert reset("usb:001,005") is False
    assert "no libusb backend" in caplog.text and "libusb-package" in caplog.text


def test_missing_backend_is_logged_by_the_lookup(monkeypatch, caplog):
    import libusb_package
    import usb.backend.libusb0
    import usb.backend.libusb1
    import usb.backend.openusb

    monkeypatch.setattr(libusb_package, "get_libusb1_backend", lambda: None)
    for module in (usb.backend.libusb1, usb.backend.libusb0, usb.backend.openusb):
        monkeypatch.setattr(module, "get_backend", lambda *a, **k: None)
    camusb._backend.cache_clear()
    try:
        with caplog.at_level(logging.ERROR, logger="drivers.camera.usb"):
            assert camusb._backend() is None
        assert camusb.NO_BACKEND_MESSAGE in caplog.text
    finally:
        camusb._backend.cache_clear()


@pytest.mark.parametrize("port, needle", [("usb:001,127", "no USB device with a still-image interface"),
                                          ("usb:", "not a USB port"), ("ptpip:192.0.2.1", "not a USB port")])
def test_reset_of_an_unknown_port_is_false_with_a_message(port, needle, caplog):
    with caplog.at_level(logging.INFO, logger="drivers.camera.usb"):
        assert reset(port) is False
    assert needle in caplog.text and port in caplog.text


def test_parse_port():
    assert parse_port("usb:002,011") == (2, 11)
    assert parse_port("usb:") is None
