"""The optimiser loop of inverse design: a resumable minimisation of eq. (4) (sections 3.3-3.4, 5.2).

`optimise` starts from the uniform density of section 5.2 (or a start design, or a `Checkpoint`),
minimises eq. (4), hands a `Checkpoint` to a `CheckpointStore` every few evaluations, and on any stop
(convergence, iteration limit, `should_stop`, Ctrl-C) returns the best design found. It reads and writes
no file: the run folder (configuration, checkpoints, outputs) is `design.files.rundir`, whose
`run_design` is the public entry.

Optimisers (`DesignConfig.optimizer`): "lbfgs" (default), the lean L-BFGS of `design.inverse.lbfgs`, whose
step costs a small fraction of an evaluation and whose whole state goes into every checkpoint, so a
resumed run repeats the uninterrupted one evaluation for evaluation (with its default line search,
`DesignConfig.line_search` "luksan", it evaluates the designs nlopt's LD_LBFGS evaluates, checked by
tests/design/inverse/test_lbfgs.py, at a fraction of its cost per step); or nlopt's "LD_LBFGS",
"LD_MMA", "LD_CCSAQ", whose internal state is not accessible: their resumes restart with an empty
memory from the last evaluated design.

Bounds 0 <= rho_hat <= 1. With ``bounds="cosine"`` (default) the optimiser sees unconstrained
variables z and ``rho_hat = (1 - cos z) / 2``; with ``bounds="box"`` nlopt gets the box directly
(the "lbfgs" optimiser is unconstrained and requires the cosine map). The cosine map is the default
because nlopt's LD_LBFGS (Luksan's code) handles active box bounds poorly on this objective, and
because, unlike a sigmoid map, whose saturated variables lose their gradient for good, the periodic
map has no flat region in which L-BFGS can report success far from a minimum.

The cosine map has one trap: ``d rho_hat / dz = sqrt(rho_hat (1 - rho_hat))`` vanishes at the bounds, so a
variable at exactly 0 or 1 has a zero gradient in z whatever dJ/d rho_hat, and is a stationary point in z even
where J would fall as it moves inside (a saddle, not a minimum). J_binary drives the variables of an extruded
design to 0 and 1 (to round-off) within its first beta stage; every later session (the next beta stages, the restarts,
the defect-correction rounds of `design.inverse.defect`, whose targets have moved) then began with a zero
gradient for all of them and ended at once, its design unchanged. So every new session of an extruded (or ICO)
design starts from rho_hat moved `SESSION_FLOOR` inside the bounds (``from_x``), where
the gradient in z is about ``sqrt(SESSION_FLOOR)`` of dJ/d rho_hat: the variables whose J falls inwards move,
the others return to the bound. A run's first session starts inside anyway
(`design.inverse.objective.START_OUTSIDE`), and a resumed session restores its optimiser's own variables, so
resumes stay exact. Free 3D (nfc) designs keep their
sessions' variables as they are: there the floor helped one of two shapes and set the other back
(docs/design.md#optimiser-sessions-start-inside-the-bounds).

One "iteration" here is one objective-and-gradient evaluation; L-BFGS line searches occasionally
need more than one per step, so the evaluation count bounds the work exactly.

Both optimisers end early on this piecewise-smooth objective (a line search that finds no acceptable
step, or nlopt's step criteria reporting success far from a minimum); the run then restarts from the
best point with an empty curvature memory while each session still lowers J by `RESTART_GAIN`, at
most `MAX_RESTARTS` times per beta stage.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Callable, Protocol

import nlopt
import numpy as np

from design.inverse.config import DesignConfig
from design.inverse.lbfgs import CONVERGED, STALLED, Lbfgs, LbfgsSettings
from design.inverse.objective import DesignObjective
from design.inverse.problem import Problem
from design.inverse.settings import BETA_STAGES
from design.inverse.status import DesignStatus
from design.threads import in_parts

log = logging.getLogger(__name__)

IterationCallback = Callable[[int, np.ndarray, dict], None]
"""``on_iteration(k, x, terms)``: evaluation ``k``, its design variables ``x`` in the variable shape, and its
terms (`optimise`)."""


def with_phase(on_iteration: IterationCallback | None, phase: str) -> IterationCallback | None:
    """``on_iteration`` with ``terms["phase"]`` set to ``phase`` (which run of a multi-start, which correction
    round, for progress); a phase the terms already name is a part of it: "PHASE, PART"."""
    if on_iteration is None:
        return None
    return lambda k, x, terms: on_iteration(k, x, dict(terms, phase=f"{phase}, {terms['phase']}" if "phase" in terms
                                                        else phase))


StartDesign = Callable[[DesignObjective, Problem], np.ndarray]
MAX_RESTARTS = 20
"""L-BFGS restarts from the best point after the optimiser ends early (module doc)."""
RESTART_GAIN = 1e-3
"""Relative decrease of J a session must achieve for another restart to be tried."""
SESSION_FLOOR = {"extruded": 1e-3, "ico": 1e-3}
"""With the cosine map, how far inside the bounds 0 and 1 every new session (a beta stage, a restart, a defect
correction round) starts each variable of rho_hat, per design space (0 for the spaces it does not name; module
doc). ICO designs: J_binary at their fixed beta drives their variables to the bounds, and without the floor the
pill's correction rounds at resolution 48 stalled at their first evaluation (docs/design.md#physical-correction)."""
_ERROR = "error"
"""The stop reason of an evaluation that raised (the error is re-raised; never a run's status)."""
HISTORY_COLUMNS = ("iteration", "J", "J_fit", "J_binary", "J_fab", "fab_seconds", "grad_norm", "seconds")
"""One row per evaluation: ``fab_seconds`` is the time of that evaluation's J_fab (the ICO solves), s;
``seconds`` the run time so far, s."""


@dataclass(frozen=True)
class Checkpoint:
    """What a run resumes from (``checkpoint.npz``, `design.files.records`).

    Attributes
    ----------
    x : (N,) ndarray of float
        The last evaluated design variables rho_hat, flat.
    best_x : (N,) ndarray of float
        The best design variables of the current beta stage, flat.
    best_value : float
        J at ``best_x``.
    stage : int
        The beta stage the run continues with (`beta_stages`).
    history : (M, len(HISTORY_COLUMNS)) ndarray of float
        Every evaluation so far.
    lbfgs : dict of str to ndarray
        The "lbfgs" optimiser's state (`design.inverse.lbfgs.Lbfgs.state`) when a trial point is pending,
        else empty.
    beta : float
        The projection steepness of the objective at the checkpoint: the beta the outputs of a finished
        run are computed at. NaN when not recorded (then the beta of ``stage``).
    status : DesignStatus or None
        How the optimisation ended (the last checkpoint of a session), None while it runs.
    fab : dict of str to ndarray
        The fabrication term's state (`design.inverse.spaces.FabTerm.state`: the ICO term's warm starts
        and counters), empty without one.
    """

    x: np.ndarray
    best_x: np.ndarray
    best_value: float
    stage: int
    history: np.ndarray
    lbfgs: dict[str, np.ndarray] = field(default_factory=dict)
    beta: float = float("nan")
    status: DesignStatus | None = None
    fab: dict[str, np.ndarray] = field(default_factory=dict)


class CheckpointStore(Protocol):
    """Where `optimise` keeps its checkpoints (`design.files.rundir.CheckpointFile` writes ``checkpoint.npz``).

    ``save(checkpoint, wait=False)`` may write while the next evaluation runs: the arrays are handed over
    as they are, not copied, and `optimise` calls ``wait()`` before the optimiser changes them; ``wait()``
    raises what a pending write raised.
    """

    def save(self, checkpoint: Checkpoint, *, wait: bool = True) -> None: ...

    def wait(self) -> None: ...


@dataclass(frozen=True)
class Outcome:
    """What `optimise` returns.

    Attributes
    ----------
    status : DesignStatus
    iterations : int
        Objective evaluations over all sessions of the run (resumes included).
    best_value : float
    best_x : ndarray of float, variable shape
        The best design variables found.
    history : list of rows with `HISTORY_COLUMNS`
    session_seconds : float
        Wall time of this session.
    """

    status: DesignStatus
    iterations: int
    best_value: float
    best_x: np.ndarray
    history: list[list[float]]
    session_seconds: float


class _Run:
    """State of one optimisation session: best design, history, checkpoints, stop reason."""

    def __init__(self, objective: DesignObjective, store: CheckpointStore, config: DesignConfig, start: int,
                 history: list[list[float]], on_iteration: IterationCallback | None,
                 should_stop: Callable[[], bool] | None) -> None:
        self.objective = objective
        self.store = store
        self.config = config
        self.k = start
        self.history = history
        self.on_iteration = on_iteration
        self.should_stop = should_stop
        self.best_x: np.ndarray | None = None
        self.best_value = min((row[1] for row in history), default=np.inf)
        self.last_x: np.ndarray | None = None
        self.stop_reason: DesignStatus | str | None = None
        self.error: Exception | None = None
        self.opt: nlopt.opt | None = None
        self.lbfgs: Lbfgs | None = None  # the "lbfgs" optimiser with a pending trial point
        self.stage = 0  # index of the beta stage a resume continues with
        self.terms: dict = {}
        self.t0 = time.perf_counter() - (history[-1][-1] if history else 0.0)
        self.session_t0 = time.perf_counter()
        self.session_start = start
        self.cosine = config.bounds == "cosine"
        self.stage_end = config.max_iter

    def to_x(self, z: np.ndarray) -> np.ndarray:
        """Design variables rho_hat from the optimiser's variables."""
        return _cosine_map(z) if self.cosine else z

    def from_x(self, x: np.ndarray) -> np.ndarray:
        """The optimiser's variables of a new session from rho_hat, with the cosine map each at least the design
        space's `SESSION_FLOOR` inside the bounds (module doc)."""
        if not self.cosine:
            return x
        edge = 1.0 - 2.0 * SESSION_FLOOR.get(self.objective.space.name, 0.0)
        return np.arccos(np.clip(1.0 - 2.0 * x, -edge, edge))

    def __call__(self, z: np.ndarray, grad: np.ndarray) -> float:
        """nlopt's ``f(x, grad)``. Stops go through ``opt.force_stop()``: an exception raised in
        the callback leaves nlopt's Python wrapper calling back with the error still set."""
        try:
            return self._step(z, grad)
        except KeyboardInterrupt:
            return self._stop(DesignStatus.INTERRUPTED, grad)
        except Exception as exc:  # noqa: BLE001 -- re-raised by _optimise after nlopt returns
            self.error = exc
            return self._stop(_ERROR, grad)

    def _stop(self, reason: DesignStatus | str, grad: np.ndarray) -> float:
        self.stop_reason = self.stop_reason or reason
        self.opt.force_stop()
        if grad.size:
            grad[:] = 0.0
        return float(self.best_value) if np.isfinite(self.best_value) else 0.0

    def _step(self, z: np.ndarray, grad: np.ndarray) -> float:
        if self.stop_reason is not None:
            return self._stop(self.stop_reason, grad)
        reason = self.stop_requested()  # nlopt's maxeval may allow one extra evaluation
        if reason is not None:
            return self._stop(reason, grad)
        value = self.evaluate(z, grad)
        self.report()
        return value

    def stop_requested(self) -> DesignStatus | None:
        """MAX_ITER at the stage's evaluation limit, STOPPED when `should_stop` says so, else None."""
        if self.k >= self.stage_end:
            return DesignStatus.MAX_ITER
        if self.should_stop is not None and self.should_stop():
            return DesignStatus.STOPPED
        return None

    def evaluate(self, z: np.ndarray, grad: np.ndarray) -> float:
        """J at the optimiser's variables ``z``, dJ/dz written into ``grad`` (if not empty); records
        the evaluation in the history and the best design."""
        x = self.to_x(z) if self.cosine else z.copy()  # a new array: kept as last_x/best_x as it is
        ev = self.objective.evaluate(x.reshape(self.objective.space.var_shape))
        self.store.wait()  # the optimiser's update, after this returns, changes the saved arrays
        if grad.size:
            if self.cosine:
                _cosine_map_adjoint(z, ev.grad.ravel(), grad)
            else:
                grad[:] = ev.grad.ravel()
        self.k += 1
        self.last_x = x
        if ev.value < self.best_value or self.best_x is None:
            self.best_value = ev.value
            self.best_x = x
        elapsed = time.perf_counter() - self.t0
        t = ev.terms
        self.history.append([self.k, t["J"], t["J_fit"], t["J_binary"], t["J_fab"], t.get("fab_seconds", 0.0),
                             t["grad_norm"], elapsed])
        per_eval = (time.perf_counter() - self.session_t0) / (self.k - self.session_start)
        self.terms = dict(t, seconds=elapsed, eta_s=per_eval * max(self.config.max_iter - self.k, 0))
        return ev.value

    def report(self) -> None:
        """After an evaluation (and the optimiser's update): checkpoint when due, then `on_iteration`."""
        if self.k % self.config.checkpoint_every == 0:
            self.checkpoint(wait=False)
        if self.on_iteration is not None:
            x = self.last_x.reshape(self.objective.space.var_shape)
            x.flags.writeable = False  # a view of the run's own variables
            self.on_iteration(self.k, x, self.terms)

    def checkpoint(self, wait: bool = True, status: DesignStatus | None = None) -> None:
        """Hand the current and best variables, the history, the stage, the objective's beta, the "lbfgs"
        optimiser's state (when a trial is pending), the fabrication term's state and, at the end of a
        session, its ``status`` to the store.

        With ``wait=False`` the store may write while the next evaluation runs (the optimiser's 2 m N
        doubles take seconds to write at 128^3). The arrays are handed over as
        they are, not copied: the evaluation only reads them and writes the trial gradient, which is not
        saved, and `evaluate` waits for the store before returning to the optimiser.
        """
        self.store.wait()
        if self.last_x is None:
            return
        state = {} if self.lbfgs is None else dict(self.lbfgs.state())
        term = self.objective.space.fab_term
        self.store.save(Checkpoint(x=self.last_x, best_x=self.best_x, best_value=self.best_value, stage=self.stage,
                                   history=np.array(self.history, dtype=float).reshape(-1, len(HISTORY_COLUMNS)),
                                   lbfgs=state, beta=float(self.objective.beta), status=status,
                                   fab={} if term is None else term.state()), wait=wait)


def _cosine_map(z: np.ndarray) -> np.ndarray:
    """rho_hat = (1 - cos z) / 2 of the cosine map (module doc), a new array."""
    x = np.empty(z.shape)
    flat_z, flat_x = z.reshape(-1), x.reshape(-1)

    def part(i: int, j: int) -> None:
        o = flat_x[i:j]
        np.cos(flat_z[i:j], out=o)
        np.subtract(1.0, o, out=o)
        np.multiply(0.5, o, out=o)

    in_parts(part, z.size)
    return x


def _cosine_map_adjoint(z: np.ndarray, grad_x: np.ndarray, out: np.ndarray) -> None:
    """dJ/dz = dJ/drho_hat sin(z) / 2 of the cosine map, written into ``out`` (flat)."""
    def part(i: int, j: int) -> None:
        o = out[i:j]
        np.multiply(grad_x[i:j], np.sin(z[i:j]), out=o)
        o *= 0.5

    in_parts(part, z.size)


def _optimise(run: _Run, x0: np.ndarray, remaining: int) -> DesignStatus:
    """One nlopt session (algorithm `DesignConfig.optimizer`) from ``x0``, at most ``remaining`` evaluations."""
    cfg = run.config
    if run.stop_reason == DesignStatus.MAX_ITER:  # the previous beta stage's end, not the run's
        run.stop_reason = None
    opt = nlopt.opt(getattr(nlopt, cfg.optimizer), x0.size)
    if not run.cosine:
        opt.set_lower_bounds(0.0)
        opt.set_upper_bounds(1.0)
    opt.set_min_objective(run)
    opt.set_maxeval(remaining)
    run.stage_end = run.k + remaining
    opt.set_ftol_rel(cfg.ftol_rel)
    opt.set_xtol_rel(cfg.xtol_rel)
    if cfg.optimizer == "LD_LBFGS":
        opt.set_vector_storage(cfg.lbfgs_memory)  # L-BFGS memory: O(m N) doubles
    run.opt = opt
    try:
        opt.optimize(run.from_x(x0))
    except KeyboardInterrupt:
        return DesignStatus.INTERRUPTED
    except Exception as exc:  # noqa: BLE001 -- nlopt reports forced stops, roundoff and failures alike
        if run.error is not None:
            raise run.error
        if run.stop_reason is None:
            log.info("nlopt stopped (%s: %s) after %d evaluations", type(exc).__name__, exc, run.k)
            return DesignStatus.STALLED
    finally:
        run.opt = None  # nlopt's L-BFGS memory (m N doubles) goes with it
    if run.error is not None:
        raise run.error
    if run.stop_reason is not None:
        return run.stop_reason
    code = opt.last_optimize_result()
    return DesignStatus.MAX_ITER if code == nlopt.MAXEVAL_REACHED else DesignStatus.CONVERGED


def beta_stages(config: DesignConfig) -> list[tuple[float, int]]:
    """``(beta, last evaluation)`` of each stage of a run.

    Without continuation (``beta_final`` None) one stage at ``beta``. With it, `BETA_STAGES` stages
    of equal length whose beta rises geometrically from ``beta`` to ``beta_final``.
    """
    if config.beta_final is None or config.beta_final == config.beta:
        return [(float(config.beta), config.max_iter)]
    ratios = np.linspace(0.0, 1.0, BETA_STAGES)
    betas = config.beta * (config.beta_final / config.beta) ** ratios
    ends = [int(round(config.max_iter * (i + 1) / BETA_STAGES)) for i in range(BETA_STAGES)]
    return [(float(b), e) for b, e in zip(betas, ends)]


def _stage_lbfgs(run: _Run, start: np.ndarray, stage_end: int, state: dict | None) -> DesignStatus:
    """`design.inverse.lbfgs` from ``start`` (or from a checkpointed ``state``) until evaluation
    ``stage_end``; after an early end a new session starts at the best design so far, as `_stage`
    restarts nlopt (module doc), its count and the best J it began with kept in the optimiser's state."""
    cfg = run.config
    settings = LbfgsSettings(memory=cfg.lbfgs_memory, ftol_rel=cfg.ftol_rel, xtol_rel=cfg.xtol_rel,
                             line_search=cfg.line_search)
    if state is not None:
        opt = Lbfgs.from_state(state)
    else:
        opt = Lbfgs(run.from_x(start), settings)
        opt.f_restart = run.best_value
    run.lbfgs, run.stage_end = opt, stage_end
    try:
        while True:
            reason = run.stop_requested()
            if reason is not None:
                return reason
            outcome = opt.tell(run.evaluate(opt.x_trial, opt.g_trial))
            ended = None
            if outcome in (CONVERGED, STALLED):  # decided before the checkpoint, which must hold it
                if opt.restarts < MAX_RESTARTS and run.best_value < opt.f_restart * (1.0 - RESTART_GAIN):
                    log.info("restarting L-BFGS from the best design (J = %.6g)", run.best_value)
                    sessions, opt = opt.restarts + 1, Lbfgs(run.from_x(run.best_x), settings)
                    opt.restarts, opt.f_restart = sessions, run.best_value
                    run.lbfgs = opt
                else:
                    ended = DesignStatus.STALLED if outcome == STALLED else DesignStatus.CONVERGED
                    run.lbfgs, run.stage = None, run.stage + 1
            run.report()
            if ended is not None:
                return ended
    except KeyboardInterrupt:
        return DesignStatus.INTERRUPTED


_ENDED_EARLY = (DesignStatus.STALLED, DesignStatus.CONVERGED)
"""Statuses after which a stage restarts from the best design while that still makes progress (module doc)."""


def _stage(run: _Run, start: np.ndarray, stage_end: int) -> DesignStatus:
    """nlopt from ``start`` until evaluation ``stage_end``, restarting after early ends."""
    status = DesignStatus.MAX_ITER
    for _ in range(1 + MAX_RESTARTS):
        remaining = stage_end - run.k
        if remaining <= 0:
            return DesignStatus.MAX_ITER
        before = run.best_value
        status = _optimise(run, start, remaining)
        start = run.best_x.copy() if run.best_x is not None else start
        # nlopt's L-BFGS ends early on the piecewise-smooth fast-marching objective (line-search
        # failure, or its internal step criteria reporting success far from a minimum); restart
        # from the best point with empty curvature memory while that still makes progress
        if status not in _ENDED_EARLY or not run.best_value < before * (1.0 - RESTART_GAIN):
            break
        log.info("restarting L-BFGS from the best design (J = %.6g)", run.best_value)
    return status


def build_objective(problem: Problem, config: DesignConfig) -> DesignObjective:
    """The objective of eq. (4) for a prepared problem and its run's settings."""
    return DesignObjective(problem.space, problem.target.released_mm3, problem.target.total_time_mm,
                           radius_vox=problem.radius_vox, beta=config.beta, w_binary=config.w_binary,
                           w_fab=config.w_fab, w_rate=config.w_rate, robust_eta=config.robust_eta,
                           rate_span=tuple(config.rate_span),
                           w_conn=0.0 if config.allow_pieces else config.w_connect,
                           conn_planes=config.connect_planes, conn_tail=config.connect_tail,
                           anisotropy=config.anisotropy, swelling_mm=config.swelling_mm,
                           w_channel=config.w_channel or 0.0, channel_mm=config.swelling_mm,
                           rate_lag=max(1, round(config.rate_window_vox * problem.space.dx_mm * (config.samples - 1)
                                                 / problem.target.total_time_mm)))


def restore_objective(objective: DesignObjective, saved: Checkpoint, config: DesignConfig) -> None:
    """Put ``objective`` in the state the run of ``saved`` left it: its beta (the one a finished run's
    outputs are computed at; for a checkpoint that did not record it, the beta of its stage) and the
    fabrication term's warm starts and counters, so that a resumed run repeats the uninterrupted one."""
    stages = beta_stages(config)
    objective.beta = saved.beta if np.isfinite(saved.beta) else stages[min(int(saved.stage), len(stages) - 1)][0]
    if saved.fab and objective.space.fab_term is not None:
        objective.space.fab_term.restore(saved.fab)


def optimise(objective: DesignObjective, problem: Problem, config: DesignConfig, store: CheckpointStore, *,
             saved: Checkpoint | None = None, start: StartDesign | None = None,
             on_iteration: IterationCallback | None = None,
             should_stop: Callable[[], bool] | None = None) -> Outcome:
    """Minimise eq. (4) through the beta stages of ``config``, from ``saved`` or a start design.

    Parameters
    ----------
    objective : DesignObjective
        `build_objective` of the problem; its beta follows the stages.
    problem : Problem
    config : DesignConfig
    store : CheckpointStore
        Receives a `Checkpoint` every ``config.checkpoint_every`` evaluations and at the end.
    saved : Checkpoint, optional
        Continue from it: exactly where the run stopped with the "lbfgs" optimiser; with nlopt's, from
        the last evaluated design with an empty memory.
    start : callable, optional
        ``start(objective, problem)`` returns the start variables of a new run (variable shape);
        default the uniform start of section 5.2 (`DesignObjective.uniform_start`).
    on_iteration : callable, optional
        ``on_iteration(k, x, terms)`` after every evaluation ``k`` (from 1); ``x`` the evaluated design
        variables rho_hat in the variable shape (`DesignSpace.var_shape`: 3D, or 2D for an extruded design),
        read-only; ``terms`` holds J, J_fit, J_binary, J_fab, grad_norm, seconds and eta_s (upper bound
        from the iteration limit).
    should_stop : callable, optional
        Polled before every evaluation; True stops cleanly.

    Returns
    -------
    Outcome
    """
    history: list[list[float]] = [] if saved is None else [list(r) for r in saved.history]
    if saved is not None:
        x0 = saved.x.reshape(problem.space.var_shape)
    elif start is not None:
        x0 = np.asarray(start(objective, problem), dtype=float).reshape(problem.space.var_shape)
    else:
        x0 = objective.uniform_start(problem.start_region)
    run = _Run(objective, store, config, len(history), history, on_iteration, should_stop)
    lbfgs_state = None
    stages = beta_stages(config)
    if saved is not None:
        run.best_x = saved.best_x.ravel().copy()
        run.last_x = saved.x.ravel().copy()
        run.best_value = float(saved.best_value)
        run.stage = int(saved.stage)
        restore_objective(objective, saved, config)
        if config.optimizer == "lbfgs":  # its run continues from its saved state, else from the best
            lbfgs_state = dict(saved.lbfgs) or None
            x0 = run.best_x.reshape(problem.space.var_shape)
    # with no stage left to run, the status the run ended with
    status = (saved.status if saved is not None and saved.status is not None and saved.status.finished
              else DesignStatus.MAX_ITER if run.k >= config.max_iter else DesignStatus.STALLED)
    start, resume_stage = x0.ravel().copy(), run.stage
    for i, (beta, stage_end) in enumerate(stages):
        if i < resume_stage or run.k >= stage_end:
            continue
        state = lbfgs_state if i == resume_stage else None
        run.stage = i
        if beta != objective.beta:  # beta continuation: J changes, so the best so far is re-judged
            log.info("beta continuation: beta = %.4g from evaluation %d", beta, run.k + 1)
            objective.beta = beta
            if state is None:  # a resumed stage keeps the best of its own evaluations
                run.best_value = np.inf
        if config.optimizer == "lbfgs":
            status = _stage_lbfgs(run, start, stage_end, state)
        else:
            status = _stage(run, start, stage_end)
        start = run.best_x.copy() if run.best_x is not None else start
        if status in _ENDED_EARLY:
            run.stage = i + 1
        if not status.finished:
            break
    run.checkpoint(status=status)
    run.lbfgs = None  # its 2 m N doubles are not needed for the outputs
    best = (run.best_x if run.best_x is not None else x0.ravel()).reshape(problem.space.var_shape)
    return Outcome(status, run.k, float(run.best_value), best, history, time.perf_counter() - run.session_t0)
