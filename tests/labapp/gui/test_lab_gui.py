"""The GUI, offscreen: a full simulated run driven through the main window (pytest-qt)."""
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from labapp.gui import dialogs
from labapp.gui.live_view import grid_segments, mirrored_x
from labapp.gui.main_window import MainWindow
from labapp.records.manifests import read_run
from labapp.records.verification import verify_run

FIGURES = Path(__file__).resolve().parents[3] / "docs" / "figures"


@pytest.mark.slow
def test_full_simulated_run_through_the_gui(qtbot, tmp_path, sim_calibration, monkeypatch):
    _, cal_path = sim_calibration
    monkeypatch.setattr(dialogs, "confirm", lambda parent, question: True)     # Stop: the operator confirms
    win = MainWindow(tmp_path / "runs", simulate=True, speed=200.0, sample="sphere")
    qtbot.addWidget(win)
    win.resize(1500, 950)
    win.show()
    try:
        win.connect_devices()                                     # connect: one preview frame and one reading
        # the window hears of the end through a queued signal, after the engine's own state changes; the first
        # Connect computes the sample's dissolution in a child process (40 s on a loaded 2-core machine)
        qtbot.waitUntil(lambda: win.engine.outcome == "complete" and not win.engine.running
                        and not win.controls.stop_button.isEnabled(), timeout=180_000)
        # no calibration yet and "stop at steady state" ticked: Start says why it is disabled
        assert not win.controls.start_button.isEnabled() and "needs a bench calibration" in \
            win.controls.start_reason.text()
        assert win.live.image.image is not None and win.devices.readouts["plate_c"].text() != "-"

        win.controls.calibration.setText(str(cal_path))
        win.controls.max_hours.setValue(48.0)  # 864 s at 200x: the test, not the clock, ends the run
        win.controls.stop_on_steady.setChecked(False)
        assert win.controls.start_button.isEnabled()
        win.controls.start_button.click()
        try:
            qtbot.waitUntil(win.controls.drop_button.isEnabled, timeout=120_000)   # bath stable, reference taken
        except Exception:
            raise AssertionError(_diagnosis(win)) from None
        assert win.status.phase.startswith("waiting")
        win.controls.drop_button.click()
        # until the curve has risen: the simulated print wets for up to 10 min before it dissolves (its hidden
        # wetting lag), and how many frames that takes depends on the print, not on the test
        qtbot.waitUntil(lambda: _risen(win.plots.conc, RISE_G_PER_KG) or not win.engine.running, timeout=300_000)
        assert _risen(win.plots.conc, RISE_G_PER_KG), _diagnosis(win)
        win.controls.stop_button.click()
        qtbot.waitUntil(lambda: not win.engine.running, timeout=120_000)
        assert win.engine.outcome == "stopped"

        folder = win.procedure.run.path
        snap = read_run(folder)
        assert snap.status == "stopped" and len(snap.frames) >= 2 and verify_run(folder).ok
        assert (folder / "reference.jpg").is_file() and snap.meta["object_name"] == ""
        qtbot.waitUntil(lambda: len(win.plots.t_s) == len(snap.frames), timeout=120_000)   # queued events
        win.plots.redraw()
        t_plot, conc_plot = win.plots.raw_curve.getData()
        assert np.allclose(t_plot, [f.t_s for f in snap.frames], atol=1e-3), (t_plot, snap.frames)  # all plotted
        assert conc_plot[-1] > conc_plot[0] + 0.1      # dissolving: the frames after the Stop keep the rise
        assert len(win.plots.smooth_curve.getData()[0]) == len(t_plot)
        t_bath, plate = win.plots.plate_curve.getData()                   # the bath logged with every frame,
        assert np.all(t_bath[:-len(t_plot)][np.isfinite(t_bath[:-len(t_plot)])] <= 0.0)   # after its heating
        assert np.allclose(t_bath[-len(t_plot):], t_plot, atol=1e-3)
        stored = np.array([np.nan if f.plate_c is None else f.plate_c for f in snap.frames])
        assert np.allclose(plate[-len(t_plot):], stored, atol=1e-6, equal_nan=True)
        speeds = [f.speed_rpm for f in snap.frames if f.speed_rpm is not None]
        assert speeds and min(speeds) >= 0.95 * 150                     # stirred before the reference frame
        qtbot.waitUntil(lambda: win.live.caption.text().startswith("frame_"), timeout=120_000)
        win.refresh()
        shot = tmp_path / "lab_gui_run.png"
        assert win.grab().save(str(shot))
        assert shot.stat().st_size > 10_000
        if os.environ.get("SFR_FIGURES"):                  # refresh the docs picture on request only
            shutil.copyfile(shot, FIGURES / "lab_gui_run.png")

        win.browser.refresh()
        win.browser.select(folder)
        assert win.browser.selected_path() == folder and "stopped" in win.browser.info.text()
    finally:
        win.engine.abort()
        win.engine.join(30)
        win.shutdown()


RISE_G_PER_KG = 0.15
"""How far the measured curve has risen when the test presses Stop, g/kg: above the 0.1 g/kg it then asserts, by
more than the measurement's noise."""


def _risen(conc: list[float], by: float) -> bool:
    """True once the last concentration is ``by`` above the first (the object is dissolving)."""
    return len(conc) >= 2 and conc[-1] > conc[0] + by


def _diagnosis(win: MainWindow) -> str:
    """What the window and the run folder say, for a run that did not get far enough."""
    run = win.procedure.run if win.procedure is not None else None
    stored = len(read_run(run.path).frames) if run is not None else 0
    return (f"{len(win.plots.t_s)} frames plotted, {stored} stored; engine outcome {win.engine.outcome!r}; "
            f"status {win.status.line()}\n{win.messages.toPlainText()}")


def test_crop_overlay_geometry():
    xs, ys = grid_segments(10, 20, 100, 10)
    assert len(xs) == 4 * 11 and xs.min() == 10 and xs.max() == 110 and ys.max() == 120
    assert mirrored_x(100, 50, 300) == 450                       # the square mirrored across column 300


@pytest.mark.slow  # a whole series, its fit, a reanalysis and a design through the GUI: over 30 s
def test_calibration_wizard_reanalysis_and_design_launcher(qtbot, tmp_path, monkeypatch):
    win = MainWindow(tmp_path / "data", simulate=True, speed=float("inf"), sample="sphere")
    qtbot.addWidget(win)
    try:
        win.wizard.masses.setText("")                         # the operator enters every mass
        win.wizard.start_button.click()
        # the first start builds the simulated bench: its object's dissolution is computed in a child process
        qtbot.waitUntil(lambda: win.simulated.bench is not None, timeout=120_000)
        for mass in (0.25, 0.75, 1.5):
            qtbot.waitUntil(win.wizard.capture_button.isEnabled, timeout=120_000)
            win.wizard.mass.setValue(mass)
            win.wizard.capture_button.click()
        qtbot.waitUntil(win.wizard.capture_button.isEnabled, timeout=120_000)
        win.wizard.finish_button.click()
        qtbot.waitUntil(lambda: "calibration saved" in win.wizard.result_label.text(), timeout=120_000)
        cal_path = Path(win.controls.calibration.text())      # now the active calibration
        series = cal_path.parent
        assert cal_path.name == "bench_calibration.json"
        assert (series / "masses.csv").read_text().splitlines()[1:] == [
            "cal_000.jpg,0.000000", "cal_001.jpg,0.250000", "cal_002.jpg,0.750000", "cal_003.jpg,1.500000"]

        win.browser.refresh()                                 # reanalyse the series' frames with the fit
        win.browser.select(series)
        win.browser.calibration.setText(str(cal_path))
        win.browser.window.setValue(60.0)
        monkeypatch.setattr(dialogs, "ask_reason", lambda parent, question, required: "")   # no reason, as the CLI allows
        win.browser.reanalyse()
        qtbot.waitUntil(lambda: "frames analysed" in win.browser.info.text(), timeout=120_000)
        assert len(win.browser.plots.conc) == 4 and abs(win.browser.plots.conc[-1] - 3.0) < 0.1
        assert {"curve.csv", "cells.csv", "curve.png"} <= {p.name for p in (series / "analysis").iterdir()}

        target = tmp_path / "target.csv"
        target.write_text("tau_mm,released_mm3\n0,0\n1,300\n2,500\n3,600\n")
        win.design.source.setText(str(target))
        win.design.resolution.setValue(16)
        win.design.max_iter.setValue(3)
        win.design.start()
        qtbot.waitUntil(lambda: win.design.start_button.isEnabled() and "design" in win.design.status.text()
                        and "evaluations" in win.design.status.text(), timeout=120_000)
        tau, target_mm3 = win.design.target_curve.getData()
        assert len(tau) > 10 and target_mm3[-1] == max(target_mm3)
        assert len(win.design.achieved_curve.getData()[0]) == len(tau)
    finally:
        win.engine.abort()
        win.engine.join(30)
        win.shutdown()
