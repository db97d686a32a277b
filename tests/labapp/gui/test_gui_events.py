"""Typed engine events reach the GUI by type, and driver/engine warnings reach its event log through a
logging handler (headless)."""
import logging

from labapp.acquisition.bench import PUBLISHED
from labapp.acquisition.clock import SteppedClock
from labapp.acquisition.engine import Engine
from labapp.acquisition.events import CalibrationLevel, FrameStored, Message
from labapp.gui.bridge import EngineBridge, LogBridge


def test_bridge_routes_by_type(qtbot):
    engine = Engine(SteppedClock(start_s=10.0))
    bridge = EngineBridge(engine)
    frames, levels, messages = [], [], []
    bridge.frame.connect(frames.append)
    bridge.level.connect(levels.append)
    bridge.message.connect(lambda level, text: messages.append((level, text)))
    engine.emit(CalibrationLevel(0, "cal_000.jpg", "/x/cal_000.jpg", None, 0.25, 0.5, 1))
    engine.emit(FrameStored(3, "frame_000003.jpg", "/x/f.jpg", 33.0, 4))
    engine.emit(Message("warning", "camera busy", topic="camera-missed"))
    qtbot.waitUntil(lambda: len(messages) == 1, timeout=120_000)
    assert [f.index for f in frames] == [3] and [lv.added_mass_g for lv in levels] == [0.25]
    assert frames[0].t_unix_s == 10.0 and messages == [("warning", "camera busy")]
    bridge.detach()


def test_driver_warnings_reach_the_event_log(qtbot):
    bridge = LogBridge()
    seen = []
    bridge.message.connect(lambda level, text: seen.append((level, text)))
    try:
        logging.getLogger("drivers.hotplate.heidolph").warning("link lost on %s; reconnect 1 of 3", "/dev/ttyUSB0")
        logging.getLogger("drivers.camera.gphoto").info("not shown: below warning")
        logging.getLogger("labapp.acquisition.bench").warning("shown once, as an engine event", extra={PUBLISHED: True})
        qtbot.waitUntil(lambda: len(seen) == 1, timeout=120_000)
        assert seen == [("warning", "drivers.hotplate.heidolph: link lost on /dev/ttyUSB0; reconnect 1 of 3")]
    finally:
        bridge.detach()


def test_live_plot_smooths_with_the_analysis_window(qtbot):
    from analysis.curve import DEFAULT_ORDER, DEFAULT_WINDOW_S
    from labapp.gui.plots import PlotsPanel

    panel = PlotsPanel()
    qtbot.addWidget(panel)
    assert (panel.smooth_window_s, panel.smooth_order) == (DEFAULT_WINDOW_S, DEFAULT_ORDER)


def test_design_launcher_starts_from_the_cli_defaults_and_layout(qtbot, tmp_path):
    from design.inverse.config import DesignConfig
    from labapp.gui.design_launcher import DesignLauncher
    from labapp.jobs.design import design_folder

    launcher = DesignLauncher(tmp_path)
    qtbot.addWidget(launcher)
    cli = DesignConfig(target="sphere")                         # what `sfr design --target sphere` builds
    assert (launcher.space.currentText(), launcher.resolution.value(), launcher.max_iter.value(),
            launcher.allow_infeasible.isChecked()) == (cli.space, cli.resolution, cli.max_iter, cli.allow_infeasible)
    assert design_folder(tmp_path, "my target").parent == tmp_path / "designs"
