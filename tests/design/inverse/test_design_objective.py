"""The full objective of eq. (4): gradient through filters, projection, binary term, replication."""
from dataclasses import replace

import numpy as np
import pytest

from design.errors import DesignError
from design.forward.simulator import simulate, total_time
from design.inverse.filters import project
from design.inverse.objective import DesignObjective, rel_rmse
from design.inverse.rate import rate_fit, rate_shape_fit
from design.inverse.spaces import SpaceRequest, build_space
from tests.design.gradcheck import assert_gradient_matches_fd


def _objective(name, request, w_fab=0.0, fab=None, w_rate=0.0, robust_eta=0.0, rate_span=(0.0, 1.0), w_conn=0.0):
    space = build_space(name, request)
    if fab is not None:
        space = replace(space, fab_term=fab)
    big_t = total_time(space.grid_shape, space.dx_mm, space.mirror)
    target = simulate(np.full(space.grid_shape, 0.4), space.dx_mm, mirror=space.mirror,
                      total_time_mm=big_t).released_mm3
    return DesignObjective(space, target, big_t, radius_vox=2.0, beta=3.0, w_binary=20.0, w_fab=w_fab,
                           w_rate=w_rate, robust_eta=robust_eta, rate_span=rate_span, w_conn=w_conn)


class _QuadraticFab:
    """A stand-in J_fab = sum(rho^2) for checking the hook's gradient plumbing."""

    name = "quadratic"
    seconds = 0.0

    def normalise_at(self, rho):
        return 1.0

    def __call__(self, rho):
        return float(np.sum(rho ** 2)), 2.0 * rho


@pytest.mark.parametrize("name, request_, fab, w_rate, robust_eta, w_conn", [
    ("nfc", SpaceRequest((12, 12, 12), 0.5), None, 0.0, 0.0, 0.0),
    ("extruded", SpaceRequest((12, 10, 8), 0.5, 5), None, 0.0, 0.0, 0.0),
    ("nfc", SpaceRequest((10, 10, 10), 0.5), _QuadraticFab(), 0.0, 0.0, 0.0),
    ("nfc", SpaceRequest((12, 12, 12), 0.5), None, 3.0, 0.0, 0.0),
    ("extruded", SpaceRequest((12, 10, 8), 0.5, 5), None, 3.0, 0.0, 0.0),
    ("nfc", SpaceRequest((12, 12, 12), 0.5), _QuadraticFab(), 3.0, 0.1, 0.0),
    ("nfc", SpaceRequest((12, 12, 12), 0.5), None, 0.0, 0.0, 30.0),
    ("extruded", SpaceRequest((12, 10, 8), 0.5, 5), None, 0.0, 0.0, 30.0),
])
def test_full_objective_gradient_matches_central_differences(name, request_, fab, w_rate, robust_eta, w_conn):
    # the robust case also restricts J_rate to the target's 5%-95%
    objective = _objective(name, request_, w_fab=1.5 if fab else 0.0, fab=fab, w_rate=w_rate,
                           robust_eta=robust_eta, rate_span=(0.05, 0.95) if robust_eta else (0.0, 1.0),
                           w_conn=w_conn)
    rng = np.random.default_rng(4)
    x = rng.uniform(0.2, 0.8, objective.space.var_shape)
    ev = objective.evaluate(x)
    assert_gradient_matches_fd(objective, x, ev.grad, rng, entries=5)


def test_uniform_start_matches_target_mass():
    objective = _objective("extruded", SpaceRequest((12, 10, 8), 0.5, 5))
    x0 = objective.uniform_start()
    space = objective.space
    mass = objective.density(x0).sum() * space.dx_mm ** 3 * space.multiplicity
    assert np.ptp(x0) == 0.0
    assert mass == pytest.approx(objective.target_mm3[-1], rel=1e-9)


def test_rel_rmse_is_relative_to_final_value():
    target = np.linspace(0.0, 10.0, 11)
    assert rel_rmse(target + 0.1, target) == pytest.approx(0.01)


def test_objective_guards():
    space = build_space("nfc", SpaceRequest((8, 8, 8), 1.0))
    target = np.linspace(0, 1, 11)
    with pytest.raises(DesignError, match="no fabrication term"):
        DesignObjective(space, target, 4.0, radius_vox=2.0, beta=3.0, w_binary=1.0, w_fab=1.0)
    with pytest.raises(DesignError, match="beta > 0"):
        DesignObjective(space, target, 4.0, radius_vox=2.0, beta=0.0, w_binary=1.0)
    with pytest.raises(DesignError, match="positive end"):
        DesignObjective(space, np.zeros(11), 4.0, radius_vox=2.0, beta=3.0, w_binary=1.0)
    with pytest.raises(DesignError, match="robust_eta"):
        DesignObjective(space, target, 4.0, radius_vox=2.0, beta=3.0, w_binary=1.0, robust_eta=0.45)


def test_robust_objective_adds_the_rate_shape_of_the_eroded_and_dilated_designs():
    request = SpaceRequest((10, 10, 10), 0.5)
    robust = _objective("nfc", request, w_rate=2.0, robust_eta=0.1, rate_span=(0.05, 0.95))
    x = np.random.default_rng(5).uniform(0.2, 0.8, robust.space.var_shape)
    ev = robust.evaluate(x)
    space, smoothed, s3 = robust.space, robust.filter.apply(x), robust.scale ** 3
    args = (robust.dtau_mm * robust.scale, robust.rate_lag, robust.rate_time_scale_mm * robust.scale,
            robust.rate_samples)
    rates = []
    for eta in (0.4, 0.5, 0.6):
        curve = simulate(project(smoothed, robust.beta, eta), space.dx_mm, mirror=space.mirror,
                         total_time_mm=robust.total_time_mm).released_mm3
        measure = rate_fit if eta == 0.5 else rate_shape_fit
        rates.append(measure(curve * s3, robust.target_mm3 * s3, *args)[0])
    assert ev.terms["J_rate"] == pytest.approx(np.mean(rates), rel=1e-12)
    # J_fit, J_binary and the reported density are the nominal design's
    nominal = _objective("nfc", request, w_rate=2.0, rate_span=(0.05, 0.95)).evaluate(x)
    np.testing.assert_array_equal(ev.rho, nominal.rho)
    assert ev.terms["J_fit"] == nominal.terms["J_fit"]
    assert ev.terms["J_binary"] == nominal.terms["J_binary"]
    with pytest.raises(DesignError, match="needs w_rate > 0"):
        _objective("nfc", request, robust_eta=0.1)




def test_objective_simulates_on_the_targets_own_tau_step():
    # a 501-sample target: the objective must simulate with dtau = T / 500, not the default T / 1000
    space = build_space("nfc", SpaceRequest((8, 8, 8), 0.5))
    big_t = total_time(space.grid_shape, space.dx_mm, space.mirror)
    target = simulate(np.full(space.grid_shape, 0.4), space.dx_mm, mirror=space.mirror, total_time_mm=big_t,
                      dtau_mm=big_t / 500).released_mm3
    assert target.size == 501
    objective = DesignObjective(space, target, big_t, radius_vox=2.0, beta=3.0, w_binary=1.0)
    ev = objective.evaluate(np.full(space.var_shape, 0.5))
    assert ev.release.released_mm3.size == 501 and np.isfinite(ev.value)


def test_connectivity_term_is_the_weighted_penalty_of_the_nominal_design():
    request = SpaceRequest((12, 10, 8), 0.5, 5)
    plain = _objective("extruded", request)
    connected = _objective("extruded", request, w_conn=30.0)
    x = np.random.default_rng(3).uniform(0.2, 0.8, plain.space.var_shape)
    a, b = plain.evaluate(x), connected.evaluate(x)
    assert b.terms["J_conn"] > 0 and a.terms["J_conn"] == 0.0
    assert b.value == pytest.approx(a.value + 30.0 * b.terms["J_conn"], rel=1e-12)


def test_a_3d_design_solves_j_conn_on_blocks_of_half_the_radius_with_an_exact_gradient():
    # radius 3 voxels: J_conn's distances on blocks of 2 (an eighth of the release's grid), 2D designs keep blocks of 1
    space = build_space("nfc", SpaceRequest((16, 16, 16), 0.5))
    big_t = total_time(space.grid_shape, space.dx_mm, space.mirror)
    target = simulate(np.full(space.grid_shape, 0.4), space.dx_mm, mirror=space.mirror, total_time_mm=big_t).released_mm3
    objective = DesignObjective(space, target, big_t, radius_vox=3.0, beta=3.0, w_binary=20.0, w_conn=30.0)
    assert objective.connectivity.coarsen == 2
    assert _objective("extruded", SpaceRequest((12, 10, 8), 0.5, 5), w_conn=30.0).connectivity.coarsen == 1
    rng = np.random.default_rng(5)
    x = rng.uniform(0.2, 0.8, space.var_shape)
    ev = objective.evaluate(x)
    assert ev.terms["J_conn"] > 0
    assert_gradient_matches_fd(objective, x, ev.grad, rng, entries=5)
