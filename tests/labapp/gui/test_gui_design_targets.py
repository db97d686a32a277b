"""The design launcher takes every target `sfr design --target` takes, shows its curve and feasibility before
Design, reports "iteration i of N", shows the printed solid in three slices with a scale bar, and a stopped
design resumes from its checkpoint (offscreen)."""
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
    qtbot.waitUntil(lambda: not launcher.check_task.running, timeout=60_000)
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


def test_measured_target_needs_simcal_and_is_optimised_despite_its_noise(qtbot, launcher, tmp_path):
    curve = tmp_path / "measured.csv"
    t = np.arange(0.0, 7200.0, 60.0)
    np.savetxt(curve, np.column_stack([t, 1.7 * (1 - np.exp(-t / 2000.0))]), delimiter=",",
               header="t_s,released_g", comments="")
    assert not launcher.allow_infeasible.isChecked()
    text = _checked(qtbot, launcher, str(curve))
    assert NO_SIMCAL in text
    assert launcher.allow_infeasible.isChecked()        # a measured target: the check reports, it does not block
    launcher.source.setText("sphere")
    assert launcher.allow_infeasible.isChecked()        # the operator's choice stays as it is


def test_design_progress_solid_slices_stop_and_resume(qtbot, launcher):
    launcher.max_iter.setValue(400)
    launcher.source.setText("sphere")
    launcher.start()
    qtbot.waitUntil(lambda: "iteration" in launcher.progress.format(), timeout=60_000)
    assert "of 400" in launcher.progress.format()
    launcher.stop()
    qtbot.waitUntil(lambda: not launcher.busy and launcher.start_button.isEnabled(), timeout=60_000)
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
