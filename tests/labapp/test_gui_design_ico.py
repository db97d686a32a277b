"""The design launcher offers the ico space and reports the overhang figure and the run's warnings (headless)."""
import numpy as np
import pytest

pytest.importorskip("pytestqt")

from labapp.gui.design_launcher import DesignLauncher


def test_launcher_runs_an_ico_design_and_shows_overhangs(qtbot, tmp_path):
    tau = np.linspace(0.0, 4.0, 41)
    released = 800.0 * (1.0 - (1.0 - tau / 4.0) ** 3)  # a sphere-like decreasing rate
    target = tmp_path / "target.csv"
    np.savetxt(target, np.column_stack([tau, released]), delimiter=",", header="tau_mm,released_mm3", comments="")
    launcher = DesignLauncher(tmp_path)
    qtbot.addWidget(launcher)
    assert [launcher.space.itemText(i) for i in range(launcher.space.count())] == ["extruded", "nfc", "ico"]
    launcher.source.setText(str(target))
    launcher.space.setCurrentText("ico")
    launcher.resolution.setValue(16)
    launcher.max_iter.setValue(3)
    launcher.start()
    qtbot.waitUntil(lambda: launcher.start_button.isEnabled() and "evaluations" in launcher.status.text(),
                    timeout=120_000)
    assert "Overhangs along +z" in launcher.status.text() and "longest run" in launcher.status.text()


def test_launcher_shows_the_run_s_warnings(qtbot, tmp_path):
    import trimesh
    boxes = [trimesh.creation.box(extents=(4.0, 4.0, 4.0)).apply_translation([x, 0.0, 0.0]) for x in (-4.0, 4.0)]
    source = tmp_path / "two_boxes.stl"
    trimesh.util.concatenate(boxes).export(source)
    launcher = DesignLauncher(tmp_path)
    qtbot.addWidget(launcher)
    launcher.source.setText(str(source))
    launcher.space.setCurrentText("nfc")
    launcher.resolution.setValue(16)
    launcher.max_iter.setValue(2)
    launcher.start()
    qtbot.waitUntil(lambda: launcher.start_button.isEnabled() and "evaluations" in launcher.status.text(),
                    timeout=120_000)
    assert "Warning: the source is 2 separate pieces" in launcher.status.text()
