"""A measured curve becomes a feasible design target: its monotone least-squares fit, projected onto the
isoperimetric bound the feasibility check applies, changed by no more than the measurement's noise, and designed
from by `sfr design --target RUN` without --allow-infeasible.

The measured curves are the simulated bench's objects (forward model at resolution 48, the hidden material's
scales) sampled every 30 s with noise of 0.2-1 % of the mass, as in tests/labapp/jobs/test_simcal_job.py.
"""
import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from analysis.simcal import SimCal
from design.files.targets_io import load_problem
from design.inverse.config import DesignConfig
from design.inverse.targets import Target, isoperimetric_bound, isotonic_fit, project_isoperimetric
from labapp.acquisition.simbench import Material, sample_release
from labapp.jobs.physical import TARGET_CSV, TARGET_SLACK, adjustment_line, read_measured_target, write_target_csv
from labapp.records.curvefiles import PhysicalCurve
from labapp.records.simcal import FORMAT, FORWARD_MODEL, SimCalFile

MATERIAL = Material(1850.0, 1.24)
SIMCAL = SimCalFile(SimCal("constant", 1850.0, 1.24e-3), 32, 0.5, 500.0, Path("simcal.json"))


def _isotonic_brute(y, w=None):
    """The min-max formula of (weighted) isotonic regression: x_i = max_{j<=i} min_{k>=i} mean of y[j..k]."""
    n, w = len(y), np.ones(len(y)) if w is None else np.asarray(w, float)
    return np.array([max(min(np.average(y[j:k + 1], weights=w[j:k + 1]) for k in range(i, n)) for j in range(i + 1))
                     for i in range(n)])


def test_isotonic_fit_is_the_least_squares_monotone_sequence():
    assert isotonic_fit(np.array([1.0, 3.0, 2.0, 4.0])).tolist() == [1.0, 2.5, 2.5, 4.0]
    rng = np.random.default_rng(3)
    for _ in range(20):
        y = np.cumsum(rng.normal(0.2, 1.0, 12))
        np.testing.assert_allclose(isotonic_fit(y), _isotonic_brute(y), rtol=0, atol=1e-12)
    y = np.sort(rng.normal(size=30))
    assert np.array_equal(isotonic_fit(y), y)                  # already monotone: unchanged
    plateau = np.array([0.0, 1.0, 2.0, 2.0, 1.9, 2.1, 2.0, 2.6])    # a noisy plateau ending on a high sample
    assert isotonic_fit(plateau)[-1] == 2.6                    # unconstrained: the end is that one sample
    np.testing.assert_allclose(isotonic_fit(plateau, end_block=5), [0.0, 1.0, 2.0] + [2.12] * 5)  # the last 5 pooled
    for _ in range(20):       # = the least-squares fit with the last 4 equal: their mean, weighted 4
        y = np.cumsum(rng.normal(0.2, 1.0, 12))
        fit = _isotonic_brute(np.concatenate([y[:8], [np.mean(y[8:])]]), [1.0] * 8 + [4.0])
        np.testing.assert_allclose(isotonic_fit(y, end_block=4), np.concatenate([fit, [fit[-1]] * 3]), atol=1e-12)


def _sphere(tau, radius):
    """A sphere's release, mm^3: exactly on the isoperimetric bound (section 5.2)."""
    return 4.0 / 3.0 * np.pi * (radius ** 3 - np.clip(radius - tau, 0.0, None) ** 3)


def test_the_projection_keeps_a_feasible_curve_and_puts_a_slow_one_on_the_bound():
    tau = np.linspace(0.0, 6.0, 601)
    sphere = _sphere(tau, 5.0)                                 # ends at tau = 5, flat after
    assert np.array_equal(project_isoperimetric(tau, sphere, 0.05), sphere)
    slow = _sphere(tau / 1.2, 5.0)                             # 1.2 times slower: rate/bound 1/1.2 = 0.83
    projected = project_isoperimetric(tau, slow, 0.05)
    assert projected[-1] == slow[-1] and np.all(projected <= slow) and np.all(np.diff(projected) >= 0)
    rate, bound = isoperimetric_bound(Target(tau, projected, "projected"))
    left = projected[-1] - 0.5 * (projected[1:] + projected[:-1])
    live = (left > 0.02 * projected[-1]) & (projected[:-1] > 0.0)   # not in the tail, nor at a flat start
    assert np.min(rate[live] / bound[live]) >= 0.95 - 1e-9
    moved = live & (projected[1:] < slow[1:])                  # intervals whose end the sweep lowered: on the bound
    np.testing.assert_allclose(rate[moved] / bound[moved], 0.95, rtol=1e-9)
    assert projected[0] == 0.0 and np.count_nonzero(projected == 0.0) > 1      # 1.2 x 5 mm > 5 mm: flat start


@pytest.fixture(scope="module")
def releases():
    return {s: sample_release(s, index=7, resolution=48, material=MATERIAL) for s in ("sphere", "polyhedron")}


def _measured(release, noise_pct, seed):
    rng = np.random.default_rng(seed)
    t = np.arange(30.0, 1.15 * release.duration_s, 30.0)
    truth = np.interp(t, release.t_s, release.released_g, left=0.0)
    return t, truth, truth + noise_pct / 100.0 * release.mass_g * rng.standard_normal(t.size)


@pytest.mark.slow
@pytest.mark.parametrize("shape, noise_pct", list(itertools.product(("sphere", "polyhedron"), (0.2, 1.0))))
def test_a_noisy_measured_curve_becomes_feasible_within_its_noise(tmp_path, releases, shape, noise_pct):
    release = releases[shape]
    t, truth, grams = _measured(release, noise_pct, 1)
    sigma = noise_pct / 100.0 * release.mass_g
    # the cause: made non-decreasing by a running maximum, the noise leaves flat stretches below the bound
    ratchet = np.concatenate([[0.0], np.maximum.accumulate(np.clip(grams, 0.0, None))])
    tau, vol = SIMCAL.cal.to_simulation(np.concatenate([[0.0], t]), ratchet, 500.0)
    (tmp_path / "ratchet.csv").write_text("tau_mm,released_mm3\n" + "".join(f"{a},{b}\n" for a, b in zip(tau, vol)))
    assert not load_problem(DesignConfig(target=str(tmp_path / "ratchet.csv"), resolution=36)).feasibility.feasible

    written = write_target_csv(PhysicalCurve(t, grams, release.mass_g, 500.0, "measured"), SIMCAL,
                               tmp_path / "target.csv")
    for resolution in (24, 36, 64):
        feasibility = load_problem(DesignConfig(target=str(written.csv), resolution=resolution)).feasibility
        assert feasibility.feasible, (resolution, feasibility.text())
    rows = np.genfromtxt(written.csv, delimiter=",", names=True)
    assert rows.dtype.names == ("tau_mm", "released_mm3", "t_s", "target_g")
    adjusted = np.interp(t, rows["t_s"], rows["target_g"])
    # within the noise: of the truth, of the measurement, and the projection's own share
    assert np.max(np.abs(adjusted - truth)) < 4.0 * sigma
    assert np.sqrt(np.mean((adjusted - grams) ** 2)) < 2.0 * sigma
    assert written.projection_max_g < 4.0 * sigma and written.fit_max_g < 5.0 * sigma
    assert written.noise_g == pytest.approx(sigma, rel=0.15)
    notes = json.loads(written.csv.with_suffix(".json").read_text())
    assert notes["mass_basis"] == "weighed" and notes["mass_g"] == pytest.approx(release.mass_g)
    assert notes["projection_max_pct"] == pytest.approx(100.0 * written.projection_max_g / release.mass_g)
    assert f"relaxed by {TARGET_SLACK:g}" in notes["method"] and "% of the weighed mass" in notes["text"]


@pytest.mark.slow
def test_sfr_design_takes_a_measured_run_without_the_override(tmp_path, releases, capsys):
    from labapp.cli.main import main

    release = releases["polyhedron"]
    t, _, grams = _measured(release, 0.5, 2)
    run = tmp_path / "run"
    run.mkdir()
    np.savetxt(run / "curve.csv", np.column_stack([t, grams, grams / 0.5]), delimiter=",", comments="",
               header="t_s,released_g,conc_g_per_kg", fmt="%.6f")
    simcal = tmp_path / "simcal.json"
    simcal.write_text(json.dumps({"format": FORMAT, "forward_model": FORWARD_MODEL, "model": "constant",
                                  "physics": {"anisotropy": 1.0, "offset_mm": 0.0}, "seconds_per_mm": 1850.0,
                                  "g_per_mm3": 1.24e-3, "resolution": 32, "voxel_size_mm": 0.5, "water_g": 500.0}))
    out = tmp_path / "design"
    assert main(["design", "--target", str(run), "--simcal", str(simcal), "--resolution", "24", "--max-iter", "120",
                 "--out", str(out)]) == 0
    assert "target is feasible" in (out / "feasibility.txt").read_text()
    notes = json.loads((out / TARGET_CSV).with_suffix(".json").read_text())
    assert notes["points_lowered"] > 0 and notes["projection_max_pct"] < 2.0
    line = adjustment_line(read_measured_target(out / TARGET_CSV))      # the launcher's line, printed too
    assert line.startswith("Measured target adjusted") and line in capsys.readouterr().out.splitlines()
    assert json.loads((out / "summary.json").read_text())["simcal"]["model"] == "constant"
