"""Safety in the bench GUI (offscreen): final actions ask first and say what cannot be undone, Abort is kept apart
from Stop, fields refuse what is out of range instead of clamping it, Start says why it is disabled, the
heater's state is shown and never stale without saying so, and alarms stay until acknowledged."""
import logging
import threading
import time

import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication, QMessageBox

from labapp.acquisition.engine import Engine
from labapp.acquisition.events import Alarm, AlarmKind, Outcome, Phase, Reading, StateChanged
from labapp.acquisition.settings import OBJECT_MASS, STIRRING
from labapp.acquisition.status import RunStatus
from labapp.gui import dialogs
from labapp.gui.alarms import AlarmBanner
from labapp.gui.bridge import LogBridge
from labapp.gui.device_panel import DevicePanel
from labapp.gui.fields import SettingBox
from labapp.gui.main_window import MainWindow
from labapp.gui.run_controls import NO_CALIBRATION_STEADY, RunControls


class Asked:
    """Stands in for :func:`labapp.gui.dialogs.confirm`: records each question, answers ``answer``."""

    def __init__(self, answer: bool) -> None:
        self.answer, self.questions = answer, []

    def __call__(self, parent, question):
        self.questions.append(question)
        return self.answer


def _type(qtbot, box, text):
    box.lineEdit().selectAll()
    qtbot.keyClicks(box.lineEdit(), text)
    box.interpretText()


def test_stop_and_abort_ask_first_naming_the_run_and_abort_is_apart(qtbot, monkeypatch):
    controls = RunControls(simulate=True)
    qtbot.addWidget(controls)
    controls.show()
    controls.follow(StateChanged(Phase.STARTING, procedure="run"))
    controls.follow(StateChanged(Phase.OPENED, folder="/data/runs/20261203-101500_pill"))
    controls.set_running(True)
    stops, aborts = [], []
    controls.stop_requested.connect(lambda: stops.append(1))
    controls.abort_requested.connect(lambda: aborts.append(1))
    no = Asked(False)
    monkeypatch.setattr(dialogs, "confirm", no)
    controls.stop_button.click()
    controls.abort_button.click()
    assert stops == [] and aborts == []                         # declined: nothing happens
    stop_q, abort_q = no.questions
    assert stop_q.question == "Stop run 20261203-101500_pill?" and "'stopped'" in stop_q.consequences
    assert "cannot be resumed" in stop_q.consequences and stop_q.safe == dialogs.KEEP_RUNNING
    assert abort_q.question == "Abort run 20261203-101500_pill?" and "'aborted'" in abort_q.consequences
    assert "cannot be resumed" in abort_q.consequences
    monkeypatch.setattr(dialogs, "confirm", Asked(True))
    controls.stop_button.click()
    controls.abort_button.click()
    assert stops == [1] and aborts == [1]
    # Abort: another look, in its own box at the far end, not beside Stop
    assert controls.abort_button.styleSheet() and not controls.stop_button.styleSheet()
    assert controls.abort_button.parentWidget() is not controls.stop_button.parentWidget()
    gap = controls.abort_button.mapTo(controls, controls.abort_button.rect().topLeft()).y() - \
        controls.stop_button.mapTo(controls, controls.stop_button.rect().bottomLeft()).y()
    assert gap > 40, gap


def test_the_confirmation_box_defaults_to_the_safe_choice(qtbot):
    seen = {}

    def answer():
        box = QApplication.activeModalWidget()
        assert isinstance(box, QMessageBox)
        seen["default"], seen["escape"] = box.defaultButton().text(), box.escapeButton().text()
        seen["text"] = box.text() + "\n" + box.informativeText()
        box.defaultButton().click()                                # Enter: the safe choice
    QTimer.singleShot(50, answer)
    assert dialogs.confirm(None, dialogs.abort_question("run", "pill")) is False
    assert seen["default"] == seen["escape"] == "Keep running"
    assert seen["text"].startswith("Abort run pill?") and "cannot be resumed" in seen["text"]


def _idle_procedure():
    class Waits:
        name = "run"
        run = None

        def startup(self, engine):
            pass

        def execute(self, engine):
            while not engine.should_stop():
                time.sleep(0.01)

        def shutdown(self, engine, outcome):
            pass
    return Waits()


def test_closing_mid_run_asks_and_interrupts_the_run_resumably(qtbot, tmp_path, monkeypatch):
    win = MainWindow(tmp_path / "runs", simulate=True, speed=200.0)
    qtbot.addWidget(win)
    win.show()
    try:
        assert win._start(_idle_procedure())
        no = Asked(False)
        monkeypatch.setattr(dialogs, "confirm", no)
        win.close()
        assert win.isVisible() and win.engine.running            # kept running
        (question,) = no.questions
        assert question.safe == dialogs.KEEP_RUNNING
        assert "the run is interrupted: heating and stirring are switched off and the run is left 'interrupted'" \
            in question.consequences and "Resume acquisition" in question.consequences
        monkeypatch.setattr(dialogs, "confirm", Asked(True))
        win.close()
        qtbot.waitUntil(lambda: not win.engine.running, timeout=120_000)
        assert win.engine.outcome == Outcome.INTERRUPTED
        qtbot.waitUntil(lambda: not win.isVisible(), timeout=120_000)
    finally:
        win.engine.abort()
        win.engine.join(10)
        win.shutdown()


def test_closing_names_a_running_design_and_sweep_and_the_launcher_stops_both(qtbot, tmp_path, monkeypatch):
    win = MainWindow(tmp_path / "runs", simulate=True, speed=200.0)
    qtbot.addWidget(win)
    launcher, sweep = win.design, win.design.sweep
    try:
        assert win.busy_work() == []
        with monkeypatch.context() as m:                  # undone before the window is closed at teardown
            m.setattr(type(launcher), "busy", property(lambda self: True))
            m.setattr(type(sweep), "busy", property(lambda self: True))
            launcher.out_dir, sweep.sweep_dir = tmp_path / "design-a", tmp_path / "sweep-b"
            design_work, sweep_work = win.busy_work()
            stopped = []
            m.setattr(type(launcher), "stop", lambda self: stopped.append("design"))
            m.setattr(type(sweep), "stop", lambda self: stopped.append("sweep"))
            launcher.stop_all()
        assert "the design in" in design_work and "design-a" in design_work and "Resume..." in design_work
        assert "the sweep in" in sweep_work and "sweep-b" in sweep_work
        assert stopped == ["design", "sweep"]
        assert win.busy_work() == []
    finally:
        win.shutdown()


def test_finalise_asks_first(qtbot, tmp_path, monkeypatch):
    from labapp.records.manifests import read_run
    from labapp.records.storage import create_run

    run = create_run(tmp_path / "runs", "pill", {"kind": "run", "config": {}})
    run.update(writer_pid=None, writer_started=None)         # the writer is gone: interrupted
    run.close()
    win = MainWindow(tmp_path / "runs", simulate=True, speed=200.0)
    qtbot.addWidget(win)
    try:
        win.browser.refresh()
        win.browser.select(run.path)
        no = Asked(None)
        monkeypatch.setattr(dialogs, "ask_reason", lambda parent, q, required: no(parent, q))
        win.browser.finalise_button.click()
        assert read_run(run.path).status == "interrupted"
        assert no.questions[0].question == f"Finalise run {run.path.name} without resuming it?"
        assert "can no longer be resumed" in no.questions[0].consequences and no.questions[0].safe == "Cancel"
        monkeypatch.setattr(dialogs, "ask_reason", lambda parent, q, required: "sample lost")
        win.browser.finalise_button.click()
        assert read_run(run.path).status == "stopped"
    finally:
        win.shutdown()


def test_fields_refuse_out_of_range_values_in_the_field(qtbot):
    panel = DevicePanel(simulate=True)
    qtbot.addWidget(panel)
    panel.show()
    setpoint, rpm = panel.bath_fields["setpoint_c"], panel.bath_fields["speed_rpm"]
    _type(qtbot, setpoint, "-20")
    assert setpoint.value() == -20.0                                     # kept as typed, not -0.0
    assert setpoint.problem() == "bath temperature must be in [25, 100] C, got -20 C"
    assert setpoint.error_label.isVisible() and "-20" in setpoint.toolTip() and setpoint.styleSheet()
    _type(qtbot, setpoint, "20")                                         # below room temperature
    assert "must be in [25, 100] C, got 20 C" in setpoint.problem()
    _type(qtbot, rpm, "3000")
    assert rpm.value() == 3000.0 and rpm.problem() == f"stirring speed must be in [0, {STIRRING.high:g}] rpm, got 3000 rpm"
    assert STIRRING.high == 600                                          # the driver's own limit
    assert len(panel.problems()) == 2
    setpoint.set_stored(None)                                            # the explicit choice: no heating
    assert setpoint.text() == "no heating" and setpoint.problem() == ""
    _type(qtbot, rpm, "150")
    assert panel.problems() == [] and panel.bath().setpoint_c is None and not setpoint.error_label.isVisible()


def test_start_is_disabled_with_the_reason(qtbot, tmp_path):
    controls = RunControls(simulate=True)
    qtbot.addWidget(controls)
    panel = DevicePanel(simulate=True)
    qtbot.addWidget(panel)
    controls.watch(panel.bath_fields)
    controls.show()
    assert controls.stop_on_steady.isChecked() and controls.calibration.text() == ""
    assert not controls.start_button.isEnabled() and NO_CALIBRATION_STEADY in controls.start_reason.text()
    controls.stop_on_steady.setChecked(False)
    assert controls.start_button.isEnabled() and not controls.start_reason.isVisible()
    _type(qtbot, panel.bath_fields["setpoint_c"], "-20")
    assert not controls.start_button.isEnabled()
    assert "bath temperature must be in [25, 100] C, got -20 C" in controls.start_reason.text()
    _type(qtbot, panel.bath_fields["setpoint_c"], "70")
    _type(qtbot, controls.interval, "0")
    assert "frame interval must be > 0 s" in controls.start_reason.text()
    _type(qtbot, controls.interval, "11")
    controls.calibration.setText(str(tmp_path / "missing.json"))
    assert "does not exist" in controls.start_reason.text()
    controls.calibration.setText("")
    assert controls.start_button.isEnabled()
    assert "leaves 70 +/- 2 C" in controls.band_label.text()           # the run settings say the alarm band
    # the object's mass: "not weighed" unless entered, recorded as None (no mass)
    assert controls.object_mass.text() == "not weighed" and OBJECT_MASS.default is None
    assert controls.config(panel.bath()).object_mass_g is None
    controls.object_mass.stepBy(1)
    assert controls.object_mass.stored() == pytest.approx(0.0001) and controls.object_mass.problem() == ""
    controls.object_mass.stepBy(-1)
    assert controls.object_mass.stored() is None


def _reading(heating, t=0.0):
    return Reading(80.0 if heating else 45.0, 70.1 if heating else 44.0, 150.0 if heating else 0.0, 70.0, 150.0,
                   heating, heating, t_unix_s=t)


def test_the_heater_state_is_prominent_and_goes_stale(qtbot):
    panel = DevicePanel(simulate=True)
    qtbot.addWidget(panel)
    panel.stale_after_s = 0.3
    panel.show_reading(_reading(True))
    assert panel.heater.text() == "HEATING ON: setpoint 70.0 C, bath 70.1 C, stirring 150 rpm" and not panel.stale
    panel.show_reading(_reading(False))                 # the run ended: heating switched off
    assert panel.heater.text() == "HEATING OFF: bath 44.0 C, stirring off" and not panel.stale
    qtbot.waitUntil(lambda: panel.stale, timeout=120_000)
    assert panel.stale_label.text().startswith("stale since ") and "no reading for more than 0.3 s" in \
        panel.stale_label.text()
    assert "stale since" in panel.heater_text() and panel.readouts["plate_c"].styleSheet()
    panel.show_reading(_reading(False))
    assert not panel.stale and panel.stale_label.text() == "" and not panel.readouts["plate_c"].styleSheet()
    status = RunStatus()
    status.update(_reading(True))
    assert "heating ON (70 C)" in status.line()
    status.update(_reading(False))
    assert status.line().endswith("0 rpm heating OFF")


def test_an_alarm_stays_until_acknowledged_with_a_mark_and_a_beep_by_default(qtbot, monkeypatch):
    marks = []

    class Plots:
        def mark(self, kind, t_s, text="", end_s=None):
            marks.append((kind, t_s, text))
    banner = AlarmBanner(Plots())
    qtbot.addWidget(banner)
    beeps = []
    monkeypatch.setattr(QApplication, "beep", staticmethod(lambda: beeps.append(1)))
    assert banner.isHidden() and banner.sound.isChecked()               # sound on by default
    banner.sound.setChecked(False)
    banner.raise_alarm(Alarm(AlarmKind.TEMPERATURE_EXCURSION, "bath at 64.8 C, outside the setpoint 70 +/- 2 C", 600.0))
    banner.raise_alarm(Alarm(AlarmKind.HEAT_TIMEOUT, "the bath did not hold 70 +/- 0.5 C"))
    assert not banner.isHidden() and beeps == []
    assert "2 alarms to acknowledge" in banner.text.text() and "TEMPERATURE EXCURSION: bath at 64.8 C" in banner.text.text()
    assert marks == [("excursion", 600.0, "temperature excursion")]     # the heat timeout has no time since the drop
    banner.sound.setChecked(True)
    banner.raise_alarm(Alarm(AlarmKind.CAMERA_FAULT, "frame missed", 660.0))
    assert beeps == [1] and banner.kinds()[-1] == AlarmKind.CAMERA_FAULT
    banner.acknowledge()
    assert banner.isHidden() and banner.pending == [] and len(banner.history) == 3


def test_alarms_reach_the_window_from_the_engine(qtbot, tmp_path):
    win = MainWindow(tmp_path / "runs", simulate=True, speed=200.0)
    qtbot.addWidget(win)
    win.show()
    try:
        threading.Thread(target=win.engine.emit, args=(Alarm(AlarmKind.LINK_FAULT, "hotplate link lost", 120.0),)).start()
        qtbot.waitUntil(lambda: win.alarms.kinds() == [AlarmKind.LINK_FAULT], timeout=120_000)
        assert win.alarms.isVisible() and ("alarm", 120.0, "hotplate link fault") in win.plots.marks
    finally:
        win.shutdown()


def test_analysis_warnings_reach_the_event_log_with_their_text(qtbot):
    bridge = LogBridge()
    seen = []
    bridge.message.connect(lambda level, text: seen.append((level, text)))
    try:
        logging.getLogger("analysis.runfolder").warning("the reference frame reads +3.9 g/kg on the zero level")
        qtbot.waitUntil(lambda: len(seen) == 1, timeout=120_000)
        assert seen == [("warning", "analysis.runfolder: the reference frame reads +3.9 g/kg on the zero level")]
    finally:
        bridge.detach()


def test_setting_boxes_keep_what_is_typed(qtbot):
    box = SettingBox(STIRRING)
    qtbot.addWidget(box)
    _type(qtbot, box, "1400")
    assert box.value() == 1400 and "got 1400 rpm" in box.problem()
    engine = Engine()
    assert engine.stop_reason == ""


def test_the_wizard_redoes_the_last_level_and_refuses_a_negative_mass(qtbot, tmp_path):
    from labapp.acquisition.calseries import RedoLevel
    from labapp.acquisition.events import PromptKind

    win = MainWindow(tmp_path / "runs", simulate=True, speed=200.0)
    qtbot.addWidget(win)
    try:
        win.wizard.set_asking(True, "enter the cumulative mass")
        assert win.wizard.redo_button.isEnabled() and win.wizard.capture_button.isEnabled()
        _type(qtbot, win.wizard.mass, "-0.5")
        assert not win.wizard.capture_button.isEnabled() and "must be >= 0 g" in win.wizard.mass.problem()
        win.wizard.redo_button.click()
        assert isinstance(win.engine._answers[PromptKind.ADDED_MASS], RedoLevel)
        assert not win.wizard.redo_button.isEnabled()              # until the series asks again
    finally:
        win.shutdown()
