"""Changing the recording run's maximum or minimum duration from the bench window, with a reason
(:func:`labapp.gui.dialogs.ask_changes`), through ``labapp.jobs.run.change_setting`` as ``sfr change`` does: the
request waits in a worker thread for the run's next frame, where the engine's thread applies it."""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from PySide6.QtCore import QObject, Signal
from PySide6.QtWidgets import QWidget

from labapp.acquisition.engine import Engine
from labapp.acquisition.procedures import RunProcedure
from labapp.acquisition.settings import CHANGEABLE_DURING_RUN
from labapp.errors import UsageError
from labapp.gui import dialogs
from labapp.gui.bridge import BackgroundTask
from labapp.jobs.run import change_setting
from labapp.records.operators import OperatorError


class DurationChange(QObject):
    """Asks for the changes and makes them; emits ``message(level, text)`` for the event log.

    Parameters
    ----------
    engine : Engine
        The engine recording the run (a change is withdrawn once it no longer runs).
    closed : callable
        True once the window has closed (a change is withdrawn, a refusal no longer shown in a box).
    parent : QWidget
        The window: the dialogs' parent.
    """

    message = Signal(str, str)

    def __init__(self, engine: Engine, closed: Callable[[], bool], parent: QWidget) -> None:
        super().__init__(parent)
        self.engine, self.closed = engine, closed
        self.task: BackgroundTask | None = None
        """A change waiting for the run's next frame."""

    def ask(self, procedure: object, elapsed_s: float | None) -> None:
        """Ask for new durations of ``procedure``'s run (recording for ``elapsed_s``) and a reason, and make the
        changes; the outcome comes back in :meth:`_changed`."""
        if not (self.engine.running and isinstance(procedure, RunProcedure) and procedure.run is not None):
            self.message.emit("warning", "no run is recording: its duration changes only while it records")
            return
        if self.task is not None and self.task.running:
            self.message.emit("warning", "a change is still waiting for the run's next frame")
            return
        folder = procedure.run.path
        current = {s.name: getattr(procedure.config, s.name) for s in CHANGEABLE_DURING_RUN}
        asked = dialogs.ask_changes(self.parent(), dialogs.change_question(folder.name, elapsed_s),
                                    CHANGEABLE_DURING_RUN, current)
        if asked is None:
            return
        changes, reason = asked
        gone = lambda: self.closed() or not self.engine.running     # noqa: E731 (the run ended: withdraw)
        self.message.emit("info", f"waiting for {folder.name}'s next frame to change its duration ...")
        self.task = BackgroundTask(lambda progress: change_settings(folder, changes, reason, gone), self)
        self.task.finished.connect(self._changed)
        self.task.failed.connect(self._failed)
        self.task.start()

    def _changed(self, outcome: tuple[list[str], str]) -> None:
        """A change of the run's duration was answered: each change made in the event log, a refusal said."""
        done, refused = outcome
        for detail in done:
            self.message.emit("info", f"changed {detail}")
        if refused:
            self.message.emit("error", f"not changed: {refused}")
            if not self.closed():
                dialogs.tell(self.parent(), "change refused", refused)

    def _failed(self, message: str) -> None:
        self._changed(([], message))


def change_settings(folder: Path, changes: dict[str, float], reason: str,
                    gone: Callable[[], bool]) -> tuple[list[str], str]:
    """Apply ``changes`` to the recording run in ``folder`` one by one (each waits for the run's next frame;
    ``gone()``: the run ended, withdraw): the changes made, and the refusal that stopped them ("" if none)."""
    done = []
    for name, value in changes.items():
        try:
            done.append(change_setting(folder, name, value, reason, should_stop=gone))
        except (UsageError, OperatorError) as exc:
            return done, str(exc)
    return done, ""
