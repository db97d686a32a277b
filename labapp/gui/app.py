"""Start the bench GUI: the QApplication and the main window (``sfr lab`` calls :func:`launch`)."""
from __future__ import annotations

import gc
import logging
import sys
from pathlib import Path

from pyqtgraph.util.garbage_collector import GarbageCollector
from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication

from labapp.errors import EXIT_USAGE, UsageError
from labapp.gui.login import ask_operator
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


def launch(data_dir: Path, simulate: bool, speed: float | None, sample: str, calibration: str | None,
           autostart: bool, quit_after_s: float | None = None, screenshot: str | None = None) -> int:
    """Show the main window and run the event loop; returns the exit code.

    ``autostart`` starts a run at once (simulated: the object drops by itself); ``quit_after_s`` closes the
    window after that many seconds, saving ``screenshot`` (PNG) first (scripted, offscreen sessions).
    """
    problem = None if QApplication.instance() else xcb_problem()
    if problem:
        raise UsageError(problem)
    app = QApplication.instance() or QApplication(sys.argv[:1])
    operator = ask_operator(simulate)      # no operator, nothing recorded: the GUI does not start
    if operator is None:
        return EXIT_USAGE
    collector = gui_thread_garbage_collector()
    window = MainWindow(Path(data_dir), simulate=simulate, speed=speed, sample=sample)
    window.setWindowTitle(f"{window.windowTitle()} - operator: {operator}")
    if calibration:
        window.controls.calibration.setText(calibration)
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
    code = app.exec()
    window.shutdown()
    collector.timer.stop()
    gc.enable()
    return code
