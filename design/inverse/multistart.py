"""Multi-start, coarse-to-fine inverse design (``sfr design --starts N``, `DesignConfig.starts`).

N seeded starts run cheaply at a coarse resolution (half the run's by default: an nfc evaluation
there costs about an eighth), each from the usual start design plus smooth seeded noise (start 0
unperturbed). The coarse design with the lowest J is interpolated onto the full-resolution grid and
refined there from that start. Every run is an ordinary resumable design folder: the coarse ones in
``OUT/starts/NN``, the refinement in ``OUT`` itself, so an interrupted multi-start resumes where it
stopped (finished starts are not run again). The whole costs about ``1 + N / 8`` single nfc runs of
the same iteration limit (``1 + N / 4`` extruded).
"""
from __future__ import annotations

import json
import logging
from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np
from scipy import ndimage

from design.inverse.objective import DesignObjective
from design.inverse.optimize import IterationCallback, run_design, with_phase
from design.inverse.problem import DesignConfig, Problem

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


def perturbed_start(seed: int) -> Callable[[DesignObjective, Problem], np.ndarray]:
    """A `design.inverse.optimize.run_design` start: the default start plus smooth noise seeded by ``seed``."""

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


def _best_value(folder: Path) -> float:
    """The lowest J in a finished run's history."""
    history = np.loadtxt(folder / "history.csv", delimiter=",", skiprows=1, ndmin=2)
    return float(history[:, 1].min())


def coarse_start(config: DesignConfig, out_dir: str | Path, *, on_iteration: IterationCallback | None = None,
                 should_stop: Callable[[], bool] | None = None) -> Callable[[DesignObjective, Problem], np.ndarray] | None:
    """Run ``config.starts`` coarse seeded starts and return the start of the full-resolution run.

    Called by `design.inverse.optimize.run_design` for a new (or not yet started) run with ``starts > 1``.

    Parameters
    ----------
    config : DesignConfig
        The full-resolution run; every coarse start uses it at `coarse_resolution`, with the same
        iteration limit and a single start.
    out_dir : str or Path
        The full-resolution run's folder; the starts go to ``out_dir/starts/NN`` and the choice to
        ``out_dir/multistart.json``.
    on_iteration, should_stop : callable, optional
        As for `design.inverse.optimize.run_design`, passed to every coarse run.

    Returns
    -------
    callable or None
        ``start(objective, problem)``: the best coarse design (lowest J) interpolated onto the full
        grid; None when `should_stop` ended a coarse run (the caller then stops at once too).

    Raises
    ------
    KeyboardInterrupt
        When a coarse run was interrupted (Ctrl-C); resuming continues with that start.
    """
    out_dir = Path(out_dir)
    coarse = replace(config, resolution=coarse_resolution(config.resolution), starts=1)
    results = []
    for k in range(config.starts):
        folder = out_dir / "starts" / f"{k:02d}"
        if not (folder / "summary.json").exists():
            phase = f"coarse start {k + 1} of {config.starts} at resolution {coarse.resolution}"
            log.info(phase)
            resume = (folder / "config.json").exists()
            result = run_design(None if resume else coarse, folder, on_iteration=with_phase(on_iteration, phase),
                                should_stop=should_stop, resume=resume, start=perturbed_start(k))
            if result.status == "interrupted":
                raise KeyboardInterrupt
            if result.status == "stopped":
                return None
        results.append((_best_value(folder), folder))
    best_value, best_folder = min(results, key=lambda r: r[0])
    log.info("refining start %s (J = %.6g at resolution %d)", best_folder.name, best_value, coarse.resolution)
    (out_dir / "multistart.json").write_text(json.dumps(
        {"coarse_resolution": coarse.resolution, "refined": best_folder.name,
         "best_J": {folder.name: value for value, folder in results}}, indent=2))
    with np.load(best_folder / "density.npz") as data:
        x_coarse, dx_coarse = data["rho_hat"], float(data["dx_mm"])

    def refine_start(objective: DesignObjective, problem: Problem) -> np.ndarray:
        return upsample(x_coarse, dx_coarse, objective.space.var_shape, problem.dx_mm)

    return refine_start
