"""design.montecarlo.erosion: the per-step probability of the Arrhenius law, seeds, convergence of the mean over
seeds, closed cavities, mirror unfolding, and the tuned model against the analytic release of a sphere."""
import math

import numpy as np
import pytest

from design import DesignError
from design.files.pipeline import input_grid
from design.montecarlo.erosion import GAS_CONSTANT, MonteCarloParams, default_dt_s, erosion_times, simulate_mc
from design.montecarlo.tuning import tune_mc, unit_runs


@pytest.fixture(scope="module")
def sphere():
    return input_grid("sample:sphere", resolution=16)


def test_a_lone_voxel_dissolves_after_a_geometric_number_of_steps():
    # p_b = 1 - exp(-dt A exp(-b Ea/RT)); a lone voxel has b = 0, two touching voxels b = 1 each
    params = MonteCarloParams(a_per_s=2.0, ea_j_per_mol=3000.0, temp_k=300.0)
    dt = 0.05
    p0 = 1 - math.exp(-dt * 2.0)
    lone = np.zeros((3, 3, 3))
    lone[1, 1, 1] = 1
    steps = np.array([np.nanmax(erosion_times(lone, params, seed=s, dt_s=dt)) / dt for s in range(600)])
    se = math.sqrt(1 - p0) / p0 / math.sqrt(steps.size)
    assert steps.mean() == pytest.approx(1 / p0, abs=4 * se)
    pair = np.zeros((3, 4, 3))
    pair[1, 1:3, 1] = 1
    p1 = 1 - math.exp(-dt * 2.0 * math.exp(-3000.0 / (GAS_CONSTANT * 300.0)))
    first = np.array([np.nanmin(erosion_times(pair, params, seed=s, dt_s=dt)) / dt for s in range(600)])
    q = 1 - (1 - p1) ** 2  # either of the two b = 1 voxels
    assert first.mean() == pytest.approx(1 / q, abs=4 * math.sqrt(1 - q) / q / math.sqrt(first.size))


def test_a_seed_reproduces_a_run_and_another_seed_differs(sphere):
    rho, dx, mirror = sphere
    params = MonteCarloParams(1.0, 5000.0)
    a = erosion_times(rho, params, seed=3, mirror=mirror)
    np.testing.assert_array_equal(a, erosion_times(rho, params, seed=3, mirror=mirror))
    assert not np.array_equal(a, erosion_times(rho, params, seed=4, mirror=mirror))
    np.testing.assert_array_equal(np.isnan(a), rho < 0.5)


def test_the_mean_curve_converges_as_seeds_are_added(sphere):
    rho, dx, _ = sphere
    params = MonteCarloParams(1.0, 5000.0)
    reference = simulate_mc(rho, dx, params, seeds=range(1000, 1256), samples=201)
    grid = reference.t_s

    def distance(n):
        """RMS distance of an n-seed mean to the 256-seed mean, averaged over 4 disjoint groups of seeds."""
        out = []
        for k in range(4):
            run = simulate_mc(rho, dx, params, seeds=range(k * n, (k + 1) * n), t_s=grid)
            out.append(np.sqrt(np.mean((run.released_mm3 - reference.released_mm3) ** 2)) / reference.volume_mm3)
        return float(np.mean(out))

    d1, d4, d16 = distance(1), distance(4), distance(16)
    # the standard error falls as 1/sqrt(n): 1/2 for 4 seeds, 1/4 for 16 (plus the reference's own 1/16)
    assert d4 < 0.7 * d1 and d16 < 0.4 * d1 and d16 < d4
    assert reference.released_std_mm3.max() > 0
    assert reference.released_mm3[-1] == pytest.approx(reference.volume_mm3)


def test_the_default_time_step_is_converged(sphere):
    # p = 1 - exp(-dt A exp(-b Ea/RT)) with synchronous steps converges as dt -> 0; the default dt (a kink
    # dissolves with probability 0.02 per step) stays within seed noise of dt/4, ten times it does not
    rho, dx, _ = sphere
    params = MonteCarloParams(1.0, 5000.0)
    dt = default_dt_s(params)
    fine = simulate_mc(rho, dx, params, seeds=range(200, 216), dt_s=dt / 4, samples=301)

    def distance(step):
        run = simulate_mc(rho, dx, params, seeds=range(16), dt_s=step, t_s=fine.t_s)
        return float(np.sqrt(np.mean((run.released_mm3 - fine.released_mm3) ** 2))) / fine.volume_mm3

    assert distance(dt) < 0.01  # 0.66 %: the difference of two 16-seed means is about 0.4 %
    assert distance(10 * dt) > 0.03  # 6 %


def test_a_closed_cavity_is_wetted_only_when_the_erosion_reaches_it():
    rho = np.ones((9, 9, 9))
    rho[3:6, 3:6, 3:6] = 0  # a cavity 3 voxels below every face
    lining = np.zeros_like(rho, bool)
    lining[2:7, 2:7, 2:7] = True
    lining[3:6, 3:6, 3:6] = False
    dt = 1.0
    for seed in range(5):
        times = erosion_times(rho, MonteCarloParams(1.0, 1000.0), seed=seed, dt_s=dt)
        # the two voxels above it must go, one per step, before a lining voxel touches solvent; a cavity
        # wetted from the start would expose all 98 lining voxels (p = 0.16 each) at step 1
        assert np.nanmin(times[lining]) >= 3 * dt
        assert np.isnan(times[3:6, 3:6, 3:6]).all() and np.isfinite(times[rho > 0]).all()


def test_mirrored_input_is_unfolded_to_the_whole_object():
    half, dx, mirror = input_grid("sample:sphere", resolution=16, symmetry="xyz")
    full, dx_full, _ = input_grid("sample:sphere", resolution=16)
    params = MonteCarloParams(1.0, 5000.0)
    a = simulate_mc(half, dx, params, mirror=mirror, seeds=4)
    assert a.dissolution_s.shape[1:] == tuple(2 * n for n in half.shape)
    assert a.volume_mm3 == pytest.approx(8 * (half >= 0.5).sum() * dx ** 3)


def test_tuned_on_the_analytic_sphere_it_stays_within_5_percent_rms():
    # The analytic release of a sphere whose surface recedes at a constant speed (the forward model's
    # assumption): fraction 1 - (1 - v t / R)^3, here dissolved in 3000 s. The lattice model is tuned
    # on it and must come within 5 % RMS (how close it comes:
    # docs/evidence/science.md#the-monte-carlo-baseline).
    rho, dx, mirror = input_grid("sample:sphere", resolution=24)
    radius = (3 * (rho >= 0.5).sum() * dx ** 3 / (4 * math.pi)) ** (1 / 3)
    t = np.linspace(0, 3000.0, 301)
    fraction = 1 - np.clip(1 - t / 3000.0, 0, None) ** 3
    tuning = tune_mc(unit_runs([(rho, dx, mirror)], seeds=4), [(t, fraction)])
    assert len(tuning.grid) == 16
    assert tuning.rms < 0.05
    assert tuning.rms <= tuning.grid_best.rms
    run = simulate_mc(rho, dx, tuning.params, seeds=range(10, 14), samples=401)
    model = np.interp(t, run.t_s, run.released_mm3 / run.volume_mm3, right=1.0)
    assert np.sqrt(np.mean((model - fraction) ** 2)) < 0.05  # fresh seeds, physical time
    assert tuning.params.dx_mm == pytest.approx(dx) and radius > 0


def test_parameters_are_checked_and_rescaled_with_the_voxel_size():
    with pytest.raises(DesignError, match="a_per_s must be finite and > 0"):
        MonteCarloParams(0.0, 1000.0)
    with pytest.raises(DesignError, match="ea_j_per_mol must be finite and >= 0"):
        MonteCarloParams(1.0, -1.0)
    with pytest.raises(DesignError, match="nothing to erode"):
        simulate_mc(np.zeros((4, 4, 4)), 1.0, MonteCarloParams(1.0, 0.0))
    tuned = MonteCarloParams(10.0, 5000.0, dx_mm=0.5)
    assert tuned.at_voxel_size(0.25).a_per_s == pytest.approx(20.0)
    assert MonteCarloParams.from_dict(tuned.to_dict()) == tuned
    with pytest.raises(DesignError, match="need numbers"):
        MonteCarloParams.from_dict({"a_per_s": 1.0})


def test_leave_one_out_tuning_ignores_the_left_out_curve(sphere):
    rho, dx, mirror = sphere
    runs = unit_runs([(rho, dx, mirror), (rho, dx, mirror)], ea_values=(5000.0,), seeds=2)
    t = np.linspace(0, 3000.0, 101)
    fraction = 1 - np.clip(1 - t / 3000.0, 0, None) ** 3
    unusable = (t, 0.1 * fraction)  # never reaches half its mass: refused when used
    alone = tune_mc(runs, [(t, fraction), unusable], subset=[0])
    assert len(alone.per_object_rms) == 1 and len(alone.grid) == 4
    with pytest.raises(DesignError, match="reaches only 10%"):
        tune_mc(runs, [(t, fraction), unusable])
    mean, spread = runs.fraction(5000.0, 0, alone.params.a_per_s, t)
    assert mean[0] == 0 and mean[-1] == pytest.approx(1.0, abs=0.02) and spread.max() > 0
