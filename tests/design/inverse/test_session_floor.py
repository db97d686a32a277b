"""Every optimiser session of an extruded design starts inside the bounds (`design.inverse.optimize.SESSION_FLOOR`):
with the cosine map a variable at exactly 0 or 1 has a zero gradient in z, so a design binary in rho_hat stalls every
later session.

Known answers: a separable quadratic whose minimum is rho_hat = 1/2 everywhere, started from a binary design
(the floor: the minimum, to 1e-9; no floor: the start, unchanged), and an extruded disc grown to the disc whose
release is the target (the floor: J down twentyfold within 80 evaluations; no floor: the start's J)."""
from types import SimpleNamespace

import numpy as np
import pytest

from design.forward.simulator import simulate
from design.inverse import optimize
from design.inverse.config import DesignConfig
from design.inverse.objective import DesignObjective
from design.inverse.optimize import optimise
from design.inverse.spaces import SpaceRequest, extruded_space
from design.inverse.status import DesignStatus


class _Store:
    def save(self, checkpoint, *, wait=True):
        pass

    def wait(self):
        pass


class _Quadratic:
    """J = sum (rho_hat - 1/2)^2 over an (8, 8) field; the minimum J = 0 at rho_hat = 1/2."""

    def __init__(self):
        self.space = SimpleNamespace(name="extruded", var_shape=(8, 8), fab_term=None)
        self.beta = 3.0

    def evaluate(self, x):
        r = x - 0.5
        value = float(np.sum(r * r))
        terms = {"J": value, "J_fit": value, "J_binary": 0.0, "J_fab": 0.0, "grad_norm": float(np.linalg.norm(2 * r))}
        return SimpleNamespace(value=value, terms=terms, grad=2.0 * r)


def _binary(shape):
    x = np.zeros(shape)
    x[::2] = 1.0  # rows of exact 0 and 1
    return x


def _config(**kw):
    return DesignConfig(target="sphere", space="extruded", physical_correction="none", **kw)


@pytest.mark.parametrize("optimizer", ["lbfgs", "LD_LBFGS"])
def test_a_binary_start_reaches_the_quadratics_minimum(optimizer):
    objective = _Quadratic()
    config = _config(max_iter=60, beta=3.0, beta_final=3.0, optimizer=optimizer)
    problem = SimpleNamespace(space=objective.space, start_region=None)
    outcome = optimise(objective, problem, config, _Store(), start=lambda o, p: _binary(o.space.var_shape))
    assert outcome.best_value < 1e-9
    np.testing.assert_allclose(outcome.best_x, 0.5, atol=1e-4)


def test_without_the_floor_a_binary_start_stalls(monkeypatch):
    monkeypatch.setattr(optimize, "SESSION_FLOOR", {"extruded": 0.0})
    objective = _Quadratic()
    config = _config(max_iter=60, beta=3.0, beta_final=3.0)
    problem = SimpleNamespace(space=objective.space, start_region=None)
    start = _binary(objective.space.var_shape)
    outcome = optimise(objective, problem, config, _Store(), start=lambda o, p: start)
    assert outcome.best_value == pytest.approx(16.0, rel=1e-12)  # 64 variables, (1/2)^2 each: not moved
    np.testing.assert_allclose(outcome.best_x, start, atol=1e-12)


def _disc_case():
    """An extruded (12, 12, 4) quadrant grid; the target is the release of a binary disc of radius 8 voxels, the start
    a binary disc of radius 5 (identity filter, no J_binary: rho = rho_hat at 0 and 1)."""
    space = extruded_space(SpaceRequest((24, 24, 4), 1.0))
    centres = np.hypot(*np.meshgrid(np.arange(12) + 0.5, np.arange(12) + 0.5, indexing="ij"))
    target = simulate(space.to_grid((centres <= 8.0).astype(float)), 1.0, mirror=space.mirror, total_time_mm=8.0,
                      dtau_mm=0.05).released_mm3
    objective = DesignObjective(space, target, 8.0, radius_vox=1.0, beta=12.0, w_binary=0.0)
    problem = SimpleNamespace(space=space, start_region=None)
    return objective, problem, (centres <= 5.0).astype(float)


@pytest.mark.parametrize("floor, gain", [(None, 20.0), (0.0, 1.0)])
def test_a_binary_extruded_disc_grows_to_the_target_only_with_the_floor(monkeypatch, floor, gain):
    if floor is not None:
        monkeypatch.setattr(optimize, "SESSION_FLOOR", {"extruded": floor})
    objective, problem, start = _disc_case()
    j_start = objective.evaluate(start).value
    config = _config(max_iter=80, beta=12.0, beta_final=12.0)
    outcome = optimise(objective, problem, config, _Store(), start=lambda o, p: start)
    if floor is None:  # the default floor: J falls at least twentyfold
        assert outcome.best_value < j_start / gain
    else:  # no floor: the gradient in z is zero to round-off and the run ends at its start
        assert outcome.best_value == pytest.approx(j_start, rel=1e-12)
        assert outcome.status in (DesignStatus.STALLED, DesignStatus.CONVERGED)  # ended early, far from J = 0


def test_nfc_sessions_keep_their_variables():
    objective = _Quadratic()
    objective.space.name = "nfc"
    config = _config(max_iter=60, beta=3.0, beta_final=3.0)
    problem = SimpleNamespace(space=objective.space, start_region=None)
    outcome = optimise(objective, problem, config, _Store(), start=lambda o, p: _binary(o.space.var_shape))
    assert outcome.best_value == pytest.approx(16.0, rel=1e-12)
