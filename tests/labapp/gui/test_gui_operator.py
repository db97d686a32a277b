"""What an operator expects of the bench window (offscreen): it never freezes, shows progress and marks, keeps
settings and methods, opens any run folder and a simcal.json, offers to resume interrupted runs, and says which
system library Qt lacks."""
import json
import time
from pathlib import Path

import pytest

pytest.importorskip("pytestqt")

from PySide6.QtCore import QElapsedTimer, QTimer

from labapp.acquisition.events import Message, Phase, StateChanged
from labapp.acquisition.procedures import RunConfig
from labapp.acquisition.settings import BathSettings
from labapp.gui import persist
from labapp.gui.main_window import MainWindow
from labapp.gui.plots import PlotsPanel, TimeAxis, hmm
from labapp.gui.syslibs import XCB_LIBRARIES, xcb_problem

FIXTURE_RUN = Path(__file__).resolve().parents[3] / "fixtures" / "bench" / "run"
MAX_BLOCK_MS = 100


def _window(qtbot, data_dir, **kwargs) -> MainWindow:
    win = MainWindow(data_dir, simulate=True, speed=kwargs.pop("speed", 200.0), **kwargs)
    qtbot.addWidget(win)
    win.show()
    return win


class _Latency:
    """The GUI thread's event loop ticking every 10 ms: the ticks counted and the longest gap between two, ms."""

    def __init__(self) -> None:
        self.clock, self.worst_ms, self.ticks = QElapsedTimer(), 0, 0
        self.timer = QTimer()
        self.timer.setInterval(10)
        self.timer.timeout.connect(self._tick)
        self.clock.start()
        self.timer.start()

    def _tick(self) -> None:
        self.ticks += 1
        self.worst_ms = max(self.worst_ms, self.clock.restart())


def test_connect_never_blocks_the_gui_thread(qtbot, tmp_path):
    win = _window(qtbot, tmp_path / "runs")
    try:
        qtbot.wait(200)
        latency = _Latency()
        start = time.perf_counter()
        win.connect_devices()                        # builds the simulated bench (seconds cold) in a worker thread
        called_ms = (time.perf_counter() - start) * 1000
        assert called_ms < MAX_BLOCK_MS, called_ms
        assert "connecting" in win.devices.connect_button.text()          # until the built bench arrives
        assert not win.devices.connect_button.isEnabled()
        qtbot.waitUntil(lambda: not win.building, timeout=120_000)
        build_ms = (time.perf_counter() - start) * 1000
        latency.timer.stop()
        # the event loop kept turning while the bench was built: a build on the GUI thread would leave one gap as
        # long as the build; measured against the build's own duration, so a loaded machine's slower ticks pass
        assert latency.ticks >= 5 and latency.worst_ms < 0.5 * build_ms, (latency.ticks, latency.worst_ms, build_ms)
        qtbot.waitUntil(lambda: win.live.image.image is not None and not win.engine.running, timeout=120_000)
        assert win.devices.connect_button.isEnabled() and "connecting" not in win.devices.connect_button.text()
    finally:
        win.engine.abort()
        win.engine.join(30)
        win.shutdown()


class _SlowStop:
    """A procedure that takes a while to shut down (a heater being switched off, a folder finalised)."""

    name = "slow"

    def startup(self, engine) -> None:
        pass

    def execute(self, engine) -> None:
        while not engine.should_stop():
            time.sleep(0.01)

    def shutdown(self, engine, outcome) -> None:
        time.sleep(1.0)


def test_closing_mid_procedure_says_stopping_and_closes_when_done(qtbot, tmp_path, monkeypatch):
    from labapp.gui import dialogs
    win = _window(qtbot, tmp_path / "runs")
    asked = []
    monkeypatch.setattr(dialogs, "confirm", lambda parent, q: asked.append(f"{q.question} {q.consequences}") or True)
    win._start(_SlowStop())
    start = time.perf_counter()
    assert win.close() is False                      # not yet: it stops first, without waiting here
    assert (time.perf_counter() - start) * 1000 < MAX_BLOCK_MS
    assert asked and "slow" in asked[0]
    assert "stopping" in win.statusBar().currentMessage()
    qtbot.waitUntil(lambda: not win.isVisible(), timeout=120_000)
    assert not win.engine.running


def test_plots_use_h_mm_degrees_and_show_marks_band_and_percent(qtbot):
    panel = PlotsPanel()
    qtbot.addWidget(panel)
    assert isinstance(panel.release.getAxis("bottom"), TimeAxis)
    assert panel.release.getAxis("bottom").tickStrings([0, 5400, 14400], 1, 1800) == ["0:00", "1:30", "4:00"]
    assert hmm(3725, seconds=True) == "1:02:05"
    assert "\u00b0C" in panel.temps.getAxis("left").labelText
    panel.set_setpoint_band(70.0, 0.5)
    assert panel.band.isVisible() and panel.band.getRegion() == (69.5, 70.5)
    panel.mark("drop", 0.0, "drop")
    panel.mark("gap", 600.0, "gap", end_s=900.0)
    panel.mark("fault", 1200.0, "camera")
    assert [m[0] for m in panel.marks] == ["drop", "gap", "fault"]
    assert len([i for i in panel.release.items if i.__class__.__name__ in ("InfiniteLine", "LinearRegionItem")]) == 3
    assert not panel.percent.isEnabled() and not panel.percent.isVisibleTo(panel)
    panel.set_water(500.0)
    panel.set_object_mass(2.0)
    panel.percent.setChecked(True)
    # 4 g/kg in 500 g of water is 2 g released: 100 % of a 2 g object
    assert panel.release.getAxis("right").scale == pytest.approx(0.5 / 2.0 * 100.0)
    panel.clear()
    assert panel.marks == []


def test_run_progress_and_marks_from_engine_events(qtbot, tmp_path, monkeypatch):
    win = _window(qtbot, tmp_path / "runs")
    try:
        config = RunConfig(max_duration_s=4 * 3600.0, interval_s=10.0, bath=BathSettings(setpoint_c=70.0,
                                                                                          tolerance_c=0.5))
        win.display.prepare(config)
        win.status.phase, win.status.t_s = Phase.ACQUIRING, 3600.0
        win.display.on_event(StateChanged(Phase.ACQUIRING))
        win.display.on_event(Message("info", "steady state reached at t=3600 s", topic="steady"))
        from labapp.acquisition.events import FrameStored
        for t in (0.0, 10.0, 20.0, 30.0, 500.0, 510.0):             # one gap of 470 s in 10 s frames
            win.display.on_frame(FrameStored(0, "f.jpg", str(tmp_path / "f.jpg"), t, 1, conc_g_per_kg=0.1))
        assert [m[0] for m in win.plots.marks] == ["drop", "steady", "gap"]
        assert win.plots.marks[-1][1] == 30.0
        assert win.plots.band.isVisible()
        monkeypatch.setattr(type(win.engine), "running", property(lambda self: True))
        win.display.show_progress(win.engine.running, win.procedure)
        monkeypatch.undo()
        assert win.progress.isVisibleTo(win) and win.progress.value() == 3600
        assert win.progress.format().startswith("1:00 of 4:00, 3:00 left")
    finally:
        win.shutdown()


def test_settings_persist_methods_load_and_lock(qtbot, tmp_path, monkeypatch):
    from labapp.records.operators import DEMO_OPERATOR, OPERATOR_ENV
    monkeypatch.setenv(OPERATOR_ENV, DEMO_OPERATOR)               # a method names who made it
    win = _window(qtbot, tmp_path / "runs")
    win.controls.name.setText("pill-A")
    win.controls.interval.set_stored(30.0)
    win.devices.bath_fields["setpoint_c"].set_stored(37.0)
    config = win.forms.current()
    persist.remember_run(win.settings, config, "")
    method = win.forms.save_method(str(tmp_path / "dissolution"))
    assert method.name == "dissolution.json"
    assert json.loads(method.read_text())["settings"]["setpoint_c"] == 37.0
    win.shutdown()

    again = _window(qtbot, tmp_path / "runs")                 # the next session starts where this one left off
    assert again.controls.name.text() == "pill-A"
    assert again.controls.interval.stored() == 30.0 and again.devices.bath_fields["setpoint_c"].stored() == 37.0
    again.controls.name.setText("other")
    again.devices.bath_fields["setpoint_c"].set_stored(50.0)
    assert again.forms.load_method(str(method))
    assert again.controls.name.text() == "other" and again.devices.bath_fields["setpoint_c"].stored() == 37.0
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "something else"}')
    assert not again.forms.load_method(str(bad)) and str(bad) in again.messages.toPlainText()
    again.forms.set_locked(True)
    assert again.controls.interval.isReadOnly() and again.devices.bath_fields["setpoint_c"].isReadOnly()
    assert not again.devices.connect_button.isEnabled()
    again.forms.set_locked(False)
    assert not again.controls.interval.isReadOnly()
    again.shutdown()


def test_open_any_run_folder_and_load_a_simcal(qtbot, tmp_path):
    win = _window(qtbot, tmp_path / "runs")
    try:
        win.open_run(str(FIXTURE_RUN))                       # outside the data directory, offline layout
        assert win.browser.selected_path() == FIXTURE_RUN.resolve()
        assert win.tabs.currentWidget() is win.browser and "a folder of 90 frames" in win.browser.info.text()
        assert win.browser.analysis_dir(FIXTURE_RUN.resolve()) == tmp_path / "runs" / "analyses" / "run"
        win.open_run(str(tmp_path))                           # nothing in it
        assert "not a run folder" in win.messages.toPlainText()
        win.load_simcal(str(tmp_path / "missing.json"))
        assert "missing.json" in win.messages.toPlainText()
    finally:
        win.shutdown()


def test_startup_offers_to_resume_interrupted_runs(qtbot, tmp_path):
    from labapp.records.manifests import read_run
    data = tmp_path / "runs"
    folder = data / "20261203-090000_run"
    folder.mkdir(parents=True)
    doc = {"format": 1, "kind": "run", "name": "run", "status": "interrupted", "simulated": True,
           "created_unix_s": 1.0, "files": {}, "gaps": [], "resumed": 0, "config": {}}
    (folder / "run.json").write_text(json.dumps(doc))
    from labapp.records.manifests import FRAME_COLUMNS
    (folder / "frames.csv").write_text(",".join(FRAME_COLUMNS) + "\n")
    try:
        snap = read_run(folder)
    except Exception as exc:                                  # the record layout is the storage module's
        pytest.skip(f"hand-written run record not readable: {exc}")
    if snap.status != "interrupted":
        pytest.skip(f"hand-written record reads as {snap.status}")
    win = _window(qtbot, data)
    try:
        qtbot.waitUntil(lambda: win.resume_box is not None and win.resume_box.isVisible(), timeout=120_000)
        assert "20261203-090000_run" in win.resume_box.text()
    finally:
        if win.resume_box is not None:
            win.resume_box.close()
        win.shutdown()


def test_missing_xcb_library_named_with_its_package():
    present = {name for name, _ in XCB_LIBRARIES} - {"xcb-cursor"}
    cache = "\n".join(f"\tlib{name}.so.0 (libc6,x86-64) => /usr/lib/lib{name}.so.0" for name in present)
    problem = xcb_problem({"DISPLAY": ":0"}, "linux", find=lambda name: None, ldconfig=lambda: cache)
    assert "libxcb-cursor" in problem and "libxcb-cursor0" in problem and "\n" not in problem
    assert xcb_problem({"QT_QPA_PLATFORM": "offscreen"}, "linux", find=lambda name: None, ldconfig=str) is None
    assert xcb_problem({"DISPLAY": ":0"}, "darwin", find=lambda name: None, ldconfig=str) is None
    assert "libxcb-cursor0 libxkbcommon-x11-0" in xcb_problem({"QT_QPA_PLATFORM": "xcb"}, "linux",
                                                             find=lambda name: None, ldconfig=str)
    assert xcb_problem({"DISPLAY": ":0"}, "linux", find=lambda name: name) is None
