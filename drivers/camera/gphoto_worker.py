"""The libgphoto2 side of `GPhotoCamera`: runs in its own process, one request at a time.

A hung libgphoto2 call cannot be interrupted inside a process, only killed with it; so every call to
python-gphoto2 happens here, and the parent (`drivers.camera.gphoto`) waits on a pipe with a
deadline. gphoto2 is imported in the worker only, after the parent's environment (``VCAMERADIR``,
``CAMLIBS``, ``HOME``) is inherited, because python-gphoto2 reads it at import time.

Requests are ``(op, args)`` tuples; replies are ``("ok", result)``, ``("gp", code, message)`` for a
libgphoto2 error, or ``("err", message)`` for anything else.
"""
from __future__ import annotations

from multiprocessing.connection import Connection

SETTING_WIDGETS: dict[str, tuple[str, ...]] = {
    "aperture": ("aperture", "f-number"),
    "shutter_speed": ("shutterspeed", "shutterspeed2"),
    "iso": ("iso", "isospeed"),
    "image_format": ("imagequality", "imageformat"),
}
"""Config widget names, per setting, in the order libgphoto2 drivers use them (Nikon first)."""


def _normalise(value: str) -> str:
    text = value.strip().lower().replace(" ", "")
    return text[2:] if text.startswith("f/") else text


class _Session:
    """One opened camera inside the worker."""

    def __init__(self) -> None:
        import gphoto2 as gp

        self.gp = gp
        self.camera = None

    def detect(self) -> list[tuple[str, str]]:
        return [(name, addr) for name, addr in self.gp.Camera.autodetect()]

    def open(self, model: str | None, port: str | None) -> tuple[str, str]:
        gp = self.gp
        found = self.detect()
        matches = [(n, a) for n, a in found
                   if (model is None or model.lower() in n.lower()) and (port is None or a == port)]
        if not matches:
            raise gp.GPhoto2Error(gp.GP_ERROR_MODEL_NOT_FOUND)
        name, addr = matches[0]
        camera = gp.Camera()
        abilities = gp.CameraAbilitiesList()
        abilities.load()
        camera.set_abilities(abilities[abilities.lookup_model(name)])
        ports = gp.PortInfoList()
        ports.load()
        camera.set_port_info(ports[ports.lookup_path(addr)])
        camera.init()
        self.camera = camera
        return name, addr

    def configure(self, settings: dict[str, str | None]) -> dict[str, str]:
        gp = self.gp
        config = self.camera.get_config()
        outcome: dict[str, str] = {}
        wanted = dict(settings, capture_target="Internal RAM")
        names = dict(SETTING_WIDGETS, capture_target=("capturetarget",))
        for key, value in wanted.items():
            if value is None:
                continue
            widget = None
            for name in names[key]:
                try:
                    widget = config.get_child_by_name(name)
                    break
                except gp.GPhoto2Error:
                    continue
            if widget is None:
                outcome[key] = "not exposed by this camera"
                continue
            choices = [widget.get_choice(i) for i in range(widget.count_choices())]
            pick = next((c for c in choices if _normalise(c) == _normalise(value)), None)
            if pick is None:
                outcome[key] = f"{value!r} not offered (choices: {', '.join(choices[:12])})"
                continue
            widget.set_value(pick)
            outcome[key] = f"set to {pick}"
        self.camera.set_config(config)
        return outcome

    def capture(self, event_wait_ms: int) -> list[tuple[str, bytes]]:
        gp = self.gp
        path = self.camera.capture(gp.GP_CAPTURE_IMAGE)
        paths = [(path.folder, path.name)]
        while True:  # companion files (the NEF of NEF+JPEG) arrive as events
            kind, data = self.camera.wait_for_event(event_wait_ms)
            if kind == gp.GP_EVENT_FILE_ADDED:
                paths.append((data.folder, data.name))
            elif kind in (gp.GP_EVENT_TIMEOUT, gp.GP_EVENT_CAPTURE_COMPLETE):
                break
        files = []
        for folder, name in paths:
            camera_file = self.camera.file_get(folder, name, gp.GP_FILE_TYPE_NORMAL)
            files.append((name, bytes(memoryview(camera_file.get_data_and_size()))))
            self.camera.file_delete(folder, name)
        return files

    def close(self) -> None:
        if self.camera is not None:
            self.camera.exit()
            self.camera = None


def serve(conn: Connection) -> None:
    """Answer requests on ``conn`` until ``("quit", ())`` or the pipe closes (worker process target)."""
    session = _Session()
    gp = session.gp
    ops = {"detect": session.detect, "open": session.open, "configure": session.configure,
           "capture": session.capture, "close": session.close}
    while True:
        try:
            op, args = conn.recv()
        except EOFError:
            break
        if op == "quit":
            session.close()
            conn.send(("ok", None))
            break
        try:
            conn.send(("ok", ops[op](*args)))
        except gp.GPhoto2Error as exc:
            conn.send(("gp", exc.code, exc.string))
        except Exception as exc:  # reported to the parent, which raises CameraError with it
            conn.send(("err", f"{type(exc).__name__}: {exc}"))
