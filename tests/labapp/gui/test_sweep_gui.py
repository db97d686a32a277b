"""The design launcher's sweep panel: a small sweep on the local cluster, then its contact sheet."""
import pytest

from labapp.gui.design_launcher import DesignLauncher
from labapp.gui.sweep_panel import parse_values


@pytest.mark.slow
def test_the_launcher_runs_a_small_sweep_and_browses_its_contact_sheet(qtbot, tmp_path):
    launcher = DesignLauncher(tmp_path)
    qtbot.addWidget(launcher)
    launcher.source.setText("sphere")
    launcher.space.setCurrentText("nfc")
    launcher.resolution.setValue(16)
    launcher.max_iter.setValue(5)
    launcher.allow_infeasible.setChecked(False)
    assert launcher.sweep_settings() == ("sphere", {"space": "nfc", "resolution": 16, "max_iter": 5,
                                                    "allow_infeasible": False}, None)
    panel = launcher.sweep
    panel.w_binary.setText("10")
    panel.radius.setText("2, 3")
    panel.beta.setText("x")
    panel.start()
    assert "beta: expected numbers" in panel.status.text() and panel.task is None
    panel.beta.setText("3")
    panel.preset.setCurrentText("paper:sphere")
    panel.workers.setValue(2)
    panel.start()
    qtbot.waitUntil(panel.sweep_button.isEnabled, timeout=120_000)
    assert "3 designs, 0 failed" in panel.status.text(), panel.status.text()
    items = [panel.designs.item(i).text() for i in range(panel.designs.count())]
    assert items[0] == "contact sheet (ranked)" and len(items) == 4
    assert {i.split(" ", 1)[1] for i in items[1:]} == {
        "preset=paper-sphere", "beta=3,radius_vox=2,w_binary=10", "beta=3,radius_vox=3,w_binary=10"}
    assert not panel.picture.pixmap().isNull()          # the contact sheet
    panel.designs.setCurrentRow(1)
    assert not panel.picture.pixmap().isNull()          # the best design's report.png
    assert panel.sweep_dir.parent == tmp_path / "sweeps" and (panel.sweep_dir / "sweep.csv").is_file()


def test_grid_fields_are_checked():
    assert parse_values("1, 2.5;3", "w") == [1.0, 2.5, 3.0]
    with pytest.raises(ValueError, match="radius: give at least one value"):
        parse_values(" , ", "radius")
