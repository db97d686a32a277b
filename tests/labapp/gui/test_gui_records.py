"""The GUI's login and signing dialogs: a wrong password is refused, the right one acts and signs."""
import pytest

from labapp.records import operators
from labapp.records.audit import check_trail
from labapp.records.runrecord import RecordStatus
from labapp.records.storage import create_run

PASSWORD = "correct horse battery"


@pytest.fixture
def users(tmp_path, monkeypatch):
    monkeypatch.setenv(operators.USERS_ENV, str(tmp_path / "users.json"))
    monkeypatch.delenv(operators.OPERATOR_ENV, raising=False)
    operators.add_user("A. Jones", PASSWORD)
    yield
    operators.log_out()


def test_login_checks_the_password(users, qtbot):
    from labapp.gui.login import LoginDialog

    dialog = LoginDialog(simulate=False)
    qtbot.addWidget(dialog)
    assert not dialog.demo_button.isVisibleTo(dialog)
    dialog.password.setText("wrong password")
    dialog.log_in()
    assert dialog.operator is None and "Wrong password" in dialog.message.text() and operators.current() is None
    dialog.password.setText(PASSWORD)
    dialog.log_in()
    assert dialog.operator == "A. Jones" == operators.current()


def test_the_demo_operator_is_offered_on_the_simulated_bench_only(users, qtbot):
    from labapp.gui.login import LoginDialog

    dialog = LoginDialog(simulate=True)
    qtbot.addWidget(dialog)
    assert dialog.demo_button.isVisibleTo(dialog)
    dialog.as_demo()
    assert operators.current() == operators.DEMO_OPERATOR


def test_signing_refuses_a_wrong_password_then_signs(users, qtbot, tmp_path):
    from labapp.gui.signing import SignDialog

    operators.log_in("A. Jones")
    run = create_run(tmp_path / "data", "pill", {"simulated": True})
    run.finish(RecordStatus.COMPLETE)
    run.close()
    dialog = SignDialog(run.path)
    qtbot.addWidget(dialog)
    dialog.meaning.setCurrentText("reviewed")
    dialog.password.setText("wrong password")
    dialog.sign()
    assert dialog.signature is None and "wrong password" in dialog.message.text()
    dialog.password.setText(PASSWORD)
    dialog.reason.setText("checked the curve")
    dialog.sign()
    assert dialog.signature["meaning"] == "reviewed" and dialog.signature["reason"] == "checked the curve"
    assert [e["action"] for e in check_trail(run.path).entries][-2:] == ["sign-refused", "sign"]
