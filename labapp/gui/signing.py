"""The run browser's record actions: sign a record (:class:`SignDialog`) and save its report (:func:`save_report`).

Both call the functions ``sfr sign`` and ``sfr report`` call (:func:`labapp.records.signatures.sign`,
:func:`labapp.jobs.report.write_report`); the password is asked again for every signature.
"""
from __future__ import annotations

from pathlib import Path

from PySide6.QtWidgets import (
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QFileDialog,
    QFormLayout,
    QLabel,
    QLineEdit,
    QVBoxLayout,
    QWidget,
)

from labapp.errors import LabError
from labapp.records import operators
from labapp.records.signatures import Meaning, sign

__all__ = ["SignDialog", "save_report", "sign_record"]


class SignDialog(QDialog):
    """Sign ``folder`` as the session's operator: meaning, reason and the password again.
    :attr:`signature` holds the stored signature once signed; a refusal (wrong password, a record that does
    not verify) is shown and the dialog stays open."""

    def __init__(self, folder: str | Path, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.folder = Path(folder)
        self.signature: dict | None = None
        self.setWindowTitle(f"Sign {self.folder.name}")
        signer = operators.current()
        self.meaning = QComboBox()
        self.meaning.addItems([m.value for m in Meaning])
        self.reason = QLineEdit()
        self.reason.setPlaceholderText("optional: why (stored with the signature)")
        self.password = QLineEdit()
        self.password.setEchoMode(QLineEdit.EchoMode.Password)
        self.message = QLabel(f"Signing {self.folder} as {signer or 'nobody (log in first)'}. The signature is "
                              "bound to the record as it is now: any later change shows it as BROKEN.")
        self.message.setWordWrap(True)
        form = QFormLayout()
        form.addRow("meaning", self.meaning)
        form.addRow("reason", self.reason)
        form.addRow(f"password of {signer}", self.password)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Ok | QDialogButtonBox.StandardButton.Cancel)
        buttons.button(QDialogButtonBox.StandardButton.Ok).setText("Sign")
        buttons.accepted.connect(self.sign)
        buttons.rejected.connect(self.reject)
        layout = QVBoxLayout(self)
        layout.addWidget(self.message)
        layout.addLayout(form)
        layout.addWidget(buttons)

    def sign(self) -> None:
        """Sign; accept, or show the refusal (it is in the audit trail) and stay open."""
        try:
            self.signature = sign(self.folder, self.meaning.currentText(), self.password.text(),
                                  reason=self.reason.text().strip() or None)
        except LabError as exc:
            self.message.setText(f"Not signed: {exc}")
            self.password.clear()
            return
        self.accept()


def sign_record(folder: str | Path, parent: QWidget | None = None) -> dict | None:
    """Show :class:`SignDialog` for ``folder``; the signature, or None when cancelled."""
    dialog = SignDialog(folder, parent)
    return dialog.signature if dialog.exec() == QDialog.DialogCode.Accepted else None


def save_report(folder: str | Path, parent: QWidget | None = None, out: str | Path | None = None) -> Path | None:
    """Ask where to save the report of the run ``folder`` (unless ``out`` is given) and write it; the PDF's path,
    or None when cancelled. Raises what :func:`labapp.jobs.report.write_report` raises."""
    from labapp.jobs.report import write_report

    if out is None:
        out, _ = QFileDialog.getSaveFileName(parent, "Save the run report", str(Path(folder).with_suffix(".pdf")),
                                             "PDF (*.pdf)")
        if not out:
            return None
    return write_report(folder, out)
