"""Per-cell Beer-Lambert fits, robust inversion, re-anchoring and the calibration file."""
import numpy as np
import pytest

from analysis import (
    AnalysisError,
    BenchCalibration,
    CropGeometry,
    estimate_concentration,
    fit_bench_calibration,
    reanchor_t0,
    reference_offset,
)

GEOMETRY = CropGeometry(0, 0, 40, grid=4)
LEVELS = np.repeat([0.0, 1.0, 2.0, 3.0, 4.0], 2)


def _truth(seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.8, 0.95, (4, 4)), rng.uniform(0.15, 0.25, (4, 4))


def _series(t0, k, noise, seed=1):
    rng = np.random.default_rng(seed)
    cells = t0 * np.exp(-k * LEVELS[:, None, None])
    return cells * (1 + noise * rng.standard_normal(cells.shape))


def test_exact_data_gives_exact_laws():
    t0, k = _truth()
    cal = fit_bench_calibration(_series(t0, k, 0.0), LEVELS, GEOMETRY, 500.0)
    assert np.allclose(cal.t0, t0, rtol=1e-10) and np.allclose(cal.k, k, rtol=1e-10)
    assert cal.good.all() and np.all(cal.rms_rel < 1e-10)


def test_fit_uncertainty_covers_the_truth():
    t0, k = _truth()
    cal = fit_bench_calibration(_series(t0, k, 0.003), LEVELS, GEOMETRY, 500.0)
    # 16 cells, each inside 4 standard errors (probability of a false failure < 1e-3).
    assert np.all(np.abs(cal.k - k) < 4 * cal.k_sigma)
    assert np.all(np.abs(cal.t0 - t0) < 4 * cal.t0_sigma)
    assert np.median(cal.rms_rel) == pytest.approx(0.003, rel=0.5)


def test_estimate_inverts_and_rejects_an_intrusion():
    t0, k = _truth()
    cal = fit_bench_calibration(_series(t0, k, 0.002), LEVELS, GEOMETRY, 500.0)
    frame = t0 * np.exp(-k * 2.5) * (1 + 0.002 * np.random.default_rng(5).standard_normal((4, 4)))
    frame[0, :2] *= 0.3                    # an object piece darkens two cells
    est = estimate_concentration(frame, cal)
    assert sorted(est.rejected_cells) == [(0, 0), (0, 1)] and est.n_used == 14
    # 14 cells with 0.2 % noise (about 0.01 g/kg each at k = 0.2 per g/kg) plus fit error: 4 sigma.
    assert abs(est.conc_g_per_kg - 2.5) < 4 * est.uncertainty_g_per_kg
    assert est.uncertainty_g_per_kg < 0.01


def test_reference_reanchors_a_changed_setup_and_warns():
    t0, k = _truth()
    cal = fit_bench_calibration(_series(t0, k, 0.001), LEVELS, GEOMETRY, 500.0)
    shifted = 0.9 * t0                     # another day: 10 % less light reaches the crop
    reference = shifted.copy()
    reference[3, 3] *= 0.5                 # a bubble in the reference frame
    anchored = reanchor_t0(reference, cal)
    assert np.allclose(anchored[:3], shifted[:3]) and anchored[3, 3] == pytest.approx(shifted[3, 3], rel=2e-3)
    frame = shifted * np.exp(-k * 1.5)
    assert estimate_concentration(frame, cal, reference_cells=reference).conc_g_per_kg == pytest.approx(1.5, abs=5e-3)
    assert estimate_concentration(frame, cal).conc_g_per_kg > 1.9     # without re-anchoring: off by ln(1/0.9)/k
    _, message = reference_offset(reference, cal)
    assert message is not None and "reference frame reads" in message
    assert reference_offset(t0, cal)[1] is None


def test_json_round_trip(tmp_path):
    t0, k = _truth()
    cal = fit_bench_calibration(_series(t0, k, 0.002), LEVELS, GEOMETRY, 500.0, {"iso": "160"},
                                image_shape=(536, 800), reduce=2)
    cal.save(tmp_path / "cal.json")
    back = BenchCalibration.load(tmp_path / "cal.json")
    assert back.geometry == GEOMETRY and back.image_shape == (536, 800) and back.reduce == 2
    assert back.camera == {"iso": "160"} and np.array_equal(back.good, cal.good)
    assert np.allclose(back.k, cal.k) and np.allclose(back.cov_t0_k, cal.cov_t0_k)


def test_guards():
    t0, k = _truth()
    with pytest.raises(AnalysisError, match="at least 3 distinct"):
        fit_bench_calibration(_series(t0, k, 0.0)[:4], LEVELS[:4], GEOMETRY, 500.0)
    with pytest.raises(AnalysisError, match="does not match"):
        fit_bench_calibration(_series(t0, k, 0.0), LEVELS[:5], GEOMETRY, 500.0)
    with pytest.raises(AnalysisError, match="positive"):
        fit_bench_calibration(-_series(t0, k, 0.0), LEVELS, GEOMETRY, 500.0)
    cal = fit_bench_calibration(_series(t0, k, 0.001), LEVELS, GEOMETRY, 500.0)
    with pytest.raises(AnalysisError, match="grid"):
        estimate_concentration(np.ones((3, 3)), cal)


def test_load_refuses_other_files(tmp_path):
    (tmp_path / "x.json").write_text('{"format": "something else"}')
    with pytest.raises(AnalysisError, match="not a bench calibration"):
        BenchCalibration.load(tmp_path / "x.json")
    with pytest.raises(AnalysisError, match="cannot read"):
        BenchCalibration.load(tmp_path / "missing.json")
