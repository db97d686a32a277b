"""Defect correction: aim the design grid's objective at what the printed solid releases.

The design grid's release (first-order fast marching, `design.forward.fmm`) carries an O(dx) error that
depends on the shape (curved fronts, corners, channels), and the printed solid (the mass-preserving cut of
the density, `design.fabrication.extract`) is not the grey density the objective simulates. A design that
matches the target on the grid therefore misses it in the print by a shape-dependent bias. After the
optimisation of eq. (4), each of `DesignConfig.correction_rounds` rounds

1. extracts the printed solid of the current design x, as the run's outputs do, and releases it with the
   reference evaluator (`design.forward.reference`, at the print's anisotropy) on the target's tau grid: P(x);
2. takes the bias b(x) = G(x) - P(x), where G(x) is the design grid's release of the density that J_fit
   sees (eqs. 5-7);
3. re-targets J_fit (eq. 4) at C* + b(x) (at a step, below) and continues the optimiser from x for
   `DesignConfig.correction_evals` evaluations at the final beta (twice it for nfc designs, `ROUND_BETA_FACTOR`).

At a fixed point G(x) = C* + b(x), so P(x) = C*: the print meets the target as the reference evaluator judges
it. The iteration converges when the bias changes little from one design to the next. The grid's error does not
change much, but the cut's can:

- in a free 3D design at the final beta the grey layer the filter leaves is a large part of the bias and the
  optimiser moves it without moving the solid, so nfc rounds steepen the projection (the density they judge and
  continue is nearly binary). Extruded designs lost fit that way and keep the final beta;
- the print's volume follows the extraction level, which a small change of the density can move across its whole
  range (an extruded design's equal-density columns pin it to an end of `design.fabrication.extract.LEVEL_RANGE`),
  so a full step can overshoot.

The rounds are therefore a safeguarded iteration. Round r, from a design x, aims J_fit at
G(x) + s_r (C* - P(x)) = C* + b(x) - (1 - s_r) (C* - P(x)): the full correction for s_r = 1, a share s_r of the
print's residual otherwise. The first round starts from the optimisation's result with s_1 = `FIRST_STEP` of the
space; a round whose print beats the best so far hands its design and step to the next; one that does not sends
the next back to the best design with `BACKTRACK` times the step. Every design a round starts from, and the last
round's, is judged by its print; the result is the one-piece design whose print fits best
(docs/design.md#physical-correction).

`optimise_physical` runs the optimisation and the rounds; what a resume needs between rounds (the round in
progress, its bias and start design, the best print so far) goes to a `RoundStore`, which
`design.files.rounds` keeps in the run folder. The optimiser's own checkpoints of a round go to the run's
`CheckpointStore` as usual, so a run interrupted in a round resumes inside it, evaluation for evaluation
with the "lbfgs" optimiser.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from typing import Callable, Protocol

import numpy as np

from design.fabrication.extract import count_pieces, density_mesh, mass_preserving_level, revoxelize
from design.forward.reference import DEFAULT_CELLS, MIN_CELLS, design_lattice
from design.forward.simulator import simulate
from design.inverse.config import DesignConfig
from design.inverse.objective import DesignObjective, rel_rmse
from design.inverse.optimize import (
    HISTORY_COLUMNS,
    Checkpoint,
    CheckpointStore,
    IterationCallback,
    Outcome,
    StartDesign,
    beta_stages,
    build_objective,
    optimise,
    with_phase,
)
from design.inverse.problem import Problem
from design.inverse.release_cache import cached_reference_release
from design.inverse.status import DesignStatus
from design.inverse.targets import Target

log = logging.getLogger(__name__)

ROUND_BETA_FACTOR = {"nfc": 2.0}
"""The rounds' projection steepness as a multiple of the run's final beta, per design space (1 for the others),
at most `MAX_BETA` (docs/design.md#physical-correction)."""
MAX_BETA = 64.0
"""The steepest projection a `DesignConfig` allows."""

REFERENCE_PER_VOXEL = {"extruded": 1.0}
"""Lattice cells of the rounds' reference releases (`design.forward.reference.reference_release`) per design
voxel along the print's longest side, per design space (`DEFAULT_REFERENCE_PER_VOXEL` for the others), between
the evaluator's `MIN_CELLS` and `DEFAULT_CELLS`: the lattice resolves what the design grid can make, and its cost
follows the design's. An extruded design's evaluations are cheap (a 2D density), so its rounds' releases would
dominate its time at 2 cells; at 1 the bias they find differs from the finer one's by far less than the fit
(docs/design.md#physical-correction). The run's reported figures are the outputs', at `design_lattice`."""
DEFAULT_REFERENCE_PER_VOXEL = 2.0
"""`REFERENCE_PER_VOXEL` of the spaces it does not name."""
FIRST_STEP = {"extruded": 0.5}
"""The first round's step s per design space (1 for the spaces it does not name; module doc). An extruded design's
density is equal along each column, so its extraction level sits at an end of `design.fabrication.extract.LEVEL_RANGE`
and flips with a small change of the mass; the print's volume then moves several times as much as the design
grid's (the star prism at resolution 128: by 5.7% of the target's volume for 1.9%). A step s converges while
the print moves less than 2 / s times as much as the grid: a full step overshoots there, half a step does not
(docs/design.md#physical-correction)."""
BACKTRACK = 0.5
"""The factor on the correction's step s after a round whose print does not beat the best so far; the next round
starts from the best design (module doc, docs/design.md#physical-correction)."""


@dataclass(frozen=True)
class PrintCheck:
    """A design judged by its print (`check_print`).

    Attributes
    ----------
    fit : float
        rel. RMSE of the print's release against the target, fraction of the target's final release.
    pieces : int
        Face-connected pieces of the printed solid on the design grid (`design.fabrication.extract.count_pieces`).
    grid_mm3 : (K,) ndarray of float, mm^3
        G(x): the design grid's release of the density J_fit sees, on the target's tau grid.
    print_mm3 : (K,) ndarray of float, mm^3
        P(x): the reference evaluator's release of the printed solid (zeros when nothing can be extracted).
    cells : int
        The lattice cells of that release (`check_cells`; 0 when nothing was released).
    """

    fit: float
    pieces: int
    grid_mm3: np.ndarray
    print_mm3: np.ndarray
    cells: int = 0

    @property
    def bias_mm3(self) -> np.ndarray:
        """b(x) = G(x) - P(x), mm^3 per tau sample."""
        return self.grid_mm3 - self.print_mm3


def printed_mesh(objective: DesignObjective, problem: Problem, x: np.ndarray):
    """The printed solid of design variables ``x``: the mass-preserving contour of the full density, as
    `design.files.outputs.write_outputs` writes ``design.stl`` (a `trimesh.Trimesh`, mm), or None when no
    density reaches the extraction level."""
    rho_full = objective.space.unfold(objective.density(x))
    level = mass_preserving_level(rho_full)
    if not np.any(rho_full >= level):
        return None
    return density_mesh(rho_full, objective.space.dx_mm, problem.origin_mm, level=level)


def check_cells(space: str, extent_mm: float, dx_mm: float) -> int:
    """The lattice cells of a print check's reference release: `REFERENCE_PER_VOXEL` of design ``space`` per voxel
    of ``dx_mm`` along the print's longest side ``extent_mm``, between the evaluator's `MIN_CELLS` and
    `DEFAULT_CELLS`."""
    per_voxel = REFERENCE_PER_VOXEL.get(space, DEFAULT_REFERENCE_PER_VOXEL)
    return int(np.clip(np.ceil(per_voxel * extent_mm / dx_mm), MIN_CELLS, DEFAULT_CELLS))


def check_print(objective: DesignObjective, problem: Problem, x: np.ndarray) -> PrintCheck:
    """Judge design variables ``x`` (variable shape) by their print: G(x), P(x), the print's fit and pieces."""
    space, target = objective.space, problem.target
    anisotropy = objective.physics["anisotropy"]
    dtau_mm = target.total_time_mm / (target.tau_mm.size - 1)
    grid = simulate(objective.density(x), space.dx_mm, mirror=space.mirror, total_time_mm=target.total_time_mm,
                    dtau_mm=dtau_mm, anisotropy=anisotropy).released_mm3
    mesh = printed_mesh(objective, problem, x)
    if mesh is None:
        return PrintCheck(np.inf, 0, grid, np.zeros_like(grid))
    cells = check_cells(space.name, float(np.max(mesh.extents)), space.dx_mm)
    printed = cached_reference_release(mesh, target.tau_mm, cells=cells, anisotropy=anisotropy).released_mm3
    pieces = count_pieces(revoxelize(mesh, space.dx_mm, problem.origin_mm, problem.full_shape))
    return PrintCheck(rel_rmse(printed, target.released_mm3), pieces, grid, printed, cells)


def retargeted(problem: Problem, config: DesignConfig, bias_mm3: np.ndarray) -> DesignObjective:
    """The objective of eq. (4) with J_fit aimed at C* + ``bias_mm3``, at the rounds' beta (`round_beta`)."""
    target = problem.target
    aimed = Target(target.tau_mm, target.released_mm3 + bias_mm3, target.source)
    objective = build_objective(replace(problem, target=aimed), config)
    objective.beta = round_beta(config)
    return objective


def final_beta(config: DesignConfig) -> float:
    """The projection steepness of the run's last beta stage (`design.inverse.optimize.beta_stages`)."""
    return beta_stages(config)[-1][0]


def round_beta(config: DesignConfig) -> float:
    """The projection steepness of the correction rounds, of their prints and of the run's outputs:
    the space's `ROUND_BETA_FACTOR` times the final beta, at most `MAX_BETA`."""
    return min(MAX_BETA, ROUND_BETA_FACTOR.get(config.space, 1.0) * final_beta(config))


@dataclass(frozen=True)
class RoundState:
    """Where the correction rounds stand: what a resume needs (`RoundStore`).

    Attributes
    ----------
    round : int
        The round in progress, from 1; `DesignConfig.correction_rounds` + 1 when all rounds are judged.
    start : int
        Evaluations of the run when the round in progress began.
    end : int
        Evaluations of the run at which it ends.
    bias_mm3 : (K,) ndarray of float, mm^3
        Its bias b (J_fit aims at C* + b).
    x_start : (N,) ndarray of float
        The design variables it starts from, flat.
    best_x : (N,) ndarray of float
        The design whose print is best so far (one piece first, then the lowest fit), flat.
    best_fit : float
        That print's fit (`PrintCheck.fit`).
    best_pieces : int
        Its pieces.
    fits : (R,) ndarray of float
        The print's fit of each design judged so far, in order (the optimisation's result first).
    status : str
        How the optimisations so far ended, as a `DesignStatus`: "max_iter" while each reached its limit, else
        the first early end (the run's status unless its evaluations reach `DesignConfig.max_iter`).
    step : float
        The step s of the round in progress (module doc): its bias is b(x) - (1 - s) (C* - P(x)) for its start
        design x.
    best_grid_mm3, best_print_mm3 : (K,) ndarray of float, mm^3
        G and P of the best design (`PrintCheck`), from which a round after one that did not improve is aimed;
        empty in a state that did not record them (then judged again when needed).
    """

    round: int
    start: int
    end: int
    bias_mm3: np.ndarray
    x_start: np.ndarray
    best_x: np.ndarray
    best_fit: float
    best_pieces: int
    fits: np.ndarray
    status: str
    step: float = 1.0
    best_grid_mm3: np.ndarray = field(default_factory=lambda: np.zeros(0))
    best_print_mm3: np.ndarray = field(default_factory=lambda: np.zeros(0))


class RoundStore(Protocol):
    """Where `optimise_physical` keeps its `RoundState` (`design.files.rounds.RoundFile` in the run folder)."""

    def load(self) -> RoundState | None:
        """The stored state, None when no round has begun."""

    def save(self, state: RoundState) -> None:
        """Store ``state`` (atomically: a resume reads the old state or the new one)."""


def _better(check: PrintCheck, state: RoundState | None) -> bool:
    """Whether a judged design beats the best so far: any print beats no print (no density reaches the extraction
    level); of two prints, fewer pieces, else a lower fit. Of two designs with no print yet, the later one (the
    optimisation's progress)."""
    if state is None or state.best_pieces == 0:
        return True
    if check.pieces == 0:
        return False
    return check.pieces < state.best_pieces or (check.pieces == state.best_pieces and check.fit < state.best_fit)


def aimed_bias(check: PrintCheck, target_mm3: np.ndarray, step: float) -> np.ndarray:
    """The bias a round from the design of ``check`` aims J_fit with at step ``step``: J_fit's aim
    C* + bias = G + step (C* - P), that is bias = b - (1 - step) (C* - P) (b exactly for ``step`` 1), mm^3.
    A design with no print yet (no density reaches the extraction level) has no bias to measure: 0, the round
    aims at the target itself."""
    if check.pieces == 0:
        return np.zeros_like(target_mm3)
    if step == 1.0:
        return check.bias_mm3
    return check.bias_mm3 - (1.0 - step) * (target_mm3 - check.print_mm3)


def _judged(state: RoundState | None, check: PrintCheck, config: DesignConfig, outcome: Outcome,
            target_mm3: np.ndarray, judge: Callable[[np.ndarray], PrintCheck]) -> RoundState:
    """The state after judging the result of an optimisation (round ``state.round``, or the first optimisation
    for ``state`` None): the best so far updated, and the next round set up (module doc): from this design with
    the same step when its print is the best so far, else from the best design with `BACKTRACK` times the step.
    ``judge(x)`` judges a flat design again (a state that did not record the best design's curves)."""
    x, evaluations = np.ravel(outcome.best_x).copy(), len(outcome.history)
    round_ = 1 if state is None else state.round + 1
    best = _better(check, state)
    log.info("print of the design before round %d: rel. RMSE %.3f%%, %d piece(s)", round_, 100 * check.fit, check.pieces)
    if best:
        base, x_base, step = check, x, FIRST_STEP.get(config.space, 1.0) if state is None else state.step
    else:
        base = (PrintCheck(state.best_fit, state.best_pieces, state.best_grid_mm3, state.best_print_mm3)
                if state.best_grid_mm3.size else judge(state.best_x))
        x_base, step = state.best_x, BACKTRACK * state.step
        log.info("the print did not improve: the next round starts from the best design (%.3f%%) at step %.3g",
                 100 * state.best_fit, step)
    return RoundState(round=round_, start=evaluations, end=evaluations + config.correction_evals,
                      bias_mm3=aimed_bias(base, target_mm3, step), x_start=x_base,
                      best_x=x if best else state.best_x, best_fit=check.fit if best else state.best_fit,
                      best_pieces=check.pieces if best else state.best_pieces,
                      fits=np.append([] if state is None else state.fits, check.fit),
                      status=str(outcome.status if state is None or state.status == DesignStatus.MAX_ITER
                                 else state.status),
                      step=step, best_grid_mm3=base.grid_mm3, best_print_mm3=base.print_mm3)


def correction_plan(config: DesignConfig) -> tuple[int, int]:
    """``(rounds, first)``: the correction rounds a run makes and the evaluations of its first optimisation.

    The rounds' evaluations are part of ``config.max_iter``: the first optimisation gets what they leave, and
    at least half of it; the rounds that do not fit are dropped ((0, max_iter) without correction).
    """
    if config.physical_correction != "defect":
        return 0, config.max_iter
    rounds = min(config.correction_rounds, (config.max_iter // 2) // config.correction_evals)
    return rounds, config.max_iter - rounds * config.correction_evals


def round_phase(round_: int, rounds: int) -> str:
    """The progress phase (``terms["phase"]``) of correction round ``round_`` (from 1) of ``rounds``."""
    return f"physical correction round {round_} of {rounds}"


class _Running:
    """A `CheckpointStore` that records every checkpoint as running (no status): the optimisations of a run with
    correction rounds are parts of it, and only `optimise_physical` knows when the whole has finished."""

    def __init__(self, store: CheckpointStore) -> None:
        self.store = store

    def save(self, checkpoint: Checkpoint, *, wait: bool = True) -> None:
        self.store.save(replace(checkpoint, status=None), wait=wait)

    def wait(self) -> None:
        self.store.wait()


def outputs_reuse(cells: int, config: DesignConfig) -> bool:
    """Whether the outputs of a run of ``config`` reuse the release of a print checked on ``cells`` lattice cells
    (`design.inverse.release_cache`): the outputs' lattice (`design.forward.reference.design_lattice`), with no print
    offset or swelling, which the outputs release otherwise."""
    return cells == design_lattice(config.resolution) and config.print_offset_mm == 0.0 and config.swelling_mm == 0.0


def _telling_reuse(on_iteration: IterationCallback | None, check: PrintCheck, config: DesignConfig
                   ) -> IterationCallback | None:
    """``on_iteration`` with ``terms["outputs_reuse"]`` (`outputs_reuse` of ``check``'s lattice), for the time left
    (`design.inverse.progress.RunClock`)."""
    if on_iteration is None:
        return None
    reuse = outputs_reuse(check.cells, config)
    return lambda k, x, terms: on_iteration(k, x, dict(terms, outputs_reuse=reuse))


def optimise_physical(objective: DesignObjective, problem: Problem, config: DesignConfig, store: CheckpointStore,
                      rounds: RoundStore, *, saved: Checkpoint | None = None, start: StartDesign | None = None,
                      on_iteration: IterationCallback | None = None,
                      should_stop: Callable[[], bool] | None = None) -> tuple[Outcome, DesignObjective]:
    """`design.inverse.optimize.optimise`, then the defect-correction rounds of ``config`` (module doc).

    Parameters are those of `optimise`, and ``rounds``, where the state between rounds is kept (read only when
    resuming, ``saved`` given). With ``config.physical_correction`` "none" this is `optimise`. A resume whose
    ``max_iter`` is above the run's evaluations after its rounds makes one more round up to it. With
    correction, every checkpoint records the run as running until the last round is judged; the last one
    holds the chosen design as ``best_x`` and the first optimisation's status.

    Returns
    -------
    Outcome
        Of the whole run: the first optimisation's status (the rounds are bounded additions to it), every
        evaluation in the history, and as ``best_x`` the design whose print fits best once the rounds are
        over (the last optimisation's best while they are not); ``best_value`` is the last optimisation's
        lowest J (NaN for a run resumed after its last round was judged).
    DesignObjective
        The objective the outputs evaluate the density with (at the rounds' beta once they have begun).
    """
    n_rounds, first = correction_plan(config)
    if n_rounds == 0:
        return optimise(objective, problem, config, store, saved=saved, start=start, on_iteration=on_iteration,
                        should_stop=should_stop), objective
    t0 = time.perf_counter()
    running = _Running(store)
    beta = round_beta(config)
    target_mm3 = problem.target.released_mm3

    def judge(x: np.ndarray) -> PrintCheck:
        return check_print(objective, problem, x.reshape(objective.space.var_shape))

    state = rounds.load() if saved is not None else None
    if state is None:
        outcome = optimise(objective, problem, replace(config, max_iter=first), running, saved=saved, start=start,
                           on_iteration=on_iteration, should_stop=should_stop)
        if not outcome.status.finished:
            return replace(outcome, session_seconds=time.perf_counter() - t0), objective
        objective.beta = beta  # the prints are judged at the rounds' beta, as the outputs cut them
        check = check_print(objective, problem, outcome.best_x)
        state = _judged(None, check, config, outcome, target_mm3, judge)
        rounds.save(state)
        told = _telling_reuse(on_iteration, check, config)
        history, saved, best_value = outcome.history, None, outcome.best_value
    else:
        history, best_value = [list(row) for row in saved.history], np.nan
        objective.beta = beta
        told = on_iteration
    while state.round <= n_rounds or (len(history) < config.max_iter and state.status == DesignStatus.MAX_ITER):
        if state.round > n_rounds and state.end != config.max_iter:  # a resume raised the limit: one more round
            state = replace(state, end=config.max_iter)
            rounds.save(state)
        aimed = retargeted(problem, config, state.bias_mm3)
        if saved is None or len(saved.history) <= state.start:  # the round has not checkpointed yet
            rows = np.array(history[:state.start], dtype=float).reshape(state.start, len(HISTORY_COLUMNS))
            saved = Checkpoint(x=state.x_start, best_x=state.x_start, best_value=np.inf, stage=0, history=rows,
                               beta=beta)
        outcome = optimise(aimed, problem, replace(config, beta=beta, beta_final=beta, max_iter=state.end), running,
                           saved=saved, should_stop=should_stop,
                           on_iteration=with_phase(told, round_phase(state.round, max(n_rounds, state.round))))
        saved, history, best_value = None, outcome.history, outcome.best_value
        if not outcome.status.finished:
            return replace(outcome, session_seconds=time.perf_counter() - t0), aimed
        del aimed  # its fast-marching buffers
        check = check_print(objective, problem, outcome.best_x)
        state = _judged(state, check, config, outcome, target_mm3, judge)
        rounds.save(state)
        told = _telling_reuse(on_iteration, check, config)
    log.info("physical correction: print fits %s; keeping %.3f%%, %d piece(s)",
             ", ".join(f"{100 * f:.3f}%" for f in state.fits), 100 * state.best_fit, state.best_pieces)
    status = DesignStatus.MAX_ITER if len(history) >= config.max_iter else DesignStatus(state.status)
    store.save(Checkpoint(x=state.best_x, best_x=state.best_x, best_value=float(best_value), stage=len(beta_stages(config)),
                          history=np.array(history, dtype=float).reshape(len(history), len(HISTORY_COLUMNS)),
                          beta=beta, status=status))
    return Outcome(status, len(history), float(best_value), state.best_x.reshape(objective.space.var_shape), history,
                   time.perf_counter() - t0), objective
