"""The one confirmation of a final action (stop, abort, finalise, closing mid-run), and what each says.

Every final action asks through :func:`confirm`: a warning box that names the run and what cannot be undone,
with the safe choice ("Keep running", "Cancel") as its default and Escape button, so Enter or Escape never
ends a run. Tests answer it by monkeypatching :func:`confirm` (callers look it up through this module) or by
clicking the box.
"""
from __future__ import annotations

from dataclasses import dataclass

from PySide6.QtWidgets import QMessageBox, QWidget

KEEP_RUNNING = "Keep running"
CANCEL = "Cancel"


@dataclass(frozen=True)
class Question:
    """A final action to confirm: the box's title, the question (naming the run), what happens and cannot be
    undone, the action's button text and the safe button's."""

    title: str
    question: str
    consequences: str
    action: str
    safe: str = KEEP_RUNNING


def confirm(parent: QWidget | None, q: Question) -> bool:
    """Ask ``q`` in a modal warning box; True only if the operator chose the action (the safe button is the
    default and the Escape button)."""
    box = QMessageBox(QMessageBox.Icon.Warning, q.title, q.question, parent=parent)
    box.setInformativeText(q.consequences)
    act = box.addButton(q.action, QMessageBox.ButtonRole.DestructiveRole)
    keep = box.addButton(q.safe, QMessageBox.ButtonRole.RejectRole)
    box.setDefaultButton(keep)
    box.setEscapeButton(keep)
    box.exec()
    return box.clickedButton() is act


def _what(procedure: str, name: str) -> str:
    kind = {"run": "run", "calibration": "calibration series", "preview": "connection check"}.get(procedure, procedure)
    return f"{kind} {name}" if name else f"the {kind}"


def stop_question(procedure: str, name: str) -> Question:
    """Stop: the engine's clean stop (heating off, the record finalised as ``stopped``)."""
    what = _what(procedure, name)
    if procedure == "calibration":
        text = ("Capturing ends now and heating and stirring are switched off. With 3 or more levels captured "
                "the series is fitted; the series is finalised as 'stopped' and cannot be continued.")
    else:
        text = ("Acquisition ends now: heating and stirring are switched off and the run is finalised as "
                "'stopped' with the frames recorded so far. A stopped run is a finished record: it cannot be "
                "resumed.")
    return Question("stop", f"Stop {what}?", text, "Stop")


def abort_question(procedure: str, name: str) -> Question:
    """Abort: as stop, at once, the record marked ``aborted`` (a series is not fitted)."""
    what = _what(procedure, name)
    if procedure == "calibration":
        text = ("Capturing ends at once and heating and stirring are switched off. The series is marked "
                "'aborted' and not fitted; it cannot be continued.")
    else:
        text = ("Acquisition ends at once: heating and stirring are switched off and the run is marked "
                "'aborted'. Its frames are kept, but an aborted run cannot be resumed.")
    return Question("abort", f"Abort {what}?", text, "Abort")


def interrupt_effect(procedure: str, name: str) -> str:
    """What closing the window does to the running procedure (the engine's interrupt: a run stays
    resumable)."""
    what = _what(procedure, name)
    if procedure == "run":
        return (f"{what} is interrupted: heating and stirring are switched off and the run is left 'interrupted' "
                "with its frames; resume it later from the Runs tab (Resume acquisition) or with `sfr run --resume`")
    return (f"{what} is stopped: heating and stirring are switched off and it is finalised as 'stopped'; it cannot "
            "be continued")


def close_question(effects: list[str]) -> Question:
    """Closing the window while work runs: each of ``effects`` says what happens to one piece of work."""
    return Question("quit", "Close the window while work is running?",
                    "Closing now:\n- " + "\n- ".join(effects) + "\n\nThe window closes once all of it has stopped.",
                    "Stop and close")


def finalise_question(name: str, frames: int) -> Question:
    """Finalise: an interrupted run closed without resuming (``labapp.records.storage.finalise_run``)."""
    return Question("finalise", f"Finalise run {name} without resuming it?",
                    f"Its status becomes 'stopped' with its {frames} frames, and it can no longer be resumed.",
                    "Finalise", CANCEL)
