"""A design run's phases in order and the time it has left (``terms["eta_s"]`` of the progress callback).

A run is a sequence of phases (`run_plan`): the seeded starts of a multi-start (`design.inverse.multistart`), the
optimisation at the run's resolution (the refinement of the best coarse start, or the single run), its correction
rounds (`design.inverse.defect`), each after a check of the current design's print, and the outputs, whose print
is extracted and released by the reference evaluator (`design.files.outputs`). Each phase is named as the progress
line names it (``terms["phase"]``) and costs a number of objective evaluations, each weighted by the size of its
grid against the run's (an evaluation is a fast-marching solve and its adjoint, whose cost follows the voxels); the
print checks and the outputs cost what `stage_costs` says in the run's evaluations: for a mesh target from what the
reference evaluator took for the target's release and what one evaluation of the run's objective takes (both timed
before the run's first evaluation), else measured constants (`PRINT_CHECK_EVALS`, `OUTPUTS_EVALS`).

`RunClock` wraps the run's progress callback: at every evaluation it measures the seconds per weighted evaluation of
the phase in progress and sets ``eta_s`` to what is left of it and of every later phase at that rate. The work between
two phases (a print check, with the outputs after the last) is timed too, from the previous phase's last evaluation
to the next one's first, and from then on what is left of that work (the later checks and the outputs) is estimated
at the seconds per weighted evaluation it took there: a print check's release and an evaluation's solves do not keep the
same ratio on every shape and machine load. A phase that ends early (an optimisation that converges or stalls before
its limit) makes the estimate fall at once. A coarse start's weight is measured too when the run gives the clock the
seconds of one evaluation at its own resolution (`evaluation_seconds`): through the first coarse start it times, it
is that start's seconds per evaluation over them, so that the refinement is estimated at the cost of
its own grid's evaluations, which against the coarse grid's moves with the source (J_conn's blocks) and with the
load (the full grid's solves share both cores). It also sets
``terms["limit"]``, the evaluations of the run the phase is part of (a coarse start's, or the optimisation's and its
rounds').
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass, replace

from design.inverse.config import DesignConfig
from design.inverse.optimize import IterationCallback, build_objective
from design.inverse.problem import Problem

PRINT_CHECK_EVALS = {"extruded": 16.0}
"""The time of a correction round's print check (extraction, the reference evaluator's release, the design grid's
release) in evaluations of the run's grid, per design space (`DEFAULT_PRINT_CHECK_EVALS` for the others), until the
run has timed one (`RunClock`), as measured in default designs at resolution 128
(docs/evidence/design.md#a-default-design-at-128-in-two-minutes)."""
DEFAULT_PRINT_CHECK_EVALS = 25.0
"""`PRINT_CHECK_EVALS` of the spaces it does not name (nfc, ico)."""
OUTPUTS_EVALS = {"extruded": 77.0}
"""The time of the outputs (the print's extraction and release on the full lattice, the binary solid's release,
the report) in evaluations of the run's grid, per design space (`DEFAULT_OUTPUTS_EVALS` for the others), as measured
in default designs at resolution 128: in nfc 0.7-2 print checks (its release is on the full lattice, the checks' on
2 cells per voxel), a few seconds when the last check judged the print on the outputs' lattice and the outputs reuse
its release (`design.inverse.release_cache`; docs/evidence/design.md#a-default-design-at-128-in-two-minutes)."""
DEFAULT_OUTPUTS_EVALS = 35.0
"""`OUTPUTS_EVALS` of the spaces it does not name."""
CHECK_PER_REFERENCE = {"extruded": 1.0}
"""The time of a print check over the time of the target's reference release (`Problem.target_release_s`), per
design space (`DEFAULT_CHECK_PER_REFERENCE` for the others): the check releases a print of the target's size on a
lattice of 2 cells per voxel (nfc: the target's 160 cells at 128; extruded, 1 per voxel: about 86), a mesh of many
more triangles, after extracting it. Measured in default designs at resolution 128 on an idle 2-core machine: nfc
3.9-5.7 (pill 5.7, torus 4.2, spinner_top 4.0, polyhedron 4.6, csg 3.9), extruded 0.7 (spinner_top) and 1.3
(cone on its tip) (docs/evidence/design.md#a-default-design-at-128-in-two-minutes)."""
DEFAULT_CHECK_PER_REFERENCE = 4.5
"""`CHECK_PER_REFERENCE` of the spaces it does not name."""
OUTPUTS_PER_CHECK = {"extruded": 3.7}
"""The time of the outputs over a print check's, per design space (`DEFAULT_OUTPUTS_PER_CHECK` for the others), in
the same designs: nfc 1.2-2.1 (0.2 where the outputs reuse the last check's release: the csg), extruded 3.4-4.1 (the
outputs release the print on the full lattice, the checks on 1 cell per voxel)."""
DEFAULT_OUTPUTS_PER_CHECK = 1.5
"""`OUTPUTS_PER_CHECK` of the spaces it does not name."""
REUSED_OUTPUTS_PER_CHECK = 0.2
"""The time of the outputs over a print check's where the checks release the print on the outputs' lattice, whose
release the outputs then reuse (`design.inverse.release_cache`): extraction and the report, measured 0.18 (csg)."""
COARSE_EVAL_WEIGHT = {"extruded": 0.16}
"""The cost of an evaluation of a multi-start's coarse start (half the resolution) in evaluations of the run's grid,
per design space (`DEFAULT_COARSE_EVAL_WEIGHT` for the others), as measured in default designs at resolution 128 on
an idle 2-core machine: extruded 0.16 (spinner_top), nfc 0.24 (pill) and 0.17 (spinner_top). An eighth of the voxels,
but fixed costs per evaluation, J_conn's distances on finer blocks at the coarse grid (nfc), and full-grid solves
that share the two cores where coarse ones are too small to
(docs/evidence/design.md#a-default-design-at-128-in-two-minutes)."""
DEFAULT_COARSE_EVAL_WEIGHT = 0.22
"""`COARSE_EVAL_WEIGHT` of the spaces it does not name; both stand until the run has timed its first coarse start
against `evaluation_seconds`."""
COARSE_OUTPUTS_EVALS = 6.0
"""The time of a coarse start's outputs (ranked by J alone: no reference release of the print) in evaluations of the
run's grid, measured at resolution 128 in nfc and extruded designs."""
RATE_MIN_EVALS = 3
"""Evaluations of a phase after which its own rate replaces the one carried from the phase before."""
PROBE_EVALS = 3
"""Evaluations of the run's objective that `evaluation_seconds` times (the median counts: the first one's
allocations are no evaluation's cost)."""


@dataclass(frozen=True)
class Phase:
    """One phase of a run.

    Attributes
    ----------
    name : str or None
        ``terms["phase"]`` of its evaluations (None: a single run's optimisation, which names none).
    end : int
        The run-local evaluation count at which it ends (a start counts its own evaluations).
    evals : int
        Its evaluations.
    weight : float
        The cost of one of its evaluations in evaluations of the run's grid.
    after : float
        What follows it before the next phase's first evaluation (print checks, outputs), in evaluations of the
        run's grid.
    limit : int
        The run-local evaluation count at which the run it is part of ends (a coarse start's, or the optimisation's
        and its rounds'): the progress line's "it k/limit". 0: ``end``.
    coarse : bool
        A coarse start of a multi-start: its weight is measured (`RunClock`), and what follows it (its outputs, which
        release no print) does not set the pace of the print checks.
    """

    name: str | None
    end: int
    evals: int
    weight: float
    after: float
    limit: int = 0
    coarse: bool = False


@dataclass(frozen=True)
class StageCosts:
    """What a print check and the outputs cost, in evaluations of the run's grid.

    Attributes
    ----------
    check : float
    fresh_outputs, reused_outputs : float
        The outputs when they release the print, and when they reuse the release of a checked print.
    reused : bool
        Which of the two is expected (until a check tells: ``terms["outputs_reuse"]``, `RunClock`).
    """

    check: float
    fresh_outputs: float
    reused_outputs: float
    reused: bool = False

    @property
    def outputs(self) -> float:
        """The outputs' expected cost."""
        return self.reused_outputs if self.reused else self.fresh_outputs


def stage_costs(config: DesignConfig, full_eval_s: float | None = None, problem: Problem | None = None) -> StageCosts:
    """The costs of a run of ``config``: from the seconds of one evaluation of its objective (``full_eval_s``,
    `evaluation_seconds`) and of its mesh target's reference release (``problem.target_release_s``) by
    `CHECK_PER_REFERENCE` and `OUTPUTS_PER_CHECK` when both are known, else `PRINT_CHECK_EVALS` and `OUTPUTS_EVALS`;
    reused outputs at `REUSED_OUTPUTS_PER_CHECK`, expected where a print of the source's size would be checked on the
    outputs' lattice."""
    from design.inverse.defect import check_cells, outputs_reuse

    reference_s = None if problem is None else problem.target_release_s
    if not (full_eval_s and reference_s):
        check = PRINT_CHECK_EVALS.get(config.space, DEFAULT_PRINT_CHECK_EVALS)
        return StageCosts(check, OUTPUTS_EVALS.get(config.space, DEFAULT_OUTPUTS_EVALS), REUSED_OUTPUTS_PER_CHECK * check)
    check = CHECK_PER_REFERENCE.get(config.space, DEFAULT_CHECK_PER_REFERENCE) * reference_s / full_eval_s
    cells = check_cells(config.space, float(max(problem.source_mesh.extents)), problem.space.dx_mm)
    return StageCosts(check, check * OUTPUTS_PER_CHECK.get(config.space, DEFAULT_OUTPUTS_PER_CHECK),
                      check * REUSED_OUTPUTS_PER_CHECK, reused=outputs_reuse(cells, config))


def _single(config: DesignConfig, prefix: str | None, costs: StageCosts) -> list[Phase]:
    """The phases of one run of ``config`` (no multi-start): its optimisation, its rounds, its outputs."""
    from design.inverse.defect import correction_plan, round_phase

    rounds, first = correction_plan(config)

    def named(name: str | None) -> str | None:
        return prefix if name is None else name if prefix is None else f"{prefix}, {name}"

    limit = first + rounds * config.correction_evals
    phases = [Phase(named(None), first, first, 1.0, costs.check if rounds else costs.outputs, limit)]
    for r in range(1, rounds + 1):
        end = first + r * config.correction_evals
        after = costs.check + (costs.outputs if r == rounds else 0.0)
        phases.append(Phase(named(round_phase(r, rounds)), end, config.correction_evals, 1.0, after, limit))
    return phases


def run_plan(config: DesignConfig, costs: StageCosts | None = None) -> list[Phase]:
    """The phases of a design run of ``config`` in order (module doc), its checks and outputs at ``costs`` (default
    `stage_costs` of ``config``'s measured constants)."""
    from design.inverse.multistart import coarse_config, coarse_phase, coarse_resolution, refinement_config, refinement_phase

    costs = costs or stage_costs(config)
    if config.starts <= 1:
        return _single(config, None, costs)
    resolution = coarse_resolution(config.resolution)
    if resolution == config.resolution:  # every start a whole run; the chosen one's outputs written again
        phases = [p for k in range(config.starts)
                  for p in _single(config, coarse_phase(k, config.starts, resolution, coarse=False), costs)]
        last = phases[-1]
        return phases[:-1] + [replace(last, after=last.after + costs.outputs)]
    weight = COARSE_EVAL_WEIGHT.get(config.space, DEFAULT_COARSE_EVAL_WEIGHT)
    evals = coarse_config(config).max_iter
    coarse = [Phase(coarse_phase(k, config.starts, resolution), evals, evals, weight, COARSE_OUTPUTS_EVALS,
                    coarse=True) for k in range(config.starts)]
    return coarse + _single(refinement_config(config), refinement_phase(config.resolution), costs)


def evaluation_seconds(problem: Problem, config: DesignConfig) -> float:
    """Wall seconds of one evaluation of the objective of ``config`` on ``problem`` (J and its gradient at the start
    design; the median of `PROBE_EVALS`), for `RunClock.full_eval_s` and `stage_costs`. It evaluates a copy of the
    design space, whose fabrication term keeps warm starts and counters, so that the run does not depend on the
    timing."""
    objective = build_objective(replace(problem, space=copy.deepcopy(problem.space)), config)
    x = objective.uniform_start(problem.start_regions[0])
    seconds = []
    for _ in range(PROBE_EVALS):
        t0 = time.perf_counter()
        objective.evaluate(x)
        seconds.append(time.perf_counter() - t0)
    return sorted(seconds)[len(seconds) // 2]


class RunClock:
    """The progress callback of a run with ``eta_s`` set to the time its plan has left (module doc).

    Parameters
    ----------
    plan : list of Phase
        `run_plan` of the run.
    on_iteration : callable
        The callback it wraps.
    costs : StageCosts, optional
        The checks' and the outputs' costs of ``plan`` (`stage_costs`): the outputs' expected one, for `outputs_s`,
        changes to the fresh or the reused outputs' when an evaluation's terms tell (``terms["outputs_reuse"]``, set
        after each print check, `design.inverse.defect`). None: no outputs.
    full_eval_s : float, optional
        Seconds of one evaluation of the run's grid (`evaluation_seconds`): the first coarse start the clock times,
        against it, weighs every coarse start. None: `COARSE_EVAL_WEIGHT`.
    """

    def __init__(self, plan: list[Phase], on_iteration: IterationCallback, costs: StageCosts | None = None,
                 full_eval_s: float | None = None) -> None:
        self.plan = plan
        self.on_iteration = on_iteration
        self.costs = costs
        self.full_eval_s = full_eval_s
        self.weighing: int | None = None  # the coarse start whose pace weighs them all
        self.rate: float | None = None  # seconds per evaluation of the run's grid
        self.after_rate: float | None = None  # seconds per evaluation of the run's grid of the work between phases
        self.current: int | None = None
        self.t0 = self.k0 = self.last = 0.0

    def _index(self, name: str | None, k: int) -> int | None:
        """The phase of an evaluation: the first of that name that has not ended before ``k``."""
        for i, phase in enumerate(self.plan):
            if phase.name == name and k <= phase.end and (self.current is None or i >= self.current):
                return i
        return None

    def eta_s(self, name: str | None, k: int) -> float | None:
        """Seconds left after evaluation ``k`` of the phase named ``name``; None before a rate is known."""
        now = time.perf_counter()
        i = self._index(name, k)
        if i is None:
            return None
        phase = self.plan[i]
        if i != self.current:
            self._time_between(i, now - self.last - (self.rate or 0.0) * phase.weight)
            self.current, self.t0, self.k0 = i, now, k
        self.last = now
        if k - self.k0 >= RATE_MIN_EVALS:
            per_eval = (now - self.t0) / (k - self.k0)
            if phase.coarse and self.full_eval_s and self.weighing in (None, i):
                self.weighing = i
                phase = self._weigh_coarse(i, per_eval / self.full_eval_s)
            self.rate = per_eval / phase.weight
        if self.rate is None:
            return None
        evals = (phase.end - k) * phase.weight + sum(p.evals * p.weight for p in self.plan[i + 1:])
        after = phase.after + sum(p.after for p in self.plan[i + 1:])
        return self.rate * evals + (self.after_rate or self.rate) * after

    def _weigh_coarse(self, i: int, weight: float) -> Phase:
        """Give every coarse start of the plan ``weight`` (at most 1); returns phase ``i``."""
        weight = min(weight, 1.0)
        self.plan = [replace(p, weight=weight) if p.coarse else p for p in self.plan]
        return self.plan[i]

    def _time_between(self, i: int, seconds: float) -> None:
        """Set `after_rate` from the ``seconds`` between the phase before phase ``i`` and its first evaluation."""
        before = self.current
        if before is None or i != before + 1 or self.rate is None or seconds <= 0:
            return
        if self.plan[before].coarse or not self.plan[before].after > 0:
            return
        self.after_rate = seconds / self.plan[before].after

    def outputs_s(self) -> float | None:
        """The estimated seconds of the outputs (their expected cost at the rate of the work between phases, else of
        the evaluations); None before a rate is known."""
        if self.rate is None:
            return None
        return (self.after_rate or self.rate) * (self.costs.outputs if self.costs is not None else 0.0)

    def _expect_outputs(self, reused: bool) -> None:
        """Count the last phase's outputs as reused or fresh (`StageCosts`)."""
        if self.costs is None or self.costs.reused == reused:
            return
        costs = replace(self.costs, reused=reused)
        last = self.plan[-1]
        self.plan = self.plan[:-1] + [replace(last, after=last.after - self.costs.outputs + costs.outputs)]
        self.costs = costs

    def __call__(self, k: int, x, terms: dict) -> None:
        if "outputs_reuse" in terms:
            terms = dict(terms)
            self._expect_outputs(bool(terms.pop("outputs_reuse")))
        eta = self.eta_s(terms.get("phase"), k)
        if self.current is not None:  # the evaluations of the run this phase is part of (``terms["limit"]``)
            phase = self.plan[self.current]
            terms = dict(terms, limit=phase.limit or phase.end)
        # before the phase's rate is measured no estimate is given: the optimiser's own covers its run alone
        self.on_iteration(k, x, dict(terms, eta_s=eta))
