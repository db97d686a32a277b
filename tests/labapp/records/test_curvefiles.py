"""labapp.records.curvefiles: every physical curve file of the project through one reader, bad values named by row."""
import json

import numpy as np
import pytest

from labapp.records.curvefiles import CurveFileError, read_physical_curve


def _write(path, text):
    path.write_text(text)
    return path


def test_analyze_curve_csv_gives_water_and_mass_from_run_json(tmp_path):
    run = tmp_path / "run"
    (run / "analysis").mkdir(parents=True)
    (run / "run.json").write_text(json.dumps({"object_mass_g": 1.7, "water_g": 400.0}))
    csv = _write(run / "analysis" / "curve.csv",
                 "t_s,conc_g_per_kg,conc_smooth_g_per_kg,released_g,uncertainty_g_per_kg,n_rejected_cells,file\n"
                 "0,0,0,0,0.01,0,a.jpg\n11,1.0,1.0,0.4,0.01,0,b.jpg\n22,2.0,2.0,0.8,0.01,0,c.jpg\n")
    curve = read_physical_curve(csv)
    np.testing.assert_allclose(curve.t_s, [0, 11, 22])
    np.testing.assert_allclose(curve.released_g, [0, 0.4, 0.8])
    assert curve.water_g == pytest.approx(400.0)
    assert curve.object_mass_g == pytest.approx(1.7)
    assert read_physical_curve(run / "analysis").source == str(csv)


def test_plain_and_design_csvs(tmp_path):
    plain = read_physical_curve(_write(tmp_path / "m.csv", "released_g,t_s\n0,0\n1.5,60\n"))
    assert plain.object_mass_g is None and plain.water_g is None
    np.testing.assert_allclose(plain.released_g, [0, 1.5])
    design = _write(tmp_path / "curves_physical.csv", "t_s,target_released_g,design_released_g\n0,0,0\n900,1,0.9\n")
    assert read_physical_curve(design).released_g[-1] == pytest.approx(0.9)
    assert read_physical_curve(design, column="target_released_g").released_g[-1] == pytest.approx(1.0)
    sim = read_physical_curve(_write(tmp_path / "release_physical.csv",
                                     "t_s,released_g,conc_g_per_kg\n0,0,0\n500,0.5,1.0\n"))
    assert sim.water_g == pytest.approx(500.0)


@pytest.mark.parametrize("body, message", [
    ("t_s,released_g\n0,0\nnan,1\n", r"bad\.csv: row 2: t_s = nan is not a finite number"),
    ("t_s,released_g\n0,0\n1,inf\n", r"row 2: released_g = inf"),
    ("t_s,released_g\n0,0\n5,1\n5,2\n", r"row 3: t_s = 5 s does not increase"),
    ("t_s,released_g\n0,0\n1,x\n", r"row 2: released_g = 'x' is not a number"),
    ("t_s,mass\n0,0\n", r"no column released_g; the header has t_s, mass"),
    ("t_s,released_g\n0,0\n", r"1 data rows"),
])
def test_bad_values_name_file_and_row(tmp_path, body, message):
    with pytest.raises(CurveFileError, match=message):
        read_physical_curve(_write(tmp_path / "bad.csv", body))


def test_missing_and_ambiguous(tmp_path):
    with pytest.raises(CurveFileError, match="no such file"):
        read_physical_curve(tmp_path / "nope.csv")
    _write(tmp_path / "curve.csv", "t_s,released_g\n0,0\n1,1\n")
    _write(tmp_path / "release_physical.csv", "t_s,released_g\n0,0\n1,1\n")
    with pytest.raises(CurveFileError, match="name the file"):
        read_physical_curve(tmp_path)
    with pytest.raises(CurveFileError, match="neither a run folder"):
        read_physical_curve(tmp_path / "..")


def test_times_in_hours_or_minutes_are_refused_naming_the_file(tmp_path):
    from labapp.records.curvefiles import check_same_unit

    hours = _write(tmp_path / "hours.csv", "t_s,released_g\n0,0\n1.2,1\n2.43,1.5\n")
    with pytest.raises(CurveFileError, match=r"hours\.csv: t_s ends at 2\.43, .* look like hours \(2\.43 h = 8748 s\)"):
        read_physical_curve(hours)
    check_same_unit([("a.csv", 8748.0), ("b.csv", 7000.0)])                 # two runs of one product
    with pytest.raises(CurveFileError, match=r"^min\.csv: .* 60 times less than s\.csv .* look like minutes"):
        check_same_unit([("s.csv", 8748.0), ("min.csv", 145.8)])
