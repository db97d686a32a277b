"""Simulate the release of a mesh, sample shape or density array (`sfr simulate`).

Two models make ``release.csv``:

- ``exact`` (the default for a mesh or ``sample:NAME``): the reference evaluator
  (:mod:`design.forward.reference`): exact surface distances, sealed voids wetted when the front reaches them,
  a lattice sized by the solid's own thickness and refined until its stated error is within
  `design.forward.solid_lattice.DEFAULT_TOLERANCE` of the volume; the curve ends at the mesh's exact volume. A
  part too thin for it is refused, naming its thickness. A calibration's print physics: anisotropy is the
  evaluator's metric; a surface offset o releases the print {signed distance > -o}
  (:mod:`design.forward.offset_lattice`; its volume the quadrature's); a swelling width w shuts the print's channels
  narrower than w, which the exact model does not model: when the grid model's voxels of the print
  (:func:`swelling_plug`) have none, swelling changes nothing and the release is the exact model's.
- ``grid`` (the only one for a density array; the default fallback, warned about, for a print whose offset meets a
  sealed void, and for one whose swelling shuts a channel, where only the shut channels are the grid's: the exact
  print's release plus the grid's release with swelling less without, :func:`_swelling_on_exact`): first-order fast
  marching on voxels (eqs. 5-7), at ``--resolution`` voxels along the longest side, with its error estimated against
  the exact release (a mesh; with the print's offset) or a grid twice as coarse (a density array).

Every output is written atomically (``labapp.records.fileio.atomic_write``): a full disk leaves no partial file
and is a :class:`labapp.records.fileio.StorageError` naming it.
"""
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
from design.forward.reference import reference_release
from design.forward.solid_lattice import DEFAULT_TOLERANCE, TooThinError
from design.geometry.shapes import sample_shape
from design.geometry.voxelize import DEFAULT_RESOLUTION
from labapp.errors import UsageError
from labapp.jobs.meshunits import MIN_RESOLUTION, SIMULATE_BYTES_PER_VOXEL, check_memory, grid_shape, load_mesh_mm, size_warnings
from labapp.records.fileio import StorageError, atomic_write
from labapp.records.outpaths import FolderKind, check_out

log = logging.getLogger(__name__)

GRID_WARN_FRACTION = 0.01
"""A grid-model curve whose estimated error exceeds this fraction of the volume is warned about."""
MODELS = ("exact", "grid")
"""The models of :func:`simulate` (``sfr simulate --model``; ``mc`` is :mod:`labapp.jobs.simulate_mc`)."""


@dataclass(frozen=True)
class ExactRelease:
    """The exact model's release: ``tau_mm`` (uniform, mm), ``released_mm3``, the solid's volume and the depth at
    which it has all dissolved (mm), with the reference evaluation that made it."""

    tau_mm: Any
    released_mm3: Any
    volume_mm3: float
    total_time_mm: float
    reference: Any

    @property
    def dtau_mm(self) -> float:
        return float(self.tau_mm[1] - self.tau_mm[0]) if len(self.tau_mm) > 1 else 0.0


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
    if resolution is not None and int(resolution) < MIN_RESOLUTION:
        raise UsageError(f"--resolution {resolution}: expected a whole number >= {MIN_RESOLUTION} voxels")
    if _is_density(source):
        if units != "mm":
            raise UsageError("--units applies to meshes; a density array's voxel size is in mm")
        rho, dx, mirror = input_grid(source, resolution=resolution, voxel_size_mm=voxel_size_mm, symmetry=symmetry)
        if rho.ndim != 3:
            raise UsageError(f"{source}: its density rho has shape {tuple(rho.shape)}; expected a 3-D array "
                             "(X, Y, Z) of densities in [0, 1] with its voxel edge dx_mm")
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
                   mirror: tuple[bool, ...], anisotropy: float = 1.0, offset_mm: float = 0.0) -> dict[str, Any]:
    """How far a simulated release (at build-direction ``anisotropy``, of the print with surface offset
    ``offset_mm``) is from the solid's physical release, mm^3 and as a fraction of its volume.

    A mesh (or sample shape) is released by the reference evaluator (`design.forward.reference`, exact
    surface distances) on the same tau samples, on its lattice sized by the solid: the estimate is the largest
    difference, and
    the evaluator's own stated error bounds how far that estimate can be off. A density array has no other
    description of its solid than its grid: the estimate is the largest difference from the same
    density averaged over blocks of 2 voxels per axis, simulated on voxels twice as large (the fast
    marcher's error is first-order in the voxel size, so the finer grid is off by about that difference).
    """
    import numpy as np

    if not _is_density(source):
        try:
            ref = reference_release(_source_mesh(source, units), release.tau_mm, anisotropy=anisotropy, source=source,
                                    offset_mm=offset_mm)
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
             progress: Callable[[str], None] | None = None, model: str | None = None) -> SimulationOutputs:
    """Simulate the release of a mesh, ``sample:NAME`` or density array into ``out`` (release.csv,
    summary.json, release.png). ``model`` ``exact`` (the default for a mesh; a print it cannot model falls back to
    ``grid`` with a warning) or ``grid`` (the default for a density array); see the module docstring. The
    summary's ``model``, ``method``, ``error`` and ``lattice`` (or grid) say what made release.csv, how far it is
    from the solid's physical release and why its resolution. ``physics`` (``anisotropy``, ``offset_mm``,
    ``swelling_mm``: a calibration's print physics) simulates the print instead of the mesh.

    Raises
    ------
    UsageError
        For an ``out`` that is an input or another command's folder, a grid option with the exact model, a part
        too thin for the exact model, a grid that would not fit in memory, or a density array not 3-D.
    StorageError
        When an output cannot be written (a full disk); nothing partial is left of it.
    design.DesignError
        For an unreadable or invalid input.
    """
    say = progress or (lambda message: None)
    out = check_out(out, FolderKind.SIMULATION, [source])
    physics = {"anisotropy": 1.0, "offset_mm": 0.0, **(physics or {})}
    chosen = model or ("grid" if _is_density(source) else "exact")
    if chosen not in MODELS:
        raise UsageError(f"model {chosen!r}: expected one of {', '.join(MODELS)}")
    if chosen == "exact":
        if _is_density(source):
            raise UsageError(f"{source}: a density array has no surface for the exact model; use --model grid")
        given = [name for name, v in (("--resolution", resolution), ("--voxel-size", voxel_size_mm),
                                      ("--symmetry", symmetry)) if v]
        if given:
            raise UsageError(f"{', '.join(given)} set the grid model's voxels; the exact model sizes its lattice by "
                             "the solid: drop them or add --model grid")
        fallback, swelling = _exact_unmodelled(source, units, physics, say)
        if fallback and model == "exact":
            raise UsageError(f"{fallback}; use --model grid")
        if fallback:
            log.warning("%s: the grid model simulates it", fallback)
            release, summary, warnings = _simulate_grid(source, units, physics, say, resolution=None,
                                                        voxel_size_mm=None, symmetry="")
            if swelling:
                release = _swelling_on_exact(source, units, physics, release, summary)
            warnings.insert(0, f"{fallback}: simulated by the grid model (first order)"
                            + (", added to the exact model's release of the print" if swelling else ""))
            summary["exact_model_not_used"] = fallback
        else:
            release, summary, warnings = _simulate_exact(source, units, physics, say)
    else:
        release, summary, warnings = _simulate_grid(source, units, physics, say, resolution=resolution,
                                                    voxel_size_mm=voxel_size_mm, symmetry=symmetry)
    say(f"[3/3] writing {out}/ ({summary['seconds']:.1f} s)")
    write_outputs(out, release.tau_mm, release.released_mm3, summary, source)
    return SimulationOutputs(release, summary, out, tuple(warnings))


def swelling_plug(source: str, units: str, physics: dict) -> tuple[float, float]:
    """The volume (mm^3) of the print's channels that its swelling width shuts, on the grid model's voxels of the print
    at its default resolution (`design.forward.swelling.shut_channels`, the grid model's definition of a shut
    channel), and that voxel edge (mm); (0, 0) without swelling."""
    from design.forward.swelling import shut_channels

    width = float(physics.get("swelling_mm", 0.0))
    if width == 0.0:
        return 0.0, 0.0
    rho, dx, _ = mesh_grid(_source_mesh(source, units), offset_mm=physics["offset_mm"])
    return float(shut_channels(rho, dx, width).sum()) * dx ** 3, dx


def _exact_unmodelled(source: str, units: str, physics: dict, say: Callable[[str], None]) -> tuple[str, bool]:
    """Why the exact model cannot release this print alone ('' when it can), and whether that is a swelling width
    that shuts a channel of the print (:func:`swelling_plug`; the grid model's share then is the shut channels only)
    rather than a surface offset on a mesh with sealed voids."""
    from design.forward.wetting import wetting

    if physics["offset_mm"]:
        voids = wetting(_source_mesh(source, units))[1]
        if voids:
            return (f"{source}: a surface offset on a mesh with {voids} sealed void(s) is not modelled by the exact "
                    "model"), False
    if physics.get("swelling_mm", 0.0):
        say(f"      checking for channels narrower than the swelling width {physics['swelling_mm']:g} mm ...")
        plug, dx = swelling_plug(source, units, physics)
        if plug > 0.0:
            return (f"{source}: the print's swelling width {physics['swelling_mm']:g} mm shuts {plug:.3g} mm^3 of "
                    f"its channels (on {dx:.3g} mm voxels), which the exact model does not model"), True
    return "", False


def _swelling_on_exact(source: str, units: str, physics: dict, release, summary: dict[str, Any]) -> ExactRelease:
    """The print's release with swelling that shuts a channel, as a calibration's predictions make it
    (`labapp.jobs.printrelease.print_release`): the reference evaluator's release of the print (with its offset and
    anisotropy) plus the grid model's shut channels, its release with swelling less its release without (both on
    ``release``'s grid, at the print's volume), on uniform depths to where both are complete. Updates ``summary``."""
    import numpy as np

    from labapp.jobs.printrelease import print_release

    mesh = _source_mesh(source, units)
    grid = mesh_grid(mesh, offset_mm=physics["offset_mm"])
    tau, released = print_release(mesh, grid, DEFAULT_RESOLUTION, {"swelling_mm": 0.0, **physics}, release)
    done = float(tau[int(np.argmax(released >= released[-1] * (1.0 - 1e-12)))])
    uniform = np.linspace(0.0, max(float(release.tau_mm[-1]), done), len(release.tau_mm))
    curve = np.interp(uniform, tau, released)
    summary.update({"method": "the exact model's release of the print with the grid model's shut channels added: "
                              "first-order fast marching with swelling less without, on its voxels "
                              "(labapp.jobs.printrelease.print_release, as a calibration's predictions)",
                    "volume_mm3": float(curve[-1]), "total_time_mm": float(uniform[-1]),
                    "dtau_mm": float(uniform[1] - uniform[0])})
    summary["error"] = {"error_mm3": None, "error_fraction": None,
                        "method": "not estimated: the shut channels' share is the grid model's (first order)"}
    return ExactRelease(uniform, curve, float(curve[-1]), float(uniform[-1]), None)


def _simulate_exact(source: str, units: str, physics: dict, say: Callable[[str], None]
                    ) -> tuple[ExactRelease, dict[str, Any], list[str]]:
    """The reference evaluator's release of a mesh or sample shape, on a lattice sized by the solid."""
    import time

    start = time.perf_counter()
    say(f"[1/3] loading {source} ...")
    mesh = _source_mesh(source, units)
    warnings = size_warnings(mesh.extents, float(mesh.volume), None, source)
    for w in warnings:
        log.warning("%s", w)
    say(f"[2/3] exact release by surface distances ({time.perf_counter() - start:.1f} s) ...")
    try:
        ref = reference_release(mesh, anisotropy=physics["anisotropy"], source=source,
                                progress=lambda line: say(f"      {line}"), offset_mm=physics["offset_mm"])
    except TooThinError as exc:
        raise UsageError(str(exc)) from exc
    if ref.relative_error > DEFAULT_TOLERANCE:
        warnings.append(f"{source}: the exact model's stated error is {ref.relative_error:.2%} of the volume, above "
                        f"the {DEFAULT_TOLERANCE:.2%} it aims at ({ref.lattice})")
    release = ExactRelease(ref.tau_mm, ref.released_mm3, ref.volume_mm3, float(ref.tau_mm[-1]), ref)
    seconds = time.perf_counter() - start
    summary = {"input": source, "units": units, "model": "exact", "method": ref.method,
               "volume_mm3": ref.volume_mm3, "total_time_mm": release.total_time_mm, "dtau_mm": release.dtau_mm,
               "error": {"error_mm3": ref.error_mm3, "error_fraction": ref.relative_error,
                         "method": "stated by the reference evaluator: max |C_h - C_2h| against a lattice twice as "
                                   "coarse (the curve's own error is about a third of it)"
                                   + (f", plus {ref.unsure_mm3:.3g} mm^3 whose arrival the grown surface may delay"
                                      if ref.unsure_mm3 else "")},
               "lattice": {"spacing_mm": ref.cell_mm, "reason": ref.lattice},
               "bodies": len(mesh.split(only_watertight=False)),
               "seconds": seconds, "warnings": warnings, "physics": physics}
    if physics.get("swelling_mm", 0.0):
        summary["swelling"] = (f"no channel of the print is narrower than the swelling width {physics['swelling_mm']:g} "
                               "mm on the grid model's voxels: swelling shuts none")
    return release, summary, warnings


def _simulate_grid(source: str, units: str, physics: dict, say: Callable[[str], None], *, resolution: int | None,
                   voxel_size_mm: float | None, symmetry: str) -> tuple[Any, dict[str, Any], list[str]]:
    """The grid model's release (first-order fast marching, eqs. 5-7) with its error estimate."""
    import time

    start = time.perf_counter()
    say(f"[1/3] loading and voxelising {source} ...")
    rho, dx, mirror, warnings = simulation_grid(source, resolution=resolution, voxel_size_mm=voxel_size_mm,
                                                symmetry=symmetry, units=units, offset_mm=physics["offset_mm"])
    say(f"[2/3] fast marching {rho.size:,} voxels of {dx:.4g} mm ({time.perf_counter() - start:.1f} s) ...")
    release = forward(rho, dx, mirror=mirror, anisotropy=physics["anisotropy"], swelling_mm=physics.get("swelling_mm", 0.0))
    say(f"      estimating its error ({time.perf_counter() - start:.1f} s) ...")
    if release.plug is not None:
        error = {"error_mm3": None, "error_fraction": None,
                 "method": "not estimated: the reference evaluator does not shut channels (swelling)"}
    else:
        error = error_estimate(source, units, release, rho, dx, mirror, physics["anisotropy"], physics["offset_mm"])
    if error.get("error_fraction") is not None and error["error_fraction"] > GRID_WARN_FRACTION:
        warnings.append(f"{source}: the grid model's curve is {error['error_fraction']:.1%} of the volume off the "
                        f"solid's release ({error['method']}); raise --resolution, or use the exact model "
                        "(the default for a mesh)")
    why = ("--voxel-size" if voxel_size_mm else f"--resolution {resolution}" if resolution else
           f"the default {DEFAULT_RESOLUTION} voxels along the longest side")
    summary = {"input": source, "units": units, "model": "grid",
               "method": "first-order fast marching on voxels (eqs. 5-7)", "volume_mm3": release.volume_mm3,
               "total_time_mm": release.total_time_mm, "voxels": int(rho.size), "grid_shape": list(rho.shape),
               "voxel_size_mm": dx, "resolution_reason": why, "mirror": list(mirror), "dtau_mm": release.dtau_mm,
               "error": error, "seconds": time.perf_counter() - start, "warnings": warnings, "physics": physics}
    return release, summary, warnings


def write_outputs(out: Path, tau_mm, released_mm3, summary: dict[str, Any], title: str) -> None:
    """release.csv, summary.json and release.png into ``out``, each written atomically.

    Raises
    ------
    StorageError
        Naming the file that could not be written (a full disk); nothing partial is left of it.
    """
    import io

    import numpy as np

    out.mkdir(parents=True, exist_ok=True)
    table = io.StringIO()
    np.savetxt(table, np.column_stack([tau_mm, released_mm3]), delimiter=",", header="tau_mm,released_mm3",
               comments="", fmt="%.9g")
    picture = io.BytesIO()
    _plot_release(tau_mm, released_mm3, picture, title)
    for name, data in (("release.csv", table.getvalue().encode()),
                       ("summary.json", (json.dumps(summary, indent=2) + "\n").encode()),
                       ("release.png", picture.getvalue())):
        write_file(out / name, data)


def write_file(path: Path, data: bytes) -> None:
    """``labapp.records.fileio.atomic_write`` with a full or read-only disk as a :class:`StorageError`."""
    import os

    try:
        atomic_write(path, data)
    except StorageError:
        raise
    except OSError as exc:
        path.with_name(f".{path.name}.part").unlink(missing_ok=True)
        raise StorageError(f"cannot write {path}: {exc.strerror or os.strerror(exc.errno or 0)}; nothing of it was "
                           "left; free space or choose another --out") from exc


def _plot_release(tau_mm, released_mm3, path, title: str) -> None:
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
    fig.savefig(path, dpi=120, format="png")
    plt.close(fig)
