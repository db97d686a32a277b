"""The design launcher's fields are made from the design settings' declarations (`design.inverse.settings`)."""
import pytest

pytest.importorskip("pytestqt")

from design.inverse.settings import MAX_ITER, RESOLUTION, SPACE
from labapp.gui.design_launcher import DesignLauncher


def test_the_fields_take_their_choices_defaults_and_ranges_from_the_declarations(qtbot, tmp_path):
    launcher = DesignLauncher(tmp_path)
    qtbot.addWidget(launcher)
    assert [launcher.space.itemText(i) for i in range(launcher.space.count())] == list(SPACE.choices)
    assert launcher.settings() == {"space": SPACE.default, "resolution": RESOLUTION.default,
                                   "max_iter": MAX_ITER.default, "allow_infeasible": False}
    launcher.resolution.setValue(9)                        # odd: refused, not rounded
    assert launcher.resolution.problem() == "resolution must be a whole number >= 8 voxels (even), got 9 voxels"
    launcher.source.setText("sphere")
    launcher.start()
    assert launcher.status.text() == launcher.resolution.problem() and not launcher.busy
    launcher.resolution.setValue(300)                       # no cap of the GUI's own: what sfr design takes
    assert launcher.resolution.problem() == "" and launcher.settings()["resolution"] == 300
