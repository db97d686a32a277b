"""Simulate the drug's release from a drug mesh inside a barrier mesh (`sfr simulate --barrier`)."""
from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from design.errors import DesignError
from design.files.pipeline import SAMPLE_PREFIX
from design.files.twogrid import two_material_grid, union_bounds
from design.forward.solid_lattice import DEFAULT_TOLERANCE, TooThinError
from design.forward.twomaterial import TwoMaterialRelease, barrier_cover, check_barrier_speed, simulate_two
from design.geometry.shapes import sample_shape
from design.geometry.voxelize import DEFAULT_RESOLUTION
from labapp.errors import UsageError
from labapp.jobs.meshunits import SIMULATE_BYTES_PER_VOXEL, check_memory, grid_shape, load_mesh_mm, size_warnings
from labapp.records.outpaths import FolderKind, check_out

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class BarrierSimulation:
    """What :func:`simulate_barrier` wrote: the release, its summary, the output folder and the warnings."""

    release: TwoMaterialRelease
    summary: dict[str, Any]
    out: Path
    warnings: tuple[str, ...]


def _mesh(source: str, units: str, role: str):
    if Path(source).suffix.lower() in (".npy", ".npz"):
        raise UsageError(f"{source}: the {role} must be a mesh (STL/OBJ/PLY/OFF/3MF) or sample:NAME with --barrier")
    return sample_shape(source[len(SAMPLE_PREFIX):]) if source.startswith(SAMPLE_PREFIX) else load_mesh_mm(source, units)


def sealed_regions(release: TwoMaterialRelease) -> list[float]:
    """Volumes of the face-connected drug regions sealed inside an insoluble barrier, largest first, mm^3."""
    from scipy.ndimage import label, sum_labels

    labels, count = label(release.sealed)
    if count == 0:
        return []
    volumes = sum_labels(release.drug_density, labels, index=np.arange(1, count + 1))
    return sorted((float(v) * release.dx_mm ** 3 * release.multiplicity for v in volumes), reverse=True)


def coarse_error(release: TwoMaterialRelease) -> dict[str, Any]:
    """The first-order error estimate: the largest difference from the same densities averaged over blocks of
    2 voxels per axis, simulated on voxels twice as large, mm^3 and as a fraction of the drug volume."""
    drug, barrier = release.drug_density, release.barrier_density
    even = tuple(slice(0, n - n % 2) for n in drug.shape)
    if min(n // 2 for n in drug.shape) < 1:
        return {"error_mm3": None, "error_fraction": None, "method": "grid too small to coarsen"}

    def block(a):
        a = a[even]
        return a.reshape([v for n in a.shape for v in (n // 2, 2)]).mean(axis=tuple(range(1, 2 * a.ndim, 2)))

    coarse = simulate_two(block(drug), block(barrier), 2.0 * release.dx_mm, release.barrier_speed, mirror=release.mirror,
                          total_time_mm=release.total_time_mm, dtau_mm=release.dtau_mm)
    scale = release.drug_volume_mm3 / coarse.drug_volume_mm3 if coarse.drug_volume_mm3 > 0 else 1.0
    diff = float(np.abs(release.released_mm3 - scale * coarse.released_mm3).max())
    return {"error_mm3": diff, "error_fraction": diff / release.drug_volume_mm3,
            "method": "first-order: against both materials on voxels twice as large"}


OPEN_COVER_VOXELS = 0.01
"""A barrier cover under this many voxels is no barrier: void on the way costs n_min dx per voxel (eq. 2)."""


def _release_start(cover_mm: float, s: float, dx_mm: float) -> float | None:
    """When the drug's release starts, tau in mm: cover / s; 0 for drug open to the bath; None when sealed."""
    if cover_mm < OPEN_COVER_VOXELS * dx_mm:
        return 0.0
    return cover_mm / s if s > 0 else None


def simulate_barrier_exact(source: str, barrier: str, out: str | Path, *, barrier_speed: float, units: str = "mm",
                           progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """The drug's release from ``source`` inside ``barrier`` by the two-material reference evaluator (exact
    distances, refracted paths, its error stated and within the default tolerance) into ``out`` (release.csv,
    summary.json, release.png); returns the summary.

    Raises
    ------
    UsageError
        As :func:`simulate_barrier`.
        For drug too thin for the evaluator within its lattice budget
        (:class:`design.forward.solid_lattice.TooThinError`'s message: use the grid model).
    design.DesignError
        For an invalid mesh.
    """
    from design.forward.twomaterial_reference import MAX_POINTS as TWO_MATERIAL_POINTS
    from design.forward.twomaterial_reference import two_material_reference_release

    say = progress or (lambda message: None)
    out = check_out(out, FolderKind.SIMULATION, [source, barrier])
    try:
        s = check_barrier_speed(barrier_speed)
    except DesignError as exc:
        raise UsageError(f"--barrier-speed: {exc}") from exc
    start = time.perf_counter()
    say(f"[1/3] loading {source} and the barrier {barrier} ...")
    drug_mesh, barrier_mesh = _mesh(source, units, "drug"), _mesh(barrier, units, "barrier")
    say(f"[2/3] exact refracted distances, barrier speed {s:g} ...")
    try:
        ref = two_material_reference_release(drug_mesh, barrier_mesh, s, source=source,
                                             progress=lambda line: say(f"      {line}"))
    except TooThinError as exc:
        raise UsageError(f"{source} in {barrier}: the exact two-material model needs a lattice of about "
                         f"{exc.spacing_mm:.3g} mm for an error within {DEFAULT_TOLERANCE:.2%} of the drug volume, about "
                         f"{exc.points / 1e6:.2g} million points, over the {TWO_MATERIAL_POINTS / 1e6:.2g} million it "
                         "evaluates within a minute; simulate it with the grid model (--model grid, first order, its "
                         "error stated)") from exc
    warnings = []
    if ref.relative_error > DEFAULT_TOLERANCE:
        warnings.append(f"{source}: the exact model's stated error is {ref.relative_error:.2%} of the drug volume, above "
                        f"the {DEFAULT_TOLERANCE:.2%} it aims at ({ref.lattice})")
    if ref.sealed_mm3 > 0:
        warnings.append(f"{ref.sealed_mm3:.4g} mm^3 of drug ({ref.sealed_mm3 / ref.volume_mm3:.1%}) is sealed inside "
                        f"the insoluble barrier in {len(ref.sealed_regions_mm3)} region(s) and never releases; open the "
                        "barrier or give it a barrier speed > 0")
    if ref.straight_mm3 > 0:
        warnings.append(f"{ref.straight_mm3:.4g} mm^3 of drug lies in bodies whose hull holds barrier: a straight "
                        "path there may cross barrier, so its release may be early (--model grid follows any path)")
    for w in warnings:
        log.warning("%s", w)
    seconds = time.perf_counter() - start
    say(f"[3/3] writing {out}/ ({seconds:.1f} s)")
    out.mkdir(parents=True, exist_ok=True)
    np.savetxt(out / "release.csv", np.column_stack([ref.tau_mm, ref.released_mm3]), delimiter=",",
               header="tau_mm,released_mm3", comments="", fmt="%.9g")
    summary = {"input": source, "barrier": barrier, "barrier_speed": s, "units": units, "model": "exact",
               "method": ref.method, "lattice": {"spacing_mm": ref.cell_mm, "reason": ref.lattice},
               "volume_mm3": ref.volume_mm3, "barrier_volume_mm3": ref.barrier_volume_mm3,
               "sealed_mm3": ref.sealed_mm3, "sealed_regions_mm3": list(ref.sealed_regions_mm3),
               "straight_paths_mm3": ref.straight_mm3, "total_time_mm": ref.total_time_mm,
               "error": {"error_mm3": ref.error_mm3, "error_fraction": ref.relative_error,
                         "method": "max |C_h - C_2h| against the lattice and interfaces twice as coarse"},
               "seconds": seconds, "warnings": warnings}
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    _plot_curve(ref.tau_mm, ref.released_mm3, ref.volume_mm3, ref.sealed_mm3, out / "release.png",
                f"{source} in {barrier} (barrier speed {s:g}, exact)")
    return summary


def simulate_barrier(source: str, barrier: str, out: str | Path, *, barrier_speed: float,
                     resolution: int | None = None, voxel_size_mm: float | None = None, symmetry: str = "",
                     units: str = "mm", progress: Callable[[str], None] | None = None) -> BarrierSimulation:
    """Simulate the drug's release from ``source`` inside ``barrier`` into ``out`` (release.csv, summary.json,
    release.png).

    Both meshes are voxelised on one grid (where they overlap the voxel is drug; ``symmetry``: mirror planes
    through the centre of the box holding both, as for one material); the barrier erodes at
    ``barrier_speed`` times the drug's rate (0: insoluble). Drug sealed inside an insoluble barrier never
    releases: its volume and regions are in the summary and in a warning.

    Raises
    ------
    UsageError
        For an ``out`` that is an input or another command's folder, a density array as input, a negative
        speed or a grid that would not fit in memory.
    design.DesignError
        For an unreadable or invalid mesh.
    """
    say = progress or (lambda message: None)
    out = check_out(out, FolderKind.SIMULATION, [source, barrier])
    try:
        s = check_barrier_speed(barrier_speed)
    except DesignError as exc:
        raise UsageError(f"--barrier-speed: {exc}") from exc
    start = time.perf_counter()
    say(f"[1/3] loading and voxelising {source} and the barrier {barrier} ...")
    drug_mesh, barrier_mesh = _mesh(source, units, "drug"), _mesh(barrier, units, "barrier")
    extents = np.diff(union_bounds(drug_mesh, barrier_mesh), axis=0)[0]
    dx = voxel_size_mm or float(extents.max()) / (resolution or DEFAULT_RESOLUTION)
    warnings = (size_warnings(drug_mesh.extents, float(drug_mesh.volume), dx, source)
                + size_warnings(barrier_mesh.extents, float(barrier_mesh.volume), None, barrier))
    check_memory(grid_shape(extents, dx), SIMULATE_BYTES_PER_VOXEL, f"simulating {source} with {barrier}")
    grid = two_material_grid(drug_mesh, barrier_mesh, resolution=resolution, voxel_size_mm=voxel_size_mm,
                             symmetry=symmetry)
    say(f"[2/3] fast marching {grid.rho_d.size:,} voxels of {grid.dx_mm:.4g} mm, barrier speed {s:g} "
        f"({time.perf_counter() - start:.1f} s) ...")
    release = simulate_two(grid.rho_d, grid.rho_b, grid.dx_mm, s, mirror=grid.mirror)
    regions = sealed_regions(release)
    cover = barrier_cover(grid.rho_d, grid.rho_b, grid.dx_mm, mirror=grid.mirror)
    if regions:
        warnings.append(f"{release.sealed_mm3:.4g} mm^3 of drug ({release.sealed_mm3 / release.drug_volume_mm3:.1%}) is "
                        f"sealed inside the insoluble barrier in {len(regions)} region(s) and never releases; "
                        "open the barrier or give it a barrier speed > 0")
    say(f"      estimating its error ({time.perf_counter() - start:.1f} s) ...")
    error = coarse_error(release)
    for w in warnings:
        log.warning("%s", w)
    seconds = time.perf_counter() - start
    say(f"[3/3] writing {out}/ ({seconds:.1f} s)")
    out.mkdir(parents=True, exist_ok=True)
    np.savetxt(out / "release.csv", np.column_stack([release.tau_mm, release.released_mm3]), delimiter=",",
               header="tau_mm,released_mm3", comments="", fmt="%.9g")
    summary = {"input": source, "barrier": barrier, "barrier_speed": s, "units": units,
               "volume_mm3": release.drug_volume_mm3, "barrier_volume_mm3": release.barrier_volume_mm3,
               "sealed_mm3": release.sealed_mm3, "sealed_regions_mm3": regions, "barrier_cover_mm": cover,
               "release_starts_mm": _release_start(cover, s, grid.dx_mm),
               "total_time_mm": release.total_time_mm, "voxels": int(grid.rho_d.size),
               "grid_shape": list(grid.rho_d.shape), "voxel_size_mm": grid.dx_mm, "mirror": list(grid.mirror),
               "origin_mm": grid.origin_mm.tolist(),
               "overlap_voxels": grid.overlap_voxels, "dtau_mm": release.dtau_mm, "error": error, "seconds": seconds,
               "warnings": warnings}
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    _plot(release, out / "release.png", f"{source} in {barrier} (barrier speed {s:g})")
    return BarrierSimulation(release, summary, out, tuple(warnings))


def _plot(release: TwoMaterialRelease, path: Path, title: str) -> None:
    """The grid model's release drawn by :func:`_plot_curve`."""
    _plot_curve(release.tau_mm, release.released_mm3, release.drug_volume_mm3, release.sealed_mm3, path, title)


def _plot_curve(tau: np.ndarray, released: np.ndarray, volume: float, sealed: float, path: Path, title: str) -> None:
    """The drug's cumulative release (with its total and any sealed part) and its rate, one above the other."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(6, 6), constrained_layout=True)
    top.plot(tau, released, label="drug released")
    top.axhline(volume, color="0.5", ls="--", lw=1, label="drug volume")
    if sealed > 0:
        top.axhline(volume - sealed, color="C3", ls=":", lw=1, label="unsealed drug")
    top.set_ylabel("released drug C (mm$^3$)")
    top.set_title(title, fontsize=9)
    top.legend(fontsize=8)
    bottom.plot(tau, np.gradient(released, tau) if len(tau) > 1 else np.zeros(len(tau)))
    bottom.set_ylabel("rate dC/d$\\tau$ (mm$^3$/mm)")
    bottom.set_xlabel("dissolution time $\\tau$ (mm of drug dissolved)")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    fig.savefig(path, dpi=120)
    plt.close(fig)
