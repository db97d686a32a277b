"""Real benches from the operator's choices: a camera spec and a hotplate port, as typed on the command line
or picked in the GUI's device panel."""
from __future__ import annotations

from pathlib import Path

from drivers.camera.base import CameraSettings
from drivers.hotplate import HeidolphHotplate
from labapp.acquisition.bench import Bench
from labapp.errors import UsageError

CAMERA_SPECS = "gphoto2 | gphoto2:MODEL | gphoto2:MODEL@PORT | folder:PATH"


def make_camera(spec: str, deadline_s: float = 30.0):
    """A camera from ``spec`` (see :data:`CAMERA_SPECS`).

    Raises
    ------
    UsageError
        For a spec that names no known camera kind.
    """
    kind, _, rest = spec.partition(":")
    if kind == "gphoto2":
        from drivers.camera import GPhotoCamera

        model, _, port = rest.partition("@")
        return GPhotoCamera(model=model or None, port=port or None, deadline_s=deadline_s)
    if kind == "folder":
        from drivers.camera import FolderCamera

        if not rest:
            raise UsageError("camera spec 'folder:' needs a path, e.g. folder:/media/card/DCIM")
        return FolderCamera(Path(rest))
    raise UsageError(f"unknown camera {spec!r}; expected {CAMERA_SPECS}")


def make_hotplate(url: str | None):
    """A Heidolph hotplate on a serial URL (``/dev/ttyUSB0``, ``socket://host:port``), or None.

    The driver's own keep-alive is off: the engine's hotplate monitor polls it.
    """
    if not url:
        return None

    return HeidolphHotplate(url, keep_alive=False)


def make_bench(camera: str, hotplate: str | None, settings: CameraSettings | None = None) -> Bench:
    """A real bench: camera from its spec, hotplate from its port (None: no hotplate)."""
    desc = f"camera {camera}" + (f", hotplate {hotplate}" if hotplate else ", no hotplate")
    return Bench(make_camera(camera), make_hotplate(hotplate), settings or CameraSettings(), simulated=False,
                 description=desc)
