"""The one confirmation of a final action (stop, abort, finalise, closing mid-run), and what each says.

Every final action asks through :func:`confirm`: a warning box that names the run and what cannot be undone,
with the safe choice ("Keep running", "Cancel") as its default and Escape button, so Enter or Escape never
ends a run. An action that changes a record after the fact (finalising an interrupted run, reanalysing a
recorded one) asks through :func:`ask_reason` instead: the same question with a field for the reason its
audit entry carries, required where the job function requires one; a setting changed while a run records
(:func:`ask_changes`) is asked the same way, with the setting fields above the reason. Tests answer them by
monkeypatching :func:`confirm`, :func:`ask_reason`, :func:`ask_changes` and :func:`tell` (callers look them up
through this module) or by driving the dialogs.
"""
from __future__ import annotations

from dataclasses import dataclass

from PySide6.QtWidgets import (
    QDialog,
    QDialogButtonBox,
    QFormLayout,
    QLabel,
    QLineEdit,
    QMessageBox,
    QVBoxLayout,
    QWidget,
)

from labapp.acquisition.settings import Setting
from labapp.gui.fields import add_rows, problems

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


class ReasonDialog(QDialog):
    """A final action's question with a reason field: :meth:`reason` is what the operator typed (stripped).

    The safe button is the default and the Escape button; with ``required``, the action button refuses an
    empty reason and says so in the dialog, which stays open.
    """

    def __init__(self, parent: QWidget | None, q: Question, required: bool) -> None:
        super().__init__(parent)
        self.setWindowTitle(q.title)
        self.required = required
        self.question = QLabel(q.question)
        self.question.setStyleSheet("font-weight: bold;")
        self.consequences = QLabel(q.consequences + "\n\nThe audit trail records who did it, when, and the reason "
                                   "given here.")
        for label in (self.question, self.consequences):
            label.setWordWrap(True)
        self.reason_edit = QLineEdit()
        self.reason_edit.setPlaceholderText("reason (required)" if required else
                                            "reason (optional, as `sfr analyze --reason`)")
        self.problem = QLabel("")
        self.problem.setStyleSheet("color: #b00000;")
        self.problem.hide()
        buttons = QDialogButtonBox()
        self.action_button = buttons.addButton(q.action, QDialogButtonBox.ButtonRole.AcceptRole)
        self.safe_button = buttons.addButton(q.safe, QDialogButtonBox.ButtonRole.RejectRole)
        self.action_button.setAutoDefault(False)
        self.safe_button.setDefault(True)
        buttons.accepted.connect(self._act)
        buttons.rejected.connect(self.reject)
        layout = QVBoxLayout(self)
        for widget in (self.question, self.consequences, QLabel("reason:"), self.reason_edit, self.problem, buttons):
            layout.addWidget(widget)

    def reason(self) -> str:
        """The reason as typed, without surrounding white space."""
        return self.reason_edit.text().strip()

    def _act(self) -> None:
        if self.required and not self.reason():
            self.problem.setText("a reason is required: it is recorded in the audit trail")
            self.problem.show()
            self.reason_edit.setFocus()
            return
        self.accept()


def ask_reason(parent: QWidget | None, q: Question, required: bool) -> str | None:
    """Ask ``q`` with a reason field (modal); the reason given (``""`` when none was typed and none is
    ``required``), or None when the operator chose the safe button or Escape."""
    dialog = ReasonDialog(parent, q, required)
    return dialog.reason() if dialog.exec() == QDialog.DialogCode.Accepted else None


def tell(parent: QWidget | None, title: str, text: str) -> None:
    """Say ``text`` in a modal warning box (an action the operator asked for was refused, and why)."""
    QMessageBox.warning(parent, title, text)


class ChangeSettingsDialog(ReasonDialog):
    """Settings of a recording run to change, each a field made from its declaration (:class:`SettingBox`,
    prefilled with the current value, in the shown unit), and the required reason.

    The action button refuses, with the dialog left open and the problem shown in it: a field out of its
    setting's range, no field changed, an empty reason. :meth:`changes` are the fields changed (stored units).
    """

    def __init__(self, parent: QWidget | None, q: Question, settings: tuple[Setting, ...],
                 current: dict[str, float]) -> None:
        super().__init__(parent, q, required=True)
        self.current = dict(current)
        form = QFormLayout()
        self.boxes = add_rows(form, settings)
        for name, box in self.boxes.items():
            box.set_stored(current[name])
        self.layout().insertLayout(2, form)           # under the question, above the reason

    def changes(self) -> dict[str, float]:
        """The settings whose field differs from the current value as shown, by name, in stored units."""
        changed = {}
        for name, box in self.boxes.items():
            if abs(box.value() - box.setting.shown(self.current[name])) >= 0.5 * 10.0 ** -box.decimals():
                changed[name] = box.stored()
        return changed

    def _act(self) -> None:
        found = problems(self.boxes)
        if not found and not self.changes():
            found = ["nothing changed: set a new value first"]
        if found:
            self.problem.setText("; ".join(found))
            self.problem.show()
            return
        super()._act()


def ask_changes(parent: QWidget | None, q: Question, settings: tuple[Setting, ...], current: dict[str, float],
                ) -> tuple[dict[str, float], str] | None:
    """Ask which of ``settings`` (``current``: their values now, stored units) change, and why (modal); the
    changed values by name (stored units) and the reason, or None when the operator cancelled."""
    dialog = ChangeSettingsDialog(parent, q, settings, current)
    if dialog.exec() != QDialog.DialogCode.Accepted:
        return None
    return dialog.changes(), dialog.reason()


def change_question(name: str, elapsed_s: float | None) -> Question:
    """Changing the duration of the run ``name`` while it records (``labapp.jobs.run.change_setting``)."""
    so_far = "" if elapsed_s is None else f" It has recorded for {elapsed_s / 3600:.2f} h since the drop."
    return Question("change duration", f"Change the duration of run {name}?",
                    f"The run takes the new values at its next frame and run.json keeps them; a maximum below the "
                    f"time recorded ends the run at that frame.{so_far} Every other setting stays as it started.",
                    "Change", CANCEL)


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


def reanalyse_question(name: str, out: str, calibration: str) -> Question:
    """Reanalyse a recorded run: its analysis folder is written again (``labapp.jobs.analyse.analyse_run``)."""
    return Question("reanalyse", f"Reanalyse run {name}?",
                    f"{out} (curve.csv, cells.csv, summary.json, curve.png) is written again from the frames with "
                    f"the calibration {calibration}; the frames themselves are not changed.", "Reanalyse", CANCEL)
