"""The bench window's benches: the device panel's bench built in a worker thread and handed over in the GUI
thread, the simulated one kept between procedures (:class:`~labapp.gui.simulated_session.SimulatedSession`), and
the hotplate of the bench the last procedure used polled while no procedure holds it
(:class:`~labapp.gui.plate_poller.IdlePlatePoller`)."""
from __future__ import annotations

from collections.abc import Callable

from PySide6.QtCore import QObject, Signal

from drivers.hotplate.base import Hotplate
from labapp.acquisition.bench import Bench
from labapp.acquisition.devices import make_bench
from labapp.acquisition.engine import Engine
from labapp.acquisition.settings import KEEPALIVE
from labapp.acquisition.simbench import SimulatedBench
from labapp.gui.bridge import BackgroundTask
from labapp.gui.device_panel import SIMULATED, DevicePanel
from labapp.gui.plate_poller import IdlePlatePoller
from labapp.gui.simulated_session import SimulatedSession


class BenchBuilder(QObject):
    """Builds the bench the device panel describes, off the GUI thread.

    Emits ``connecting(busy, doing)`` when a build starts (``doing``: what it is for, "connecting",
    "starting" ...) and ends, and ``message(level, text)`` for the event log.

    Parameters
    ----------
    devices : DevicePanel
        The camera, hotplate, camera settings and bath to build with.
    engine : Engine
        Its clock is the new bench's.
    poller : IdlePlatePoller
        Polls the hotplate of the bench the last procedure used.
    simulated : SimulatedSession
        Keeps the simulated bench.
    """

    connecting = Signal(bool, str)
    message = Signal(str, str)

    def __init__(self, devices: DevicePanel, engine: Engine, poller: IdlePlatePoller, simulated: SimulatedSession,
                 parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.devices, self.engine, self.poller, self.simulated = devices, engine, poller, simulated
        self.hotplate: Hotplate | None = None
        """The hotplate of the bench the last procedure used: the one polled while idle."""
        self.task: BackgroundTask | None = None
        self._then: Callable[[Bench], None] | None = None
        self._closed = False

    @property
    def building(self) -> bool:
        """True while a bench is being built in the background."""
        return self.task is not None and self.task.running

    def with_bench(self, then: Callable[[Bench], None], doing: str = "connecting") -> None:
        """Call ``then(bench)`` in the GUI thread with the device panel's bench, built in a worker thread (a
        simulated bench takes seconds to build and is kept until the bath's water changes; opening real devices
        may wait on a port)."""
        if self.building:
            self.message.emit("warning", "still building the bench; wait for it to finish")
            return
        try:
            camera, hotplate, bath = self.devices.camera_spec(), self.devices.hotplate_spec(), self.devices.bath()
            cam_settings = self.devices.settings()
        except Exception as exc:
            self.message.emit("error", f"cannot build the bench: {exc}")
            return
        if camera == SIMULATED and self.simulated.fits(bath.water_g):
            then(self.simulated.bench.bench())
            return
        clock, simulated = self.engine.clock, self.simulated

        def build(progress):
            if camera == SIMULATED:
                return simulated.build(bath.water_g, hotplate == SIMULATED, clock)
            return make_bench(camera, hotplate, cam_settings)
        self._then = then
        self.task = BackgroundTask(build, self)
        self.task.finished.connect(self._built)
        self.task.failed.connect(self._failed)
        self.connecting.emit(True, doing)
        self.task.start()

    def _built(self, built) -> None:
        self.connecting.emit(False, "")
        then, self._then = self._then, None
        if self._closed:
            if isinstance(built, SimulatedBench):
                built.close()
            return
        if isinstance(built, SimulatedBench):
            self.keep_simulated(built)               # with the sample's release: computed once a session
            built = built.bench()
        if then is not None:
            then(built)

    def _failed(self, message: str) -> None:
        self.connecting.emit(False, "")
        self._then = None
        self.message.emit("error", f"cannot build the bench: {message}")

    def keep_simulated(self, bench: SimulatedBench | None) -> None:
        """Keep ``bench`` as the simulated bench (None: none, the next is built anew); the old one closes."""
        if self.simulated.keep(bench, self.hotplate):
            self.hotplate = None         # the emulator goes, its port with it: the idle poller lets go of it

    def use(self, bench: Bench | None) -> None:
        """A procedure starts on ``bench``: its hotplate is the one polled once the procedure has ended."""
        self.hotplate = getattr(bench, "hotplate", None)

    def poll_idle(self) -> None:
        """Poll the hotplate of the bench the last procedure used while no procedure holds it (every keepalive of
        the engine's clock, off the GUI thread): the panel and the status line show the heater as it is after a
        run, and while idle."""
        if self._closed or self.hotplate is None:
            return
        try:
            keepalive_s = self.devices.bath().keepalive_s
        except Exception:                          # a field being edited: the default period
            keepalive_s = KEEPALIVE.default
        self.poller.hold(self.hotplate, keepalive_s)

    def close(self) -> None:
        """The window closes: stop polling (heating and stirring off, as every close of the hotplate), close
        the simulated bench, and close a bench still being built once it arrives."""
        self._closed = True
        self.poller.close()
        self.keep_simulated(None)
