"""The design launcher takes every target `sfr design --target` takes, shows its curve and feasibility before
Design, reports "iteration i of N", shows the printed solid in three slices with a scale bar, and a stopped
design resumes from its checkpoint (offscreen)."""
import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pytestqt")

from labapp.gui.design_launcher import ANALYTIC_TARGETS, NO_SIMCAL, DesignLauncher

SHAPES = Path(__file__).resolve().parents[3] / "fixtures" / "shapes"


@pytest.fixture
def launcher(qtbot, tmp_path):
    widget = DesignLauncher(tmp_path)
    qtbot.addWidget(widget)
    widget.resolution.setValue(16)
    return widget


def _checked(qtbot, launcher, target: str) -> str:
    launcher.use_target(target)
    qtbot.waitUntil(lambda: not launcher.check_task.running, timeout=120_000)
    qtbot.wait(20)
    return launcher.status.text()


def test_sample_mesh_and_analytic_targets_show_curve_and_report(qtbot, launcher):
    samples = [launcher.sample.itemText(i) for i in range(1, launcher.sample.count())]
    assert "pill" in samples and "sphere" in samples
    assert [launcher.analytic.itemText(i) for i in range(1, launcher.analytic.count())] == list(ANALYTIC_TARGETS)
    for target in ("zero-order", "sphere", str(SHAPES / "pill.stl")):
        text = _checked(qtbot, launcher, target)
        assert text.startswith(f"Target {target}:") and "target is feasible" in text.lower(), text
        tau, released = launcher.target_curve.getData()
        assert len(tau) > 10 and released[-1] > 0 and np.all(np.diff(released) >= -1e-9)


def _measured_run(folder: Path, seed: int = 4) -> Path:
    """A run folder whose curve is a 1.7 g sphere's release (exactly on the isoperimetric bound at 1850 s/mm and
    1.24 g/cm^3) sampled every 30 s with noise of 0.5 % of its mass."""
    mass, g_per_mm3, rate = 1.7, 1.24e-3, 1850.0
    end_s = (3.0 * mass / g_per_mm3 / (4.0 * np.pi)) ** (1.0 / 3.0) * rate
    t = np.arange(30.0, 1.15 * end_s, 30.0)
    grams = mass * (1.0 - np.clip(1.0 - t / end_s, 0.0, None) ** 3)
    grams += 0.005 * mass * np.random.default_rng(seed).standard_normal(t.size)
    folder.mkdir()
    np.savetxt(folder / "curve.csv", np.column_stack([t, grams, grams / 0.5]), delimiter=",", comments="",
               header="t_s,released_g,conc_g_per_kg", fmt="%.6f")
    return folder


def _simcal(path: Path) -> Path:
    from labapp.records.simcal import FORMAT, FORWARD_MODEL

    path.write_text(json.dumps({"format": FORMAT, "forward_model": FORWARD_MODEL, "model": "constant",
                                "physics": {"anisotropy": 1.0, "offset_mm": 0.0}, "seconds_per_mm": 1850.0,
                                "g_per_mm3": 1.24e-3, "resolution": 32, "voxel_size_mm": 0.5, "water_g": 500.0}))
    return path


def test_a_noisy_measured_run_is_made_feasible_and_designs_without_the_override(qtbot, launcher, tmp_path):
    run = _measured_run(tmp_path / "run")
    assert not launcher.allow_infeasible.isChecked()
    text = _checked(qtbot, launcher, str(run))
    assert NO_SIMCAL in text                                 # a measured target needs a simulation calibration
    launcher.set_simcal(_simcal(tmp_path / "simcal.json"))
    text = _checked(qtbot, launcher, str(run))
    assert "target is feasible" in text.lower() and "adjusted to a feasible curve" in text, text
    assert "% of the final release mass" in text and not launcher.allow_infeasible.isChecked()
    launcher.max_iter.setValue(30)
    launcher.start()
    qtbot.waitUntil(lambda: not launcher.busy and launcher.start_button.isEnabled(), timeout=180_000)
    qtbot.wait(50)
    assert launcher.progress.format() == "done", launcher.status.text()      # not refused by the check
    assert "target is feasible" in (launcher.out_dir / "feasibility.txt").read_text()
    notes = json.loads((launcher.out_dir / "target_from_measurement.json").read_text())
    assert 0 < notes["projection_max_pct"] < 2.0 and notes["mass_basis"] == "final release"


def test_design_progress_solid_slices_stop_and_resume(qtbot, launcher):
    launcher.max_iter.setValue(400)
    launcher.source.setText("sphere")
    launcher.start()
    qtbot.waitUntil(lambda: "iteration" in launcher.progress.format(), timeout=120_000)
    assert "of 400" in launcher.progress.format()
    launcher.stop()
    qtbot.waitUntil(lambda: not launcher.busy and launcher.start_button.isEnabled(), timeout=120_000)
    qtbot.wait(50)
    assert launcher.progress.format().startswith("stopped"), launcher.progress.format()
    stopped_at = launcher.progress.value()
    assert 0 < stopped_at < 400 and (launcher.out_dir / "checkpoint.npz").is_file()
    launcher.max_iter.setValue(1)                        # resume keeps the run's own settings
    launcher.resume(launcher.out_dir)
    qtbot.waitUntil(lambda: not launcher.busy and launcher.start_button.isEnabled(), timeout=180_000)
    qtbot.wait(50)
    assert launcher.progress.format() == "done", launcher.status.text()
    for image in launcher.solid.images:
        assert image.image is not None and image.image.ndim == 2
    assert len(launcher.solid.bars) == 3 and launcher.solid.bars[0].text.toPlainText().endswith(" mm")
    assert "mm" in launcher.solid.caption.text() and "voxels" in launcher.solid.caption.text()
