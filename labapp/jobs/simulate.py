"""Simulate the release of a mesh, sample shape or density array (`sfr simulate`)."""
from __future__ import annotations

import json
import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from design import simulate as forward
from design.errors import DesignError
from design.files.meshio import DENSITY_SUFFIXES
from design.files.pipeline import SAMPLE_PREFIX, input_grid, mesh_grid
from design.forward.reference import design_lattice, reference_release
from design.geometry.shapes import sample_shape
from design.geometry.voxelize import DEFAULT_RESOLUTION
from labapp.errors import UsageError
from labapp.jobs.meshunits import SIMULATE_BYTES_PER_VOXEL, check_memory, grid_shape, load_mesh_mm, size_warnings
from labapp.records.outpaths import FolderKind, check_out

log = logging.getLogger(__name__)



@dataclass(frozen=True)
class SimulationOutputs:
    """What :func:`simulate` wrote: the ``design.Release``, its summary and the output folder."""

    release: Any
    summary: dict[str, Any]
    out: Path
    warnings: tuple[str, ...]


def simulation_grid(source: str, *, resolution: int | None = None, voxel_size_mm: float | None = None,
                    symmetry: str = "", units: str = "mm", offset_mm: float = 0.0
                    ) -> tuple[Any, float, tuple[bool, ...], list[str]]:
    """The density grid a simulation of ``source`` (mesh, ``sample:NAME`` or density array) runs on.

    A mesh is scaled from ``units`` to mm, checked for an implausible size (warnings naming the likely
    unit error) and its grid's memory estimated before anything is allocated.

    Returns
    -------
    rho : ndarray of float in [0, 1]
    dx_mm : float
    mirror : tuple of bool
    warnings : list of str
    """
    if _is_density(source):
        if units != "mm":
            raise UsageError("--units applies to meshes; a density array's voxel size is in mm")
        rho, dx, mirror = input_grid(source, resolution=resolution, voxel_size_mm=voxel_size_mm, symmetry=symmetry)
        return rho, dx, mirror, ([f"{source}: a density array is simulated as given; the calibration's surface "
                                  f"offset {offset_mm:g} mm applies to meshes only"] if offset_mm else [])
    mesh = _source_mesh(source, units)
    dx = voxel_size_mm or float(mesh.extents.max()) / (resolution or DEFAULT_RESOLUTION)
    warnings = size_warnings(mesh.extents, float(mesh.volume), dx, source)
    for w in warnings:
        log.warning("%s", w)
    check_memory(grid_shape(mesh.extents, dx), SIMULATE_BYTES_PER_VOXEL, f"simulating {source}")
    rho, dx, mirror = mesh_grid(mesh, resolution=resolution, voxel_size_mm=voxel_size_mm, symmetry=symmetry,
                                offset_mm=offset_mm)
    return rho, dx, mirror, warnings


def _is_density(source: str) -> bool:
    return Path(source).suffix.lower() in DENSITY_SUFFIXES and not source.startswith(SAMPLE_PREFIX)


def _source_mesh(source: str, units: str):
    """The mesh of a mesh file (scaled to mm) or ``sample:NAME``."""
    return sample_shape(source[len(SAMPLE_PREFIX):]) if source.startswith(SAMPLE_PREFIX) else load_mesh_mm(source, units)


def error_estimate(source: str, units: str, release, rho, dx_mm: float,
                   mirror: tuple[bool, ...], anisotropy: float = 1.0) -> dict[str, Any]:
    """How far a simulated release (at build-direction ``anisotropy``) is from the solid's physical release, mm^3
    and as a fraction of its volume.

    A mesh (or sample shape) is released by the reference evaluator (`design.forward.reference`, exact
    surface distances) on the same tau samples, on the lattice a design on a grid of the simulation's size
    is judged on (`design.forward.reference.design_lattice`): the estimate is the largest difference, and
    the evaluator's own stated error bounds how far that estimate can be off. A density array has no other
    description of its solid than its grid: the estimate is the largest difference from the same
    density averaged over blocks of 2 voxels per axis, simulated on voxels twice as large (the fast
    marcher's error is first-order in the voxel size, so the finer grid is off by about that difference).
    """
    import numpy as np

    if not _is_density(source):
        try:
            ref = reference_release(_source_mesh(source, units), release.tau_mm, cells=design_lattice(max(rho.shape)),
                                    anisotropy=anisotropy)
        except DesignError as exc:  # a mesh the voxeliser takes but the evaluator does not (not closed)
            return {"error_mm3": None, "error_fraction": None, "method": f"not estimated: {exc}"}
        diff = float(np.abs(release.released_mm3 - ref.released_mm3).max())
        return {"error_mm3": diff, "error_fraction": diff / ref.volume_mm3, "method": "reference evaluator",
                "reference_volume_mm3": ref.volume_mm3, "reference_error_mm3": ref.error_mm3,
                "reference_method": ref.method}
    even = tuple(slice(0, n - n % 2) for n in rho.shape)
    if min(n // 2 for n in rho.shape) < 1:
        return {"error_mm3": None, "error_fraction": None, "method": "grid too small to coarsen"}
    block = rho[even].reshape([v for n in rho[even].shape for v in (n // 2, 2)]).mean(axis=tuple(range(1, 2 * rho.ndim, 2)))
    coarse = forward(block, 2.0 * dx_mm, mirror=mirror, total_time_mm=release.total_time_mm, dtau_mm=release.dtau_mm,
                     anisotropy=anisotropy)
    # the blocks hold the even part of the grid: compare fractions of each grid's own volume
    scale = release.volume_mm3 / coarse.volume_mm3 if coarse.volume_mm3 > 0 else 1.0
    diff = float(np.abs(release.released_mm3 - scale * coarse.released_mm3).max())
    return {"error_mm3": diff, "error_fraction": diff / release.volume_mm3 if release.volume_mm3 > 0 else None,
            "method": "first-order: against the density on voxels twice as large"}


def simulate(source: str, out: str | Path, *, resolution: int | None = None, voxel_size_mm: float | None = None,
             symmetry: str = "", units: str = "mm", physics: dict | None = None,
             progress: Callable[[str], None] | None = None) -> SimulationOutputs:
    """Simulate the release of a mesh, ``sample:NAME`` or density array into ``out`` (release.csv,
    summary.json, release.png); the grid comes from :func:`simulation_grid`. The summary's ``error``
    states how far the curve is from the solid's physical release (:func:`error_estimate`). ``physics``
    (``anisotropy``, ``offset_mm``, a calibration's print physics) simulates the print instead of the mesh.

    Raises
    ------
    UsageError
        For an ``out`` that is an input or another command's folder, or a grid that would not fit in memory.
    design.DesignError
        For an unreadable or invalid input.
    """
    import time

    import numpy as np

    say = progress or (lambda message: None)
    out = check_out(out, FolderKind.SIMULATION, [source])
    start = time.perf_counter()
    say(f"[1/3] loading and voxelising {source} ...")
    physics = physics or {"anisotropy": 1.0, "offset_mm": 0.0}
    rho, dx, mirror, warnings = simulation_grid(source, resolution=resolution, voxel_size_mm=voxel_size_mm,
                                                symmetry=symmetry, units=units, offset_mm=physics["offset_mm"])
    say(f"[2/3] fast marching {rho.size:,} voxels of {dx:.4g} mm ({time.perf_counter() - start:.1f} s) ...")
    release = forward(rho, dx, mirror=mirror, anisotropy=physics["anisotropy"], swelling_mm=physics.get("swelling_mm", 0.0))
    say(f"      estimating its error ({time.perf_counter() - start:.1f} s) ...")
    if physics["offset_mm"] != 0.0 or physics.get("swelling_mm", 0.0) != 0.0:
        error = {"error_mm3": None, "error_fraction": None,
                 "method": "not estimated: the reference evaluator has no surface offset or swelling"}
    else:
        error = error_estimate(source, units, release, rho, dx, mirror, physics["anisotropy"])
    seconds = time.perf_counter() - start
    say(f"[3/3] writing {out}/ ({seconds:.1f} s)")
    out.mkdir(parents=True, exist_ok=True)
    np.savetxt(out / "release.csv", np.column_stack([release.tau_mm, release.released_mm3]), delimiter=",",
               header="tau_mm,released_mm3", comments="", fmt="%.9g")
    summary = {"input": source, "units": units, "volume_mm3": release.volume_mm3,
               "total_time_mm": release.total_time_mm, "voxels": int(rho.size), "grid_shape": list(rho.shape),
               "voxel_size_mm": dx, "mirror": list(mirror), "dtau_mm": release.dtau_mm, "error": error,
               "seconds": seconds, "warnings": warnings, "physics": physics}
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    _plot_release(release.tau_mm, release.released_mm3, out / "release.png", source)
    return SimulationOutputs(release, summary, out, tuple(warnings))


def _plot_release(tau_mm, released_mm3, path: Path, title: str) -> None:
    """The cumulative curve and its rate dC/dtau, one above the other."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(6, 6), constrained_layout=True)
    top.plot(tau_mm, released_mm3)
    top.set_ylabel("released volume C (mm$^3$)")
    top.set_title(f"simulated release: {title}")
    bottom.plot(tau_mm, np.gradient(released_mm3, tau_mm))
    bottom.set_ylabel("rate dC/d$\\tau$ (mm$^3$/mm)")
    bottom.set_xlabel("dissolution time $\\tau$ (mm dissolved)")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    fig.savefig(path, dpi=120)
    plt.close(fig)
