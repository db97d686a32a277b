"""The GUI, offscreen: a full simulated run driven through the main window (pytest-qt)."""
import shutil
from pathlib import Path

import numpy as np

from labapp.gui.live_view import grid_segments, mirrored_x
from labapp.gui.main_window import MainWindow
from labapp.storage import read_run, verify_run

FIGURES = Path(__file__).resolve().parents[2] / "docs" / "figures"


def test_full_simulated_run_through_the_gui(qtbot, tmp_path, sim_calibration):
    _, cal_path = sim_calibration
    win = MainWindow(tmp_path / "runs", simulate=True, speed=200.0, sample="sphere")
    qtbot.addWidget(win)
    win.resize(1500, 950)
    win.show()
    try:
        win.connect_devices()                                     # connect: one preview frame and one reading
        qtbot.waitUntil(lambda: win.engine.outcome == "complete" and not win.engine.running, timeout=60_000)
        assert win.live.image.image is not None and win.devices.readouts["plate_c"].text() != "-"

        win.controls.calibration.setText(str(cal_path))
        win.controls.max_hours.setValue(2.0)
        win.controls.stop_on_steady.setChecked(False)
        win.controls.start_button.click()
        qtbot.waitUntil(win.controls.drop_button.isEnabled, timeout=120_000)   # bath stable, reference taken
        assert win.status.phase.startswith("waiting")
        win.controls.drop_button.click()
        qtbot.waitUntil(lambda: len(win.plots.t_s) >= 25, timeout=120_000)
        win.controls.stop_button.click()
        qtbot.waitUntil(lambda: not win.engine.running, timeout=60_000)
        assert win.engine.outcome == "stopped"

        folder = win.procedure.run.path
        snap = read_run(folder)
        assert snap.status == "stopped" and len(snap.frames) >= 25 and verify_run(folder).ok
        assert (folder / "reference.jpg").is_file() and snap.meta["object_name"] == ""
        qtbot.waitUntil(lambda: len(win.plots.t_s) == len(snap.frames), timeout=10_000)   # queued events
        win.plots.redraw()
        t_plot, conc_plot = win.plots.raw_curve.getData()
        assert np.allclose(t_plot, [f.t_s for f in snap.frames], atol=1e-3), (t_plot, snap.frames)  # all plotted
        assert conc_plot[-1] > conc_plot[0] + 0.1                         # the object is dissolving
        assert len(win.plots.smooth_curve.getData()[0]) == len(t_plot)
        qtbot.waitUntil(lambda: win.live.caption.text().startswith("frame_"), timeout=10_000)
        win.refresh()
        shot = tmp_path / "lab_gui_run.png"
        assert win.grab().save(str(shot))
        FIGURES.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(shot, FIGURES / "lab_gui_run.png")

        win.browser.refresh()
        win.browser.select(folder)
        assert win.browser.selected_path() == folder and "stopped" in win.browser.info.text()
    finally:
        win.engine.abort()
        win.engine.join(30)
        win.shutdown()


def test_crop_overlay_geometry():
    xs, ys = grid_segments(10, 20, 100, 10)
    assert len(xs) == 4 * 11 and xs.min() == 10 and xs.max() == 110 and ys.max() == 120
    assert mirrored_x(100, 50, 300) == 450                       # the square mirrored across column 300
