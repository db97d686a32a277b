"""Changing a recording run's duration from the Run tab (offscreen, a simulated run at 100x with no heating and
no object): "Change duration..." is enabled only while the run records, its dialog is prefilled and checked by
the settings' declarations and requires a reason, the change goes through ``labapp.jobs.run.change_setting``
(applied by the engine at its next frame), the audit trail names the operator and the reason, run.json holds
the new value, the progress bar counts to it and the run stops there; a change the run refuses is said."""
import numpy as np
import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication

from labapp.acquisition.simbench import SampleRelease
from labapp.gui import dialogs
from labapp.gui.main_window import MainWindow
from labapp.records.audit import check_trail
from labapp.records.manifests import read_run

INTERVAL_S = 30.0
FIRST_MAX_S, NEW_MAX_S = 360.0, 720.0          # 0.1 h, then 0.2 h: 12 frames, then 24 (3.6 s, then 7.2 s at 100x)
REASON = "the object dissolves slower than planned"


@pytest.fixture
def recording(qtbot, tmp_path, monkeypatch):
    """The main window recording a simulated run (max 0.1 h, frames every 30 s, at 100x), past its drop."""
    # a test that fails mid-run: pytest-qt closes the window before this fixture ends the run; keep it open
    monkeypatch.setattr(dialogs, "confirm", lambda parent, question: False)
    win = MainWindow(tmp_path / "runs", simulate=True, speed=100.0)
    qtbot.addWidget(win)
    win.simulated.release = SampleRelease("none", np.array([0.0, 1.0]), np.zeros(2))   # no object: the bench builds at once
    c = win.controls
    c.interval.set_stored(INTERVAL_S)
    c.max_hours.set_stored(FIRST_MAX_S)
    c.stop_on_steady.setChecked(False)
    c.auto_drop.setChecked(True)
    win.devices.bath_fields["setpoint_c"].set_stored(None)        # no heating: no wait for the bath
    assert not c.change_button.isEnabled()                        # nothing records
    assert c.start_button.isEnabled(), c.start_reason.text()
    c.start_button.click()
    try:
        qtbot.waitUntil(c.change_button.isEnabled, timeout=120_000)    # acquiring after the drop
        yield win
    finally:
        win.engine.abort()
        win.engine.join(30)
        win.shutdown()


def _drive(qtbot, act) -> None:
    """Once the change dialog is open, call ``act(dialog)``."""
    def step() -> None:
        dialog = QApplication.activeModalWidget()
        if not isinstance(dialog, dialogs.ChangeSettingsDialog):
            QTimer.singleShot(20, step)
            return
        act(dialog)
    QTimer.singleShot(0, step)


def test_the_maximum_duration_changes_during_the_run_with_a_reason(qtbot, recording, monkeypatch):
    win, c = recording, recording.controls
    told = []
    monkeypatch.setattr(dialogs, "tell", lambda parent, title, text: told.append(text))
    folder = win.procedure.run.path
    assert c.max_hours.isReadOnly() and c.interval.isReadOnly() and not c.stop_on_steady.isEnabled()  # locked
    seen = []

    def act(dialog) -> None:
        seen.append({name: box.value() for name, box in dialog.boxes.items()})
        seen.append(dialog.windowTitle())
        dialog.action_button.click()                              # nothing changed: refused
        seen.append((dialog.isVisible(), dialog.problem.text()))
        dialog.boxes["max_duration_s"].setValue(-1.0)             # out of the declared range: refused
        dialog.action_button.click()
        seen.append((dialog.isVisible(), dialog.problem.text()))
        dialog.boxes["max_duration_s"].setValue(NEW_MAX_S / 3600.0)
        dialog.action_button.click()                              # no reason: refused
        seen.append((dialog.isVisible(), dialog.problem.text()))
        qtbot.keyClicks(dialog.reason_edit, REASON)
        dialog.action_button.click()
        seen.append(dialog.isVisible())
    _drive(qtbot, act)
    c.change_button.click()
    prefilled, title, unchanged, out_of_range, no_reason, closed = seen
    assert prefilled == {"max_duration_s": 0.1, "min_duration_s": 30.0} and title == "change duration"
    assert unchanged == (True, "nothing changed: set a new value first")
    assert out_of_range == (True, "maximum duration must be > 0 h, got -1 h")
    assert no_reason == (True, "a reason is required: it is recorded in the audit trail")
    assert closed is False

    qtbot.waitUntil(lambda: "changed max_duration_s: 0.1 -> 0.2 h" in win.messages.toPlainText(), timeout=120_000)
    assert win.engine.running, "the run ended before the change was applied"      # applied at ~t = 1-2 min
    qtbot.waitUntil(lambda: win.progress.maximum() == int(NEW_MAX_S), timeout=120_000)   # at the next status tick
    assert "of 0:12" in win.progress.format(), win.progress.format()
    qtbot.waitUntil(lambda: not win.engine.running and not c.change_button.isEnabled(), timeout=120_000)
    assert win.engine.outcome == "complete" and told == []

    snap = read_run(folder)
    assert snap.status == "complete" and snap.record.config["max_duration_s"] == pytest.approx(NEW_MAX_S)
    last = snap.frames[-1].t_s
    assert NEW_MAX_S - INTERVAL_S <= last <= NEW_MAX_S + 2 * INTERVAL_S, last      # the new limit, not the first
    trail = check_trail(folder)
    assert trail.ok, trail.problems
    changes = [e for e in trail.entries if e["action"] == "change-setting"]
    assert len(changes) == 1, trail.entries
    assert (changes[0]["operator"], changes[0]["reason"]) == ("tester", REASON)
    assert changes[0]["detail"] == "max_duration_s: 0.1 -> 0.2 h"
    assert f"max_duration_s: 0.1 -> 0.2 h, by tester: {REASON}" in (folder / "events.log").read_text()


def test_a_change_the_run_refuses_is_said_and_changes_nothing(qtbot, recording, monkeypatch):
    win, c = recording, recording.controls
    told = []
    monkeypatch.setattr(dialogs, "tell", lambda parent, title, text: told.append((title, text)))
    folder = win.procedure.run.path

    def act(dialog) -> None:
        dialog.boxes["min_duration_s"].setValue(45.0)
        qtbot.keyClicks(dialog.reason_edit, REASON)
        win.engine.stop()                                         # the run ends while the dialog is open
        win.engine.join(30)
        dialog.action_button.click()
    _drive(qtbot, act)
    c.change_button.click()
    qtbot.waitUntil(lambda: bool(told), timeout=120_000)
    ((title, text),) = told
    assert title == "change refused" and "is not being recorded (stopped)" in text, text
    assert f"not changed: {text}" in win.messages.toPlainText()
    snap = read_run(folder)
    assert snap.record.config["min_duration_s"] == 1800.0 and snap.record.config["max_duration_s"] == FIRST_MAX_S
    assert not [e for e in check_trail(folder).entries if e["action"] == "change-setting"]
