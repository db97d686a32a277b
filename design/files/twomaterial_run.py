"""A two-material design run in its folder: settings, feasibility, checkpoints, resume and outputs.

The folder holds ``config.json`` (the `TwoMaterialSettings`, with ``"kind": "two-material"``),
``feasibility.txt`` (what the target needs of the barrier, and why one material cannot release it),
``checkpoint.npz`` (`TwoMaterialCheckpoint`, after every stage and every few evaluations) and, once the run
has finished, the outputs of `design.files.twomaterial_outputs`. A resumed run continues from the
checkpoint's best variables and stage (with an empty L-BFGS memory).
"""
from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from design.errors import DesignError
from design.files.targets_io import read_curve_csv
from design.files.twomaterial_outputs import write_outputs
from design.inverse.twomaterial_objective import TwoMaterialObjective
from design.inverse.twomaterial_optimize import TwoMaterialCheckpoint, optimise_two
from design.inverse.twomaterial_problem import TwoMaterialProblem, TwoMaterialSettings, prepare_two, start_layout
from design.inverse.twomaterial_targets import is_two_material_spec

KIND = "two-material"
"""``config.json``'s ``kind`` of a two-material run."""
CHECKPOINT = "checkpoint.npz"


@dataclass(frozen=True)
class TwoMaterialResult:
    """What a run returns: its status, its summary (None while unfinished) and its folder."""

    status: str
    summary: dict[str, Any] | None
    out: Path
    unchanged: bool = False


def load_settings(out: Path) -> TwoMaterialSettings:
    """The settings of the run in ``out`` (``config.json``).

    Raises
    ------
    DesignError
        When ``out`` holds no two-material run or its config cannot be read.
    """
    try:
        values = json.loads((Path(out) / "config.json").read_text())
    except (OSError, ValueError) as exc:
        raise DesignError(f"{out}/config.json cannot be read: {exc}") from exc
    if values.pop("kind", None) != KIND:
        raise DesignError(f"{out} holds a one-material design run; resume it without --barrier-speed")
    return TwoMaterialSettings.from_dict(values)


def is_two_material_run(out: str | Path) -> bool:
    """Whether ``out`` holds a two-material run (a ``config.json`` of kind `KIND`), to resume as one."""
    try:
        return json.loads((Path(out) / "config.json").read_text()).get("kind") == KIND
    except (OSError, ValueError, AttributeError):
        return False


def save_settings(out: Path, settings: TwoMaterialSettings) -> None:
    """Write the run's ``config.json``."""
    (Path(out) / "config.json").write_text(json.dumps(dict(settings.to_dict(), kind=KIND), indent=2) + "\n")


def problem_for(settings: TwoMaterialSettings) -> TwoMaterialProblem:
    """Prepare the problem, reading a CSV target's columns."""
    curve = None if is_two_material_spec(settings.target) else read_curve_csv(settings.target)
    return prepare_two(settings, curve)


def _save(path: Path, state: TwoMaterialCheckpoint) -> None:
    part = path.with_suffix(".part.npz")
    np.savez(part, x=state.x, stage=state.stage, evaluations=state.evaluations, best_value=state.best_value,
             history=np.asarray(state.history, float).reshape(-1, 6), status=state.status)
    part.replace(path)


def _load(path: Path) -> TwoMaterialCheckpoint:
    with np.load(path) as z:
        return TwoMaterialCheckpoint(np.array(z["x"]), int(z["stage"]), int(z["evaluations"]), float(z["best_value"]),
                                     [list(r) for r in z["history"]], str(z["status"]))


def feasibility_text(problem: TwoMaterialProblem) -> str:
    """What the target needs of the barrier and why one material cannot release it."""
    lines = [f"target {problem.target.source}, barrier speed {problem.settings.barrier_speed:g}",
             "it needs:"] + [f"  - {n}" for n in problem.needs]
    lines += (["one material cannot release it:"] + [f"  - {p}" for p in problem.one_material]
              if problem.one_material else ["one material passes the one-material checks for it too"])
    return "\n".join(lines) + "\n"


def run_two_material(settings: TwoMaterialSettings | None, out: str | Path, *, resume: bool = False,
                     reference: bool = True, on_iteration: Callable[[int, dict], None] | None = None,
                     should_stop: Callable[[], bool] | None = None) -> TwoMaterialResult:
    """Start (``settings``) or resume (``resume=True``) a two-material design in the existing folder ``out``.

    Raises
    ------
    DesignError
        For a target the barrier or the domain cannot give (before any work), or a folder without a run to resume.
    """
    out = Path(out)
    ckpt = out / CHECKPOINT
    if resume:
        settings = load_settings(out)
        if (out / "summary.json").is_file():
            return TwoMaterialResult("finished", json.loads((out / "summary.json").read_text()), out, unchanged=True)
    problem = problem_for(settings)
    if not resume:
        save_settings(out, settings)
        (out / "feasibility.txt").write_text(feasibility_text(problem))
        np.savetxt(out / "target.csv", np.column_stack([problem.target.tau_mm, problem.target.released_mm3]),
                   delimiter=",", header="tau_mm,released_mm3", comments="", fmt="%.9g")
    saved = _load(ckpt) if resume and ckpt.is_file() else None
    objective = TwoMaterialObjective(problem.space, problem.target.released_mm3, problem.target.total_time_mm,
                                     radius_vox=problem.radius_vox, slowness=problem.slowness, beta=settings.beta,
                                     w_binary=settings.w_binary)
    start = time.perf_counter()
    state, fields = optimise_two(objective, settings, start_layout(problem), saved=saved,
                                 save=lambda st: _save(ckpt, st), on_iteration=on_iteration, should_stop=should_stop)
    if state.status == "stopped":
        return TwoMaterialResult(state.status, None, out)
    seconds = (state.history[-1][-1] if state.history else time.perf_counter() - start)
    summary = write_outputs(problem, fields, out, status=state.status, evaluations=state.evaluations,
                            seconds=seconds, reference=reference)
    return TwoMaterialResult(state.status, summary, out)
