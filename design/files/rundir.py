"""A design run's folder and the public `run_design`.

A run folder holds ``config.json`` (the `DesignConfig`), ``feasibility.txt`` (the target's check),
``checkpoint.npz`` (the optimiser's `Checkpoint`, rewritten atomically every few evaluations) and, once the
run stops, the outputs of `design.files.outputs`; the three records and their formats are
`design.files.records`. A run with physical correction keeps where its rounds stand in ``rounds.npz``
(`design.files.rounds`). A multi-start run (`DesignConfig.starts` > 1) keeps its starts as ordinary run
folders in ``starts/NN`` and its choice in ``multistart.json``; the refinement runs in the folder itself, or,
for starts at the run's resolution, the chosen start's checkpoint and rounds are copied into it and its
outputs written there.
"""
from __future__ import annotations

import json
import logging
import threading
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from design.errors import DesignError
from design.files.outputs import DesignOutputs, write_outputs
from design.files.records import (
    CHECKPOINT,
    CONFIG,
    SUMMARY,
    DesignSummary,
    load_checkpoint,
    load_config,
    load_summary,
    save_checkpoint,
    save_config,
    stored_form,
)
from design.files.rounds import ROUNDS, RoundFile
from design.files.targets_io import load_problem
from design.inverse.config import DesignConfig
from design.inverse.defect import optimise_physical
from design.inverse.multistart import coarse_start, refine_start, refinement_config, refinement_phase, start_name
from design.inverse.optimize import (
    Checkpoint,
    IterationCallback,
    StartDesign,
    build_objective,
    restore_objective,
    with_phase,
)
from design.inverse.problem import Problem
from design.inverse.progress import RunClock, evaluation_seconds, run_plan, stage_costs
from design.inverse.status import FINISHED, DesignStatus

log = logging.getLogger(__name__)

FEASIBILITY = "feasibility.txt"
MULTISTART = "multistart.json"
STARTS = "starts"


@dataclass(frozen=True)
class DesignResult:
    """What a design run returns.

    Attributes
    ----------
    out_dir : Path
    status : DesignStatus
    iterations : int
        Objective evaluations over all sessions of the run (resumes included).
    best_value : float
    outputs : DesignOutputs
    unchanged : bool
    """

    out_dir: Path
    status: DesignStatus
    iterations: int
    best_value: float
    outputs: DesignOutputs
    unchanged: bool = False
    """True for a resumed run that had already finished with its outputs written: nothing was done."""


class CheckpointFile:
    """A run's ``checkpoint.npz``: the `design.inverse.optimize.CheckpointStore` of `run_design`.

    ``save(..., wait=False)`` writes from a thread; `wait` joins it and raises its error, if any.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self._writer: threading.Thread | None = None  # the checkpoint being written
        self._writer_error: BaseException | None = None

    def save(self, checkpoint: Checkpoint, *, wait: bool = True) -> None:
        """Write ``checkpoint`` atomically; with ``wait=False`` from a thread."""
        self.wait()
        if wait:
            save_checkpoint(self.path, checkpoint)
            return

        def write() -> None:
            try:
                save_checkpoint(self.path, checkpoint)
            except BaseException as exc:  # noqa: BLE001 -- re-raised in the run's thread by wait
                self._writer_error = exc

        self._writer = threading.Thread(target=write, name="checkpoint", daemon=True)
        self._writer.start()

    def wait(self) -> None:
        """Wait for a checkpoint being written; raise its error, if any."""
        if self._writer is None:
            return
        self._writer.join()
        self._writer, error, self._writer_error = None, self._writer_error, None
        if isinstance(error, DesignError):  # save_checkpoint's own message names the file
            raise error
        if error is not None:
            raise DesignError(f"cannot write checkpoint {self.path}: {error}") from error


class _StartFolders:
    """The coarse runs of a multi-start (`design.inverse.multistart.CoarseRuns`): run folders ``starts/NN``."""

    def __init__(self, out_dir: Path, should_stop: Callable[[], bool] | None, resolution: int) -> None:
        self.out_dir = out_dir
        self.should_stop = should_stop
        self.resolution = resolution  # the run's: a start below it is ranked by its J, its print not judged

    def folder(self, k: int) -> Path:
        return self.out_dir / STARTS / start_name(k)

    def finished(self, k: int) -> bool:
        return (self.folder(k) / SUMMARY).exists()

    def run(self, k: int, config: DesignConfig, start: StartDesign,
            on_iteration: IterationCallback | None) -> DesignStatus:
        folder = self.folder(k)
        resume = (folder / CONFIG).exists()
        return run_design(None if resume else config, folder, on_iteration=on_iteration,
                          should_stop=self.should_stop, resume=resume, start=start, coarse_start=True,
                          judge_print=config.resolution == self.resolution).status

    def best_value(self, k: int) -> float:
        history = np.loadtxt(self.folder(k) / "history.csv", delimiter=",", skiprows=1, ndmin=2)
        return float(history[:, 1].min())

    def print_fit(self, k: int) -> float:
        fit = load_summary(self.folder(k)).get("rel_rmse_print")
        return np.inf if fit is None else float(fit)

    def adopt(self, k: int) -> Checkpoint:
        """Make finished start ``k`` the run's own: its last checkpoint and correction rounds copied into the run
        folder (each written atomically, the rounds first), and that checkpoint returned."""
        folder = self.folder(k)
        state = RoundFile(folder / ROUNDS).load()
        if state is not None:
            RoundFile(self.out_dir / ROUNDS).save(state)
        saved = load_checkpoint(folder / CHECKPOINT)
        save_checkpoint(self.out_dir / CHECKPOINT, saved)
        return saved


def _multistart(config: DesignConfig, out_dir: Path, on_iteration: IterationCallback | None,
                should_stop: Callable[[], bool] | None) -> StartDesign | Checkpoint | None:
    """Run the starts of a multi-start in ``out_dir/starts`` and record the choice in ``multistart.json``. Returns
    the refinement's start, or for starts at the run's resolution the chosen start's last checkpoint, now the
    run's own (`_StartFolders.adopt`); None when `should_stop` ended a start."""
    folders = _StartFolders(out_dir, should_stop, config.resolution)
    choice = coarse_start(config, folders, on_iteration=on_iteration)
    if choice is None:
        return None
    best_j = {start_name(k): value for k, value in enumerate(choice.best_values)}
    if choice.final:
        record = {"resolution": choice.coarse_resolution, "chosen": start_name(choice.refined),
                  "print_fit": {start_name(k): fit for k, fit in enumerate(choice.print_fits)}, "best_J": best_j}
    else:
        record = {"coarse_resolution": choice.coarse_resolution, "refined": start_name(choice.refined), "best_J": best_j}
    (out_dir / MULTISTART).write_text(json.dumps(record, indent=2))
    if choice.final:
        return folders.adopt(choice.refined)
    density = folders.folder(choice.refined) / "density.npz"
    try:
        with np.load(density, allow_pickle=False) as data:
            x_coarse, dx_coarse = data["rho_hat"], float(data["dx_mm"])
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as exc:
        raise DesignError(f"{density}: the chosen coarse start's density cannot be read ({exc}); remove "
                          f"{density.parent} to run that start again") from exc
    return refine_start(x_coarse, dx_coarse)


def _resume_config(out_dir: Path, stored: DesignConfig, config: DesignConfig | None) -> DesignConfig:
    """The configuration a resume runs with: the stored one, whose evaluation limit ``config`` may raise;
    any other difference is refused."""
    if config is None or config == stored:
        return stored
    given, kept = stored_form(config), stored_form(stored)  # as config.json holds them, migrated alike
    differ = [name for name in kept if given.get(name) != kept[name]]
    if not differ:
        return stored
    if differ != ["max_iter"] or config.max_iter < stored.max_iter:
        shown = ", ".join(f"{name} {given.get(name)!r} (stored {kept[name]!r})" for name in differ)
        raise DesignError(f"cannot resume {out_dir / CONFIG} with different settings: {shown}; a resume keeps the "
                          "run's settings, except that it may raise max_iter")
    return config


def _finished(saved: Checkpoint, out_dir: Path, config: DesignConfig) -> bool:
    """Whether the optimisation of a run is over and a resume has no evaluation to make: its last checkpoint
    says it finished, unless it reached an evaluation limit that ``config`` raises. A checkpoint that did not
    record how the run ended counts as finished when the run's summary says so for its evaluations."""
    status = saved.status
    if status is None:
        summary = _complete_outputs(out_dir, saved)
        status = None if summary is None else summary["status"]
    if status not in FINISHED:
        return False
    return not (status == DesignStatus.MAX_ITER and len(saved.history) < refinement_config(config).max_iter)


def _complete_outputs(out_dir: Path, saved: Checkpoint) -> DesignSummary | None:
    """The run's summary when its outputs are those of ``saved`` (``summary.json``, written last, names the
    status and evaluation count the checkpoint holds), else None."""
    try:
        summary = load_summary(out_dir)
    except (OSError, ValueError, DesignError):
        return None
    if summary.get("iterations") != len(saved.history):
        return None
    if saved.status is not None and summary.get("status") != saved.status:
        return None
    return summary


def finished_run(out_dir: str | Path, config: DesignConfig | None = None) -> DesignResult | None:
    """What resuming ``out_dir`` (with ``config``, as `run_design`) would do when it has nothing to do: the
    run finished and wrote all its outputs (``unchanged``); else None. Reads the records only.

    Raises
    ------
    DesignError
        For a folder without a readable ``config.json`` or checkpoint, or a ``config`` the run cannot
        resume with.
    """
    out_dir = Path(out_dir)
    stored = load_config(out_dir)
    config = _resume_config(out_dir, stored, config)
    ckpt = out_dir / CHECKPOINT
    if not ckpt.exists():
        return None
    saved = load_checkpoint(ckpt, variables=False)
    summary = _complete_outputs(out_dir, saved) if _finished(saved, out_dir, config) else None
    if summary is None:
        return None
    log.debug("%s already finished (%s after %d evaluations): nothing to do", out_dir, summary["status"],
             len(saved.history))
    return DesignResult(out_dir, DesignStatus(summary["status"]), len(saved.history), float(saved.best_value),
                        DesignOutputs(out_dir / SUMMARY, summary), unchanged=True)


def _problem(config: DesignConfig, out_dir: Path, announce: bool = True) -> Problem:
    """The prepared problem, its feasibility report in ``feasibility.txt`` (written when it changes); its warnings
    logged as such (``announce``) or, for a coarse start, at DEBUG level."""
    problem = load_problem(config, announce)
    text = problem.feasibility.text() + "\n"
    path = out_dir / FEASIBILITY
    if not path.is_file() or path.read_text() != text:
        path.write_text(text)
    if not problem.feasibility.feasible and not config.allow_infeasible:
        raise DesignError(problem.feasibility.text())
    return problem


def _check_size(saved: Checkpoint, problem: Problem, out_dir: Path) -> None:
    """Refuse a checkpoint whose design variables do not fit the run's design space."""
    size = int(np.prod(problem.space.var_shape))
    if saved.x.size != size or saved.best_x.size != size:
        raise DesignError(f"{out_dir / CHECKPOINT}: holds {saved.x.size} design variables, the run's configuration "
                          f"{size} ({CONFIG} changed since it was written?); restore the files or start a new run")


def _rewrite_outputs(out_dir: Path, config: DesignConfig, saved: Checkpoint, coarse_start: bool,
                     problem: Problem | None = None, judge_print: bool = True) -> DesignResult:
    """The outputs of a run whose optimisation finished, from its last checkpoint: its best design, history
    and status, with the objective as the run left it (`restore_objective`: the final beta). ``problem``: the
    run's, when already prepared."""
    problem = problem or _problem(config, out_dir, not coarse_start)
    _check_size(saved, problem, out_dir)
    objective = build_objective(problem, refinement_config(config))
    restore_objective(objective, saved, refinement_config(config))
    log.info("%s: optimisation finished (%s); writing its outputs", out_dir, saved.status)
    best = np.asarray(saved.best_x, float).reshape(problem.space.var_shape)
    history = [list(row) for row in saved.history]
    outputs = write_outputs(out_dir, problem, objective, best, history, config, status=saved.status,
                            session_seconds=0.0, announce=not coarse_start, judged=judge_print)
    return DesignResult(out_dir, saved.status, len(history), float(saved.best_value), outputs)


def run_design(config: DesignConfig | None, out_dir: str | Path, *, on_iteration: IterationCallback | None = None,
               should_stop: Callable[[], bool] | None = None, resume: bool = False,
               start: StartDesign | None = None, coarse_start: bool = False, judge_print: bool = True) -> DesignResult:
    """Run (or resume) an inverse design in ``out_dir``.

    Parameters
    ----------
    config : DesignConfig or None
        The run's settings; None with ``resume=True`` reuses the stored ``config.json``, which a resume's
        ``config`` may differ from only by a higher ``max_iter`` (then stored).
    out_dir : str or Path
        The run folder; must not hold a run unless resuming.
    on_iteration : callable, optional
        ``on_iteration(k, x, terms)`` after every evaluation, as for `design.inverse.optimize.optimise`
        (``x`` in the variable shape); in a multi-start run ``terms`` also holds ``phase`` (which coarse
        start, or the refinement).
    should_stop : callable, optional
        Polled before every evaluation; True stops cleanly (best design still written).
    resume : bool
        Continue from ``checkpoint.npz``: exactly where the run stopped with the "lbfgs" optimiser;
        with nlopt's, from the last evaluated design with an empty memory. A run whose optimisation
        finished is not continued (unless its evaluation limit is raised): with its outputs written it is
        left as it is (``unchanged``), else its outputs are written from its last checkpoint.
    start : callable, optional
        ``start(objective, problem)`` returns the start variables of a new run (variable shape);
        default the uniform start of section 5.2 (`DesignObjective.uniform_start`), or for
        ``config.starts`` > 1 the refined best of the coarse starts (`design.inverse.multistart`).
    coarse_start : bool
        The run is a coarse start of a multi-start (``starts/NN``): its warnings (pieces, evaluation limit)
        are about that start, not the design, and are logged at INFO level; its summary keeps them.
    judge_print : bool
        Release the print by the reference evaluator in the outputs (False: a coarse start below the run's
        resolution, which its J alone ranks; its print figures are None).

    Returns
    -------
    DesignResult

    Raises
    ------
    DesignError
        On an invalid configuration, an infeasible target, or a resume mismatch.
    """
    out_dir = Path(out_dir)
    ckpt = out_dir / CHECKPOINT
    saved = None
    if resume:
        done = finished_run(out_dir, config)
        if done is not None:
            return done
        stored = load_config(out_dir)
        config = _resume_config(out_dir, stored, config)
        if ckpt.exists():
            saved = load_checkpoint(ckpt)
        if saved is not None and saved.status is not None and _finished(saved, out_dir, config):
            # the optimisation ended, not all outputs got written
            return _rewrite_outputs(out_dir, stored, saved, coarse_start, judge_print=judge_print)
        if config != stored:  # a raised evaluation limit
            save_config(out_dir, config)
    else:
        if config is None:
            raise DesignError("a configuration is required to start a new design run")
        if (out_dir / CONFIG).exists():
            raise DesignError(f"{out_dir} already holds a design run; resume it or choose another folder")
        out_dir.mkdir(parents=True, exist_ok=True)
        save_config(out_dir, config)
    problem = _problem(config, out_dir, not coarse_start)
    if saved is not None:
        _check_size(saved, problem, out_dir)
    clock = None
    if on_iteration is not None and not coarse_start:  # the whole run's time left; a start's is part of it
        full_eval_s = evaluation_seconds(problem, refinement_config(config))
        costs = stage_costs(config, full_eval_s, problem)
        on_iteration = clock = RunClock(run_plan(config, costs), on_iteration, costs, full_eval_s)
    if saved is None and start is None and config.starts > 1:  # multi-start
        start = _multistart(config, out_dir, on_iteration, should_stop)
        if isinstance(start, Checkpoint):  # the chosen start is the design
            return _rewrite_outputs(out_dir, config, start, coarse_start, problem)
    optimised = refinement_config(config)  # a multi-start's refinement: its own evaluations
    objective = build_objective(problem, optimised)
    if saved is not None:
        log.info("resuming %s at evaluation %d", out_dir, len(saved.history))
    if config.starts > 1:
        on_iteration = with_phase(on_iteration, refinement_phase(config.resolution))
    outcome, objective = optimise_physical(objective, problem, optimised, CheckpointFile(ckpt), RoundFile(out_dir / ROUNDS),
                                           saved=saved, start=start, on_iteration=on_iteration, should_stop=should_stop)
    if clock is not None and clock.outputs_s() is not None:
        log.info("print: extracting design.stl and releasing it by the reference evaluator (about %.0f s)",
                 clock.outputs_s())
    outputs = write_outputs(out_dir, problem, objective, outcome.best_x, outcome.history, config,
                            status=outcome.status, session_seconds=outcome.session_seconds, announce=not coarse_start,
                            judged=judge_print)
    log.info("design %s after %d evaluations: %s", outcome.status, outcome.iterations, outputs.summary_path)
    return DesignResult(out_dir, outcome.status, outcome.iterations, outcome.best_value, outputs)
