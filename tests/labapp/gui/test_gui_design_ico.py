"""The design launcher offers the ico space and reports the overhang figure and the run's warnings (headless)."""
import numpy as np
import pytest

pytest.importorskip("pytestqt")

from labapp.gui.design_launcher import DesignLauncher


def _design(qtbot, folder, source, space, max_iter) -> DesignLauncher:
    """Run a 16-voxel design of ``source`` in the launcher and wait for its result line."""
    launcher = DesignLauncher(folder)
    qtbot.addWidget(launcher)
    launcher.source.setText(str(source))
    launcher.space.setCurrentText(space)
    launcher.resolution.setValue(16)
    launcher.max_iter.setValue(max_iter)
    launcher.start()
    qtbot.waitUntil(lambda: launcher.start_button.isEnabled() and "evaluations" in launcher.status.text(),
                    timeout=120_000)
    return launcher


def test_launcher_runs_an_ico_design_and_shows_overhangs(qtbot, tmp_path):
    tau = np.linspace(0.0, 4.0, 41)
    released = 800.0 * (1.0 - (1.0 - tau / 4.0) ** 3)  # a sphere-like decreasing rate
    target = tmp_path / "target.csv"
    np.savetxt(target, np.column_stack([tau, released]), delimiter=",", header="tau_mm,released_mm3", comments="")
    launcher = _design(qtbot, tmp_path, target, "ico", 3)
    assert [launcher.space.itemText(i) for i in range(launcher.space.count())] == ["nfc", "extruded", "ico"]
    assert "Overhangs along +z" in launcher.status.text() and "longest run" in launcher.status.text()


def test_launcher_shows_the_run_s_warnings(qtbot, tmp_path, two_boxes_stl):
    launcher = _design(qtbot, tmp_path, two_boxes_stl, "nfc", 2)
    assert "Warning: the source is 2 separate pieces" in launcher.status.text()
