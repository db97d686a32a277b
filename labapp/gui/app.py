"""Start the bench GUI: the QApplication and the main window (``sfr lab`` calls :func:`launch`)."""
from __future__ import annotations

import gc
import logging
import signal
import sys
from collections.abc import Callable
from pathlib import Path

from pyqtgraph.util.garbage_collector import GarbageCollector
from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication

from labapp.errors import EXIT_USAGE, UsageError
from labapp.gui.login import LoginInterrupted, ask_operator
from labapp.gui.main_window import MainWindow
from labapp.gui.syslibs import xcb_problem

log = logging.getLogger(__name__)

GC_INTERVAL_S = 1.0
"""How often the GUI thread runs Python's cyclic garbage collector, s."""


def gui_thread_garbage_collector() -> GarbageCollector:
    """Run Python's cyclic garbage collector only in the GUI thread, on a timer (keep the returned object).

    Left automatic, it runs in whichever thread allocates at that moment (a device, Dask or background
    task thread), and a Qt object it collects there can deadlock PySide in its destructor.
    """
    return GarbageCollector(interval=GC_INTERVAL_S)


SIGNAL_POLL_MS = 200
"""How often the event loop hands control to Python, so that a SIGINT or SIGTERM handler runs, ms."""


class SignalStop:
    """SIGINT (Ctrl-C in the terminal) and SIGTERM (a service manager, ``kill``) close ``window`` as
    closing it mid-run does, without asking: a run is interrupted (heating and stirring off, the folder left
    ``interrupted`` and resumable), a design or sweep stops at a checkpoint, and the window closes once all
    of it has stopped; :attr:`exit_code` is then 128 + the signal's number (130 for SIGINT, 143 for SIGTERM).
    A second signal changes nothing of that: the procedure is already stopping (heating off, devices closing), and
    a run still ends ``interrupted`` and resumable, the safer outcome; it is said on the terminal.

    Qt's event loop runs in C++, where Python cannot run a signal handler; a timer hands control back to
    Python every :data:`SIGNAL_POLL_MS`. Call :meth:`restore` after the loop.
    """

    def __init__(self, window: MainWindow, signals: tuple[int, ...] = (signal.SIGINT, signal.SIGTERM)) -> None:
        self.window = window
        self.received: list[int] = []
        self._previous: dict[int, Callable | int | None] = {sig: signal.signal(sig, self._handle) for sig in signals}
        self.timer = QTimer()
        self.timer.timeout.connect(self._tick)
        self.timer.start(SIGNAL_POLL_MS)

    @property
    def exit_code(self) -> int | None:
        """128 + the first signal's number, or None without a signal."""
        return 128 + self.received[0] if self.received else None

    def _tick(self) -> None:
        """Nothing: returning to Python lets a pending signal handler run."""

    def _handle(self, signum: int, frame) -> None:
        self.received.append(signum)
        name = signal.Signals(signum).name
        if len(self.received) > 1:
            print(f"sfr lab: {name} again: already stopping (heating and stirring off, devices closing); a run "
                  "stays interrupted and resumable; the window closes when it has stopped", file=sys.stderr, flush=True)
            return
        print(f"sfr lab: {name}: interrupting (heating and stirring off, a run left resumable), then closing",
              file=sys.stderr, flush=True)
        log.info("%s received: closing the window", name)
        if self.window.busy_work():
            self.window.begin_close()
        else:
            self.window.close()

    def restore(self) -> None:
        """Stop the timer and put back the previous handlers."""
        self.timer.stop()
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)


def launch(data_dir: Path, simulate: bool, speed: float | None, sample: str, calibration: str | None,
           autostart: bool, quit_after_s: float | None = None, screenshot: str | None = None) -> int:
    """Show the main window and run the event loop; returns the exit code.

    ``autostart`` starts a run at once (simulated: the object drops by itself); ``quit_after_s`` closes the
    window after that many seconds, saving ``screenshot`` (PNG) first (scripted, offscreen sessions).
    SIGINT and SIGTERM interrupt and close (:class:`SignalStop`): the exit code is then 130 or 143.
    """
    problem = None if QApplication.instance() else xcb_problem()
    if problem:
        raise UsageError(problem)
    app = QApplication.instance() or QApplication(sys.argv[:1])
    try:
        operator = ask_operator(simulate)      # no operator, nothing recorded: the GUI does not start
    except LoginInterrupted as exc:
        print(f"sfr lab: {exc}: closed at the login, nothing started", file=sys.stderr, flush=True)
        return 128 + exc.signum
    if operator is None:
        return EXIT_USAGE
    collector = gui_thread_garbage_collector()
    window = MainWindow(Path(data_dir), simulate=simulate, speed=speed, sample=sample)
    window.setWindowTitle(f"{window.windowTitle()} - operator: {operator}")
    if calibration:
        window.controls.set_calibration_path(calibration)
    window.show()
    if autostart:
        window.controls.auto_drop.setChecked(simulate)
        window.start_run()
    if quit_after_s is not None:
        def finish() -> None:
            if screenshot:
                window.grab().save(screenshot)
                log.info("screenshot saved: %s", screenshot)
            window.engine.stop()
            window.engine.join(30)
            window.shutdown()
            app.quit()
        QTimer.singleShot(int(quit_after_s * 1000), finish)
    signals = SignalStop(window)
    try:
        code = app.exec()
    finally:
        signals.restore()
    if signals.exit_code is not None:
        code = signals.exit_code
    window.shutdown()
    collector.timer.stop()
    gc.enable()
    return code
