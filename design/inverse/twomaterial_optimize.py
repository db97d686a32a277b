"""The optimiser loop of a two-material design: box-bounded L-BFGS through a beta continuation.

Both fields are in [0, 1], so the loop hands the box bounds to scipy's L-BFGS-B (no variable map, so no
variable is stuck at a bound with a zero gradient). The evaluations are shared equally by the stages of
a geometric beta continuation from ``beta`` to ``beta_final``; each stage starts from the previous
stage's best variables. A `TwoMaterialCheckpoint` after every stage, and every ``checkpoint_every``
evaluations, holds the best variables, the stage and the history: a resumed run continues the stage from
the best variables with an empty L-BFGS memory (so it does not repeat the uninterrupted run exactly).
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize

from design.inverse.status import DesignStatus
from design.inverse.twomaterial_objective import Fields, TwoMaterialObjective
from design.inverse.twomaterial_problem import TwoMaterialSettings

CHECKPOINT_EVERY = 10
"""Evaluations between checkpoints."""


@dataclass
class TwoMaterialCheckpoint:
    """What a run resumes from: the best variables of the current stage, the stage, the evaluations so far."""

    x: np.ndarray
    stage: int
    evaluations: int
    best_value: float
    history: list[list[float]] = field(default_factory=list)
    status: str = ""


class _Stop(Exception):
    """Raised inside the objective to end the session (a stop request or the evaluation limit)."""


def beta_schedule(settings: TwoMaterialSettings) -> list[tuple[float, int]]:
    """(beta, evaluation at which the stage ends) of each stage."""
    betas = np.geomspace(settings.beta, settings.beta_final, settings.stages)
    ends = np.linspace(0, settings.max_iter, settings.stages + 1)[1:].round().astype(int)
    return [(float(b), int(e)) for b, e in zip(betas, ends)]


def optimise_two(objective: TwoMaterialObjective, settings: TwoMaterialSettings, x0: np.ndarray, *,
                 saved: TwoMaterialCheckpoint | None = None,
                 save: Callable[[TwoMaterialCheckpoint], None] | None = None,
                 on_iteration: Callable[[int, dict], None] | None = None,
                 should_stop: Callable[[], bool] | None = None) -> tuple[TwoMaterialCheckpoint, Fields]:
    """Minimise the two-material objective from ``x0`` (or ``saved``) through the beta stages.

    Returns
    -------
    TwoMaterialCheckpoint
        The best variables at the last stage's beta, with the status (`DesignStatus` value).
    Fields
        The fields and the curve at those variables.
    """
    state = saved or TwoMaterialCheckpoint(np.asarray(x0, float), 0, 0, np.inf)
    t0 = time.perf_counter() - (state.history[-1][-1] if state.history else 0.0)
    status = DesignStatus.MAX_ITER
    for stage, (beta, end) in enumerate(beta_schedule(settings)):
        if stage < state.stage or state.evaluations >= end:
            continue
        if stage != state.stage:
            state.best_value = np.inf
        state.stage, objective.beta = stage, beta
        best = {"x": state.x, "value": state.best_value}

        def fun(z: np.ndarray, end: int = end, best: dict = best) -> tuple[float, np.ndarray]:
            if state.evaluations >= end or (should_stop is not None and should_stop()):
                raise _Stop
            x = z.reshape(objective.x_shape)
            value, grad, terms, _ = objective.evaluate(x)
            state.evaluations += 1
            elapsed = time.perf_counter() - t0
            state.history.append([state.evaluations, stage, terms["J"], terms["J_fit"], terms["J_binary"], elapsed])
            if value < best["value"]:
                best.update(x=x.copy(), value=value)
            if on_iteration is not None:
                on_iteration(state.evaluations, dict(terms, beta=beta, stage=stage + 1, seconds=elapsed))
            if save is not None and state.evaluations % CHECKPOINT_EVERY == 0:
                save(TwoMaterialCheckpoint(best["x"], stage, state.evaluations, best["value"], state.history))
            return value, grad.ravel()

        try:
            result = minimize(fun, best["x"].ravel(), jac=True, method="L-BFGS-B",
                              bounds=[(0.0, 1.0)] * best["x"].size,
                              options={"maxfun": end - state.evaluations + 5, "maxiter": 10 ** 6, "ftol": 1e-12,
                                       "gtol": 1e-12})
            status = DesignStatus.CONVERGED if result.success else DesignStatus.STALLED
        except _Stop:
            status = DesignStatus.MAX_ITER if state.evaluations >= end else DesignStatus.STOPPED
        state.x, state.best_value = best["x"], best["value"]
        if status == DesignStatus.STOPPED:
            break
    state.status = status.value
    if save is not None:
        save(state)
    _, _, _, fields_ = objective.evaluate(state.x)
    return state, fields_
