"""Headless soak: a simulated 4-hour run through the main window on the instant clock, with a camera fault, a
hotplate link fault and a temperature excursion injected. Each raises its alarm in the banner and a mark on
the plots, the run completes, its folder verifies, and the heater ends off (panel, status bar, emulator)."""
import threading

import pytest

pytest.importorskip("pytestqt")

from labapp.acquisition.events import Alarm, AlarmKind, FrameStored
from labapp.gui.main_window import MainWindow
from labapp.records.manifests import read_run
from labapp.records.verification import verify_run

HOURS = 4
INTERVAL_S = 120.0         # 120 frames
INJECT = {10: "camera", 30: "link", 60: "excursion"}
"""Frame index after which each fault is injected."""
COLD_FRAMES = 12
"""Cold water keeps coming for at least this many frames (24 min) after the excursion starts, and on until the
excursion's alarm is raised, each frame until then waiting up to 0.5 wall seconds for it: the plate's monitor
polls on the wall clock, so at an unbounded clock speed a dip could otherwise fall between two of its readings."""


@pytest.mark.slow
def test_four_hours_with_faults_through_the_gui(qtbot, tmp_path, sim_calibration):
    _, cal_path = sim_calibration
    win = MainWindow(tmp_path / "runs", simulate=True, speed=float("inf"), sample="sphere")
    qtbot.addWidget(win)
    win.show()
    injected = []
    excursion_raised = threading.Event()

    def inject(event) -> None:                     # in the engine's thread, as a fault would come
        if isinstance(event, Alarm) and event.kind == AlarmKind.TEMPERATURE_EXCURSION:
            excursion_raised.set()
        if not isinstance(event, FrameStored):
            return
        if INJECT[60] in injected and (event.index < 60 + COLD_FRAMES or not excursion_raised.is_set()):
            win.simulated.bench.cool_bath(6.0)    # more cold water: the bath stays below the band
            if not excursion_raised.is_set():     # and the next frame waits up to 0.5 s for the monitor's poll
                excursion_raised.wait(0.5)
        if event.index not in INJECT:
            return
        what = INJECT[event.index]
        injected.append(what)
        if what == "camera":
            win.simulated.bench.camera_busy(2)
        elif what == "link":
            win.simulated.bench.drop_hotplate_link(900.0)     # s on the emulator's clock (the engine's here)
        else:
            win.simulated.bench.cool_bath(6.0)    # cold water: 6 C below the setpoint, the plate heats it back
    win.engine.subscribe(inject)
    try:
        c = win.controls
        c.calibration.setText(str(cal_path))
        c.interval.set_stored(INTERVAL_S)
        c.max_hours.set_stored(HOURS * 3600.0)
        c.stop_on_steady.setChecked(False)
        c.auto_drop.setChecked(True)
        win.devices.bath_fields["excursion_c"].set_stored(2.0)
        assert c.start_button.isEnabled(), c.start_reason.text()
        c.start_button.click()
        qtbot.waitUntil(lambda: win.engine.outcome is not None and not win.engine.running
                        and not c.stop_button.isEnabled(), timeout=150_000)
        folder = win.procedure.run.path
        assert win.engine.outcome == "complete", win.messages.toPlainText()[-3000:]
        assert injected == ["camera", "link", "excursion"]

        kinds = set(win.alarms.kinds())
        assert {AlarmKind.CAMERA_FAULT, AlarmKind.LINK_FAULT, AlarmKind.TEMPERATURE_EXCURSION} <= kinds, kinds
        assert AlarmKind.REFERENCE_OFFSET not in kinds                  # a fresh beaker: clear water
        assert win.alarms.isVisible() and "TEMPERATURE EXCURSION" in win.alarms.text.text()
        marked = {kind for kind, _, _ in win.plots.marks}
        assert {"alarm", "excursion"} <= marked, win.plots.marks

        snap = read_run(folder)
        assert snap.status == "complete" and verify_run(folder).ok
        assert snap.frames[-1].t_s >= HOURS * 3600 - INTERVAL_S and len(snap.frames) >= HOURS * 3600 / INTERVAL_S - 3
        assert snap.record.config["excursion_c"] == 2.0 and snap.meta["object_mass_g"] is None   # not weighed
        events = (folder / "events.log").read_text()
        for text in ("capture failed: simulated camera busy", "outside the setpoint 70 +/- 2 C",
                     "heating and stirring switched off"):
            assert text in events, text
        # the monitor sees the link lost, or the driver reconnects by itself first: a link fault either way
        assert "hotplate link lost" in events or "hotplate link dropped and re-established" in events

        # the heater ends off: the last reading says so in the panel and the status bar, and the plate agrees
        qtbot.waitUntil(lambda: win.devices.heater.text().startswith("HEATING OFF"), timeout=120_000)
        assert "heating OFF" in win.status.line()
        assert not win.simulated.bench.emulator.state.heating
        win.alarms.acknowledge()
        assert win.alarms.isHidden()
    finally:
        win.engine.abort()
        win.engine.join(30)
        win.shutdown()
