"""GUI faces of the calibration loop (headless): the wizard's simulation step, the design launcher with the
active simulation calibration, and the run browser's physical overlay. Each calls the same job functions as
the commands; the numbers themselves are tested in test_simcal_job.py."""
import numpy as np
import pytest

pytest.importorskip("pytestqt")

from design.geometry.shapes import sample_shape
from labapp.acquisition.simbench import Material, sample_release
from labapp.gui.calibration_wizard import SimulationStep
from labapp.gui.design_launcher import DesignLauncher
from labapp.gui.run_browser import RunBrowser


@pytest.fixture(scope="module")
def calibration_set(tmp_path_factory):
    folder = tmp_path_factory.mktemp("set")
    material = Material(1700.0, 1.3)
    rows = []
    for i, shape in enumerate(("sphere", "pill", "csg")):
        release = sample_release(shape, index=i, resolution=24, material=material)
        t = np.arange(60.0, 1.1 * release.duration_s, 60.0)
        grams = np.interp(t, release.t_s, release.released_g)
        np.savetxt(folder / f"{shape}.csv", np.column_stack([t, grams, grams * 2.0]), delimiter=",", comments="",
                   header="t_s,released_g,conc_g_per_kg", fmt="%.6f")
        sample_shape(shape).export(folder / f"{shape}.stl")
        rows.append((folder / f"{shape}.csv", folder / f"{shape}.stl", round(release.mass_g, 4)))
    return rows


@pytest.mark.slow
def test_simulation_step_calibrates_shows_the_fit_and_activates(qtbot, tmp_path, calibration_set):
    step = SimulationStep(tmp_path)
    qtbot.addWidget(step)
    for run, mesh, mass in calibration_set:
        step.add_row(run, mesh, mass)
    step.calibrate()
    qtbot.waitUntil(step.activate_button.isEnabled, timeout=120_000)
    assert "leave-one-out" in step.result.text() and "constant: mean" in step.result.text()
    assert "90% bands:" in step.result.text() and "of held-out points inside" in step.result.text()
    assert not step.figure.pixmap().isNull()
    with qtbot.waitSignal(step.simcal_activated) as signal:
        step.activate()
    assert signal.args[0].endswith("simcal.json")
    launcher = DesignLauncher(tmp_path)
    qtbot.addWidget(launcher)
    assert "no active simulation calibration" in launcher.status.text()
    launcher.set_simcal(signal.args[0])
    assert "active simulation calibration" in launcher.status.text()
    launcher.source.setText(str(calibration_set[1][0]))         # the pill's measured curve as target
    launcher.space.setCurrentText("nfc")
    launcher.resolution.setValue(16)
    launcher.max_iter.setValue(10)
    launcher.start()
    qtbot.waitUntil(lambda: launcher.start_button.isEnabled() and "evaluations" in launcher.status.text(),
                    timeout=120_000)
    assert "print mass" in launcher.status.text() and "narrowest channel" in launcher.status.text()
    hours, grams = launcher.physical_target.getData()
    assert hours[-1] > 0.5 and grams[-1] == pytest.approx(calibration_set[1][2], rel=0.02)
    assert len(launcher.physical_design.getData()[0]) == len(hours)
    assert launcher.slice_image.image is not None and launcher.slice_image.image.ndim == 2

    browser = RunBrowser(tmp_path / "data")
    qtbot.addWidget(browser)
    browser.overlay_prediction()
    assert "no active simulation calibration" in browser.info.text()
    browser.simcal = launcher.simcal
    browser.mesh.setText(str(calibration_set[0][1]))
    browser.overlay_prediction()                                # simulated off the GUI thread
    qtbot.waitUntil(lambda: len(browser.overlay.curves) == 1, timeout=120_000)
    assert browser.overlay.bands == 1                          # the prediction's band, shaded
    browser.overlay.add_run(calibration_set[0][0])
    labels = [c[0] for c in browser.overlay.curves]
    assert labels[0].startswith("sphere.stl predicted (") and labels[1] == "sphere.csv"
    predicted, measured = browser.overlay.curves[0][2], browser.overlay.curves[1][2]
    assert predicted[-1] == pytest.approx(measured[-1], rel=0.05)
