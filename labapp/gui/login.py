"""The operator at the start of `sfr lab`: who records, checked against the users file with their password.

Nothing is recorded without an operator (:mod:`labapp.records.operators`). An operator already given
(``sfr lab --operator NAME`` or ``$SFR_OPERATOR``) is used as the command line uses it; otherwise
:func:`ask_operator` shows :class:`LoginDialog`. A machine without operators can start the simulated bench as
the built-in demo operator, who records only on the simulated bench.

Ctrl-C in the terminal (SIGINT) and SIGTERM close the dialog: :func:`ask_operator` raises :class:`LoginInterrupted`
and nothing starts. Qt's modal loop runs in C++, where Python cannot run a signal handler, so a timer hands
control back to Python every :data:`SIGNAL_POLL_MS` while the dialog is open.
"""
from __future__ import annotations

import signal
import sys

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import (
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QFormLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from labapp.records import operators

__all__ = ["LoginDialog", "LoginInterrupted", "ask_operator"]

SIGNAL_POLL_MS = 200
"""How often the dialog's loop hands control to Python, so that a SIGINT or SIGTERM handler runs, ms."""


class LoginInterrupted(Exception):
    """The login dialog was closed by a signal (``signum``)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class LoginDialog(QDialog):
    """Choose an operator and enter their password; :attr:`operator` is set when the password is right.

    Parameters
    ----------
    simulate : bool
        Offer the built-in demo operator (the simulated bench only).
    """

    def __init__(self, simulate: bool, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("sfr lab: operator")
        self.operator: str | None = None
        users = [u.name for u in operators.load_users().values() if u.enabled]
        self.user = QComboBox()
        self.user.addItems(users)
        self.password = QLineEdit()
        self.password.setEchoMode(QLineEdit.EchoMode.Password)
        self.message = QLabel("Every recorded action (run, drop, stop, analysis, calibration, design, signature) "
                              "names the operator who did it." if users else
                              f"No operators on this machine ({operators.users_path()}). Add one in a terminal: "
                              "sfr users add NAME")
        self.message.setWordWrap(True)
        form = QFormLayout()
        form.addRow("operator", self.user)
        form.addRow("password", self.password)
        self.buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Ok | QDialogButtonBox.StandardButton.Cancel)
        self.buttons.button(QDialogButtonBox.StandardButton.Ok).setText("Log in")
        self.buttons.button(QDialogButtonBox.StandardButton.Ok).setEnabled(bool(users))
        self.buttons.accepted.connect(self.log_in)
        self.buttons.rejected.connect(self.reject)
        self.demo_button = QPushButton(f"Continue as '{operators.DEMO_OPERATOR}'")
        self.demo_button.setToolTip("the built-in operator: records only on the simulated bench and cannot sign")
        self.demo_button.setVisible(simulate)
        self.demo_button.clicked.connect(self.as_demo)
        layout = QVBoxLayout(self)
        layout.addWidget(self.message)
        layout.addLayout(form)
        layout.addWidget(self.demo_button)
        layout.addWidget(self.buttons)

    def log_in(self) -> None:
        """Check the password; accept as that operator, or say why not and stay open."""
        name = self.user.currentText()
        if not name or not operators.check_password(name, self.password.text()):
            self.message.setText(f"Wrong password for {name!r} (or the operator is disabled); try again.")
            self.password.clear()
            return
        self.operator = operators.log_in(name)
        self.accept()

    def as_demo(self) -> None:
        """Act as the built-in demo operator."""
        self.operator = operators.log_in(operators.DEMO_OPERATOR)
        self.accept()


def ask_operator(simulate: bool, parent: QWidget | None = None) -> str | None:
    """The operator of this session: the one already given (option or environment), else asked; None when the
    operator cancels (then nothing can be recorded and the GUI does not start)."""
    given = operators.current()
    if given is not None:
        return operators.log_in(given)
    dialog = LoginDialog(simulate, parent)
    received: list[int] = []

    def handle(signum: int, frame) -> None:
        received.append(signum)
        dialog.reject()
    previous = {sig: signal.signal(sig, handle) for sig in (signal.SIGINT, signal.SIGTERM)}
    timer = QTimer()
    # back to Python: a pending signal handler runs; a signal that came before the dialog's loop closes it now
    timer.timeout.connect(lambda: dialog.reject() if received else None)
    timer.start(SIGNAL_POLL_MS)
    print("sfr lab: choose the operator in the login window (Ctrl-C here quits)", file=sys.stderr, flush=True)
    try:
        accepted = dialog.exec() == QDialog.DialogCode.Accepted
    finally:
        timer.stop()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if received:
        raise LoginInterrupted(received[0])
    return dialog.operator if accepted else None
