"""Defect correction (design.inverse.defect): a known bias is corrected, a resume inside a round repeats the run,
the rounds fit in the evaluation limit, bad settings are refused."""
import copy
from dataclasses import replace

import numpy as np
import pytest

import design.inverse.defect as defect
from design.errors import DesignError
from design.forward.simulator import simulate
from design.inverse.defect import RoundState, check_print, correction_plan, optimise_physical
from design.inverse.optimize import build_objective
from design.inverse.problem import DesignConfig, prepare
from design.inverse.targets import target_from_mesh

SMALL = dict(target="sphere", space="nfc", resolution=16, radius_vox=2.0, checkpoint_every=3)


class MemoryStore:
    """A checkpoint store that keeps copies of the last checkpoint."""

    def __init__(self):
        self.last = None

    def save(self, checkpoint, *, wait=True):
        self.last = copy.deepcopy(checkpoint)

    def wait(self):
        pass


class MemoryRounds:
    def __init__(self):
        self.states: list[RoundState] = []

    def load(self):
        return copy.deepcopy(self.states[-1]) if self.states else None

    def save(self, state):
        self.states.append(copy.deepcopy(state))


class DensityPrint:
    """A stand-in print: the design's density itself."""

    extents = np.ones(3)

    def __init__(self, rho):
        self.rho = rho


SHORTFALL = 0.02
"""The stand-in print releases this share less than the design grid at every tau."""


@pytest.fixture
def short_print(monkeypatch):
    """Prints that release `SHORTFALL` less than the design grid's density at every tau (as if the cut lost 2% of
    the material): the correction's fixed point is a density releasing C* / (1 - SHORTFALL) on the grid."""

    def install(problem):
        space, target = problem.space, problem.target
        dtau = target.total_time_mm / (target.tau_mm.size - 1)

        def release(mesh, tau_mm, cells=None):
            curve = simulate(mesh.rho, space.dx_mm, mirror=space.mirror, total_time_mm=target.total_time_mm,
                             dtau_mm=dtau).released_mm3
            return type("Reference", (), {"released_mm3": (1.0 - SHORTFALL) * curve})()

        monkeypatch.setattr(defect, "printed_mesh", lambda objective, problem, x: DensityPrint(objective.density(x)))
        monkeypatch.setattr(defect, "reference_release", release)
        monkeypatch.setattr(defect, "revoxelize", lambda mesh, *grid: space.unfold(mesh.rho) > 0.5)

    return install


def test_a_known_shortfall_of_the_print_is_corrected(short_print):
    config = DesignConfig(max_iter=140, correction_rounds=3, correction_evals=20, **SMALL)
    problem = prepare(config)
    # a target the design grid can meet: the sphere's own release on it
    reachable = target_from_mesh(problem.source_mesh, problem.dx_mm, problem.target.total_time_mm, "sphere on the grid",
                                 config.samples, origin_mm=problem.origin_mm, shape=problem.full_shape)
    problem = replace(problem, target=reachable)
    short_print(problem)
    rounds = MemoryRounds()
    outcome, objective = optimise_physical(build_objective(problem, config), problem, config, MemoryStore(), rounds)
    fits = rounds.states[-1].fits
    assert len(fits) == 4 and len(outcome.history) == 140
    # uncorrected, the print misses by about the shortfall's RMS; corrected, by the design grid's own fit
    assert fits[0] > 0.6 * SHORTFALL
    assert rounds.states[-1].best_fit < 0.3 * fits[0] and rounds.states[-1].best_fit == min(fits)
    check = check_print(objective, problem, outcome.best_x)
    assert check.fit == rounds.states[-1].best_fit
    # the design grid now releases about C* / (1 - shortfall): the round learned the bias
    final = problem.target.final_mm3
    assert check.grid_mm3[-1] == pytest.approx(final / (1.0 - SHORTFALL), rel=0.005)
    np.testing.assert_allclose(check.bias_mm3, SHORTFALL * check.grid_mm3, rtol=1e-12, atol=1e-9 * final)


def _history(outcome):
    return np.array(outcome.history)[:, :-1]  # all but the seconds


@pytest.mark.parametrize("at", [48, 49, 55, 63])
def test_a_run_resumed_inside_a_round_repeats_the_uninterrupted_one(short_print, at):
    # 64 evaluations: the first optimisation 48, then two rounds of 8; stopped where the first round begins
    # (48: before it has checkpointed), one evaluation into it, inside it, and inside the second round
    config = DesignConfig(max_iter=64, correction_rounds=2, correction_evals=8, **SMALL)
    problem = prepare(config)
    short_print(problem)
    assert correction_plan(config) == (2, 48)
    whole, _ = optimise_physical(build_objective(problem, config), problem, config, MemoryStore(), MemoryRounds())
    store, rounds, calls = MemoryStore(), MemoryRounds(), []
    first, _ = optimise_physical(build_objective(problem, config), problem, config, store, rounds,
                                 should_stop=lambda: len(calls) >= at,
                                 on_iteration=lambda k, x, terms: calls.append(k))
    assert first.status == "stopped" and len(first.history) == at
    assert store.last.status is None  # a run inside its rounds is not finished
    second, objective = optimise_physical(build_objective(problem, config), problem, config, store, rounds,
                                          saved=store.last)
    assert second.status == whole.status == "max_iter" and len(second.history) == 64
    np.testing.assert_array_equal(_history(second), _history(whole))
    np.testing.assert_array_equal(second.best_x, whole.best_x)
    assert objective.beta == 24.0  # the rounds' beta: twice the final one
    assert store.last.status == "max_iter" and np.array_equal(store.last.best_x, second.best_x.ravel())


def test_without_correction_it_is_the_plain_optimisation(short_print):
    config = DesignConfig(max_iter=20, physical_correction="none", **SMALL)
    problem = prepare(config)
    short_print(problem)
    rounds = MemoryRounds()
    outcome, _ = optimise_physical(build_objective(problem, config), problem, config, MemoryStore(), rounds)
    assert len(outcome.history) == 20 and rounds.states == []


def test_the_rounds_fit_in_the_evaluation_limit():
    config = DesignConfig(target="sphere", max_iter=500)
    assert config.physical_correction == "defect" and config.correction_evals == 50
    assert correction_plan(config) == (2, 400)
    assert correction_plan(DesignConfig(target="sphere", max_iter=500, physical_correction="none")) == (0, 500)
    # rounds that would leave the first optimisation less than half of the limit are dropped
    assert correction_plan(DesignConfig(target="sphere", max_iter=30, correction_evals=10, correction_rounds=3)) == (1, 20)
    assert correction_plan(DesignConfig(target="sphere", max_iter=1)) == (0, 1)


def test_bad_correction_settings_are_refused():
    with pytest.raises(DesignError, match="physical_correction must be one of"):
        DesignConfig(target="sphere", physical_correction="finer")
    with pytest.raises(DesignError, match="correction_rounds in"):
        DesignConfig(target="sphere", correction_rounds=0)
    with pytest.raises(DesignError, match="correction_evals >= 1"):
        DesignConfig(target="sphere", correction_evals=0)
