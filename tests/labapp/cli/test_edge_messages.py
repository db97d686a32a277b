"""Edges of the commands' inputs: implausible units refused with the plausible range, and messages that name the
file, the option and what was expected (not an internal field or a parser's raw text)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from analysis import AnalysisError, BenchCalibration
from labapp.cli.main import main

ROOT = Path(__file__).resolve().parents[3]
BENCH = ROOT / "fixtures" / "bench"


@pytest.mark.parametrize("water", ["0.5", "1e9"])
def test_implausible_water_is_refused_with_the_range(water, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["calibrate-bench", str(BENCH / "calibration"), "--water-g", water, "--out", str(tmp_path / "c.json")])
    assert exc.value.code == 2
    assert f"--water-g: '{water}': expected a number in [100, 5000] g" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_analyze_refuses_implausible_water_too(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["analyze", str(BENCH / "run"), "--water-g", "1e9", "--out", str(tmp_path / "a")])
    assert exc.value.code == 2
    assert "--water-g: '1e9': expected a number in [100, 5000] g" in capsys.readouterr().err


def test_the_milligram_warning_names_the_water_too():
    from labapp.jobs.calibrate_bench import implausible_levels

    (message,) = implausible_levels(np.array([0.0, 350.0, 2100.0]), 500.0)
    assert "Check the water, 500 g (--water-g), and the masses" in message and "milligrams" in message


def test_a_calibration_with_implausible_water_is_refused(tmp_path):
    from analysis import CropGeometry

    g = 2
    cells = {name: np.full((g, g), 0.1) for name in ("t0", "t0_sigma", "k", "k_sigma", "cov_t0_k", "rms_rel")}
    cal = BenchCalibration(CropGeometry(0, 0, 20, g), 500.0, good=np.ones((g, g), bool), conc_levels_g_per_kg=(0.0, 1.0), **cells)
    cal.save(tmp_path / "c.json")
    text = (tmp_path / "c.json").read_text()
    assert '"water_g": 500.0' in text
    (tmp_path / "c.json").write_text(text.replace('"water_g": 500.0', '"water_g": 1e9'))
    with pytest.raises(AnalysisError, match=r"water_g is 1e\+?0?9|water_g is 1000000000"):
        BenchCalibration.load(tmp_path / "c.json")
    with pytest.raises(AnalysisError, match=r"expected a water mass in \[100, 5000\] g"):
        BenchCalibration(CropGeometry(0, 0, 20, g), 0.5, good=np.ones((g, g), bool), conc_levels_g_per_kg=(0.0, 1.0), **cells)


def test_a_text_file_given_as_a_calibration_is_named_as_such(tmp_path, capsys):
    text = tmp_path / "notes.txt"
    text.write_text("calibrated on Monday, see lab book\n")
    with pytest.raises(AnalysisError) as exc:
        BenchCalibration.load(text)
    assert str(exc.value).startswith(f"{text} is not a bench calibration JSON") and "Expecting value" not in str(exc.value)
    assert main(["analyze", str(BENCH / "run"), "--calibration", str(text), "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert "is not a bench calibration JSON" in err and "Expecting value" not in err
