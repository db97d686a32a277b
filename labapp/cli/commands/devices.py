"""`sfr devices [--probe PORT]`: cameras and serial ports on this bench, and a Heidolph reply test."""
from __future__ import annotations

import argparse

from labapp.cli.argtypes import positive_float

NAME = "devices"
HELP = "list cameras and serial ports; --probe PORT asks a port for a Heidolph reply (read-only queries)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--probe", metavar="PORT", help="serial port or URL to test for a Heidolph hotplate")
    parser.add_argument("--deadline-s", type=positive_float, default=20.0, help="deadline for camera detection, s")


def run(args: argparse.Namespace) -> int:
    from serial.tools import list_ports

    from drivers.camera import CameraError, detect_cameras
    from drivers.camera.usb import list_cameras
    from drivers.hotplate import HeidolphHotplate, HotplateConfig, HotplateError

    try:
        cameras = detect_cameras(args.deadline_s)
    except CameraError as exc:
        cameras = []
        print(f"cameras: detection failed: {exc}")
    print(f"cameras (libgphoto2): {len(cameras)}")
    for model, port in cameras:
        print(f"  {model}  {port}")
    usb_cameras = list_cameras()
    print(f"still-image USB devices (pyusb): {len(usb_cameras)}")
    for cam in usb_cameras:
        print(f"  {cam.vendor_id:04x}:{cam.product_id:04x}  {cam.gphoto_port}")
    ports = list(list_ports.comports())
    print(f"serial ports: {len(ports)}")
    for p in ports:
        print(f"  {p.device}  {p.description}")
    if not args.probe:
        return 0
    plate = HeidolphHotplate(args.probe, config=HotplateConfig(timeout_s=1.0, reconnect_attempts=1, retries=1),
                             keep_alive=False)
    try:
        r = plate.identify()        # read-only queries: nothing is switched or set on whatever answers
    except HotplateError as exc:
        print(f"probe {args.probe}: no Heidolph reply: {exc}")
        return 1
    probe = "no probe" if r.probe_c is None else f"{r.probe_c:.1f} C"
    print(f"probe {args.probe}: Heidolph reply: plate {r.plate_c:.1f} C, probe {probe}, "
          f"{r.speed_rpm:.0f} rpm, setpoints {r.setpoint_c:.1f} C / {r.setpoint_rpm:.0f} rpm")
    return 0
