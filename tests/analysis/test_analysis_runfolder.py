"""Whole runs against the rendered fixtures' ground truth, folder formats, bad input, the CLI."""
import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import analysis.runfolder as runfolder
from analysis import AnalysisError, CropGeometry, analyze_run, fit_bench_calibration, read_cells, read_frame_list
from labapp.cli.main import main

BENCH = Path(__file__).resolve().parents[2] / "fixtures" / "bench"
CROP = tuple(json.loads((BENCH / "calibration" / "truth.json").read_text())["crop"])


def _calibration(mirror=True):
    with open(BENCH / "calibration" / "masses.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    geometry = CropGeometry(*CROP, mirror_normalise=mirror)
    cells = np.array([read_cells(BENCH / "calibration" / r["file"], geometry) for r in rows])
    conc = np.array([float(r["added_mass_g"]) for r in rows]) * 2.0     # 500 g water: g -> g/kg
    return fit_bench_calibration(cells, conc, geometry, 500.0, image_shape=(536, 800))


def _truth():
    with open(BENCH / "run" / "truth.csv", newline="") as fh:
        return {r["file"]: float(r["conc_g_per_kg"]) for r in csv.DictReader(fh)}


def _rms_percent(curve):
    truth = _truth()
    true = np.array([truth[f] for f in curve.files])
    return 100 * np.sqrt(np.mean((curve.conc_g_per_kg - true) ** 2)) / true[-1]


def test_fixture_run_meets_the_accuracy_target_and_the_mirror_earns_its_place():
    calls = []
    with_mirror = analyze_run(BENCH / "run", _calibration(), workers=2, progress=lambda d, n: calls.append((d, n)))
    without = analyze_run(BENCH / "run", _calibration(mirror=False), workers=2)
    assert len(with_mirror.files) == 90 and calls[-1] == (90, 90)
    # Issue target: RMS error <= 1 % of the final concentration, intrusion and drift frames included
    # (measured 0.36 %, docs/analysis.md); without mirror normalisation the light drift of the run
    # day stays in the data (measured 3.1 %): demand at least 3x worse.
    rms, rms_without = _rms_percent(with_mirror), _rms_percent(without)
    assert rms <= 1.0
    assert rms_without > 3 * rms
    assert (with_mirror.n_rejected > 0).sum() >= 5          # intrusions were seen and cells rejected
    assert np.allclose(with_mirror.released_g, with_mirror.conc_smooth_g_per_kg * 0.5)


def _copy_run(tmp_path, n=6):
    run = tmp_path / "run"
    run.mkdir()
    with open(BENCH / "run" / "frames.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))[:n]
    for r in rows:
        shutil.copy(BENCH / "run" / r["file"], run / r["file"])
    return run, rows


def _write_manifest(run, rows):
    with open(run / "frames.csv", "w", newline="") as fh:
        out = csv.DictWriter(fh, fieldnames=["file", "t_s"], extrasaction="ignore")
        out.writeheader()
        out.writerows(rows)


def test_corrupt_and_wrong_size_frames_are_skipped_with_their_names(tmp_path):
    run, rows = _copy_run(tmp_path)
    _write_manifest(run, rows)
    data = (run / rows[2]["file"]).read_bytes()
    (run / rows[2]["file"]).write_bytes(data[: len(data) // 3])
    Image.new("RGB", (400, 268)).save(run / rows[4]["file"], format="JPEG")
    shutil.copy(BENCH / "run" / "reference.jpg", run / "reference.jpg")     # found without run.json
    assert read_frame_list(run).reference == run / "reference.jpg"
    curve = analyze_run(run, _calibration(), workers=1)
    assert len(curve.files) == 4
    assert any(rows[2]["file"] in w and "truncated" in w for w in curve.warnings)
    assert any(rows[4]["file"] in w and "expected 800x536" in w for w in curve.warnings)


def test_cached_cells_make_a_rerun_decode_nothing(tmp_path, monkeypatch):
    run, rows = _copy_run(tmp_path)
    _write_manifest(run, rows)
    cal = _calibration()
    first = analyze_run(run, cal, cache_dir=tmp_path / "out", workers=1)

    def no_decoding(*args, **kwargs):
        raise AssertionError("decoded although cached")

    monkeypatch.setattr(runfolder, "read_cells", no_decoding)
    second = analyze_run(run, cal, cache_dir=tmp_path / "out", workers=1, window_s=100.0)
    assert np.array_equal(first.cells, second.cells)


def test_bad_folders(tmp_path):
    with pytest.raises(AnalysisError, match="missing does not exist"):
        read_frame_list(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(AnalysisError, match="no frames"):
        read_frame_list(tmp_path / "empty")
    run, rows = _copy_run(tmp_path, n=3)
    rows[2]["t_s"] = "10"
    _write_manifest(run, rows)
    with pytest.raises(AnalysisError, match="line 4: times are not increasing"):
        read_frame_list(run)
    (run / "frames.csv").write_text("name,time\nx.jpg,0\n")
    with pytest.raises(AnalysisError, match="needs the columns file,t_s"):
        read_frame_list(run)


def _with_exif(src, dst, stamp, subsec):
    exif = Image.Exif()
    exif.get_ifd(0x8769).update({36867: stamp, 37521: subsec})
    with Image.open(src) as img:
        img.save(dst, format="JPEG", quality=95, exif=exif)


def test_plain_folder_times_from_exif_or_interval(tmp_path):
    card = tmp_path / "card"
    card.mkdir()
    stamps = [("2024:05:01 10:00:00", "0"), ("2024:05:01 10:00:11", "5"), ("2024:05:01 10:00:22", "25")]
    for i, (stamp, sub) in enumerate(stamps):
        _with_exif(BENCH / "run" / f"frame_{i:04d}.jpg", card / f"DSC_{i:04d}.JPG", stamp, sub)
    frames = read_frame_list(card)
    assert frames.source == "exif" and np.allclose(frames.t_s, [0.0, 11.5, 22.25])
    assert np.allclose(read_frame_list(card, interval_s=11.0).t_s, [0.0, 11.0, 22.0])
    shutil.copy(BENCH / "run" / "frame_0000.jpg", card / "DSC_9999.JPG")    # no EXIF time
    with pytest.raises(AnalysisError, match="--interval"):
        read_frame_list(card)


def test_cli_calibrate_then_analyze(tmp_path, capsys):
    cal = tmp_path / "cal.json"
    crop = ",".join(str(v) for v in CROP)
    assert main(["calibrate-bench", str(BENCH / "calibration"), "--water-g", "500", "--crop", crop,
                 "--out", str(cal)]) == 0
    run, rows = _copy_run(tmp_path, n=12)
    _write_manifest(run, rows)
    out = tmp_path / "out"
    assert main(["analyze", str(run), "--calibration", str(cal), "--out", str(out)]) == 0
    with open(out / "curve.csv", newline="") as fh:
        curve = list(csv.DictReader(fh))
    assert len(curve) == 12 and {"t_s", "conc_g_per_kg", "conc_smooth_g_per_kg", "released_g"} <= set(curve[0])
    assert (out / "curve.png").stat().st_size > 0
    with open(out / "cells.csv", newline="") as fh:
        assert sum(1 for _ in fh) == 1 + 12 * 100
    text = capsys.readouterr().out
    assert "steady state: no" in text and "MDT " in text
    release = json.loads((out / "summary.json").read_text())["release"]
    assert release["mdt_s"] > 0 and release["best_fit"]["rank"] == 1
    short = tmp_path / "short"
    short.mkdir()
    shutil.copy(BENCH / "calibration" / "masses.csv", short / "masses.csv")
    with open(short / "masses.csv", "w") as fh:
        fh.write("file,added_mass_g\ncal_00_0.jpg,0\ncal_01_0.jpg,0.35\n")
    for name in ("cal_00_0.jpg", "cal_01_0.jpg"):
        shutil.copy(BENCH / "calibration" / name, short / name)
    assert main(["calibrate-bench", str(short), "--crop", crop, "--out", str(tmp_path / "x.json")]) == 2
    assert "at least 3 distinct" in capsys.readouterr().err
    assert main(["calibrate-bench", str(BENCH / "calibration"), "--crop", "750,10,80", "--out",
                 str(tmp_path / "y.json")]) == 2
    assert "reaches past the image" in capsys.readouterr().err
    assert main(["calibrate-bench", str(BENCH / "calibration"), "--crop", "700,10,80", "--out",
                 str(tmp_path / "y.json")]) == 2                        # on the bare panel: no response
    assert "is the crop inside the beaker" in capsys.readouterr().err


def test_cli_calibration_takes_the_series_recorded_crop(tmp_path, capsys):
    """A series folder with a run.json (as `sfr lab` records it) needs no --crop, and a run recorded with
    the same crop analyses without a crop-mismatch warning."""
    cal = tmp_path / "cal.json"
    assert main(["calibrate-bench", str(BENCH / "calibration"), "--water-g", "500", "--out", str(cal)]) == 0
    recorded = json.loads((BENCH / "calibration" / "run.json").read_text())["crop"]
    assert f"crop x={recorded['x']} y={recorded['y']} size={recorded['size']} px" in capsys.readouterr().out
    run, rows = _copy_run(tmp_path, n=6)
    _write_manifest(run, rows)
    shutil.copy(BENCH / "run" / "run.json", run / "run.json")
    assert main(["analyze", str(run), "--calibration", str(cal), "--out", str(tmp_path / "out")]) == 0
    assert "differs from the calibration" not in capsys.readouterr().err


def test_curve_csv_has_raw_grams_and_percent_of_the_weighed_mass(tmp_path):
    from analysis.runfolder import RunCurve, write_curve_csv

    n = 3
    conc = np.array([0.0, 1.0, 2.0])
    smooth = np.array([0.1, 1.0, 1.9])
    curve = RunCurve(["a.jpg", "b.jpg", "c.jpg"], np.array([0.0, 11.0, 22.0]), conc, np.full(n, 0.01), smooth,
                     smooth * 0.5, np.zeros((n, 2, 2)), np.zeros(n, int), 500.0, object_mass_g=1.9)
    write_curve_csv(curve, tmp_path / "curve.csv")
    with open(tmp_path / "curve.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r["released_raw_g"]) for r in rows] == [0.0, 0.5, 1.0]      # conc x 0.5 kg, unsmoothed
    assert [float(r["released_pct"]) for r in rows] == pytest.approx([100 * 0.05 / 1.9, 100 * 0.5 / 1.9, 50.0], abs=1e-4)
    unknown = RunCurve(curve.files, curve.t_s, conc, curve.uncertainty_g_per_kg, smooth, smooth * 0.5, curve.cells,
                       curve.n_rejected, 500.0)
    write_curve_csv(unknown, tmp_path / "curve2.csv")
    with open(tmp_path / "curve2.csv", newline="") as fh:
        header = next(csv.reader(fh))
    assert "released_raw_g" in header and "released_pct" not in header
