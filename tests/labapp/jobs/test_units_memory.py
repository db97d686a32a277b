"""Mesh units: implausible sizes are warned about with the likely unit, --units scales, and a grid that
would not fit in memory is refused with the figure before anything is allocated."""
import json
from pathlib import Path

import pytest
import trimesh

from labapp.cli.main import main
from labapp.errors import UsageError
from labapp.jobs import meshunits
from labapp.jobs.meshunits import check_memory, size_warnings

SPHERE = Path(__file__).resolve().parents[3] / "fixtures" / "shapes" / "sphere.stl"


@pytest.fixture
def metre_sphere(tmp_path):
    mesh = trimesh.load(SPHERE)
    mesh.apply_scale(0.001)                     # the same sphere exported in metres
    path = tmp_path / "sphere_m.stl"
    mesh.export(path)
    return path


def test_size_warnings_name_the_likely_unit():
    assert size_warnings([13.7] * 3, 1326.0, 0.2) == []
    (metres,) = size_warnings([0.0137] * 3, 1.326e-6)
    assert "probably in m (1.33e+03 mm^3 if so: --units m), not mm" in metres
    (small,) = size_warnings([0.9] * 3, 0.5)             # 0.5 cm^3 or 0.5 in^3: both printable, both named
    assert "probably in in (8.19e+03 mm^3 if so: --units in) or cm (500 mm^3" in small
    (huge,) = size_warnings([13700.0] * 3, 1.326e9)
    assert "micrometres" in huge
    (thin,) = size_warnings([20.0, 20.0, 0.5], 200.0, dx_mm=0.3)
    assert "under 4 voxels" in thin


def test_simulate_warns_then_scales_with_units(metre_sphere, tmp_path, capsys):
    out = tmp_path / "a"
    assert main(["simulate", "--model", "grid", str(metre_sphere), "--resolution", "16", "--out", str(out)]) == 0
    assert "not mm" in capsys.readouterr().out  # the user is told, whatever the logging setup
    summary = json.loads((out / "summary.json").read_text())
    assert summary["volume_mm3"] < 1e-3 and "--units m" in summary["warnings"][0]
    out_m = tmp_path / "b"
    ref = tmp_path / "c"
    assert main(["simulate", "--model", "grid", str(metre_sphere), "--units", "m", "--resolution", "16",
                 "--out", str(out_m)]) == 0
    assert main(["simulate", "--model", "grid", str(SPHERE), "--resolution", "16", "--out", str(ref)]) == 0
    scaled, mm = (json.loads((p / "summary.json").read_text()) for p in (out_m, ref))
    assert not any("--units" in w for w in scaled["warnings"])
    assert scaled["volume_mm3"] == pytest.approx(mm["volume_mm3"], rel=1e-6)


def test_memory_is_estimated_and_refused_with_the_figure(monkeypatch, tmp_path, capsys):
    class Small:
        available = 2 * 2**30
    monkeypatch.setattr(meshunits.psutil, "virtual_memory", lambda: Small)
    assert check_memory((100, 100, 100), 200, "x") == 200_000_000
    with pytest.raises(UsageError, match=r"600 x 600 x 600 voxels needs about 40.2 GiB, only 1.6 GiB"):
        check_memory((600, 600, 600), 200, "x")
    assert main(["simulate", "--model", "grid", str(SPHERE), "--voxel-size", "0.01", "--out", str(tmp_path / "s")]) == 2
    assert "GiB of memory is available" in capsys.readouterr().err and not (tmp_path / "s").exists()
    out = tmp_path / "d"
    assert main(["design", "--target", "sphere", "--resolution", "512", "--max-iter", "1", "--out", str(out)]) == 2
    assert "needs about" in capsys.readouterr().err and not out.exists()
