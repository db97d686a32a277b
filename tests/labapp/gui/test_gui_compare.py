"""The run browser's f2: two selected runs, or a run and its prediction, through the `sfr compare` job."""
import json

import numpy as np
import pytest

pytest.importorskip("pytestqt")

from labapp.gui.run_browser import RunBrowser  # noqa: E402


def _run(data_dir, name, tau_s, mass_g=1.7):
    folder = data_dir / name
    (folder / "analysis").mkdir(parents=True)
    (folder / "run.json").write_text(json.dumps({"status": "complete", "kind": "run", "object_mass_g": mass_g}))
    t = np.arange(0, 3 * 3600, 11.0)
    grams = mass_g * (1 - np.exp(-t / tau_s))
    np.savetxt(folder / "analysis" / "curve.csv", np.column_stack([t, grams / 0.5, grams]), delimiter=",",
               header="t_s,conc_smooth_g_per_kg,released_g", comments="", fmt="%.6f")
    return folder


def test_f2_of_two_selected_runs_and_of_a_run_and_its_prediction(qtbot, tmp_path):
    a = _run(tmp_path, "20260101-a", 2400.0)
    b = _run(tmp_path, "20260102-b", 2600.0)
    browser = RunBrowser(tmp_path)
    qtbot.addWidget(browser)
    browser.compare()
    assert "select two runs" in browser.info.text()
    for i in range(browser.tree.topLevelItemCount()):
        browser.tree.topLevelItem(i).setSelected(True)
    assert set(browser.selected_paths()) == {a, b}
    browser.compare()
    qtbot.waitUntil(lambda: "f2 = " in browser.info.text(), timeout=120_000)
    assert "MDT" in browser.info.text() and "(similar)" in browser.info.text()
    prediction = tmp_path / "release_physical.csv"
    t = np.arange(0, 3 * 3600, 60.0)
    np.savetxt(prediction, np.column_stack([t, 1.7 * (1 - np.exp(-t / 6000.0))]), delimiter=",",
               header="t_s,released_g", comments="", fmt="%.6f")
    browser.tree.clearSelection()
    browser.select(a)
    browser.prediction.setText(str(prediction))
    browser.compare()
    qtbot.waitUntil(lambda: "(not similar)" in browser.info.text(), timeout=120_000)
    assert str(prediction) in browser.info.text()
