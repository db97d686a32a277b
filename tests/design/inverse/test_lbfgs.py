"""The lean L-BFGS (`design.inverse.lbfgs`) and its use in design runs: minima against scipy, each line
search's acceptance rule on every accepted step, the "luksan" rule against nlopt's LD_LBFGS point for
point, the two-loop recursion against dense BFGS, exact checkpoint/resume, and the nlopt optimisers
kept selectable."""
import io
import logging

import nlopt
import numpy as np
import pytest
from scipy.optimize import minimize as scipy_minimize
from scipy.optimize import rosen, rosen_der

from design.errors import DesignError
from design.files.rundir import run_design
from design.inverse.config import DesignConfig
from design.inverse.lbfgs import (
    CONVERGED,
    CURVATURE_C2,
    LINE_SEARCHES,
    SEARCH,
    STALLED,
    STEP,
    Lbfgs,
    LbfgsSettings,
    _model_step,
    minimize,
)


def _rosenbrock(x, grad):
    grad[:] = rosen_der(x)
    return rosen(x)


def _quadratic(n, seed=0):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, n))
    return a @ a.T / n + 0.1 * np.eye(n), rng.normal(size=n)


@pytest.mark.parametrize("line_search", LINE_SEARCHES)
@pytest.mark.parametrize("n", [2, 10])
def test_rosenbrock_reaches_scipys_minimum(n, line_search):
    x0 = np.tile([-1.2, 1.0], n // 2)
    result = minimize(_rosenbrock, x0, max_evals=2000, settings=LbfgsSettings(line_search=line_search))
    ref = scipy_minimize(rosen, x0, jac=rosen_der, method="L-BFGS-B", options=dict(ftol=0, gtol=1e-12))
    # the minimum is x = 1; both stop within rounding of it
    assert result.status in (CONVERGED, STALLED) and result.f < 1e-20
    np.testing.assert_allclose(result.x, ref.x, atol=1e-8)
    assert result.evaluations < 1.5 * ref.nfev  # comparable work: ~1.1 evaluations per step


@pytest.mark.parametrize("line_search", LINE_SEARCHES)
def test_bounded_quadratic_through_the_cosine_map_matches_scipys_box_solution(line_search):
    a, b = _quadratic(40)

    def fun(z, grad):  # x = (1 - cos z) / 2 in [0, 1], as design.inverse.optimize maps rho_hat
        x = 0.5 * (1.0 - np.cos(z))
        grad[:] = (a @ x - b) * 0.5 * np.sin(z)
        return 0.5 * x @ a @ x - b @ x

    result = minimize(fun, np.full(40, np.pi / 2), max_evals=3000, settings=LbfgsSettings(line_search=line_search))
    ref = scipy_minimize(lambda x: 0.5 * x @ a @ x - b @ x, np.full(40, 0.5), jac=lambda x: a @ x - b,
                         method="L-BFGS-B", bounds=[(0, 1)] * 40, options=dict(ftol=0, gtol=1e-12))
    x = 0.5 * (1.0 - np.cos(result.x))
    assert np.sum((x > 1e-6) & (x < 1 - 1e-6)) < 40 and np.sum(ref.x == 0) + np.sum(ref.x == 1) > 0  # bounds active
    # variables at a bound converge like z^2 in the cosine map, hence 1e-6 rather than rounding
    np.testing.assert_allclose(x, ref.x, atol=1e-6)
    assert result.f == pytest.approx(ref.fun, rel=1e-12)


def test_every_accepted_step_satisfies_the_strong_wolfe_conditions():
    settings = LbfgsSettings(memory=5, line_search="strong-wolfe")
    opt = Lbfgs(np.tile([-1.2, 1.0], 5), settings)
    prev, steps, searches = None, 0, 0
    for _ in range(400):
        outcome = opt.tell(_rosenbrock(opt.x_trial, opt.g_trial))
        if outcome in (CONVERGED, STALLED) or opt.f < 1e-20:  # below: both sides of 3.7b are rounding
            break
        searches += outcome == SEARCH
        if outcome == STEP and prev is not None and opt.iterations > steps:
            x0, f0, g0 = prev
            s = opt.x - x0
            assert opt.f <= f0 + settings.c1 * (g0 @ s)  # sufficient decrease (eq. 3.7a)
            assert abs(opt.g @ s) <= settings.c2 * abs(g0 @ s)  # strong curvature (eq. 3.7b)
            steps = opt.iterations
        if outcome == STEP:
            prev = (opt.x.copy(), opt.f, opt.g.copy())
    assert steps > 30 and searches > 0  # many steps, some needing more than one trial


def test_two_loop_direction_equals_the_dense_bfgs_inverse_update():
    a, b = _quadratic(12, seed=3)
    opt = Lbfgs(np.zeros(12), LbfgsSettings(memory=4))
    while opt.iterations < 7:  # more steps than pairs: the ring buffer has wrapped
        x = opt.x_trial
        opt.g_trial[:] = a @ x - b
        opt.tell(0.5 * x @ a @ x - b @ x)
    order = [(opt.head + i) % 4 for i in range(opt.count)]  # oldest first
    h = opt.gamma * np.eye(12)
    for i in order:  # H+ = (I - rho s y^T) H (I - rho y s^T) + rho s s^T (Nocedal and Wright eq. 6.17)
        s, y, rho = opt.s[i], opt.y[i], opt.rho[i]
        v = np.eye(12) - rho * np.outer(y, s)
        h = v.T @ h @ v + rho * np.outer(s, s)
    d = opt.d.copy()
    opt._direction()  # recompute in place from the current gradient
    np.testing.assert_allclose(opt.d, -h @ opt.g, rtol=1e-10, atol=1e-12 * np.abs(d).max())


def test_every_luksan_step_decreases_f_and_meets_the_weak_curvature_condition_unless_a_trial_overshot():
    settings = LbfgsSettings(memory=5)
    assert settings.line_search == "luksan" and settings.c2 == CURVATURE_C2["luksan"] == 0.8
    opt = Lbfgs(np.tile([-1.2, 1.0], 5), settings)
    start, overshot, steps, weak = None, False, 0, 0
    for _ in range(400):
        x_trial = opt.x_trial.copy()
        f_trial = _rosenbrock(opt.x_trial, opt.g_trial)
        if start is not None and opt.initialised:
            x0, f0, g0 = start
            overshot |= f_trial - f0 > settings.c1 * (g0 @ (x_trial - x0))  # this trial failed the decrease test
        outcome = opt.tell(f_trial)
        if outcome in (CONVERGED, STALLED) or opt.f < 1e-20:  # below: both sides are rounding
            break
        if outcome == STEP and start is not None:
            x0, f0, g0 = start
            s = opt.x - x0
            assert opt.f - f0 <= settings.c1 * (g0 @ s)  # sufficient decrease
            if not overshot:
                assert opt.g @ s >= settings.c2 * (g0 @ s)  # weak curvature
                weak += 1
            steps += 1
        if outcome == STEP:
            start, overshot = (opt.x.copy(), opt.f, opt.g.copy()), False
    assert steps > 30 and 0 < weak < steps  # both acceptance paths taken


def _nlopt_points(fun, x0, memory, max_evals):
    """The points nlopt's LD_LBFGS evaluates minimising ``fun`` from ``x0``."""
    points = []

    def objective(x, grad):
        points.append(x.copy())
        return fun(x, grad)

    opt = nlopt.opt(nlopt.LD_LBFGS, x0.size)
    opt.set_min_objective(objective)
    opt.set_vector_storage(memory)
    opt.set_maxeval(max_evals)
    opt.optimize(x0.copy())
    return points


@pytest.mark.parametrize("problem", ["rosenbrock", "bounded quadratic"])
def test_luksan_rule_evaluates_the_points_nlopts_ld_lbfgs_evaluates_bit_for_bit(problem):
    if problem == "rosenbrock":
        fun, x0 = _rosenbrock, np.tile([-1.2, 1.0], 5)
    else:
        a, b = _quadratic(40, seed=1)

        def fun(z, grad):
            x = 0.5 * (1.0 - np.cos(z))
            grad[:] = (a @ x - b) * 0.5 * np.sin(z)
            return 0.5 * x @ a @ x - b @ x
        x0 = np.full(40, np.pi / 2)
    expected = _nlopt_points(fun, x0, memory=5, max_evals=150)
    opt = Lbfgs(x0, LbfgsSettings(memory=5))
    for k, point in enumerate(expected):
        assert np.array_equal(opt.x_trial, point), f"evaluation {k + 1} differs"
        if opt.tell(fun(opt.x_trial, opt.g_trial)) in (CONVERGED, STALLED):
            break
    assert len(expected) > 60 and opt.iterations > 30


def test_model_steps_are_exact_on_cubics_and_safeguarded():
    def phi(r):  # a cubic along the line, minimum at r = 2, slope -4 at 0
        return r ** 3 / 3 - r ** 2 / 2 - 2 * r, r ** 2 - r - 2
    (f0, p0), (f3, p3) = phi(0.0), phi(3.0)
    assert _model_step(0.0, f0, p0, 3.0, f3, p3, False) == pytest.approx(2.0, rel=1e-12)
    (f1, p1), (f15, p15) = phi(1.0), phi(1.5)  # both below the minimum: extrapolate to it
    assert _model_step(1.0, f1, p1, 1.5, f15, p15, True) == pytest.approx(2.0, rel=1e-12)
    # a linear function has no model minimum: 4 times the step out, the midpoint in
    assert _model_step(0.0, 0.0, -1.0, 1.0, -1.0, -1.0, True) == 4.0
    assert _model_step(0.0, 0.0, -1.0, 1.0, float("inf"), -1.0, False) == 0.5  # an infinite value bisects
    # interpolation stays 1% (from 0) and 10% (otherwise) inside the bracket
    assert _model_step(0.0, 0.0, -1e-6, 1.0, 1e6, 1e6, False) == pytest.approx(0.01)
    assert _model_step(0.5, 0.0, -1e-6, 1.5, 1e6, 1e6, False) == pytest.approx(0.6)
    assert np.isnan(_model_step(0.0, 0.0, 1.0, 1.0, 0.0, 1.0, False))  # no descent at the low end


@pytest.mark.parametrize("line_search", LINE_SEARCHES)
def test_a_kink_stalls_the_line_search_at_a_lower_point(line_search):
    def l1(x, grad):  # |x|_1: no step across the kink satisfies the curvature condition
        grad[:] = np.sign(x)
        return float(np.abs(x).sum())

    settings = LbfgsSettings(line_search=line_search)
    opt, outcome, evals = Lbfgs(np.array([1.0, -2.0, 0.7]), settings), SEARCH, 0
    x0, g0 = opt.x_trial.copy(), np.sign(opt.x_trial)
    outcome, evals = opt.tell(l1(opt.x_trial, opt.g_trial)), 1
    assert outcome == STEP and np.array_equal(opt.d, -g0)  # no curvature yet: steepest descent
    if line_search == "strong-wolfe":  # the first step moves no variable by more than first_step
        assert np.max(np.abs(opt.x_trial - x0)) == pytest.approx(settings.first_step)
    else:  # the unit step along -g
        np.testing.assert_array_equal(opt.x_trial, x0 - g0)
    while outcome not in (CONVERGED, STALLED) and evals < 200:
        outcome, evals = opt.tell(l1(opt.x_trial, opt.g_trial)), evals + 1
    assert outcome == STALLED and opt.f < 0.1 * 3.7
    # strong-wolfe stalls with its memory; luksan resets to steepest descent first and stalls there
    assert (opt.count > 0) == (line_search == "strong-wolfe")


@pytest.mark.parametrize("line_search", LINE_SEARCHES)
def test_saved_state_resumes_bit_for_bit(line_search):
    x0 = np.tile([-1.2, 1.0], 4)
    settings = LbfgsSettings(memory=3, line_search=line_search)
    uninterrupted, opt = [], Lbfgs(x0, settings)
    for _ in range(80):
        uninterrupted.append(opt.x_trial.copy())
        opt.tell(_rosenbrock(opt.x_trial, opt.g_trial))
    resumed, opt = [], Lbfgs(x0, settings)
    for k in range(80):
        if k in (1, 23, 24, 57):  # right after the start, and mid line search or between steps
            buffer = io.BytesIO()
            np.savez(buffer, **opt.state())
            buffer.seek(0)
            with np.load(buffer) as data:
                opt = Lbfgs.from_state({name: data[name] for name in data.files})
        resumed.append(opt.x_trial.copy())
        opt.tell(_rosenbrock(opt.x_trial, opt.g_trial))
    assert all(np.array_equal(p, q) for p, q in zip(uninterrupted, resumed))
    assert opt.settings == settings


def test_a_state_saved_before_the_line_search_setting_resumes_with_strong_wolfe():
    opt = Lbfgs(np.tile([-1.2, 1.0], 2), LbfgsSettings(c2=0.5, line_search="strong-wolfe"))
    opt.tell(_rosenbrock(opt.x_trial, opt.g_trial))
    state = opt.state()
    state["settings"] = state["settings"][:-1]  # the seven settings stored then
    resumed = Lbfgs.from_state(state)
    assert resumed.settings == opt.settings and np.array_equal(resumed.x_trial, opt.x_trial)


def test_settings_guards():
    with pytest.raises(ValueError, match="0 < c1 < c2 < 1"):
        LbfgsSettings(c1=0.9, c2=0.1)
    with pytest.raises(ValueError, match="memory"):
        LbfgsSettings(memory=0)
    with pytest.raises(ValueError, match="line_search must be one of"):
        LbfgsSettings(line_search="more-thuente")
    with pytest.raises(DesignError, match="line_search must be one of"):
        DesignConfig(target="sphere", line_search="armijo")
    with pytest.raises(ValueError, match="finite 1D"):
        Lbfgs(np.array([[1.0, np.nan]]))
    with pytest.raises(DesignError, match="needs bounds='cosine'"):
        DesignConfig(target="sphere", optimizer="lbfgs", bounds="box")
    with pytest.raises(DesignError, match="optimizer must be one of"):
        DesignConfig(target="sphere", optimizer="LD_SLSQP")


SMALL = dict(target="sphere", space="nfc", resolution=16, radius_vox=2.0, checkpoint_every=3)


def _history(folder):
    return np.loadtxt(folder / "history.csv", delimiter=",", skiprows=1)[:, :-1]  # all but seconds


@pytest.mark.parametrize("how, at", [("stop", 8), ("stop", 12), ("ctrl_c", 8)])
def test_a_resumed_design_run_repeats_the_uninterrupted_one_exactly(tmp_path, how, at):
    # beta continuation: 4 stages of 6 evaluations; the interruption falls inside the second stage
    # (8) or at the end of the second, before the third has evaluated anything (12)
    config = DesignConfig(max_iter=24, beta_final=12.0, **SMALL)
    whole = run_design(config, tmp_path / "whole")

    def interrupt(k, x, terms):
        if k == at:
            raise KeyboardInterrupt

    if how == "stop":
        calls = []
        first = run_design(config, tmp_path / "parts", should_stop=lambda: len(calls) >= at,
                           on_iteration=lambda k, x, terms: calls.append(k))
    else:
        first = run_design(config, tmp_path / "parts", on_iteration=interrupt)
    assert first.iterations == at and first.status == ("stopped" if how == "stop" else "interrupted")
    second = run_design(None, tmp_path / "parts", resume=True)
    assert second.iterations == whole.iterations == 24
    np.testing.assert_array_equal(_history(tmp_path / "parts"), _history(tmp_path / "whole"))
    with np.load(tmp_path / "whole" / "density.npz") as a, np.load(tmp_path / "parts" / "density.npz") as b:
        for name in a.files:
            np.testing.assert_array_equal(a[name], b[name])


@pytest.mark.parametrize("offset", [0, 2])
def test_a_run_resumed_around_a_restarted_session_repeats_the_uninterrupted_one(tmp_path, offset):
    # ftol_rel ends an L-BFGS session early and a new session starts at the best design; the evaluation
    # where that happens is read from the uninterrupted run's log (it depends on the floating-point
    # trajectory, so on the machine), and the run is stopped on it or two evaluations into it
    config = DesignConfig(max_iter=60, beta_final=3.0, connect_tail=0.0, ftol_rel=1e-3, **SMALL)
    seen, restarts = [], []

    class RestartMark(logging.Handler):
        def emit(self, record):
            if "restarting L-BFGS" in record.getMessage():
                restarts.append(len(seen) + 1)      # the evaluation that ended the session is reported next

    logger = logging.getLogger("design.inverse.optimize")
    mark, level = RestartMark(), logger.level
    logger.addHandler(mark)
    logger.setLevel(logging.INFO)
    try:
        whole = run_design(config, tmp_path / "whole", on_iteration=lambda k, x, terms: seen.append(k))
    finally:
        logger.removeHandler(mark)
        logger.setLevel(level)
    assert restarts, "no L-BFGS session was restarted: the test needs one"
    at = restarts[0] + offset
    calls = []
    run_design(config, tmp_path / "parts", should_stop=lambda: len(calls) >= at,
               on_iteration=lambda k, x, terms: calls.append(k))
    second = run_design(None, tmp_path / "parts", resume=True)
    assert second.iterations == whole.iterations > at
    np.testing.assert_array_equal(_history(tmp_path / "parts"), _history(tmp_path / "whole"))


def test_a_default_design_run_evaluates_what_nlopts_ld_lbfgs_evaluates(tmp_path):
    # beta continuation: 4 stages of 8 evaluations, each a fresh optimiser in both
    config = DesignConfig(max_iter=32, beta_final=12.0, **SMALL)
    lean = run_design(config, tmp_path / "lean")
    reference = run_design(DesignConfig(max_iter=32, beta_final=12.0, optimizer="LD_LBFGS", **SMALL), tmp_path / "nlopt")
    assert config.optimizer == "lbfgs" and config.line_search == "luksan"
    assert lean.iterations == reference.iterations == 32
    np.testing.assert_array_equal(_history(tmp_path / "lean"), _history(tmp_path / "nlopt"))


@pytest.mark.parametrize("optimizer", ["LD_LBFGS", "LD_MMA", "LD_CCSAQ"])
def test_nlopt_optimisers_stay_selectable(tmp_path, optimizer):
    # one beta stage: 12 evaluations do not go far when every stage starts nlopt afresh
    result = run_design(DesignConfig(max_iter=12, optimizer=optimizer, beta_final=3.0, **SMALL), tmp_path)
    history = _history(tmp_path)
    assert result.iterations == len(history) == 12
    assert history[:, 1].min() < 0.9 * history[0, 1]  # J falls below the uniform start
    assert result.outputs.summary["config"]["optimizer"] == optimizer
