"""The Qt-free acquisition engine: walks a procedure (startup / execute / shutdown) in a worker thread.

Procedures check :meth:`Engine.should_stop`, wait through :attr:`Engine.clock`, ask the operator through
:meth:`Engine.ask`, and publish typed records (:mod:`labapp.acquisition.events`); anything (the CLI status line, the GUI bridge, a
test) observes a run by registering a plain callable with :meth:`Engine.subscribe`. As in pymeasure's
``Procedure`` and bluesky's ``RunEngine.subscribe``.
"""
from __future__ import annotations

import dataclasses
import logging
import threading
from collections.abc import Callable
from typing import Any, Protocol

from drivers.errors import DriverError
from labapp.acquisition.clock import Clock, WallClock
from labapp.acquisition.events import Done, EngineEvent, Message, Outcome, Phase, Prompt, PromptKind, StateChanged
from labapp.errors import LabError

log = logging.getLogger(__name__)

ABORT = "abort"
"""The stop reason of :meth:`Engine.abort`."""
INTERRUPT = "interrupt"
"""The stop reason of :meth:`Engine.interrupt`."""
_OUTCOME_OF_REASON = {ABORT: Outcome.ABORTED, INTERRUPT: Outcome.INTERRUPTED}


def _log_failure(what: str, exc: Exception) -> None:
    """Log a procedure's failure: an expected one (a device, a record, bad settings) in one line at info
    level, since the ``error`` event carries it to the operator (the CLI's last line, the GUI's log); the
    traceback only for a bug (and at debug level for the rest)."""
    if isinstance(exc, (LabError, DriverError, ValueError, OSError)):
        log.info("%s: %s", what, exc)
        log.debug("traceback of %s", what, exc_info=exc)
    else:
        log.exception("%s", what)


class Procedure(Protocol):
    """What the engine walks. ``shutdown`` always runs, also after a failed ``startup`` or ``execute``."""

    name: str

    def startup(self, engine: Engine) -> None: ...

    def execute(self, engine: Engine) -> None: ...

    def shutdown(self, engine: Engine, outcome: Outcome) -> None: ...


class Engine:
    """Runs one procedure at a time in a background thread and publishes its events.

    Parameters
    ----------
    clock : Clock, optional
        The time base of every wait (default: the wall clock).
    """

    def __init__(self, clock: Clock | None = None) -> None:
        self.clock: Clock = clock or WallClock()
        self._subscribers: list[Callable[[EngineEvent], None]] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._stop_reason = ""
        self._answers: dict[PromptKind, Any] = {}
        self._answered = threading.Condition(self._lock)
        self._thread: threading.Thread | None = None
        self.outcome: Outcome | None = None
        self.error: BaseException | None = None

    # -- observers ---------------------------------------------------------------------------------------
    def subscribe(self, fn: Callable[[EngineEvent], None]) -> Callable[[], None]:
        """Call ``fn(event)`` for every published event (from the worker thread); returns an unsubscriber."""
        with self._lock:
            self._subscribers.append(fn)

        def unsubscribe() -> None:
            with self._lock:
                if fn in self._subscribers:
                    self._subscribers.remove(fn)
        return unsubscribe

    def emit(self, event: EngineEvent) -> EngineEvent:
        """Stamp ``event`` with the engine's clock and publish it to every subscriber; a failing subscriber
        is logged, never fatal to the run."""
        event = dataclasses.replace(event, t_unix_s=self.clock.now())
        with self._lock:
            subscribers = list(self._subscribers)
        for fn in subscribers:
            try:
                fn(event)
            except Exception:
                log.exception("event subscriber %r failed on %s", fn, type(event).__name__)
        return event

    # -- control -----------------------------------------------------------------------------------------
    def should_stop(self) -> bool:
        """True once :meth:`stop` or :meth:`abort` was called."""
        return self._stop.is_set()

    @property
    def stop_reason(self) -> str:
        """``""`` while running; else ``operator``, ``abort``, ``interrupt`` or the reason a procedure gave."""
        return self._stop_reason

    def stop(self, reason: str = "operator") -> None:
        """Ask the procedure to finish cleanly (the run's data so far is kept and finalised)."""
        if not self._stop.is_set():
            self._stop_reason = reason
            self._stop.set()
            with self._answered:
                self._answered.notify_all()

    def abort(self) -> None:
        """Stop as soon as possible; the outcome is :attr:`Outcome.ABORTED`."""
        self.stop(ABORT)

    def interrupt(self) -> None:
        """Stop as :meth:`stop` does (heating off, devices closed), but leave a run resumable: the outcome
        is :attr:`Outcome.INTERRUPTED` (a signal to the process, the window closing)."""
        self.stop(INTERRUPT)

    def answer(self, prompt: PromptKind, value: Any = True) -> None:
        """Answer an operator prompt (e.g. ``answer(PromptKind.DROP)`` or ``answer(PromptKind.ADDED_MASS, 0.25)``)."""
        with self._answered:
            self._answers[prompt] = value
            self._answered.notify_all()

    def ask(self, prompt: PromptKind, text: str, auto: Any = None) -> Any:
        """Publish a ``prompt`` event and block until :meth:`answer` (returns the value) or a stop (None).

        With ``auto`` not None the prompt answers itself with ``auto`` (simulation: the drop happens by itself).
        """
        with self._answered:
            self._answers.pop(prompt, None)
        self.emit(Prompt(prompt, text, auto is not None))
        if auto is not None:
            return auto
        with self._answered:
            while prompt not in self._answers and not self._stop.is_set():
                self._answered.wait(0.1)
            return self._answers.pop(prompt, None)

    # -- running -----------------------------------------------------------------------------------------
    @property
    def running(self) -> bool:
        """True while a procedure's thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    def _reset(self) -> None:
        self._stop.clear()
        self._stop_reason = ""
        self.outcome, self.error = None, None

    def run(self, procedure: Procedure) -> Outcome:
        """Walk ``procedure`` in the calling thread; returns its outcome."""
        self._reset()
        return self._walk(procedure)

    def _walk(self, procedure: Procedure) -> Outcome:
        outcome = Outcome.COMPLETE
        self.emit(StateChanged(Phase.STARTING, procedure=procedure.name))
        try:
            procedure.startup(self)
            if not self.should_stop():
                procedure.execute(self)
        except Exception as exc:
            _log_failure(f"{procedure.name} failed", exc)
            self.error = exc
            outcome = Outcome.FAILED
            self.emit(Message("error", f"{type(exc).__name__}: {exc}", topic=procedure.name, fatal=True))
        if outcome != Outcome.FAILED and self.should_stop():
            outcome = _OUTCOME_OF_REASON.get(self._stop_reason, Outcome.STOPPED)
        try:
            procedure.shutdown(self, outcome)
        except Exception as exc:
            _log_failure(f"{procedure.name} shutdown failed", exc)
            self.emit(Message("error", f"shutdown: {type(exc).__name__}: {exc}", topic=procedure.name))
            self.error = self.error or exc
        self.outcome = outcome
        self.emit(Done(outcome, self._stop_reason))
        return outcome

    def start(self, procedure: Procedure) -> threading.Thread:
        """Walk ``procedure`` in a new daemon thread; returns the thread.

        Raises
        ------
        RuntimeError
            If a procedure is already running.
        """
        if self.running:
            raise RuntimeError("the engine is already running a procedure; stop it first")
        self._reset()           # here, not in the thread: a stop() right after start() is never lost
        self._thread = threading.Thread(target=self._walk, args=(procedure,), name=f"engine-{procedure.name}",
                                        daemon=True)
        self._thread.start()
        return self._thread

    def join(self, timeout_s: float | None = None) -> Outcome | None:
        """Wait for the background procedure; returns its outcome (None if still running)."""
        if self._thread is not None:
            self._thread.join(timeout_s)
        return None if self.running else self.outcome
