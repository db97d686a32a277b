"""A design run's phases and its time left (design.inverse.progress)."""
import pytest

import design.inverse.progress as progress
from design.files.rundir import run_design
from design.inverse.config import DesignConfig
from design.inverse.progress import DEFAULT_OUTPUTS_EVALS as OUTPUTS_EVALS
from design.inverse.progress import DEFAULT_PRINT_CHECK_EVALS as PRINT_CHECK_EVALS
from design.inverse.progress import RunClock, run_plan
from design.inverse.settings import COARSE_EVALS_SHARE


def test_a_single_run_is_its_optimisation_its_rounds_and_its_outputs():
    plan = run_plan(DesignConfig(target="sphere", resolution=32, max_iter=100))
    assert [(p.name, p.end, p.evals, p.weight) for p in plan] == [
        (None, 80, 80, 1.0), ("physical correction round 1 of 2", 90, 10, 1.0),
        ("physical correction round 2 of 2", 100, 10, 1.0)]
    assert [p.after for p in plan] == [PRINT_CHECK_EVALS, PRINT_CHECK_EVALS, PRINT_CHECK_EVALS + OUTPUTS_EVALS]


def test_a_multistart_plan_has_its_coarse_starts_at_their_measured_cost_then_the_refinement():
    plan = run_plan(DesignConfig(target="sphere", resolution=128, max_iter=100))
    names = [p.name for p in plan]
    assert names[:4] == [f"coarse start {k} of 4 at resolution 64" for k in range(1, 5)]
    assert names[4:] == ["refinement at resolution 128", "refinement at resolution 128, physical correction round 1 of 2",
                         "refinement at resolution 128, physical correction round 2 of 2"]
    assert [p.weight for p in plan] == [progress.DEFAULT_COARSE_EVAL_WEIGHT] * 4 + [1.0] * 3
    assert [p.after for p in plan[:4]] == [progress.COARSE_OUTPUTS_EVALS] * 4
    # each coarse start COARSE_EVALS_SHARE of the evaluations; the refinement a fifth (20), then its two rounds of 10
    coarse = round(100 * COARSE_EVALS_SHARE)
    assert [(p.end, p.limit or p.end) for p in plan] == [(coarse, coarse)] * 4 + [(20, 40), (30, 40), (40, 40)]


def test_a_mesh_targets_checks_and_outputs_cost_its_timed_reference_release_in_timed_evaluations():
    from types import SimpleNamespace

    import numpy as np

    config = DesignConfig(target="sphere", resolution=32, max_iter=100)

    def problem(extent_mm):  # a source spanning extent_mm on voxels of 0.5 mm, its release timed at 1 s
        return SimpleNamespace(target_release_s=1.0, source_mesh=SimpleNamespace(extents=np.array([extent_mm, 1.0, 1.0])),
                               space=SimpleNamespace(dx_mm=0.5))

    costs = progress.stage_costs(config, full_eval_s=0.1, problem=problem(10.0))  # checked on 40 cells of 128
    assert costs.check == pytest.approx(progress.DEFAULT_CHECK_PER_REFERENCE * 10)
    assert not costs.reused and costs.outputs == pytest.approx(progress.DEFAULT_OUTPUTS_PER_CHECK * costs.check)
    assert [p.after for p in run_plan(config, costs)] == [costs.check, costs.check, costs.check + costs.outputs]
    # a print of the source's size checked on the outputs' own lattice (128 cells at 32): its release reused
    reused = progress.stage_costs(config, full_eval_s=0.1, problem=problem(32.0))
    assert reused.reused and reused.outputs == pytest.approx(progress.REUSED_OUTPUTS_PER_CHECK * reused.check)
    # without either timing (a curve target has no reference release): the measured constants
    fallback = progress.stage_costs(config, 0.1, None)
    assert (fallback.check, fallback.outputs) == (PRINT_CHECK_EVALS, OUTPUTS_EVALS)


def test_a_checks_lattice_tells_the_clock_whether_the_outputs_reuse_its_release(monkeypatch):
    now = [0.0]
    monkeypatch.setattr(progress.time, "perf_counter", lambda: now[0])
    config = DesignConfig(target="sphere", resolution=32, max_iter=100)
    costs = progress.StageCosts(check=20.0, fresh_outputs=30.0, reused_outputs=4.0, reused=True)
    seen = []
    clock = RunClock(run_plan(config, costs), lambda k, x, terms: seen.append(terms), costs)
    for k in range(1, 6):  # 1 s per evaluation
        now[0] += 1.0
        clock(k, None, {})
    assert seen[-1]["eta_s"] == pytest.approx((80 - 5) + 20 + 2 * (10 + 20) + 4)
    now[0] += 1.0
    clock(81, None, {"phase": "physical correction round 1 of 2", "outputs_reuse": False})
    assert "outputs_reuse" not in seen[-1] and clock.costs.outputs == 30.0
    assert clock.plan[-1].after == pytest.approx(20 + 30)


def test_the_progress_line_counts_the_evaluations_of_the_run_of_its_phase():
    plan = run_plan(DesignConfig(target="sphere", resolution=128, max_iter=100))
    seen = []
    clock = RunClock(plan, lambda k, x, terms: seen.append(terms.get("limit")))
    clock(1, None, {"phase": "coarse start 1 of 4 at resolution 64"})
    clock(25, None, {"phase": "refinement at resolution 128, physical correction round 1 of 2"})
    assert seen == [round(100 * COARSE_EVALS_SHARE), 40]


def test_the_time_left_is_the_plan_left_at_the_phase_rate(monkeypatch):
    now = [0.0]
    monkeypatch.setattr(progress.time, "perf_counter", lambda: now[0])
    config = DesignConfig(target="sphere", resolution=32, max_iter=100)
    plan = run_plan(config)
    seen = []
    clock = RunClock(plan, lambda k, x, terms: seen.append(terms.get("eta_s")), progress.stage_costs(config))
    for k in range(1, 11):  # 2 s per evaluation
        now[0] += 2.0
        clock(k, None, {"eta_s": -1.0})
    assert seen[0] is None  # no rate yet: no estimate (the optimiser's own covers its run alone)
    left = (80 - 10) + PRINT_CHECK_EVALS + 2 * (10 + PRINT_CHECK_EVALS) + OUTPUTS_EVALS
    assert seen[-1] == pytest.approx(2.0 * left)
    now[0] += 50.0  # the print check, 48 s, and the round's first evaluation, 2 s at the rate so far
    clock(81, None, {"phase": "physical correction round 1 of 2"})
    for k in range(82, 86):  # 1 s per evaluation in the round
        now[0] += 1.0
        clock(k, None, {"phase": "physical correction round 1 of 2"})
    # the evaluations at the round's rate, the checks and the outputs at the measured check's 48 s / PRINT_CHECK_EVALS
    after_rate = 48.0 / PRINT_CHECK_EVALS
    assert seen[-1] == pytest.approx(1.0 * ((90 - 85) + 10) + after_rate * (2 * PRINT_CHECK_EVALS + OUTPUTS_EVALS))
    assert clock.outputs_s() == pytest.approx(after_rate * OUTPUTS_EVALS)


def test_every_evaluation_of_a_run_names_a_phase_of_its_plan(tmp_path):
    config = DesignConfig(target="sphere", resolution=16, radius_vox=2.0, max_iter=20, checkpoint_every=5)
    names = {p.name for p in run_plan(config)}
    seen = []
    run_design(config, tmp_path / "run", on_iteration=lambda k, x, terms: seen.append((terms.get("phase"),
                                                                                          terms["eta_s"])))
    assert len(seen) == 20 and {name for name, _ in seen} == names
    # no estimate before the run has measured its pace (RATE_MIN_EVALS evaluations), then always time ahead: the
    # last evaluation still has its print check and outputs to come
    assert [eta is None for _, eta in seen[:progress.RATE_MIN_EVALS]] == [True] * progress.RATE_MIN_EVALS
    assert all(eta > 0 for _, eta in seen[progress.RATE_MIN_EVALS:])


def test_a_coarse_starts_outputs_do_not_set_the_pace_of_the_print_checks(monkeypatch):
    now = [0.0]
    monkeypatch.setattr(progress.time, "perf_counter", lambda: now[0])
    clock = RunClock(run_plan(DesignConfig(target="sphere", resolution=128, max_iter=100)), lambda k, x, terms: None)
    for name in ("coarse start 1 of 4 at resolution 64", "coarse start 2 of 4 at resolution 64"):
        for k in range(1, 6):
            now[0] += 0.1
            clock(k, None, {"phase": name})
        now[0] += 30.0  # the outputs: no print released
    assert clock.rate is not None and clock.after_rate is None


def test_the_first_coarse_start_weighs_every_coarse_start_against_the_runs_own_evaluation(monkeypatch):
    now = [0.0]
    monkeypatch.setattr(progress.time, "perf_counter", lambda: now[0])
    seen = []
    clock = RunClock(run_plan(DesignConfig(target="sphere", resolution=128, max_iter=100)),
                     lambda k, x, terms: seen.append(terms["eta_s"]), full_eval_s=2.0)  # an evaluation of its grid
    for k in range(1, 7):  # 0.5 s per coarse evaluation: a weight of 0.25, not the constant's
        now[0] += 0.5
        clock(k, None, {"phase": "coarse start 1 of 4 at resolution 64"})
    assert [p.weight for p in clock.plan] == [0.25] * 4 + [1.0] * 3
    assert clock.rate == pytest.approx(2.0)
    coarse = round(100 * COARSE_EVALS_SHARE)
    left = ((coarse - 6) + 3 * coarse) * 0.25 + 4 * progress.COARSE_OUTPUTS_EVALS + 40 + 3 * PRINT_CHECK_EVALS + OUTPUTS_EVALS
    assert seen[-1] == pytest.approx(2.0 * left)
    for k in range(1, 5):  # a later start, under more load: its own pace, the weight kept
        now[0] += 1.0
        clock(k, None, {"phase": "coarse start 2 of 4 at resolution 64"})
    assert [p.weight for p in clock.plan] == [0.25] * 4 + [1.0] * 3 and clock.rate == pytest.approx(4.0)


def test_timing_an_evaluation_leaves_the_runs_fabrication_term_as_it_was():
    from design.files.targets_io import load_problem
    from design.inverse.optimize import build_objective

    config = DesignConfig(target="sphere", space="ico", resolution=16, radius_vox=2.0, max_iter=5, layers=4)
    problem = load_problem(config, False)
    objective = build_objective(problem, config)
    objective.evaluate(objective.uniform_start(problem.start_regions[0]))  # warm starts to keep
    fab = problem.space.fab_term
    before = {key: value.copy() for key, value in fab.state().items()}, fab.reference
    assert progress.evaluation_seconds(problem, config) > 0
    after = fab.state()
    assert after.keys() == before[0].keys() and all((after[key] == before[0][key]).all() for key in after)
    assert fab.reference == before[1]


def test_timing_the_runs_evaluation_does_not_change_its_design(tmp_path):
    import numpy as np

    config = DesignConfig(target="sphere", space="ico", resolution=16, radius_vox=2.0, max_iter=12, layers=4,
                          checkpoint_every=4)
    timed = run_design(config, tmp_path / "timed", on_iteration=lambda k, x, terms: None)
    plain = run_design(config, tmp_path / "plain")
    with np.load(timed.out_dir / "density.npz") as a, np.load(plain.out_dir / "density.npz") as b:
        assert np.array_equal(a["rho_hat"], b["rho_hat"])


def test_a_run_resumed_in_a_later_coarse_start_weighs_them_by_the_first_it_times(monkeypatch):
    now = [0.0]
    monkeypatch.setattr(progress.time, "perf_counter", lambda: now[0])
    clock = RunClock(run_plan(DesignConfig(target="sphere", resolution=128, max_iter=100)), lambda k, x, terms: None,
                     full_eval_s=1.0)
    for k in range(1, 5):  # the run resumed in its third start: 0.4 s per coarse evaluation
        now[0] += 0.4
        clock(k, None, {"phase": "coarse start 3 of 4 at resolution 64"})
    assert [p.weight for p in clock.plan] == [pytest.approx(0.4)] * 4 + [1.0] * 3
    for k in range(1, 5):  # the fourth start does not weigh them again
        now[0] += 0.8
        clock(k, None, {"phase": "coarse start 4 of 4 at resolution 64"})
    assert [p.weight for p in clock.plan] == [pytest.approx(0.4)] * 4 + [1.0] * 3
