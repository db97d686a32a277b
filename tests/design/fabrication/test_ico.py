"""The incremental-compliance term (section 3.6): gradient, layers, warm starts, space, objective, presets."""
import numpy as np
import pytest

from design.errors import DesignError
from design.fabrication.ico import IcoConfig, IcoTerm, incremental_compliance, layer_tops
from design.forward.simulator import simulate, total_time
from design.inverse.config import DesignConfig
from design.inverse.objective import DesignObjective
from design.inverse.presets import PRESET_NAMES, preset_values
from design.inverse.problem import prepare
from design.inverse.spaces import SpaceRequest, build_space
from tests.design.gradcheck import assert_gradient_matches_fd


@pytest.mark.parametrize("coarsen,law,mirror", [(1, "simp", (True, True)), (2, "ramp", (True, False)),
                                                (2, "simp", (False, False))])
def test_ico_gradient_matches_central_differences(coarsen, law, mirror):
    """Directional derivatives along random directions; the solves are converged to 1e-12 so the
    FD error is truncation (O(h^2) ~ 1e-12) and round-off (~1e-16 J / h ~ 1e-10 relative)."""
    rng = np.random.default_rng(3)
    rho = rng.uniform(0.1, 0.9, (6, 5, 8))  # 5 voxels in y: padded with void up to the factor
    config = IcoConfig(layers=4, coarsen=coarsen, law=law, tol=1e-12, warm_start=False)
    result, _ = incremental_compliance(rho, 0.5, config, mirror=mirror)
    assert result.grad.shape == rho.shape and result.value > 0
    assert result.value == pytest.approx(result.compliances.sum() / 8.0)
    for _ in range(3):
        d = rng.standard_normal(rho.shape)
        h = 1e-6
        plus = incremental_compliance(rho + h * d, 0.5, config, mirror=mirror)[0].value
        minus = incremental_compliance(rho - h * d, 0.5, config, mirror=mirror)[0].value
        assert np.vdot(result.grad, d) == pytest.approx((plus - minus) / (2 * h), rel=1e-6)


def test_partial_designs_ignore_material_above_them():
    rng = np.random.default_rng(4)
    rho = rng.uniform(0.2, 0.9, (4, 4, 8))
    config = IcoConfig(layers=4, coarsen=1, tol=1e-12, warm_start=False)
    base, _ = incremental_compliance(rho, 1.0, config)
    changed = rho.copy()
    changed[:, :, 6:] = 0.05  # only the top layer (z voxels 6, 7) differs
    other, _ = incremental_compliance(changed, 1.0, config)
    assert np.allclose(other.compliances[:3], base.compliances[:3], rtol=1e-9)
    assert not np.isclose(other.compliances[3], base.compliances[3])
    assert layer_tops(8, 4) == [2, 4, 6, 8]
    with pytest.raises(DesignError, match="9 layers need"):
        layer_tops(8, 9)


def test_overhang_costs_more_than_the_same_mass_on_the_plate():
    """A roof held by a thin post (an overhang) is far more compliant than a block of equal mass."""
    config = IcoConfig(layers=4, coarsen=1)
    tee = np.full((8, 8, 8), 1e-3)
    tee[:2, :2, :] = 1.0  # post at the mirror axes
    tee[:, :, 6:] = 1.0  # overhanging roof
    solid = int(np.sum(tee > 0.5))
    block = np.full((8, 8, 8), 1e-3)
    flat = block.transpose(2, 1, 0).reshape(-1)  # z slowest: fills up from the plate
    flat[:solid] = 1.0
    block = flat.reshape(8, 8, 8).transpose(2, 1, 0)
    assert int(np.sum(block > 0.5)) == solid and block[:, :, 0].min() == 1.0
    j_tee, _ = incremental_compliance(tee, 1.0, config)
    j_block, _ = incremental_compliance(block, 1.0, config)
    assert j_tee.value > 3.0 * j_block.value


def test_warm_start_reuses_the_previous_solutions_and_normalises():
    rng = np.random.default_rng(5)
    rho = rng.uniform(0.2, 0.9, (16, 16, 24))  # 17 x 17 x 25 nodes: a multigrid hierarchy
    term = IcoTerm(0.5, IcoConfig(layers=4, coarsen=1))
    with pytest.raises(DesignError, match="no reference"):
        term(rho)
    reference = term.normalise_at(rho)
    cold = term.last.iterations.copy()
    value, grad = term(rho)
    assert value == pytest.approx(1.0, rel=1e-6) and np.all(term.last.iterations == 0)
    assert np.allclose(grad * reference, term.last.grad)
    term(rho * 0.99 + 0.005)
    assert term.last.iterations.sum() < cold.sum() and term.seconds > 0
    with pytest.raises(DesignError, match="no incremental compliance"):
        IcoTerm(0.5).normalise_at(np.zeros((4, 4, 16)))


def test_threaded_warm_evaluation_matches_the_sequential_cold_one():
    """Warm-started layers are solved concurrently (one thread per core); cold ones in sequence, each
    from the layer below. Both reach the same solution, and the threaded one is reproducible."""
    rng = np.random.default_rng(7)
    rho = rng.uniform(0.0, 1.0, (12, 12, 16))
    config = IcoConfig(layers=4, coarsen=1, tol=1e-10)
    _, solutions = incremental_compliance(rho, 0.5, config)
    moved = 0.98 * rho + 0.01
    cold = incremental_compliance(moved, 0.5, config)[0]
    warm = [incremental_compliance(moved, 0.5, config, warm=solutions)[0] for _ in range(2)]
    assert warm[0].value == pytest.approx(cold.value, rel=1e-8) and np.all(warm[0].iterations > 0)
    assert np.abs(warm[0].grad - cold.grad).max() <= 1e-7 * np.abs(cold.grad).max()
    assert warm[0].value == warm[1].value and np.array_equal(warm[0].grad, warm[1].grad)


def test_ico_space_and_objective_gradient_with_robust_and_rate_terms():
    request = SpaceRequest((8, 8, 16), 0.5, ico=IcoConfig(layers=4, coarsen=2, tol=1e-11))
    space = build_space("ico", request)
    assert space.grid_shape == (4, 4, 16) and space.mirror == (True, True, False) and space.fab_term.name == "ICO"
    big_t = total_time(space.grid_shape, space.dx_mm, space.mirror)
    target = simulate(np.full(space.grid_shape, 0.4), space.dx_mm, mirror=space.mirror,
                      total_time_mm=big_t).released_mm3
    objective = DesignObjective(space, target, big_t, radius_vox=1.5, beta=3.0, w_binary=20.0, w_fab=50.0,
                                w_rate=3.0, robust_eta=0.1, rate_span=(0.05, 0.95))
    start = objective.uniform_start()
    assert objective.evaluate(start).terms["J_fab"] == pytest.approx(1.0, rel=1e-6)  # normalised at the start
    rng = np.random.default_rng(6)
    x = rng.uniform(0.2, 0.8, space.var_shape)
    ev = objective.evaluate(x)
    assert ev.terms["J_fab"] > 0 and ev.terms["fab_seconds"] > 0
    assert_gradient_matches_fd(objective, x, ev.grad, rng, entries=4)


def test_presets_fill_unset_fields_and_name_themselves():
    config = DesignConfig(target="pill", space="ico", preset="paper:pill")
    assert (config.w_binary, config.w_fab, config.radius_vox, config.beta) == (30.0, 120.0, 5.0, 3.0)
    config = DesignConfig(target="pill", space="ico", preset="paper:pill", w_fab=7.0)
    assert config.w_fab == 7.0
    ext = DesignConfig(target="zero-order", space="extruded", preset="paper:design-4")
    assert ext.height_fraction == pytest.approx(200 / 256) and ext.w_binary == 10.0 and ext.beta == 9.0
    nfc = DesignConfig(target="sphere", space="nfc", preset="paper:sphere")
    assert nfc.w_fab == 0.0 and nfc.w_binary == 30.0
    assert len(PRESET_NAMES) == 13 and preset_values("paper:csg-1", "ico")["w_fab"] == 200.0
    with pytest.raises(DesignError, match="unknown preset 'paper:cube'"):
        DesignConfig(target="sphere", space="ico", preset="paper:cube")
    with pytest.raises(DesignError, match="only the ico space"):
        DesignConfig(target="sphere", space="nfc", w_fab=5.0)
    with pytest.raises(DesignError, match="stiffness law"):
        DesignConfig(target="sphere", space="ico", stiffness_law="linear")


def test_an_ico_domain_stands_the_source_on_the_plate():
    problem = prepare(DesignConfig(target="pill", space="ico", resolution=24, layers=4))
    layers = np.flatnonzero(problem.source_solid.any(axis=(0, 1)))
    assert layers[0] == 0 and layers[-1] < problem.full_shape[2] - 2  # margin above only
    assert problem.space.mirror == (True, True, False)
