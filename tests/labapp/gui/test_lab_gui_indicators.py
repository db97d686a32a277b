"""The bench window's indicators, piece by piece (offscreen): the status line and the heater's line say LINK LOST or
STALE instead of a heater state they cannot confirm, repeated warnings do not push an alarm out of the event log,
Abort looks disabled when it is, the stirring has a legend entry and an axis from zero, and Ctrl-C ends `sfr lab`
at its login dialog."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("pytestqt")

from labapp.acquisition.events import Link, Phase, Reading, StateChanged
from labapp.acquisition.status import RunStatus
from labapp.gui.device_panel import DevicePanel
from labapp.gui.event_log import EventLog
from labapp.gui.plots import PlotsPanel
from labapp.gui.run_controls import RunControls
from labapp.gui.run_display import state_of

ROOT = Path(__file__).resolve().parents[3]


def _reading(fresh_s=6.0):
    return Reading(80.0, 70.1, 150.0, 70.0, 150.0, True, True, 12.0, fresh_s=fresh_s)


def test_the_status_line_never_shows_heating_on_without_a_current_reading():
    status = RunStatus()
    status.update(StateChanged(Phase.STARTING, procedure="run"))
    status.update(StateChanged(Phase.ACQUIRING))
    status.update(_reading())
    assert "heating ON (70 C)" in status.line()
    status.update(Link(False, "hotplate link lost"))
    line = status.line()
    assert "LINK LOST since" in line and "heating ON" not in line and "unknown" in line
    assert state_of(status, running=True)[0] == "LINK LOST"
    status.update(_reading(fresh_s=0.0))                 # the link answers; this reading goes stale at once
    line = status.line()
    assert "STALE" in line and "heating ON" not in line, line
    status.update(_reading())
    assert "heating ON (70 C)" in status.line() and state_of(status, running=True)[0] == "RECORDING"


def test_each_procedure_starts_from_a_clean_status():
    status = RunStatus()
    status.update(StateChanged(Phase.STARTING, procedure="run"))
    from labapp.acquisition.events import Done, FrameStored, Message, Outcome
    status.update(FrameStored(719, "f.jpg", "/f.jpg", 9002.0, 720, conc_g_per_kg=4.173))
    status.update(Message("warning", "hotplate link lost"))
    status.update(Done(Outcome.COMPLETE))
    assert "frames 720" in status.line() and "1 warnings" in status.line()
    status.update(StateChanged(Phase.STARTING, procedure="preview"))
    assert "frames 0 " in status.line() and "warnings" not in status.line() and "t=-:--:--" in status.line()
    status.update(Done(Outcome.COMPLETE))
    assert status.line().startswith("[connected]")            # not "[done (complete)]" after a preview


def test_the_heater_line_says_link_lost_and_the_stale_text_wraps(qtbot):
    panel = DevicePanel(simulate=True)
    qtbot.addWidget(panel)
    panel.show_reading(_reading())
    assert panel.heater.text().startswith("HEATING ON")
    panel.show_link(Link(False, "hotplate link lost"))
    assert panel.heater.text().startswith("LINK LOST since") and "UNKNOWN" in panel.heater.text()
    assert "HEATING ON" not in panel.heater_text() and panel.stale
    panel.show_reading(_reading(fresh_s=0.2))
    assert panel.heater.text().startswith("HEATING ON") and not panel.stale
    qtbot.waitUntil(lambda: panel.stale, timeout=30_000)      # older than its own freshness
    assert panel.heater.text().startswith("heating UNKNOWN (reading stale)")
    assert panel.stale_label.wordWrap()                        # never wider than the dock


def test_repeated_warnings_collapse_and_keep_the_alarm_in_view(qtbot):
    log = EventLog()
    qtbot.addWidget(log)
    log.add("warning", "hotplate link lost: retrying")
    for attempt in range(1, 49):
        log.add("warning", f"drivers.hotplate.heidolph: /dev/pts/3: reconnect {attempt % 5 + 1} of 5 failed: gone")
    lines = log.toPlainText().splitlines()
    assert len(lines) == 2, lines
    assert lines[0] == "WARNING hotplate link lost: retrying"
    assert lines[1].startswith("WARNING drivers.hotplate.heidolph") and "(x48 since " in lines[1]
    log.add("error", "something else")
    log.add("info", "run ended")
    assert len(log.toPlainText().splitlines()) == 4


def test_abort_looks_disabled_when_it_is(qtbot):
    controls = RunControls(simulate=True)
    qtbot.addWidget(controls)
    controls.set_running(False)
    assert not controls.abort_button.isEnabled() and "QPushButton:disabled" in controls.abort_button.styleSheet()
    controls.show_state("RECORDING")
    assert controls.state_label.text() == "RECORDING" and "background-color" in controls.state_label.styleSheet()


def test_the_stirring_has_a_legend_entry_and_an_axis_from_zero(qtbot):
    plots = PlotsPanel()
    qtbot.addWidget(plots)
    for i in range(20):
        plots.add_reading(11.0 * i, 70.0, 69.8, 149.6 + 0.8 * (i % 2))
    plots.redraw()
    labels = [label.text for _, label in plots.temps.legend.items]
    assert any("stirring" in text for text in labels), labels
    low, high = plots.speed_view.viewRange()[1]
    assert low == 0.0 and high >= 2 * 149.6                     # noise of 0.8 rpm stays small


def test_ctrl_c_ends_sfr_lab_at_its_login_dialog(tmp_path):
    from labapp.records.operators import add_user

    add_user("A. Jones", "a-password", tmp_path / "users.json")     # operators enforced: the GUI asks who
    env = {k: v for k, v in os.environ.items() if k != "SFR_OPERATOR"}
    env.update(QT_QPA_PLATFORM="offscreen", SFR_LAB_SETTINGS=str(tmp_path / "lab.ini"),
               SFR_USERS=str(tmp_path / "users.json"))
    proc = subprocess.Popen([sys.executable, "-m", "labapp.cli.main", "lab", "--simulate", "--data",
                             str(tmp_path / "runs")], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stderr.readline()              # the dialog is up
        while line and "login window" not in line:
            line = proc.stderr.readline()
        assert "Ctrl-C here quits" in line, line
        start = time.monotonic()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, (out, err)
    assert "SIGINT: closed at the login, nothing started" in err
    assert time.monotonic() - start < 30
