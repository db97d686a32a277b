"""Engine events -> Qt signals, and a helper to run plain callables off the GUI thread.

The engine publishes from its worker thread. :class:`EngineBridge` lives in the GUI thread; its signals
are emitted from the worker and delivered (queued) to slots of GUI-thread objects, so no widget is ever
touched by an acquisition thread. Connect these signals to methods of QObjects, not to lambdas (a lambda
has no thread affinity and may run in the worker under PySide6).
"""
from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

from PySide6.QtCore import QObject, Signal

from labapp.acquisition.bench import PUBLISHED
from labapp.acquisition.engine import Engine
from labapp.acquisition.events import (
    Alarm,
    CalibrationLevel,
    Done,
    EngineEvent,
    FrameStored,
    Link,
    Message,
    Preview,
    Prompt,
    Reading,
    ReferenceStored,
    StateChanged,
)

log = logging.getLogger(__name__)


class EngineBridge(QObject):
    """Re-emits every engine event as ``event`` and by type as ``frame`` (:class:`FrameStored`), ``level``
    (:class:`CalibrationLevel`), ``preview``, ``reading``, ``link``, ``reference``, ``state``, ``prompt``, ``alarm``,
    ``done`` (each carrying the typed event) and ``message(level, text)``."""

    event = Signal(object)
    frame = Signal(object)
    level = Signal(object)
    preview = Signal(object)
    reading = Signal(object)
    link = Signal(object)
    reference = Signal(object)
    state = Signal(object)
    message = Signal(str, str)
    prompt = Signal(object)
    alarm = Signal(object)
    done = Signal(object)

    def __init__(self, engine: Engine, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.engine = engine
        self._unsubscribe = engine.subscribe(self._on_event)

    def _on_event(self, ev: EngineEvent) -> None:
        self.event.emit(ev)
        match ev:
            case FrameStored():
                self.frame.emit(ev)
            case CalibrationLevel():
                self.level.emit(ev)
            case Preview():
                self.preview.emit(ev)
            case Reading():
                self.reading.emit(ev)
            case Link():
                self.link.emit(ev)
            case ReferenceStored():
                self.reference.emit(ev)
            case StateChanged():
                self.state.emit(ev)
            case Message():
                self.message.emit(ev.level, ev.message)
            case Prompt():
                self.prompt.emit(ev)
            case Alarm():
                self.alarm.emit(ev)
            case Done():
                self.done.emit(ev)

    def detach(self) -> None:
        """Stop listening to the engine."""
        self._unsubscribe()


class LogBridge(QObject):
    """Log records of ``loggers`` at ``level`` and above (driver reconnects and retries, engine warnings, the
    analysis' warnings with their text) as the ``message(level, text)`` signal, delivered in the GUI thread;
    records also published as engine events (``labapp.acquisition.bench.PUBLISHED``) are skipped, they
    arrive through :class:`EngineBridge`."""

    message = Signal(str, str)

    def __init__(self, loggers: tuple[str, ...] = ("drivers", "labapp", "analysis"), level: int = logging.WARNING,
                 parent: QObject | None = None) -> None:
        super().__init__(parent)
        bridge = self

        class _Handler(logging.Handler):
            def emit(self, record: logging.LogRecord) -> None:
                if getattr(record, PUBLISHED, False):
                    return
                try:
                    bridge.message.emit(record.levelname.lower(), f"{record.name}: {record.getMessage()}")
                except RuntimeError:            # the window is gone while a thread still logs
                    pass

        self.handler = _Handler(level)
        self._loggers = [logging.getLogger(name) for name in loggers]
        for lg in self._loggers:
            lg.addHandler(self.handler)

    def detach(self) -> None:
        """Remove the handler from the loggers."""
        for lg in self._loggers:
            lg.removeHandler(self.handler)


class BackgroundTask(QObject):
    """Run ``fn(progress)`` in a daemon thread; ``progress(obj)`` calls become the ``progress`` signal and the
    result or error the ``finished``/``failed`` signals (all delivered in the GUI thread)."""

    progress = Signal(object)
    finished = Signal(object)
    failed = Signal(str)

    def __init__(self, fn: Callable[[Callable[[Any], None]], Any], parent: QObject | None = None) -> None:
        super().__init__(parent)
        self._fn = fn
        self._thread: threading.Thread | None = None
        self._delivered = False
        self.finished.connect(self._deliver)   # connected first: done before any slot connected later sees it
        self.failed.connect(self._deliver)

    def _deliver(self, _result: object) -> None:
        self._delivered = True

    def start(self) -> None:
        """Start the work (once)."""
        self._thread = threading.Thread(target=self._run, name="gui-task", daemon=True)
        self._thread.start()

    @property
    def running(self) -> bool:
        """True from `start` until the result or error is delivered in the GUI thread (its thread may still be
        returning then), or the thread ended without one."""
        return self._thread is not None and not self._delivered and self._thread.is_alive()

    def _run(self) -> None:
        try:
            result = self._fn(self.progress.emit)
        except Exception as exc:
            log.exception("background task failed")
            self.failed.emit(f"{type(exc).__name__}: {exc}")
            return
        self.finished.emit(result)
