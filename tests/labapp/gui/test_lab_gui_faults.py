"""The bench window shows confirmed readings and states (offscreen, pytest-qt): faults injected through its
"Simulated bench" menu on a simulated bench at 200x, each waited for as an event."""
import dataclasses

import numpy as np
import pytest

pytest.importorskip("pytestqt")

from labapp.acquisition.events import AlarmKind, Phase
from labapp.acquisition.simbench import SampleRelease
from labapp.gui import dialogs
from labapp.gui.main_window import MainWindow
from labapp.gui.run_controls import STATE_POINT_SIZE
from labapp.records.manifests import read_run

WAIT_MS = 180_000
"""A ceiling that fails a hung test only."""


def _window(qtbot, tmp_path, monkeypatch, setpoint_c=30.0):
    """A window on a simulated bench whose object releases nothing (it builds at once), a bath heated to
    ``setpoint_c`` that counts as stable after 10 s within 2 C, and 30 s frames."""
    monkeypatch.setattr(dialogs, "confirm", lambda parent, question: True)
    win = MainWindow(tmp_path / "runs", simulate=True, speed=200.0)
    qtbot.addWidget(win)
    win.simulated.release = SampleRelease("none", np.array([0.0, 1.0]), np.zeros(2))
    bath = win.devices.bath_fields
    bath["setpoint_c"].set_stored(setpoint_c)
    bath["tolerance_c"].set_stored(2.0)
    bath["hold_s"].set_stored(10.0)
    c = win.controls
    c.interval.set_stored(30.0)
    c.max_hours.set_stored(3 * 3600.0)
    c.stop_on_steady.setChecked(False)
    win.show()
    return win


def _fault(win, text):
    """Trigger the "Simulated bench" menu's action whose text starts with ``text``."""
    menu = next(a.menu() for a in win.menuBar().actions() if a.text() == "&Simulated bench")
    (action,) = [a for a in menu.actions() if a.text().startswith(text)]
    action.trigger()


def _recording(qtbot, win):
    qtbot.waitUntil(lambda: win.status.phase == Phase.ACQUIRING and win.status.frames >= 2, timeout=WAIT_MS)


def _close(win):
    win.engine.abort()
    win.engine.join(30)
    win.shutdown()


def test_a_lost_link_is_never_shown_as_heating_on_and_its_return_is_a_banner(qtbot, tmp_path, monkeypatch):
    win = _window(qtbot, tmp_path, monkeypatch)
    try:
        win.controls.auto_drop.setChecked(True)
        win.controls.start_button.click()
        _recording(qtbot, win)
        qtbot.waitUntil(lambda: "heating ON" in win.status.line(), timeout=WAIT_MS)
        driver = win.simulated.bench.hotplate           # its reconnects back off 0.1-0.4 s instead of 0.5-8 s: the
        driver.config = dataclasses.replace(driver.config, backoff_s=0.1, backoff_max_s=0.4)   # loss comes sooner
        _fault(win, "Drop the hotplate link")
        qtbot.waitUntil(lambda: AlarmKind.LINK_FAULT in win.alarms.kinds(), timeout=WAIT_MS)
        win.refresh()
        line = win.status.line()
        assert "LINK LOST" in line and "heating ON" not in line, line
        assert win.devices.heater.text().startswith("LINK LOST") and "HEATING ON" not in win.devices.heater_text()
        assert win.controls.state_label.text() == "LINK LOST"
        assert "retrying until it answers" in win.alarms.text.text()        # what the monitor does
        win.alarms.acknowledge()
        win.refresh()
        assert win.controls.state_label.text() == "LINK LOST"          # still shown after the acknowledgement
        _fault(win, "Bring the hotplate link back")
        qtbot.waitUntil(lambda: AlarmKind.LINK_RESTORED in win.alarms.kinds(), timeout=WAIT_MS)
        assert "HOTPLATE LINK BACK" in win.alarms.text.text()
        qtbot.waitUntil(lambda: win.status.link_ok and not win.devices.stale, timeout=WAIT_MS)
        win.refresh()
        assert win.controls.state_label.text() == "RECORDING"
    finally:
        _close(win)


def test_a_new_run_starts_clean_and_shows_its_reference_before_the_drop(qtbot, tmp_path, monkeypatch):
    win = _window(qtbot, tmp_path, monkeypatch)
    try:
        win.controls.auto_drop.setChecked(True)
        win.controls.max_hours.set_stored(300.0)              # 10 frames
        win.controls.start_button.click()
        _recording(qtbot, win)
        _fault(win, "Camera busy")                            # a warning the next run must not carry
        qtbot.waitUntil(lambda: win.status.warnings >= 1, timeout=WAIT_MS)
        qtbot.waitUntil(lambda: not win.engine.running and win.controls.start_button.isEnabled(), timeout=WAIT_MS)
        first = win.procedure.run.path
        assert win.plots.bath["t_s"] and win.plots.marks
        qtbot.waitUntil(lambda: win.live.caption.text().startswith("frame_"), timeout=WAIT_MS)
        win.browser.refresh()
        win.browser.select(first)                          # a run never analysed: the Runs tab says what to do
        assert "press Reanalyse" in win.browser.info.text()

        win.controls.auto_drop.setChecked(False)
        win.controls.start_button.click()
        qtbot.waitUntil(win.controls.drop_button.isEnabled, timeout=WAIT_MS)     # waiting for the drop
        qtbot.waitUntil(lambda: win.live.caption.text().startswith("reference frame"), timeout=WAIT_MS)
        win.refresh()
        line = win.status.line()
        assert win.procedure.run.path != first
        assert "frames 0 " in line and "t=-:--:--" in line and "warnings" not in line, line
        assert win.plots.bath["t_s"] == [] and win.plots.marks == []
        assert win.live.image.image is not None                        # the reference, with the crop over it
        assert win.controls.state_label.text() == "WAITING FOR DROP"
    finally:
        _close(win)


def test_heating_and_the_drop_are_visible(qtbot, tmp_path, monkeypatch):
    win = _window(qtbot, tmp_path, monkeypatch, setpoint_c=40.0)
    try:
        win.controls.start_button.click()
        qtbot.waitUntil(lambda: win.status.phase == Phase.HEATING, timeout=WAIT_MS)
        win.refresh()
        assert win.controls.state_label.text() == "HEATING"
        assert win.controls.state_label.font().pointSize() >= STATE_POINT_SIZE
        qtbot.waitUntil(lambda: len(win.plots.heating["t_unix_s"]) >= 5, timeout=WAIT_MS)
        win.plots.redraw()
        t, plate = win.plots.plate_curve.getData()
        assert len(t) >= 5 and np.all(t[np.isfinite(t)] <= 0.0)        # drawn while heating, before time zero
        qtbot.waitUntil(win.controls.drop_button.isEnabled, timeout=WAIT_MS)
        assert "heating: bath" in win.messages.toPlainText()          # progress between "heating on" and "stable"
        qtbot.waitUntil(lambda: AlarmKind.DROP in win.alarms.kinds(), timeout=WAIT_MS)  # its own queued event
        assert win.alarms.isVisible() and win.alarms.sound.isChecked()
        assert "DROP THE OBJECT NOW" in win.alarms.text.text()
        win.refresh()
        assert win.controls.state_label.text() == "WAITING FOR DROP"
        qtbot.wait(300)                                                # ten refreshes: the banner stays
        assert AlarmKind.DROP in win.alarms.kinds()
        win.controls.drop_button.click()
        _recording(qtbot, win)
        win.refresh()
        assert AlarmKind.DROP not in win.alarms.kinds() and win.controls.state_label.text() == "RECORDING"
        win.plots.redraw()
        t, plate = win.plots.plate_curve.getData()
        assert np.nanmin(t) < 0.0 < np.nanmax(t)                       # the heating before the drop, frames after
    finally:
        _close(win)


def test_a_resumed_run_shows_its_whole_history_with_the_gap(qtbot, tmp_path, monkeypatch):
    win = _window(qtbot, tmp_path, monkeypatch, setpoint_c=45.0)
    try:
        win.controls.auto_drop.setChecked(True)
        win.controls.start_button.click()
        qtbot.waitUntil(lambda: win.status.frames >= 6, timeout=WAIT_MS)
        folder = win.procedure.run.path
        win.engine.interrupt()
        qtbot.waitUntil(lambda: not win.engine.running and win.controls.start_button.isEnabled(), timeout=WAIT_MS)
        before = len(read_run(folder).frames)
        win.resume_run(str(folder))
        qtbot.waitUntil(lambda: win.status.phase == Phase.ACQUIRING and len(win.plots.bath["t_s"]) > before,
                        timeout=WAIT_MS)
        kinds = [kind for kind, _, _ in win.plots.marks]
        assert "gap" in kinds and "resume" in kinds and "drop" not in kinds, win.plots.marks
        stored = [f.t_s for f in read_run(folder).frames][:before]
        assert np.allclose(win.plots.bath["t_s"][:before], stored)      # the history from the first frame on
        (_, gap_start, _) = next(m for m in win.plots.marks if m[0] == "gap")
        assert gap_start == pytest.approx(stored[-1])
        events = (folder / "events.log").read_text()
        assert "resumed with the bath at" in events and "capture goes on at once" in events
    finally:
        _close(win)


def test_a_corrupt_frame_is_marked_on_the_plots(qtbot, tmp_path, monkeypatch, sim_calibration):
    win = _window(qtbot, tmp_path, monkeypatch)
    try:
        win.controls.calibration.setText(str(sim_calibration[1]))
        win.controls.auto_drop.setChecked(True)
        win.controls.start_button.click()
        _recording(qtbot, win)
        _fault(win, "Corrupt frame")
        qtbot.waitUntil(lambda: any(kind == "fault" for kind, _, _ in win.plots.marks), timeout=WAIT_MS)
        # the log line comes through the logging handler's own queued signal, not with the mark
        qtbot.waitUntil(lambda: "could not analyse" in win.messages.toPlainText(), timeout=WAIT_MS)
    finally:
        _close(win)
