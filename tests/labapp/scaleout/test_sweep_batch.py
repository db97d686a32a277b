"""Batch reanalysis: `sfr analyze RUN... --out DIR` on a local Dask cluster, one summary table."""
import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from analysis import CropGeometry, fit_bench_calibration, read_cells
from labapp.cli.main import main
from labapp.scaleout.batch import analyse_many, output_names

BENCH = Path(__file__).resolve().parents[3] / "fixtures" / "bench"


def _retimed(src: Path, dst: Path, factor: float) -> Path:
    """The rendered fixture run with every frame time multiplied by ``factor`` (a slower release)."""
    shutil.copytree(src, dst)
    with open(src / "frames.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    with open(dst / "frames.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, rows[0].keys())
        writer.writeheader()
        writer.writerows({**r, "t_s": f"{float(r['t_s']) * factor:.3f}"} for r in rows)
    return dst


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The bench calibration fitted to the rendered fixture series, the fixture run, a copy, a slower copy."""
    tmp = tmp_path_factory.mktemp("batch_runs")
    truth = json.loads((BENCH / "calibration" / "truth.json").read_text())
    with open(BENCH / "calibration" / "masses.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    geometry = CropGeometry(*truth["crop"], mirror_normalise=True)
    cells = np.array([read_cells(BENCH / "calibration" / r["file"], geometry) for r in rows])
    conc = np.array([float(r["added_mass_g"]) for r in rows]) * 2.0     # 500 g water: g -> g/kg
    cal_path = tmp / "calibration.json"
    fit_bench_calibration(cells, conc, geometry, 500.0, image_shape=(536, 800)).save(cal_path)
    return cal_path, [_retimed(BENCH / "run", tmp / name, f) for name, f in (("a", 1.0), ("b", 1.0), ("slow", 3.0))]


@pytest.mark.slow
def test_batch_on_a_local_cluster_writes_one_table(runs, tmp_path, capsys):
    cal_path, (a, b, c) = runs
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "frames.csv").write_text("nonsense\n")
    out = tmp_path / "batch"
    code = main(["analyze", str(a), str(b), str(c), str(broken), "--calibration", str(cal_path), "--out", str(out),
                 "--reference", str(a), "--no-plot"])
    assert code == 1  # the broken run fails; the others are analysed
    with open(out / "batch_summary.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["status"] for r in rows] == ["done", "done", "done", "failed"]
    assert rows[3]["error"] and rows[3]["run"] == str(broken)
    ref, same, slow = rows[:3]
    assert float(ref["f2"]) == pytest.approx(100.0) and float(same["f2"]) == pytest.approx(100.0)
    assert float(slow["f2"]) < 50  # three times slower: not similar
    assert float(slow["mdt_s"]) == pytest.approx(3 * float(ref["mdt_s"]), rel=0.05)
    assert float(slow["final_released_g"]) == pytest.approx(float(ref["final_released_g"]), rel=1e-3)
    for row in rows[:3]:
        assert (out / row["folder"] / "curve.csv").is_file() and float(row["final_conc_g_per_kg"]) > 0
    assert "3 of 4 runs analysed" in capsys.readouterr().out


def test_serial_batch_matches_the_single_run_analysis(runs, tmp_path):
    cal_path, (a, _, _) = runs
    assert main(["analyze", str(a), "--calibration", str(cal_path), "--out", str(tmp_path / "one"), "--no-plot"]) == 0
    result = analyse_many([a], cal_path, tmp_path / "batch", plot=False)
    single = (tmp_path / "one" / "curve.csv").read_text()
    assert (tmp_path / "batch" / result.rows[0]["folder"] / "curve.csv").read_text() == single


def test_batch_needs_out_and_distinct_names(runs, tmp_path, capsys):
    cal_path, (a, b, _) = runs
    assert main(["analyze", str(a), str(b), "--calibration", str(cal_path)]) == 2
    assert "needs --out" in capsys.readouterr().err
    assert output_names([tmp_path / "x" / "run", tmp_path / "y" / "run", tmp_path / "z"]) == ["x_run", "y_run", "z"]
    assert output_names([tmp_path / "run", tmp_path / "run"]) == [f"{tmp_path.name}_run", f"{tmp_path.name}_run-2"]
