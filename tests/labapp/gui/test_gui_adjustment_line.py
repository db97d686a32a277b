"""The line saying how much a measured target was changed to be feasible is one function's
(``labapp.jobs.physical.adjustment_line``): the design launcher shows it, `sfr design` prints it from the notes
``<stem>.json`` beside the target (``read_measured_target``; tests/labapp/jobs/test_measured_target.py runs the
command), and those notes read back as what was written."""

import pytest

pytest.importorskip("pytestqt")

from labapp.jobs.physical import adjustment_line, read_measured_target, write_target_csv
from labapp.records.simcal import SimCalError, curve_of, load_simcal
from tests.labapp.gui.test_gui_design_targets import _checked, _measured_run, _simcal, launcher  # noqa: F401


def test_the_launcher_shows_the_adjustment_line_the_cli_prints(qtbot, launcher, tmp_path):  # noqa: F811
    run = _measured_run(tmp_path / "run")
    simcal = _simcal(tmp_path / "simcal.json")
    written = write_target_csv(curve_of(str(run)), load_simcal(simcal), tmp_path / "target.csv")
    line = adjustment_line(written)
    assert line.startswith("Measured target adjusted to a feasible curve: monotone least-squares fit (changes up to ")
    assert line.endswith(" %.") and "points lowered onto the isoperimetric bound" in line
    read = read_measured_target(written.csv)             # what `sfr design` reads from the design folder
    assert read == written                               # JSON keeps every float exactly
    assert adjustment_line(read) == line

    launcher.set_simcal(simcal)
    text = _checked(qtbot, launcher, str(run))
    assert line in text.splitlines(), text


def test_the_notes_of_a_target_read_back_or_say_what_is_wrong(tmp_path):
    assert read_measured_target(tmp_path / "target.csv") is None           # not a measured target: no line
    (tmp_path / "target.json").write_text('{"mass_g": 1.7}')
    with pytest.raises(SimCalError, match=r"target\.json: not the notes of a measured target .*KeyError.*'mass_basis'"):
        read_measured_target(tmp_path / "target.csv")
