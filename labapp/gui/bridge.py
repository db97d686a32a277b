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

from labapp.engine import Engine, Event

log = logging.getLogger(__name__)


class EngineBridge(QObject):
    """Re-emits every engine :class:`Event` as ``event`` and by kind as ``frame``/``preview``/``reading``/
    ``state``/``message``/``prompt``/``done`` (each carrying the event's data dict)."""

    event = Signal(object)
    frame = Signal(object)
    preview = Signal(object)
    reading = Signal(object)
    state = Signal(object)
    message = Signal(str, str)
    prompt = Signal(object)
    done = Signal(object)

    def __init__(self, engine: Engine, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.engine = engine
        self._unsubscribe = engine.subscribe(self._on_event)

    def _on_event(self, ev: Event) -> None:
        self.event.emit(ev)
        if ev.kind == "frame":
            self.frame.emit(ev.data)
        elif ev.kind == "preview":
            self.preview.emit(ev.data)
        elif ev.kind == "reading":
            self.reading.emit(ev.data)
        elif ev.kind == "state":
            self.state.emit(ev.data)
        elif ev.kind in ("info", "warning", "error"):
            self.message.emit(ev.kind, str(ev.data.get("message", "")))
        elif ev.kind == "prompt":
            self.prompt.emit(ev.data)
        elif ev.kind == "done":
            self.done.emit(ev.data)

    def detach(self) -> None:
        """Stop listening to the engine."""
        self._unsubscribe()


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

    def start(self) -> None:
        """Start the work (once)."""
        self._thread = threading.Thread(target=self._run, name="gui-task", daemon=True)
        self._thread.start()

    @property
    def running(self) -> bool:
        """True while the work is in progress."""
        return self._thread is not None and self._thread.is_alive()

    def _run(self) -> None:
        try:
            result = self._fn(self.progress.emit)
        except Exception as exc:
            log.exception("background task failed")
            self.failed.emit(f"{type(exc).__name__}: {exc}")
            return
        self.finished.emit(result)
