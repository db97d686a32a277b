"""Everything a finished (or stopped) design run writes into its folder.

``design.stl`` (+ requested formats), ``density.npz``, ``curves.csv``
(`CURVE_COLUMNS`), ``history.csv``, ``report.png``,
``design.ini`` (PrusaSlicer profile) and ``summary.json``.

Every headline figure is the print's: ``design.stl`` released by the reference evaluator
(`design.forward.reference`, exact surface distances, independent of the design grid) against the
target's physical release (a source shape's by the same evaluator), and its volume and mass are the
mesh's own. The design grid's figures stay as diagnostics: the density's release and the binary solid's
(the printed mesh re-voxelised on the design grid, as the paper plots it, Fig. 6), both first-order fast
marching with a shape-dependent O(dx) error.

Print physics (`DesignConfig` ``anisotropy``, ``print_offset_mm``, ``swelling_mm``, from a simulation
calibration): the optimised density is the solid that must come out of the printer. A print comes out
``print_offset_mm`` larger than its mesh, so ``design.stl`` is that solid shrunk by the offset (the file to
print), and the print is ``design.stl`` grown by it again; every print figure (fit, volume, mass, channels,
pieces) is the grown solid's. With anisotropy the reference evaluator releases the print at it (exact
distances with z scaled by 1/a); with swelling the print's release is the forward model's with the print
physics on voxels half the design grid's (the reference evaluator does not shut channels).
Channels narrower than ``swelling_mm`` are filled before extraction (`close_narrow_channels`), the minimum
open channel width the print must keep, and ``summary.json`` says whether the print meets it and how many voxels
the fill added (``channel_fill_voxels``: 0 when the objective's channel-width term, weight ``w_channel``, kept the
optimised design's channels open by itself).
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

from design.errors import DesignError
from design.fabrication.extract import centred_iou, count_pieces, density_mesh, mass_preserving_level, revoxelize
from design.fabrication.printability import assess, print_mass_g, prusa_profile
from design.files.pipeline import offset_mesh
from design.files.records import SUMMARY, SUMMARY_FORMAT, DesignSummary
from design.files.report import save_report
from design.forward.reference import design_lattice, reference_release
from design.forward.simulator import simulate
from design.forward.swelling import shut_channels
from design.inverse.objective import DesignObjective, rel_rmse
from design.inverse.optimize import HISTORY_COLUMNS
from design.inverse.rate import rate_deviation, rate_deviation_vs_target
from design.inverse.status import DesignStatus

log = logging.getLogger(__name__)

CURVE_COLUMNS = ("tau_mm", "target_mm3", "print_mm3", "density_mm3", "binary_mm3")
"""``target_mm3`` the physical target, ``print_mm3`` the printed solid's release by the reference evaluator;
``density_mm3`` and ``binary_mm3`` the density's and the re-voxelised solid's on the design grid."""


@dataclass(frozen=True)
class DesignOutputs:
    """Paths and headline numbers of a run's outputs."""

    summary_path: Path
    summary: DesignSummary


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


def percent_text(value: float | None, digits: int = 2) -> str:
    """A summary's fraction as a percentage with ``digits`` decimals, "-" for a figure not computed (None)."""
    return "-" if value is None else f"{value:.{digits}%}"


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


def enclosed_voids_text(summary: dict) -> str:
    """The enclosed-void fact of a run's summary as a phrase ("no enclosed voids", "2 enclosed voids, 12.5 mm^3")."""
    count = summary.get("enclosed_voids")
    if count is None:  # a summary written before the fact was recorded
        return "enclosed voids not assessed"
    if count == 0:
        return "no enclosed voids"
    return f"{count} enclosed void{'s' if count > 1 else ''}, {summary['enclosed_void_mm3']:.4g} mm^3"


RESULT_FILES = ("design.stl", "density.npz", "curves.csv", "curves_physical.csv", "report.png", "history.csv",
                "summary.json", "design.ini")
"""The files a finished design run's result lines name, where they exist (`summary_lines`)."""


def print_fit_text(summary: DesignSummary) -> str:
    """The headline fit of a summary as text: "0.412% (+/- 0.050%)", "-" when not computed."""
    fit = summary.get("rel_rmse_print")
    if fit is None:
        return "-"
    error = summary.get("rel_rmse_print_error")
    return f"{fit:.3%}" + ("" if error is None else f" (+/- {error:.3%})")


def summary_lines(summary: DesignSummary, out_dir: Path) -> list[str]:
    """The result of a design run in a few lines of text, from its summary: what `sfr design` prints and the
    design launcher shows.

    Parameters
    ----------
    summary : DesignSummary
        The run's summary (with the physical prediction, ``simcal`` and ``rel_rmse_physical``, when it has one).
    out_dir : Path
        The run folder; the last line names the result files it holds.
    """
    s = summary
    lines = [f"{s['status']} after {s['iterations']} evaluations ({s['seconds']:.1f} s, "
             f"{s['seconds_per_iteration'] or 0:.3f} s each)",
             f"fit of the print: rel. RMSE {print_fit_text(s)} (design.stl by exact surface distances, "
             "against the target's physical release)",
             f"design grid (diagnostics): rel. RMSE density {s['rel_rmse_density']:.3%}, binary solid "
             f"{percent_text(s['rel_rmse_design_grid_binary'], 3)}"]
    dev = {k: percent_text(v) for k, v in s["rate_dev_mid80"].items()}
    lines.append(f"rate deviation, middle 80% of the release: print {dev['print']}; design grid: density "
                 f"{dev['density']}, binary solid {dev['design_grid_binary']}")
    lines.append(f"pieces {s['pieces']}, print mass {s['print_mass_g']:.3f} g, narrowest channel "
                 f"{'none' if s['min_channel_mm'] is None else format(s['min_channel_mm'], '.2f') + ' mm'}, "
                 f"{enclosed_voids_text(s)}")
    lines.append(f"overhangs along +z: {s['overhang_fraction']:.1%} of the solid, longest run "
                 f"{s['max_overhang_run_mm']:.2f} mm" + (f"; preset {s['preset']}" if s.get("preset") else ""))
    if s.get("ico"):
        ico = s["ico"]
        share = percent_text(ico["fab_time_share"], 0)
        lines.append(f"ICO J_fab {ico['J_fab']:.4g} of the start design's, {ico['layers']} layers, {share} of the time")
    physics = s.get("print_physics")
    if physics and (physics["anisotropy"], physics["offset_mm"], physics["swelling_mm"]) != (1.0, 0.0, 0.0):
        constraint = s.get("min_channel_constraint")
        lines.append(f"designed for the print: anisotropy {physics['anisotropy']:.3g}, offset {physics['offset_mm']:+.3g} mm "
                     f"(design.stl is the solid to print; the print, grown by the offset, is what the figures are of)"
                     + ("" if constraint is None else f", minimum open channel {constraint['width_mm']:.2f} mm "
                        f"{'met' if constraint['met'] else 'NOT met'}"))
    if "simcal" in s:
        lines.append(f"physical prediction ({s['simcal']['model']} model, {s['simcal']['seconds_per_mm']:.1f} s/mm): "
                     f"rel. RMSE {s['rel_rmse_physical']:.3%} of the target's final grams (curves_physical.csv)")
        band = s.get("band")
        if band:
            lines.append(f"its {band['level']:.0%} band (calibration uncertainty and leave-one-out residuals, "
                         f"{', '.join(band['columns'])}): mean half-width {band['mean_half_width_g']:.3g} g, "
                         f"{band['target_inside_fraction']:.0%} of the target inside")
    lines += [f"warning: {w}" for w in s["warnings"]]
    lines.append(f"results in {out_dir}: {', '.join(n for n in RESULT_FILES if (out_dir / n).exists())}")
    return lines


def solid_release(solid: np.ndarray, dx_mm: float, mirror: tuple[bool, ...], total_time_mm: float,
                  dtau_mm: float, anisotropy: float = 1.0, swelling_mm: float = 0.0) -> np.ndarray:
    """Released volume of a full (unfolded) binary solid, simulated on its reduced grid (with the print physics
    ``anisotropy`` and ``swelling_mm`` of `design.forward.simulator.simulate`), mm^3 per tau sample."""
    half = tuple(slice(n // 2 if m else 0, None) for n, m in zip(solid.shape, mirror))
    return simulate(solid[half].astype(float), dx_mm, mirror=tuple(mirror), total_time_mm=total_time_mm,
                    dtau_mm=dtau_mm, anisotropy=anisotropy, swelling_mm=swelling_mm).released_mm3


def fine_release(mesh, dx_mm: float, origin_mm: np.ndarray, full_shape: tuple[int, int, int],
                 mirror: tuple[bool, ...], total_time_mm: float, dtau_mm: float, factor: int,
                 anisotropy: float = 1.0, swelling_mm: float = 0.0) -> np.ndarray:
    """Released volume of a printed mesh re-voxelised on voxels `factor` times smaller than the design
    grid's (same domain: `dx_mm`, `origin_mm`, `full_shape`, `mirror`), mm^3 per tau sample; zeros
    for ``mesh`` None (no solid extracted). ``anisotropy`` and ``swelling_mm``: the print physics."""
    shape = tuple(factor * n for n in full_shape)
    fine_dx = dx_mm / factor
    solid = (revoxelize(mesh, fine_dx, origin_mm, shape) if mesh is not None else np.zeros(shape, dtype=bool))
    return solid_release(solid, fine_dx, mirror, total_time_mm, dtau_mm, anisotropy, swelling_mm)


PRINT_PHYSICS_FACTOR = 2
"""With swelling, the print's release is the forward model's on voxels this many times smaller
than the design grid's."""


def close_narrow_channels(rho_full: np.ndarray, dx_mm: float, width_mm: float, level: float
                          ) -> tuple[np.ndarray, int]:
    """The minimum open channel width as a correction stage: every channel of the solid ``rho >= level`` narrower
    than ``width_mm`` filled with material (`design.forward.swelling.shut_channels` on the full grid).

    Returns
    -------
    rho_full : ndarray of float
        The density with the filled voxels at 1.
    filled : int
        Voxels filled.
    """
    plug = shut_channels((np.asarray(rho_full) >= level).astype(float), dx_mm, width_mm)
    return np.where(plug, 1.0, rho_full), int(np.count_nonzero(plug))


def channel_constraint(solid: np.ndarray, dx_mm: float, width_mm: float, filled: int,
                       min_channel_mm: float | None) -> dict:
    """Whether the print keeps every open channel at least ``width_mm`` wide.

    ``met`` when its narrowest open channel (`design.fabrication.printability.narrowest_channel_mm`, measured to
    within dx/2) is none or at least ``width_mm - dx/2``, and no void voxel of it lies in a channel narrower than
    ``width_mm`` by the forward model's own test (`design.forward.swelling.shut_channels`; ``narrow_left_mm3``).
    ``filled_mm3`` is what the correction stage filled.
    """
    left = int(np.count_nonzero(shut_channels(solid.astype(float), dx_mm, width_mm)))
    measured = min_channel_mm is None or min_channel_mm >= width_mm - 0.5 * dx_mm
    return {"width_mm": width_mm, "met": measured and left == 0, "min_channel_mm": min_channel_mm,
            "filled_mm3": filled * dx_mm ** 3, "narrow_left_mm3": left * dx_mm ** 3}


NOT_CONVERGED_REL_RMSE = 0.05
"""A run ended by its evaluation limit whose print misses the target by more than this rel. RMSE gets the
warning that it did not converge, with the limit to raise."""


def write_outputs(out_dir: Path, problem, objective: DesignObjective, best_x: np.ndarray,
                  history: list[list[float]], config, *, status: DesignStatus,
                  session_seconds: float, announce: bool = True) -> DesignOutputs:
    """Extract, re-simulate, assess and write every output of a design run.

    Parameters
    ----------
    out_dir : Path
    problem : design.inverse.problem.Problem
    objective : DesignObjective
    best_x : ndarray of float, variable shape
        The best design variables found.
    history : list of rows with `HISTORY_COLUMNS`
    config : design.inverse.problem.DesignConfig
    status : DesignStatus
    session_seconds : float
        Wall time of this session (resumes add up through the history's seconds column).
    announce : bool
        Log the run's warnings as warnings (False: at INFO level, naming ``out_dir``; a coarse start's).
    """
    space, target = problem.space, problem.target
    physics = {"anisotropy": config.anisotropy, "swelling_mm": config.swelling_mm}
    offset = config.print_offset_mm
    rho = objective.density(best_x)
    dtau_mm = target.total_time_mm / (target.tau_mm.size - 1)
    # only the curves are kept: a Release holds its solve's work arrays (~300 MB at 128^3)
    density_curve = simulate(rho, space.dx_mm, mirror=space.mirror, total_time_mm=target.total_time_mm,
                             dtau_mm=dtau_mm, **physics).released_mm3
    rho_full = space.unfold(rho)
    warnings: list[str] = list(problem.warnings)
    level = mass_preserving_level(rho_full)
    filled = 0
    if config.swelling_mm > 0:  # the minimum open channel width: narrower channels filled (correction stage)
        rho_full, filled = close_narrow_channels(rho_full, space.dx_mm, config.swelling_mm, level)
    if np.any(rho_full >= level):
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
    else:  # a run stopped very early may still be grey everywhere
        mesh = None
        solid = np.zeros(problem.full_shape, dtype=bool)
        warnings.append(f"no density reaches the extraction level {level:.3f} yet: no solid extracted "
                        "(design.stl not written)")
    binary_curve = solid_release(solid, space.dx_mm, space.mirror, target.total_time_mm, dtau_mm, **physics)
    # the print: design.stl (grown by the offset) released by exact surface distances at the print's anisotropy,
    # its volume the mesh's own; with swelling, by the forward model with the print physics on a finer grid
    modelled = config.swelling_mm > 0
    printed = (reference_release(mesh, target.tau_mm, cells=design_lattice(config.resolution),
                                 anisotropy=config.anisotropy)
               if mesh is not None and not modelled else None)
    if modelled:
        print_curve = fine_release(mesh, space.dx_mm, problem.origin_mm, problem.full_shape, space.mirror,
                                   target.total_time_mm, dtau_mm, PRINT_PHYSICS_FACTOR, **physics)
        volume = float(mesh.volume) if mesh is not None else 0.0
    else:
        print_curve = printed.released_mm3 if printed is not None else np.zeros_like(binary_curve)
        volume = printed.volume_mm3 if printed is not None else 0.0
    fit_print = rel_rmse(print_curve, target.released_mm3)
    # |rmse(a) - rmse(b)| <= max |a - b|: the two curves' stated errors bound the fit's
    fit_error = ((printed.error_mm3 if printed is not None else 0.0) + (problem.target_error_mm3 or 0.0)) \
        / target.final_mm3
    pieces = count_pieces(solid)
    if pieces > 1:
        warnings.append(f"the solid has {pieces} separate pieces")
    if status == DesignStatus.MAX_ITER and fit_print > NOT_CONVERGED_REL_RMSE:
        warnings.append(f"did not converge: the evaluation limit ({config.max_iter}) ended the run with the print "
                        f"{fit_print:.1%} off the target (rel. RMSE above {NOT_CONVERGED_REL_RMSE:.0%}); run the design again "
                        f"with a higher limit, e.g. --max-iter {2 * config.max_iter}")
    facts = assess(solid, space.dx_mm, warn_channel_mm=max(config.warn_channel_mm, config.swelling_mm))
    warnings += list(facts.warnings)
    if config.swelling_mm > 0 and not channel_constraint(solid, space.dx_mm, config.swelling_mm, filled,
                                                         facts.min_channel_mm)["met"]:
        narrowest = "narrower than that" if facts.min_channel_mm is None else f"of {facts.min_channel_mm:.2f} mm"
        warnings.append(f"the minimum open channel width {config.swelling_mm:g} mm is not met: the print has a "
                        f"channel {narrowest}")
    np.savez_compressed(out_dir / "density.npz", rho_hat=best_x, rho=rho, rho_full=rho_full, solid=solid,
                        dx_mm=space.dx_mm, origin_mm=problem.origin_mm, mirror=np.array(space.mirror))
    curves = np.column_stack([target.tau_mm, target.released_mm3, print_curve, density_curve, binary_curve])
    _write_text(out_dir / "curves.csv", _csv(CURVE_COLUMNS, curves))
    rows = np.array(history, dtype=float).reshape(-1, len(HISTORY_COLUMNS))
    _write_text(out_dir / "history.csv", _csv(HISTORY_COLUMNS, rows))
    # NFC designs may overhang; ICO and extruded ones print without supports (section 3.6)
    _write_text(out_dir / "design.ini", prusa_profile(out_dir.name, supports=space.name == "nfc"))
    achieved = (("print", print_curve), ("density", density_curve), ("design_grid_binary", binary_curve))
    iterations = len(history)
    seconds = float(history[-1][-1]) if history else 0.0
    summary: DesignSummary = {
        "format": SUMMARY_FORMAT,
        "status": status,
        "target": target.source,
        "space": space.name,
        "rel_rmse_print": fit_print if mesh is not None else None,
        "rel_rmse_print_error": fit_error if printed is not None else None,
        "rel_rmse_density": rel_rmse(density_curve, target.released_mm3),
        "rel_rmse_design_grid_binary": rel_rmse(binary_curve, target.released_mm3),
        "reference": ({"method": f"forward model with the print physics on voxels of {space.dx_mm / PRINT_PHYSICS_FACTOR:.4g} mm",
                       "cell_mm": space.dx_mm / PRINT_PHYSICS_FACTOR, "seconds": None, "print_error_mm3": None,
                       "target_error_mm3": problem.target_error_mm3} if modelled and mesh is not None else
                      None if printed is None else {
            "method": printed.method, "cell_mm": printed.cell_mm, "seconds": printed.seconds,
            "print_error_mm3": printed.error_mm3, "target_error_mm3": problem.target_error_mm3}),
        "print_physics": {"anisotropy": config.anisotropy, "offset_mm": offset, "swelling_mm": config.swelling_mm},
        "print_files": {"design.stl": "the solid to print: the designed solid shrunk by the print offset "
                                      f"({offset:g} mm)",
                        "print": "design.stl grown by the print offset: the solid every print figure (fit, volume, "
                                 "mass, channels, pieces) is of"},
        "min_channel_constraint": (channel_constraint(solid, space.dx_mm, config.swelling_mm, filled,
                                                      facts.min_channel_mm) if config.swelling_mm > 0 else None),
        "w_channel": config.w_channel or 0.0,
        "channel_fill_voxels": filled if config.swelling_mm > 0 else None,
        "rate_dev_mid80": {name: _rate_dev(target.tau_mm, curve, target.released_mm3, False)
                           for name, curve in achieved},
        "rate_dev_mid80_vs_target": {name: _rate_dev(target.tau_mm, curve, target.released_mm3, True)
                                     for name, curve in achieved},
        "iterations": iterations,
        "seconds": seconds,
        "seconds_per_iteration": seconds / iterations if iterations else None,
        "session_seconds": session_seconds,
        "pieces": pieces,
        "extraction_level": level,
        "volume_mm3": volume,
        "print_mass_g": print_mass_g(volume),
        "min_channel_mm": facts.min_channel_mm,
        "enclosed_voids": facts.enclosed_voids,
        "enclosed_void_mm3": facts.enclosed_void_mm3,
        "overhang_fraction": facts.overhang_fraction,
        "max_overhang_run_mm": facts.max_overhang_run_mm,
        "preset": config.preset,
        "ico": _ico_summary(objective, rho, rows, seconds),
        "iou_with_source": (centred_iou(problem.source_solid, solid)
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
    for w in warnings:
        if announce:
            log.warning("%s", w)
        else:
            log.info("%s: %s", out_dir, w)
    save_report(out_dir / "report.png", target.tau_mm, target.released_mm3, print_curve, density_curve,
                binary_curve, rho_full, solid,
                f"{target.source} | {space.name} | print rel. RMSE {print_fit_text(summary)} | design grid: "
                f"density {summary['rel_rmse_density']:.2%}, binary {summary['rel_rmse_design_grid_binary']:.2%} | "
                f"overhang {facts.overhang_fraction:.1%} | {iterations} it."
                + (f" | preset {config.preset}" if config.preset else ""))
    path = out_dir / SUMMARY
    _write_text(path, json.dumps(summary, indent=2))
    return DesignOutputs(path, summary)
