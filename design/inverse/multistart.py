"""Multi-start inverse design (``sfr design --starts N``, `DesignConfig.starts`).

N seeded starts, each from one of the problem's start outlines (`Problem.start_regions`, in turn) as it is,
then plus smooth seeded noise. From resolution `MULTISTART_MIN_RESOLUTION` on they run cheaply at half the
resolution (an nfc evaluation there costs about an eighth); the coarse design with the lowest J is
interpolated onto the full-resolution grid and refined there from that start, the whole about ``1 + N / 8``
single nfc runs of the same iteration limit (``1 + N / 4`` extruded). Below it every start is a whole run at
the run's resolution, its print corrected, and the start whose print fits the target best is the design
(N single runs). Every run is an ordinary resumable design folder: the starts in ``OUT/starts/NN``, the
refinement (or the chosen start's outputs) in ``OUT`` itself, so an interrupted multi-start resumes where
it stopped (finished starts are not run again).

`coarse_start` decides which starts run and which is refined; the folders are `CoarseRuns`' business
(`design.files.rundir` keeps them).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
from scipy import ndimage

from design.inverse.config import DesignConfig
from design.inverse.defect import correction_plan
from design.inverse.objective import DesignObjective
from design.inverse.optimize import IterationCallback, StartDesign, with_phase
from design.inverse.problem import Problem
from design.inverse.settings import (
    COARSE_EVALS_SHARE,
    DEFAULT_REFINE_EVALS_SHARE,
    MULTISTART_MIN_RESOLUTION,
    REFINE_EVALS_SHARE,
)
from design.inverse.status import DesignStatus

log = logging.getLogger(__name__)

NOISE_AMPLITUDE = 0.15
"""Peak amplitude of a perturbed start's noise, in rho_hat."""
NOISE_SIGMA_VOX = 2.0
"""Correlation length of the noise (Gaussian smoothing), voxels of the coarse grid."""
MIN_COARSE_RESOLUTION = 16
"""The coarse runs use at least this many voxels along the domain's longest side."""


def coarse_resolution(resolution: int) -> int:
    """The starts' resolution: from `MULTISTART_MIN_RESOLUTION` on half the run's, even and at least
    `MIN_COARSE_RESOLUTION`; below it the run's own (on a grid half as fine the smoothing radius is about a voxel,
    and the starts' J ranks them unlike the full grid's, docs/design.md#multi-start)."""
    if resolution < MULTISTART_MIN_RESOLUTION:
        return resolution
    return max(MIN_COARSE_RESOLUTION, 2 * (resolution // 4))


def refined(config: DesignConfig) -> bool:
    """Whether a run of ``config`` refines a coarse start: a multi-start whose starts run below its resolution."""
    return config.starts > 1 and coarse_resolution(config.resolution) < config.resolution


def coarse_config(config: DesignConfig) -> DesignConfig:
    """The configuration of each coarse start of a refined multi-start (`refined`): ``config`` at `coarse_resolution`
    with a single start, no physical correction (the refinement corrects the print) and `COARSE_EVALS_SHARE` of its
    evaluations."""
    return replace(config, resolution=coarse_resolution(config.resolution), starts=1, physical_correction="none",
                   max_iter=max(1, int(round(COARSE_EVALS_SHARE * config.max_iter))))


def refinement_config(config: DesignConfig) -> DesignConfig:
    """What the optimisation of a run of ``config`` runs with: for a refined multi-start (`refined`) ``config`` with
    `REFINE_EVALS_SHARE` of its space's evaluations before the correction rounds (its beta continuation over them), whose
    evaluations follow as configured (``max_iter`` is the refinement's and its rounds'); else ``config`` itself."""
    if not refined(config):
        return config
    rounds, _ = correction_plan(config)
    # at least the rounds' evaluations: correction_plan keeps as many rounds as fit in half the evaluations
    share = REFINE_EVALS_SHARE.get(config.space, DEFAULT_REFINE_EVALS_SHARE)
    first = max(1, int(round(share * config.max_iter)), rounds * config.correction_evals)
    return replace(config, max_iter=first + rounds * config.correction_evals)


def start_name(k: int) -> str:
    """The name of coarse start ``k`` (its folder's, ``starts/NN``)."""
    return f"{k:02d}"


def coarse_phase(k: int, starts: int, resolution: int, coarse: bool = True) -> str:
    """The progress phase (``terms["phase"]``) of start ``k`` (from 0) of ``starts``: a coarse one, or one at the
    run's own resolution (``coarse`` False)."""
    return f"{'coarse start' if coarse else 'start'} {k + 1} of {starts} at resolution {resolution}"


def refinement_phase(resolution: int) -> str:
    """The progress phase (``terms["phase"]``) of the full-resolution run that refines the best coarse start."""
    return f"refinement at resolution {resolution}"


def perturbed_start(seed: int) -> StartDesign:
    """Start ``seed``'s design: the problem's start outlines in turn (`Problem.start_regions`), each as it is the
    first time and with smooth noise seeded by ``seed`` after that."""

    def start(objective: DesignObjective, problem: Problem) -> np.ndarray:
        regions = problem.start_regions
        x = objective.uniform_start(regions[seed % len(regions)])
        if seed < len(regions):
            return x
        noise = ndimage.gaussian_filter(np.random.default_rng(seed).standard_normal(x.shape), NOISE_SIGMA_VOX)
        noise *= NOISE_AMPLITUDE / max(float(np.abs(noise).max()), 1e-12)
        return np.clip(x + noise, 0.02, 0.98)

    return start


def upsample(x_coarse: np.ndarray, dx_coarse_mm: float, shape: tuple[int, ...], dx_mm: float) -> np.ndarray:
    """Linear interpolation of design variables onto a finer grid of the same domain.

    Both grids are indexed from the same face (the mirror plane, or the build plate): voxel j of the
    fine grid is centred at (j + 1/2) dx, which lies at coarse index (j + 1/2) dx / dx_coarse - 1/2.

    Parameters
    ----------
    x_coarse : ndarray of float, coarse variable shape
    dx_coarse_mm, dx_mm : float
        Voxel edges of the two grids, mm.
    shape : tuple of int
        The fine variable shape.
    """
    coords = np.meshgrid(*[(np.arange(n) + 0.5) * dx_mm / dx_coarse_mm - 0.5 for n in shape], indexing="ij")
    return np.clip(ndimage.map_coordinates(x_coarse, coords, order=1, mode="nearest"), 0.0, 1.0)


class CoarseRuns(Protocol):
    """The coarse runs of a multi-start, each a resumable design run (`design.files.rundir` keeps them in folders)."""

    def finished(self, k: int) -> bool:
        """Whether start ``k`` has finished (its outputs are written)."""

    def run(self, k: int, config: DesignConfig, start: StartDesign,
            on_iteration: IterationCallback | None) -> DesignStatus:
        """Run (or resume) start ``k`` with ``config`` from ``start``; returns the run's status."""

    def best_value(self, k: int) -> float:
        """The lowest J of finished start ``k``."""

    def print_fit(self, k: int) -> float:
        """The print's fit of finished start ``k`` (its ``rel_rmse_print``; inf without a print)."""


@dataclass(frozen=True)
class CoarseChoice:
    """The outcome of the starts: their resolution, the one chosen, each one's lowest J and, for starts at the
    run's own resolution, each one's print fit (they are ranked by it, and the chosen one is the design)."""

    coarse_resolution: int
    refined: int
    best_values: tuple[float, ...]
    print_fits: tuple[float, ...] | None = None

    @property
    def final(self) -> bool:
        """Whether the chosen start is the design itself (the starts ran at the run's resolution): no refinement."""
        return self.print_fits is not None


def coarse_start(config: DesignConfig, runs: CoarseRuns, *,
                 on_iteration: IterationCallback | None = None) -> CoarseChoice | None:
    """Run ``config.starts`` seeded starts and choose the best.

    Called by `design.files.rundir.run_design` for a new (or not yet started) run with ``starts > 1``. At
    `coarse_resolution` below the run's, each start is ``config`` at that resolution with a single start and no
    physical correction, they are ranked by their lowest J, and the best is refined at full resolution
    (`refine_start`). At the run's own resolution each start is ``config`` with a single start, physical
    correction included, they are ranked by their print's fit, and the best is the design
    (`CoarseChoice.final`): start 0 is the single run's, so the design fits no worse than it.

    Parameters
    ----------
    config : DesignConfig
        The run.
    runs : CoarseRuns
        Runs the starts not finished yet (a finished start is not run again).
    on_iteration : callable, optional
        As for `design.files.rundir.run_design`, passed to every start with its phase.

    Returns
    -------
    CoarseChoice or None
        The best start (the first of equals); None when `should_stop` ended a start (the caller then stops at
        once too).

    Raises
    ------
    KeyboardInterrupt
        When a start was interrupted (Ctrl-C); resuming continues with that start.
    """
    resolution = coarse_resolution(config.resolution)
    final = resolution == config.resolution
    # coarse runs only rank the starts by J: the refinement corrects the print (design.inverse.defect)
    start_config = replace(config, starts=1) if final else coarse_config(config)
    values = []
    for k in range(config.starts):
        if not runs.finished(k):
            phase = coarse_phase(k, config.starts, resolution, coarse=not final)
            log.info(phase)
            status = runs.run(k, start_config, perturbed_start(k), with_phase(on_iteration, phase))
            if status == DesignStatus.INTERRUPTED:
                raise KeyboardInterrupt
            if status == DesignStatus.STOPPED:
                return None
        values.append(runs.best_value(k))
    fits = tuple(runs.print_fit(k) for k in range(config.starts)) if final else None
    rank = fits if final else values
    best = min(range(len(rank)), key=rank.__getitem__)
    if final:
        log.info("keeping start %s (its print %.3f%% off the target)", start_name(best), 100 * rank[best])
    else:
        log.info("refining start %s (J = %.6g at resolution %d)", start_name(best), values[best], resolution)
    return CoarseChoice(resolution, best, tuple(values), fits)


def refine_start(x_coarse: np.ndarray, dx_coarse_mm: float) -> StartDesign:
    """The full-resolution run's start: coarse design variables ``x_coarse`` (voxel edge ``dx_coarse_mm``)
    interpolated onto its grid (`upsample`)."""

    def start(objective: DesignObjective, problem: Problem) -> np.ndarray:
        return upsample(x_coarse, dx_coarse_mm, objective.space.var_shape, problem.dx_mm)

    return start
