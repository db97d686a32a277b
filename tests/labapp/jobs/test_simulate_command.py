"""`sfr simulate`: output files, the full-object convention and error reporting."""
import csv
import json

import numpy as np
import pytest

from labapp.cli.main import main


def test_sample_shape_writes_csv_summary_and_plot(tmp_path):
    out = tmp_path / "run"
    assert main(["simulate", "sample:sphere", "--resolution", "24", "--symmetry", "xyz", "--out", str(out)]) == 0
    with open(out / "release.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["tau_mm", "released_mm3"] and len(rows) == 1002
    summary = json.loads((out / "summary.json").read_text())
    for key in ("volume_mm3", "total_time_mm", "voxels", "voxel_size_mm", "seconds"):
        assert key in summary
    # the octant was simulated, but the curve ends at the full sphere's voxel volume
    assert float(rows[-1][1]) == pytest.approx(summary["volume_mm3"], rel=1e-9)
    assert summary["voxels"] == 12 ** 3
    assert (out / "release.png").stat().st_size > 10_000


def test_density_array_input(tmp_path):
    np.savez(tmp_path / "slab.npz", rho=np.ones((4, 30, 30)), dx_mm=0.25)
    assert main(["simulate", str(tmp_path / "slab.npz"), "--out", str(tmp_path / "o")]) == 0
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    # a 1 mm thick slab dissolves from both faces: T = 0.5 mm at its mid-plane
    assert summary["total_time_mm"] == pytest.approx(0.5, rel=1e-12)


def test_errors_name_the_problem(tmp_path, capsys):
    assert main(["simulate", str(tmp_path / "nothing.stl"), "--out", str(tmp_path / "o")]) == 2
    assert "nothing.stl: no such file" in capsys.readouterr().err
    assert main(["simulate", "sample:nope", "--out", str(tmp_path / "o")]) == 2
    assert "unknown sample shape" in capsys.readouterr().err
