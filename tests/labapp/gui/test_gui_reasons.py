"""The run browser's actions that change a record after the fact ask for the reason their audit entry carries,
as the command line's do (offscreen): Finalise requires one (``labapp.jobs.run.finalise``), Reanalyse takes one
as `sfr analyze --reason` does; and the Runs list counts the frames of a run still recording."""
import shutil
from pathlib import Path

import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication

from labapp.errors import UsageError
from labapp.gui import dialogs
from labapp.gui.run_browser import FRAMES_COLUMN, RunBrowser
from labapp.jobs.run import finalise
from labapp.records.audit import check_trail
from labapp.records.manifests import read_run
from labapp.records.storage import create_run


def _interrupted(data_dir: Path) -> Path:
    run = create_run(data_dir, "pill", {"kind": "run", "config": {}})
    run.update(writer_pid=None, writer_started=None)         # the writer is gone: interrupted
    run.close()
    return run.path


def _answer(qtbot, typed: list[str], seen: list) -> None:
    """When the reason dialog opens: press the action with each of ``typed`` in turn in the field (a refused
    empty reason keeps the dialog open); record what the dialog showed."""
    def step() -> None:
        dialog = QApplication.activeModalWidget()
        if not isinstance(dialog, dialogs.ReasonDialog):
            QTimer.singleShot(20, step)
            return
        seen.append(dialog)
        for text in typed:
            dialog.reason_edit.clear()
            qtbot.keyClicks(dialog.reason_edit, text)
            dialog.action_button.click()
            seen.append((dialog.isVisible(), dialog.problem.text()))
    QTimer.singleShot(0, step)


@pytest.fixture
def browser(qtbot, tmp_path):
    widget = RunBrowser(tmp_path / "runs")
    qtbot.addWidget(widget)
    return widget


def test_finalise_asks_for_the_reason_and_the_audit_trail_carries_it(qtbot, browser, tmp_path):
    path = _interrupted(tmp_path / "runs")
    browser.refresh()
    browser.select(path)
    seen = []
    _answer(qtbot, ["   ", "power cut overnight; sample discarded"], seen)
    browser.finalise_button.click()
    dialog, refused, accepted = seen
    assert dialog.windowTitle() == "finalise" and dialog.required
    assert refused == (True, "a reason is required: it is recorded in the audit trail")   # stays open
    assert accepted[0] is False
    assert read_run(path).status == "stopped"
    trail = check_trail(path)
    assert trail.ok, trail.problems
    assert [e["action"] for e in trail.entries] == ["start", "finalise", "stop"]
    entry = trail.entries[1]
    assert (entry["operator"], entry["reason"]) == ("tester", "power cut overnight; sample discarded")


def test_finalise_cancelled_or_without_reason_changes_nothing(qtbot, browser, tmp_path, monkeypatch):
    path = _interrupted(tmp_path / "runs")
    before = (path / "audit.jsonl").read_bytes()
    browser.refresh()
    browser.select(path)
    asked = []
    monkeypatch.setattr(dialogs, "ask_reason", lambda parent, q, required: asked.append((q, required)))
    browser.finalise_button.click()                                # Cancel: None
    assert asked[0][1] is True and asked[0][0].question == f"Finalise run {path.name} without resuming it?"
    assert read_run(path).status == "interrupted" and (path / "audit.jsonl").read_bytes() == before
    with pytest.raises(UsageError, match="needs a reason"):        # the job's own rule, whoever calls it
        finalise(path, " ")
    assert read_run(path).status == "interrupted" and (path / "audit.jsonl").read_bytes() == before


def test_reanalyse_asks_for_the_reason_as_sfr_analyze_takes_it(qtbot, browser, tmp_path, sim_calibration):
    _, cal_path = sim_calibration                      # a recorded calibration series of the simulated bench
    series = tmp_path / "runs" / cal_path.parent.name
    shutil.copytree(cal_path.parent, series)
    shutil.rmtree(series / "analysis", ignore_errors=True)
    entries = len(check_trail(series).entries)
    browser.refresh()
    browser.select(series)
    browser.calibration.setText(str(series / cal_path.name))
    seen = []
    _answer(qtbot, ["smoothing window corrected"], seen)
    browser.analyse_button.click()
    dialog, accepted = seen
    assert not dialog.required and f"{series.name}/analysis" in dialog.consequences.text()
    assert accepted[0] is False
    qtbot.waitUntil(lambda: "frames analysed" in browser.info.text(), timeout=120_000)
    trail = check_trail(series)
    assert trail.ok and len(trail.entries) == entries + 1, trail.problems
    entry = trail.entries[-1]
    assert (entry["action"], entry["operator"], entry["reason"]) == ("reanalyse", "tester",
                                                                      "smoothing window corrected")


def test_the_runs_list_counts_the_frames_of_a_run_still_recording(qtbot, browser, tmp_path):
    run = create_run(tmp_path / "runs", "pill", {"kind": "run", "config": {}})
    try:
        browser.refresh()
        browser.select(run.path)
        item = browser.tree.topLevelItem(0)
        assert item.text(FRAMES_COLUMN) == "0" and ", 0 frames," in browser.info.text()
        browser.show_frames(Path(run.path), 17)                      # what each stored frame reports
        assert item.text(FRAMES_COLUMN) == "17" and ", 17 frames," in browser.info.text()
    finally:
        run.close()


def test_each_stored_frame_updates_the_runs_list(qtbot, tmp_path):
    from labapp.acquisition.events import FrameStored
    from labapp.gui.main_window import MainWindow

    run = create_run(tmp_path / "runs", "pill", {"kind": "run", "config": {}})
    win = MainWindow(tmp_path / "runs", simulate=True, speed=200.0)
    qtbot.addWidget(win)
    try:
        item = win.browser.tree.topLevelItem(0)
        assert item.text(FRAMES_COLUMN) == "0"
        win.display.on_frame(FrameStored(41, "frame_0041.jpg", str(run.path / "frame_0041.jpg"), 451.0, 42))
        assert item.text(FRAMES_COLUMN) == "42"
    finally:
        win.shutdown()
        run.close()
