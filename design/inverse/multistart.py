"""Multi-start, coarse-to-fine inverse design (``sfr design --starts N``, `DesignConfig.starts`).

N seeded starts run cheaply at a coarse resolution (half the run's by default: an nfc evaluation
there costs about an eighth), each from the usual start design plus smooth seeded noise (start 0
unperturbed). The coarse design with the lowest J is interpolated onto the full-resolution grid and
refined there from that start. Every run is an ordinary resumable design folder: the coarse ones in
``OUT/starts/NN``, the refinement in ``OUT`` itself, so an interrupted multi-start resumes where it
stopped (finished starts are not run again). The whole costs about ``1 + N / 8`` single nfc runs of
the same iteration limit (``1 + N / 4`` extruded).

`coarse_start` decides which starts run and which is refined; the folders are `CoarseRuns`' business
(`design.files.rundir` keeps them).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
from scipy import ndimage

from design.inverse.objective import DesignObjective
from design.inverse.optimize import IterationCallback, StartDesign, with_phase
from design.inverse.problem import DesignConfig, Problem
from design.inverse.status import DesignStatus

log = logging.getLogger(__name__)

NOISE_AMPLITUDE = 0.15
"""Peak amplitude of a perturbed start's noise, in rho_hat."""
NOISE_SIGMA_VOX = 2.0
"""Correlation length of the noise (Gaussian smoothing), voxels of the coarse grid."""
MIN_COARSE_RESOLUTION = 16
"""The coarse runs use at least this many voxels along the domain's longest side."""


def coarse_resolution(resolution: int) -> int:
    """Half the resolution, even and at least `MIN_COARSE_RESOLUTION` (never above the original)."""
    return min(resolution, max(MIN_COARSE_RESOLUTION, 2 * (resolution // 4)))


def start_name(k: int) -> str:
    """The name of coarse start ``k`` (its folder's, ``starts/NN``)."""
    return f"{k:02d}"


def coarse_phase(k: int, starts: int, resolution: int) -> str:
    """The progress phase (``terms["phase"]``) of coarse start ``k`` (from 0) of ``starts``."""
    return f"coarse start {k + 1} of {starts} at resolution {resolution}"


def refinement_phase(resolution: int) -> str:
    """The progress phase (``terms["phase"]``) of the full-resolution run that refines the best coarse start."""
    return f"refinement at resolution {resolution}"


def perturbed_start(seed: int) -> StartDesign:
    """A run's start design: the default start plus smooth noise seeded by ``seed``."""

    def start(objective: DesignObjective, problem: Problem) -> np.ndarray:
        x = objective.uniform_start(problem.start_region)
        if seed == 0:
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


@dataclass(frozen=True)
class CoarseChoice:
    """The outcome of the coarse starts: their resolution, the one refined and each one's lowest J."""

    coarse_resolution: int
    refined: int
    best_values: tuple[float, ...]


def coarse_start(config: DesignConfig, runs: CoarseRuns, *,
                 on_iteration: IterationCallback | None = None) -> CoarseChoice | None:
    """Run ``config.starts`` coarse seeded starts and choose the one the full-resolution run refines.

    Called by `design.files.rundir.run_design` for a new (or not yet started) run with ``starts > 1``.

    Parameters
    ----------
    config : DesignConfig
        The full-resolution run; every coarse start uses it at `coarse_resolution`, with the same
        iteration limit, a single start and no physical correction.
    runs : CoarseRuns
        Runs the starts not finished yet (a finished start is not run again).
    on_iteration : callable, optional
        As for `design.files.rundir.run_design`, passed to every coarse run with its phase.

    Returns
    -------
    CoarseChoice or None
        The start with the lowest J (the first of equals); None when `should_stop` ended a coarse run
        (the caller then stops at once too). `refine_start` makes its design the full run's start.

    Raises
    ------
    KeyboardInterrupt
        When a coarse run was interrupted (Ctrl-C); resuming continues with that start.
    """
    # the coarse runs only rank the starts by J: the refinement corrects the print (design.inverse.defect)
    coarse = replace(config, resolution=coarse_resolution(config.resolution), starts=1, physical_correction="none")
    values = []
    for k in range(config.starts):
        if not runs.finished(k):
            phase = coarse_phase(k, config.starts, coarse.resolution)
            log.info(phase)
            status = runs.run(k, coarse, perturbed_start(k), with_phase(on_iteration, phase))
            if status == DesignStatus.INTERRUPTED:
                raise KeyboardInterrupt
            if status == DesignStatus.STOPPED:
                return None
        values.append(runs.best_value(k))
    best = min(range(len(values)), key=values.__getitem__)
    log.info("refining start %s (J = %.6g at resolution %d)", start_name(best), values[best], coarse.resolution)
    return CoarseChoice(coarse.resolution, best, tuple(values))


def refine_start(x_coarse: np.ndarray, dx_coarse_mm: float) -> StartDesign:
    """The full-resolution run's start: coarse design variables ``x_coarse`` (voxel edge ``dx_coarse_mm``)
    interpolated onto its grid (`upsample`)."""

    def start(objective: DesignObjective, problem: Problem) -> np.ndarray:
        return upsample(x_coarse, dx_coarse_mm, objective.space.var_shape, problem.dx_mm)

    return start
