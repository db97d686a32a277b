"""NaN/inf anywhere is refused with the file, row or field named; duplicated or contradictory rows and
meaningless settings are refused; never a traceback or a silently wrong result."""
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

from analysis import AnalysisError, BenchCalibration
from design.errors import DesignError
from design.files.meshio import load_mesh
from design.files.targets_io import read_curve_csv
from labapp.acquisition.calseries import read_masses
from labapp.cli.main import main
from labapp.errors import UsageError

FIXTURES = Path(__file__).resolve().parents[3] / "fixtures"


def test_target_csv_nan_and_repeated_rows(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("tau_mm,released_mm3\n0,0\n1,inf\n2,5\n")
    with pytest.raises(DesignError, match=r"t.csv row 3, released_mm3: 'inf'; expected a finite number"):
        read_curve_csv(path)
    path.write_text("tau_mm,released_mm3\n0,0\n1,3\n1,4\n")
    with pytest.raises(DesignError, match="row 4: tau_mm 1 is listed twice"):
        read_curve_csv(path)


@pytest.fixture
def calibration(tmp_path):
    """A saved calibration fitted on the fixture series."""
    out = tmp_path / "cal.json"
    assert main(["calibrate-bench", str(FIXTURES / "bench" / "calibration"), "--out", str(out)]) == 0
    return out


def test_calibration_json_nan_in_a_good_cell_is_named(calibration, tmp_path, capsys):
    data = json.loads(calibration.read_text())
    data["cells"]["k"][2][7] = float("nan")               # one NaN cell: today the whole curve became NaN
    calibration.write_text(json.dumps(data))
    with pytest.raises(AnalysisError, match=r"cells.k of cell \(row 2, col 7\) is nan but the cell is marked good"):
        BenchCalibration.load(calibration)
    run = tmp_path / "run"
    shutil.copytree(FIXTURES / "bench" / "run", run)
    assert main(["analyze", str(run), "--calibration", str(calibration), "--no-plot"]) == 2
    err = capsys.readouterr().err
    assert "row 2, col 7" in err and "Traceback" not in err and not (run / "analysis" / "curve.csv").exists()
    data["cells"]["k"][2][7] = 0.19
    data["water_g"] = float("inf")
    calibration.write_text(json.dumps(data))
    with pytest.raises(AnalysisError, match="water_g is inf"):
        BenchCalibration.load(calibration)


@pytest.mark.parametrize("rows, message", [
    ("a.jpg,0\nb.jpg,nan\n", r"row 3, added_mass_g: 'nan'; expected a finite mass >= 0 g"),
    ("a.jpg,0\nb.jpg,-1\n", r"row 3, added_mass_g: '-1'"),
    ("a.jpg,0\nb.jpg,x\n", r"row 3, added_mass_g: 'x' is not a number"),
    ("a.jpg,0\nb.jpg,0.5\na.jpg,0.7\n", r"row 4: a.jpg is listed again \(contradicts row 2, 0 g\)"),
    ("a.jpg,0\na.jpg,0\n", r"row 3: a.jpg is listed again \(duplicates row 2"),
    ("a.jpg,0.5\nb.jpg,0.2\n", r"row 3, added_mass_g: 0.2 g is below the row before"),
    ("", "lists no images"),
])
def test_masses_csv_bad_rows(tmp_path, rows, message):
    (tmp_path / "masses.csv").write_text("file,added_mass_g\n" + rows)
    with pytest.raises(UsageError, match=message):
        read_masses(tmp_path)


def test_mesh_with_a_nan_vertex_is_named(tmp_path):
    box = trimesh.creation.box((10, 10, 10))
    vertices = box.vertices.copy()
    vertices[5, 2] = np.nan
    trimesh.Trimesh(vertices, box.faces, process=False).export(tmp_path / "bad.obj")
    with pytest.raises(DesignError, match=r"bad.obj: vertex 6 has non-finite coordinates"):
        load_mesh(tmp_path / "bad.obj")           # it used to be dropped, then reported as "not watertight"


@pytest.mark.parametrize("argv, says", [
    (["run", "--water-g", "0"], "--water-g: '0': expected a number in [100, 5000] g"),
    (["run", "--water-g", "nan"], "--water-g: 'nan': expected a finite number"),
    (["run", "--speed", "-5"], "--speed: '-5': expected a number >= 0"),
    (["run", "--interval", "inf"], "--interval: 'inf': expected a finite number"),
    (["analyze", "r", "--calibration", "c", "--workers", "-2"], "--workers: '-2': expected a whole number >= 1"),
    (["analyze", "r", "--calibration", "c", "--window-s", "nan"], "--window-s: 'nan'"),
    (["calibrate-bench", "s", "--water-g", "0"], "--water-g: '0'"),
    (["simulate", "sample:sphere", "--voxel-size", "-1"], "--voxel-size: '-1'"),
    (["design", "--target", "sphere", "--max-iter", "0", "--out", "x"], "--max-iter: '0'"),
    (["emulate", "heidolph", "--speed", "inf"], "--speed: 'inf'"),
])
def test_meaningless_numbers_on_the_command_line(argv, says, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert says in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("rows, message", [
    ("frame_0000.jpg,0\nframe_0001.jpg,nan\n", r"line 3: t_s='nan'; expected a finite time in s"),
    ("frame_0000.jpg,0\nframe_0000.jpg,20\n", r"line 3: frame_0000.jpg is listed again \(first on line 2\)"),
])
def test_frames_csv_nan_times_and_repeated_frames(tmp_path, rows, message):
    from analysis.frames import read_frame_list

    run = tmp_path / "run"
    shutil.copytree(FIXTURES / "bench" / "run", run)
    (run / "frames.csv").write_text("file,t_s\n" + rows)
    with pytest.raises(AnalysisError, match=message):
        read_frame_list(run)


def test_density_array_nan_names_the_voxel(tmp_path, capsys):
    rho = np.zeros((6, 6, 6))
    rho[2, 3, 4] = np.nan
    np.save(tmp_path / "rho.npy", rho)
    assert main(["simulate", str(tmp_path / "rho.npy"), "--voxel-size", "0.5", "--out", str(tmp_path / "o")]) == 2
    assert "first at index (2, 3, 4) (nan)" in capsys.readouterr().err and not (tmp_path / "o").exists()
