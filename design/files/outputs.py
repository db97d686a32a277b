"""Everything a finished (or stopped) design run writes into its folder, in this order: ``design.stl``
(+ requested formats), ``density.npz``, ``curves.csv`` (`CURVE_COLUMNS`), ``history.csv``, ``design.ini``
(PrusaSlicer profile), ``report.png`` and ``summary.json`` (`write_outputs`).

The figures are the print's (`design.files.printed`); the design grid's stay as diagnostics.
"""
from __future__ import annotations

import json
import logging
import os
import platform
from dataclasses import asdict, dataclass
from importlib import metadata
from pathlib import Path

import numpy as np
import trimesh

from design.errors import DesignError
from design.fabrication.extract import centred_iou, count_pieces, density_mesh, mass_preserving_level, revoxelize
from design.fabrication.printability import Printability, assess, print_mass_g, prusa_profile
from design.files.pipeline import offset_mesh
from design.files.printed import (
    PRINT_PHYSICS_FACTOR,
    PrintRelease,
    channel_constraint,
    close_narrow_channels,
    print_release,
)
from design.files.records import SUMMARY, SUMMARY_FORMAT, DesignSummary
from design.files.report import save_report
from design.files.summary_text import print_fit_text
from design.forward.simulator import simulate
from design.inverse.objective import DesignObjective, rel_rmse
from design.inverse.optimize import HISTORY_COLUMNS
from design.inverse.rate import rate_deviation, rate_deviation_vs_target
from design.inverse.status import DesignStatus

log = logging.getLogger(__name__)

CURVE_COLUMNS = ("tau_mm", "target_mm3", "print_mm3", "density_mm3", "binary_mm3")
"""``target_mm3`` the physical target, ``print_mm3`` the printed solid's release by the reference evaluator;
``density_mm3`` and ``binary_mm3`` the density's and the re-voxelised solid's on the design grid."""

NOT_CONVERGED_REL_RMSE = 0.05
"""A run ended by its evaluation limit whose print misses the target by more than this rel. RMSE gets the
warning that it did not converge, with the limit to raise."""


@dataclass(frozen=True)
class DesignOutputs:
    """Paths and headline numbers of a run's outputs."""

    summary_path: Path
    summary: DesignSummary


def write_outputs(out_dir: Path, problem, objective: DesignObjective, best_x: np.ndarray,
                  history: list[list[float]], config, *, status: DesignStatus,
                  session_seconds: float, announce: bool = True, judged: bool = True) -> DesignOutputs:
    """Extract, re-simulate, assess and write every output of a design run.

    Parameters
    ----------
    out_dir : Path
    problem : design.inverse.problem.Problem
    objective : DesignObjective
    best_x : ndarray of float, variable shape
        The best design variables found.
    history : list of rows with `HISTORY_COLUMNS`
    config : design.inverse.config.DesignConfig
    status : DesignStatus
    session_seconds : float
        Wall time of this session (resumes add up through the history's seconds column).
    announce : bool
        Log the run's warnings as warnings (False: at INFO level, naming ``out_dir``; a coarse start's).
    judged : bool
        Release the print by the reference evaluator (False: a coarse start's, which its J alone ranks; its print
        figures are None and its curve NaN, `design.files.printed.print_release`).
    """
    rho = objective.density(best_x)
    density_mm3 = _density_release(problem, config, rho)
    warnings: list[str] = list(problem.warnings)
    printed = _write_print(out_dir, problem, config, rho, warnings)  # design.stl (+ formats)
    release = print_release(problem, config, printed.mesh, printed.solid, judged, stl=printed.stl)
    checks = _check_print(problem, config, status, printed, release, warnings)
    _write_data(out_dir, problem, best_x, rho, printed, density_mm3, release, history)  # density.npz, csv, ini
    summary = _summary(problem, objective, config, status, history, session_seconds, rho, density_mm3, printed,
                       release, checks, warnings)
    _log_warnings(out_dir, warnings[len(problem.warnings):], announce)   # the problem's: logged when it was prepared
    _write_report(out_dir / "report.png", problem, config, printed, density_mm3, release, summary)
    path = out_dir / SUMMARY
    _write_text(path, json.dumps(summary, indent=2))
    return DesignOutputs(path, summary)


@dataclass(frozen=True)
class _Print:
    """The print extracted from a design's density.

    Attributes
    ----------
    rho_full : ndarray of float, full grid
        The unfolded density, with swelling its narrow channels filled at 1 (`close_narrow_channels`).
    level : float
        The density level the solid is extracted at (`mass_preserving_level`).
    filled : int
        Voxels the channel stage filled.
    mesh : trimesh.Trimesh or None
        The print, mm: ``design.stl`` grown by the print offset; None when no solid was extracted.
    solid : ndarray of bool, full grid
        The print re-voxelised on the design grid.
    stl : trimesh.Trimesh or None
        ``design.stl``, the file to print (the designed solid shrunk by the print offset).
    """

    rho_full: np.ndarray
    level: float
    filled: int
    mesh: trimesh.Trimesh | None
    solid: np.ndarray
    stl: trimesh.Trimesh | None = None


@dataclass(frozen=True)
class _Checks:
    """The print's pieces, printability facts and minimum open channel width (`channel_constraint`, None
    without swelling)."""

    pieces: int
    facts: Printability
    constraint: dict | None


def _density_release(problem, config, rho: np.ndarray) -> np.ndarray:
    """The density's release on the design grid with the print physics, mm^3 per tau sample."""
    space, target = problem.space, problem.target
    dtau_mm = target.total_time_mm / (target.tau_mm.size - 1)
    # only the curves are kept: a Release holds its solve's work arrays (~300 MB at 128^3)
    return simulate(rho, space.dx_mm, mirror=space.mirror, total_time_mm=target.total_time_mm, dtau_mm=dtau_mm,
                    anisotropy=config.anisotropy, swelling_mm=config.swelling_mm).released_mm3


def _write_print(out_dir: Path, problem, config, rho: np.ndarray, warnings: list[str]) -> _Print:
    """Extract the print from a density and write ``design.stl`` (+ ``config.formats``): the designed solid
    shrunk by the print offset, the print that file grown by it again. With swelling, channels narrower than
    ``swelling_mm`` are filled first. Appends a warning when no solid or no file comes out."""
    space, offset = problem.space, config.print_offset_mm
    rho_full = space.unfold(rho)
    level = mass_preserving_level(rho_full)
    filled = 0
    if config.swelling_mm > 0:  # the minimum open channel width: narrower channels filled (correction stage)
        rho_full, filled = close_narrow_channels(rho_full, space.dx_mm, config.swelling_mm, level)
    if not np.any(rho_full >= level):  # a run stopped very early may still be grey everywhere
        warnings.append(f"no density reaches the extraction level {level:.3f} yet: no solid extracted "
                        "(design.stl not written)")
        return _Print(rho_full, level, filled, None, np.zeros(problem.full_shape, dtype=bool))
    mesh = density_mesh(rho_full, space.dx_mm, problem.origin_mm, level=level)  # what must come out
    try:
        stl = mesh if offset == 0 else offset_mesh(mesh, -offset, 0.5 * space.dx_mm)
    except DesignError as exc:  # every wall of the solid thinner than twice the offset
        stl = None
        warnings.append(f"design.stl not written: the solid shrunk by the print offset {offset:g} mm is empty "
                        f"or not closed ({exc})")
    if stl is not None:
        stl.export(out_dir / "design.stl")
        for fmt in config.formats:
            stl.export(out_dir / f"design.{fmt}")
        if offset != 0:  # the print: the file to print grown by the offset
            mesh = offset_mesh(stl, offset, 0.5 * space.dx_mm)
    else:
        mesh = None
    solid = (revoxelize(mesh, space.dx_mm, problem.origin_mm, problem.full_shape) if mesh is not None
             else np.zeros(problem.full_shape, dtype=bool))
    return _Print(rho_full, level, filled, mesh, solid, stl)


def _check_print(problem, config, status: DesignStatus, printed: _Print, release: PrintRelease,
                 warnings: list[str]) -> _Checks:
    """Count the print's pieces and assess its printability and minimum open channel width, appending a warning
    for each fault and for a run its evaluation limit ended far from the target."""
    dx_mm, solid = problem.space.dx_mm, printed.solid
    pieces = count_pieces(solid)
    if pieces > 1:
        warnings.append(f"the solid has {pieces} separate pieces")
    if status == DesignStatus.MAX_ITER and release.rel_rmse > NOT_CONVERGED_REL_RMSE:
        warnings.append(f"did not converge: the evaluation limit ({config.max_iter}) ended the run with the print "
                        f"{release.rel_rmse:.1%} off the target (rel. RMSE above {NOT_CONVERGED_REL_RMSE:.0%}); "
                        f"run the design again with a higher limit, e.g. --max-iter {2 * config.max_iter}")
    facts = assess(solid, dx_mm, warn_channel_mm=max(config.warn_channel_mm, config.swelling_mm))
    warnings += list(facts.warnings)
    constraint = (channel_constraint(solid, dx_mm, config.swelling_mm, printed.filled, facts.min_channel_mm)
                  if config.swelling_mm > 0 else None)
    if constraint is not None and not constraint["met"]:
        narrowest = "narrower than that" if facts.min_channel_mm is None else f"of {facts.min_channel_mm:.2f} mm"
        warnings.append(f"the minimum open channel width {config.swelling_mm:g} mm is not met: the print has a "
                        f"channel {narrowest}")
    return _Checks(pieces, facts, constraint)


def _write_data(out_dir: Path, problem, best_x: np.ndarray, rho: np.ndarray, printed: _Print,
                density_mm3: np.ndarray, release: PrintRelease, history: list[list[float]]) -> None:
    """Write ``density.npz``, ``curves.csv`` (`CURVE_COLUMNS`), ``history.csv`` and ``design.ini``."""
    space, target = problem.space, problem.target
    np.savez_compressed(out_dir / "density.npz", rho_hat=best_x, rho=rho, rho_full=printed.rho_full,
                        solid=printed.solid, dx_mm=space.dx_mm, origin_mm=problem.origin_mm,
                        mirror=np.array(space.mirror))
    curves = np.column_stack([target.tau_mm, target.released_mm3, release.released_mm3, density_mm3,
                              release.binary_mm3])
    _write_text(out_dir / "curves.csv", _csv(CURVE_COLUMNS, curves))
    _write_text(out_dir / "history.csv", _csv(HISTORY_COLUMNS, _history_rows(history)))
    # NFC designs may overhang; ICO and extruded ones print without supports (section 3.6)
    _write_text(out_dir / "design.ini", prusa_profile(out_dir.name, supports=space.name == "nfc"))


def _summary(problem, objective: DesignObjective, config, status: DesignStatus, history: list[list[float]],
             session_seconds: float, rho: np.ndarray, density_mm3: np.ndarray, printed: _Print,
             release: PrintRelease, checks: _Checks, warnings: list[str]) -> DesignSummary:
    """The record ``summary.json`` holds (`DesignSummary`)."""
    space, target, offset, facts = problem.space, problem.target, config.print_offset_mm, checks.facts
    achieved = (("print", release.released_mm3), ("density", density_mm3), ("design_grid_binary", release.binary_mm3))
    iterations = len(history)
    seconds = float(history[-1][-1]) if history else 0.0
    return {
        "format": SUMMARY_FORMAT,
        "status": status,
        "target": target.source,
        "space": space.name,
        "rel_rmse_print": release.rel_rmse if printed.mesh is not None and np.isfinite(release.rel_rmse) else None,
        "rel_rmse_print_error": release.rel_rmse_error if release.reference is not None else None,
        "rel_rmse_density": rel_rmse(density_mm3, target.released_mm3),
        "rel_rmse_design_grid_binary": rel_rmse(release.binary_mm3, target.released_mm3),
        "reference": _reference_record(problem, config, printed, release),
        "print_physics": {"anisotropy": config.anisotropy, "offset_mm": offset, "swelling_mm": config.swelling_mm},
        "print_files": {"design.stl": "the solid to print: the designed solid shrunk by the print offset "
                                      f"({offset:g} mm)",
                        "print": "design.stl grown by the print offset: the solid every print figure (fit, volume, "
                                 "mass, channels, pieces) is of"},
        "min_channel_constraint": checks.constraint,
        "w_channel": config.w_channel or 0.0,
        "channel_fill_voxels": printed.filled if config.swelling_mm > 0 else None,
        "rate_dev_mid80": {name: _rate_dev(target.tau_mm, curve, target.released_mm3, False)
                           for name, curve in achieved},
        "rate_dev_mid80_vs_target": {name: _rate_dev(target.tau_mm, curve, target.released_mm3, True)
                                     for name, curve in achieved},
        "iterations": iterations,
        "seconds": seconds,
        "seconds_per_iteration": seconds / iterations if iterations else None,
        "session_seconds": session_seconds,
        "pieces": checks.pieces,
        "extraction_level": printed.level,
        "volume_mm3": release.volume_mm3,
        "print_mass_g": print_mass_g(release.volume_mm3),
        "min_channel_mm": facts.min_channel_mm,
        "enclosed_voids": facts.enclosed_voids,
        "enclosed_void_mm3": facts.enclosed_void_mm3,
        "overhang_fraction": facts.overhang_fraction,
        "max_overhang_run_mm": facts.max_overhang_run_mm,
        "preset": config.preset,
        "ico": _ico_summary(objective, rho, _history_rows(history), seconds),
        "iou_with_source": (centred_iou(problem.source_solid, printed.solid)
                            if problem.source_solid is not None else None),
        "target_final_mm3": target.final_mm3,
        "total_time_mm": target.total_time_mm,
        "dx_mm": space.dx_mm,
        "full_shape": list(problem.full_shape),
        "reduced_shape": list(space.grid_shape),
        "feasible": problem.feasibility.feasible,
        "warnings": warnings,
        "software": software_versions(),
        "config": asdict(config),
    }


def _reference_record(problem, config, printed: _Print, release: PrintRelease) -> dict | None:
    """How the print's release was computed, with the stated errors: by the forward model on a finer grid (with
    swelling that shuts a channel) or by the reference evaluator; None without a print."""
    if config.swelling_mm > 0 and printed.mesh is not None and release.reference is None:
        cell_mm = problem.space.dx_mm / PRINT_PHYSICS_FACTOR
        return {"method": f"forward model with the print physics on voxels of {cell_mm:.4g} mm",
                "cell_mm": cell_mm, "seconds": None, "print_error_mm3": None,
                "target_error_mm3": problem.target_error_mm3}
    reference = release.reference
    if reference is None:
        return None
    return {"method": reference.method, "cell_mm": reference.cell_mm, "seconds": reference.seconds,
            "print_error_mm3": reference.error_mm3, "target_error_mm3": problem.target_error_mm3}


def _log_warnings(out_dir: Path, warnings: list[str], announce: bool) -> None:
    """Log a run's warnings: as warnings (``announce``), else at INFO level naming ``out_dir``."""
    for w in warnings:
        if announce:
            log.warning("%s", w)
        else:
            log.info("%s: %s", out_dir, w)


def _write_report(path: Path, problem, config, printed: _Print, density_mm3: np.ndarray, release: PrintRelease,
                  summary: DesignSummary) -> None:
    """Write ``report.png``: the release curves and the design, titled with the run's headline figures."""
    target = problem.target
    save_report(path, target.tau_mm, target.released_mm3, release.released_mm3, density_mm3, release.binary_mm3,
                printed.rho_full, printed.solid,
                f"{target.source} | {problem.space.name} | print rel. RMSE {print_fit_text(summary)} | design grid: "
                f"density {summary['rel_rmse_density']:.2%}, binary {summary['rel_rmse_design_grid_binary']:.2%} | "
                f"overhang {summary['overhang_fraction']:.1%} | {summary['iterations']} it."
                + (f" | preset {config.preset}" if config.preset else ""), dx_mm=problem.dx_mm)


def _history_rows(history: list[list[float]]) -> np.ndarray:
    """A run's history as an (N, len(`HISTORY_COLUMNS`)) array."""
    return np.array(history, dtype=float).reshape(-1, len(HISTORY_COLUMNS))


def _write_text(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def _csv(columns: tuple[str, ...], rows: np.ndarray) -> str:
    body = "\n".join(",".join(f"{v:.10g}" for v in row) for row in rows)
    return ",".join(columns) + "\n" + body + ("\n" if len(rows) else "")


SOFTWARE_PACKAGES = ("shape-from-release", "numpy", "scipy", "scikit-fmm", "nlopt", "numba")
"""Packages whose versions a summary records: the design's figures move with the numerical libraries'
build (docs/results.md#software-and-machine lists those its figures were made with)."""


def software_versions() -> dict[str, str | None]:
    """Python's and `SOFTWARE_PACKAGES`' versions (None for a package that is not installed)."""
    versions: dict[str, str | None] = {"python": platform.python_version()}
    for name in SOFTWARE_PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def _rate_dev(tau_mm: np.ndarray, curve_mm3: np.ndarray, target_mm3: np.ndarray,
              vs_target: bool) -> float | None:
    """`rate_deviation` of an achieved curve: over its own middle 80% against its own mean rate, or
    (``vs_target``) over the target's middle 80% against the target's mean rate there. None when the
    curve does not rise (a grey design without a solid) or rises from 10% to 90% within one tau sample
    (no middle 80% to measure), and for a curve not computed (NaN)."""
    if not curve_mm3[-1] > curve_mm3[0]:
        return None
    if not vs_target:
        try:
            return rate_deviation(tau_mm, curve_mm3)
        except DesignError:  # the only error left for a rising curve: a middle 80% within one tau sample
            return None
    return rate_deviation_vs_target(tau_mm, curve_mm3, target_mm3)


def _ico_summary(objective: DesignObjective, rho: np.ndarray, rows: np.ndarray, seconds: float) -> dict | None:
    """The ICO term's value at the output density and its share of the run time (None without J_fab)."""
    term = objective.space.fab_term
    if term is None or not objective.w_fab > 0:
        return None
    value, _ = term(rho)
    config = term.config
    fab_seconds = float(rows[:, HISTORY_COLUMNS.index("fab_seconds")].sum())
    return {"J_fab": value, "J_fab_start": term.reference, "w_fab": objective.w_fab, "layers": config.layers,
            "coarsen": config.coarsen, "law": config.law, "poisson": config.poisson,
            "pcg_iterations_mean": (term.iterations / max(term.evaluations, 1)).round(2).tolist(),
            "fab_seconds": fab_seconds,
            "fab_time_share": fab_seconds / seconds if seconds > 0 else None}
