"""The connected bench's hotplate is polled while no procedure holds it (offscreen): after Connect has closed the
devices, a change at the plate reaches the device panel and the status line within a few polls, and the readouts
are not marked stale."""
import time

import numpy as np
import pytest

pytest.importorskip("pytestqt")

from labapp.acquisition.simbench import SampleRelease
from labapp.gui.main_window import MainWindow


def _within(qtbot, condition, timeout_s: float) -> float:
    """Wait for ``condition`` (``timeout_s``: a ceiling that fails a hung test only); the wall seconds it took."""
    start = time.monotonic()
    qtbot.waitUntil(condition, timeout=int(timeout_s * 1000))
    return time.monotonic() - start


def test_the_plate_is_polled_while_connected_and_idle(qtbot, tmp_path):
    win = MainWindow(tmp_path / "runs", simulate=True, speed=20.0)   # slow enough that the bath keeps a jump
    qtbot.addWidget(win)
    win.simulated.release = SampleRelease("none", np.array([0.0, 1.0]), np.zeros(2))   # no object: the bench builds at once
    panel = win.devices
    panel.stale_after_s = 2.0                  # the test's threshold: the panel greys after 2 s without a reading
    try:
        win.connect_devices()                  # preview: connect, one frame, one reading, close the devices
        qtbot.waitUntil(lambda: win.engine.outcome == "complete" and not win.engine.running
                        and win.plate_poller.polling, timeout=120_000)
        poller, emulator, hotplate = win.plate_poller, win.simulated.bench.emulator, win.simulated.bench.hotplate
        assert poller.monitor.poll_s == pytest.approx(0.1)    # 2 s of the engine's clock at 20x
        arrived = []
        win.bridge.reading.connect(lambda reading: arrived.append(time.monotonic()))
        qtbot.wait(4000)                       # idle for twice the stale threshold
        assert len(arrived) >= 3 and not panel.stale and panel.stale_label.text() == ""
        assert panel.heater.text().startswith("HEATING OFF") and "heating OFF" in win.status.line()
        period = (arrived[-1] - arrived[0]) / (len(arrived) - 1)    # a read is seven exchanges, 0.1 s apart
        assert period < panel.stale_after_s

        before = float(panel.readouts["probe_c"].text())
        emulator.disturb_water(8.0)            # at the plate: the water is 8 C warmer
        took = _within(qtbot, lambda: float(panel.readouts["probe_c"].text()) > before + 5.0, 120.0)
        assert took < 3 * period, (took, period)

        poller.monitor.command(hotplate.set_temperature, 60.0)     # heating on and off over the link, as another
        poller.monitor.command(hotplate.start_heating)             # client of the plate would switch it
        took = _within(qtbot, lambda: panel.heater.text().startswith("HEATING ON: setpoint 60.0 C"), 120.0)
        assert took < 3 * period and "heating ON (60 C)" in win.status.line(), (took, period)
        poller.monitor.command(hotplate.stop_heating)
        took = _within(qtbot, lambda: panel.heater.text().startswith("HEATING OFF"), 120.0)
        assert took < 3 * period, (took, period)
        qtbot.wait(50)
        assert "heating OFF" in win.status.line() and not panel.stale
    finally:
        win.shutdown()
    assert not win.plate_poller.polling
