"""Setting up an inverse-design problem: the domain, the design space, the target on its tau grid and the starts.

`prepare` turns a `design.inverse.config.DesignConfig` (its target spec: `design.inverse.target_spec`) into a
`Problem`. A source shape's target is its physical release, by exact surface distances
(`design.forward.reference`), not its release on the design grid: the design grid's first-order error
depends on the shape, and a print is judged against what the source itself releases.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import trimesh

from design._validate import MESH_SUFFIXES
from design.errors import DesignError
from design.fabrication.extract import count_pieces
from design.fabrication.ico import IcoConfig
from design.forward.reference import ReferenceRelease, design_lattice
from design.forward.simulator import total_time
from design.geometry.shapes import SAMPLE_SHAPES, sample_shape
from design.geometry.voxelize import voxelize
from design.inverse.config import DesignConfig
from design.inverse.filters import MAX_RADIUS_VOX
from design.inverse.rate import RATE_SPAN_MIN_VOX, middle_span_mm
from design.inverse.release_cache import cached_reference_release
from design.inverse.settings import DEFAULT_RADIUS_MM
from design.inverse.spaces import BUILD_AXIS, DesignSpace, SpaceRequest, build_space
from design.inverse.starts import start_regions
from design.inverse.target_spec import is_shape_target, parse_analytic
from design.inverse.targets import (
    Feasibility,
    Target,
    check_feasibility,
    constant_acceleration,
    curve_end_mm,
    target_from_curve,
    tau_grid,
)

log = logging.getLogger(__name__)

def source_release(mesh: trimesh.Trimesh, tau_mm: np.ndarray, cells: int) -> ReferenceRelease:
    """The reference evaluator's release of a source mesh on a tau grid (`reference_release` at ``cells``), kept for
    the process's later problems of the same mesh, tau grid and lattice (`design.inverse.release_cache`): a
    multi-start's coarse starts prepare the same target, each at a reference release's cost."""
    return cached_reference_release(mesh, tau_mm, cells=int(cells))

DEFAULT_DOMAIN_MM = 20.0
"""Edge of the cubic domain used when the target has no source mesh and no --domain-mm, mm."""
CSV_HORIZON_MARGIN = 1.1
"""A CSV target's default cube has a half-edge (about its horizon T) this much above the curve's end."""



@dataclass(frozen=True)
class Problem:
    """A prepared design problem.

    Attributes
    ----------
    space : DesignSpace
    target : Target
    feasibility : Feasibility
    dx_mm : float
    origin_mm : (3,) ndarray of float
        Corner of the full design grid, mm (voxel i spans origin + [i, i+1) dx).
    full_shape : tuple of 3 int
        Voxels of the full (unfolded) simulated object.
    source_solid : ndarray of bool or None
        The source mesh voxelised on the full design grid (for the recovery check).
    radius_vox : float
        Smoothing radius r on this grid, voxels (`DesignConfig.radius_vox` or its ``radius_mm``).
    start_regions : tuple of (ndarray of bool or None)
        Where the start designs hold material (`start_regions`), the default first; None = the whole domain.
    warnings : tuple of str
        What is known about the source and the target before the run (`source_warnings`,
        `rate_resolution_warnings`); logged when the problem is prepared and kept in the run's summary.
    source_mesh : trimesh.Trimesh or None
        The source mesh of a mesh target, mm.
    target_error_mm3 : float or None
        The stated error of a mesh target's release by the reference evaluator
        (`design.forward.reference.ReferenceRelease.error_mm3`), mm^3; None for other targets.
    target_release_s : float or None
        Wall seconds the reference evaluator took for a mesh target's release (its cost, which a print check and
        the outputs repeat on the print: `design.inverse.progress.stage_costs`); None for other targets.
    """

    space: DesignSpace
    target: Target
    feasibility: Feasibility
    dx_mm: float
    origin_mm: np.ndarray
    full_shape: tuple[int, int, int]
    source_solid: np.ndarray | None
    radius_vox: float
    start_regions: tuple[np.ndarray | None, ...] = (None,)
    warnings: tuple[str, ...] = ()
    source_mesh: trimesh.Trimesh | None = None
    target_error_mm3: float | None = None
    target_release_s: float | None = None

    @property
    def start_region(self) -> np.ndarray | None:
        """Where a single run's start design holds material: the first of `start_regions`."""
        return self.start_regions[0]


def source_warnings(source_solid: np.ndarray | None, allow_pieces: bool) -> tuple[str, ...]:
    """Warnings about a voxelised source: several separate pieces where the design must be one."""
    if source_solid is None or allow_pieces:
        return ()
    pieces = count_pieces(source_solid)
    if pieces < 2:
        return ()
    return (f"the source is {pieces} separate pieces and the design is held to one piece, so it cannot take "
            "the source's own shape; allow pieces (--allow-pieces) to let it",)


def rate_resolution_warnings(target: Target, dx_mm: float, w_rate: float, resolution: int) -> tuple[str, ...]:
    """Warnings about a rate-fitted target whose middle 80% spans too few voxels of tau to be measured.

    Below `design.inverse.rate.RATE_SPAN_MIN_VOX` the grid's own error in the rate deviation reaches several
    points; the warning names the resolution at which the span reaches it.
    """
    if not w_rate > 0 or not target.final_mm3 > 0:
        return ()
    lo, hi = middle_span_mm(target.tau_mm, target.released_mm3)
    span_vox = (hi - lo) / dx_mm
    if span_vox >= RATE_SPAN_MIN_VOX:
        return ()
    needed = _even_ceil(resolution * RATE_SPAN_MIN_VOX / span_vox)
    return (f"the target's middle 80% (10% to 90% released) spans {span_vox:.1f} voxels of tau at resolution "
            f"{resolution}: too few to measure a release rate to better than a few points, so the design's rate "
            f"deviation is that uncertain; at about resolution {needed} it spans {RATE_SPAN_MIN_VOX:g}",)


def _check_rate_span(target: Target, spec: str) -> None:
    """Refuse, before any optimisation, a target whose middle 80% (10% to 90% released) lies within one sample of
    its tau grid: the rate deviation every design reports (`design.inverse.rate.rate_deviation`) cannot be
    measured on it, and a release that fast has no shape to design."""
    if not target.final_mm3 > 0:
        return
    lo, hi = middle_span_mm(target.tau_mm, target.released_mm3)
    if not np.any((target.tau_mm > lo) & (target.tau_mm < hi)):
        step = float(target.tau_mm[1] - target.tau_mm[0])
        raise DesignError(f"target {spec}: the middle 80% of its release ({lo:.6g} .. {hi:.6g} mm) lies within one "
                          f"tau sample ({step:.4g} mm) of the design grid: a release that fast has no rate to design "
                          "for; check the target's time column (a measured curve: seconds since the drop)")


def _source_mesh(spec: str, mesh: trimesh.Trimesh | None) -> trimesh.Trimesh | None:
    """The source shape of a sample-shape or mesh-file target (the latter as loaded), else None."""
    if spec in SAMPLE_SHAPES:
        return sample_shape(spec)
    if is_shape_target(spec):
        if mesh is None:
            raise DesignError(f"target {spec!r} is a mesh file: load it with design.files.targets_io.load_problem")
        return mesh
    return None


def _even_ceil(x: float) -> int:
    return max(2, 2 * int(np.ceil(x / 2.0 - 1e-9)))


def _curve_target(config: DesignConfig, analytic: tuple[float, float, float] | None,
                  curve: tuple[np.ndarray, np.ndarray] | None, t_mm: float, box_volume_mm3: float,
                  box_time_mm: float) -> Target:
    """The CSV or analytic target on the tau grid up to ``t_mm``; analytic fractions of the domain box."""
    if analytic is None:
        return target_from_curve(*curve, t_mm, config.samples, source=config.target)
    q, final, duration = analytic
    if not 0 < final <= 1 or not 0 < duration <= 1:
        raise DesignError(f"analytic final and duration are fractions in (0, 1], got {final}, {duration}")
    if duration * box_time_mm > t_mm:
        raise DesignError(f"the release lasts {duration * box_time_mm:.4g} mm but the design domain dissolves by "
                          f"T = {t_mm:.4g} mm; raise the extrusion height to at least {2 * duration * box_time_mm:.4g} mm")
    return constant_acceleration(t_mm, final * box_volume_mm3, duration * box_time_mm, q, config.samples)


def extrusion_height_mm(target: Target, dx_mm: float) -> float:
    """Default extrusion height for a target without a source shape, mm.

    As tall as a cube of the target's volume (a compact dose form), but at least twice the release's
    duration plus a voxel on each face: the top and bottom faces dissolve inwards at unit speed, so a
    shorter extrusion would be gone before the target's release ends.
    """
    end = curve_end_mm(target.tau_mm, target.released_mm3)
    return max(target.final_mm3 ** (1.0 / 3.0), 2.0 * end + 2.0 * dx_mm)


def _radius_vox(config: DesignConfig, dx_mm: float) -> float:
    """The smoothing radius in voxels of edge ``dx_mm``: as given, or from mm (at least 1 voxel)."""
    if config.radius_vox is not None:
        return float(config.radius_vox)
    radius_mm = DEFAULT_RADIUS_MM if config.radius_mm is None else config.radius_mm
    radius = max(1.0, radius_mm / dx_mm)
    if radius > MAX_RADIUS_VOX:
        raise DesignError(f"smoothing radius {radius_mm} mm is {radius:.1f} voxels of {dx_mm:.4g} mm; the filter "
                          f"takes at most {MAX_RADIUS_VOX:g} (lower the resolution or the radius)")
    return radius


def prepare(config: DesignConfig, *, mesh: trimesh.Trimesh | None = None,
            curve: tuple[np.ndarray, np.ndarray] | None = None, announce: bool = True) -> Problem:
    """Build the design space, the target on its tau grid, and the feasibility report; its warnings are logged as
    warnings (``announce``: once per design run, when it is prepared) or, for a multi-start's coarse start, at DEBUG.

    Parameters
    ----------
    config : DesignConfig
    mesh : trimesh.Trimesh, optional
        The source mesh of a mesh-file target (`target_file` "mesh"), mm, as loaded.
    curve : (tau_mm, released_mm3) of (N,) ndarrays of float, optional
        The columns of a CSV target (`target_file` "csv"), as written.
        `design.files.targets_io.load_problem` reads both from the target's file and calls this.

    Raises
    ------
    DesignError
        On a target spec that names nothing known, a file target without its contents, or a problem
        the settings cannot build.
    """
    mesh = _source_mesh(config.target, mesh)
    analytic = None if mesh is not None else parse_analytic(config.target)
    if mesh is None and analytic is None and not config.target.lower().endswith(".csv"):
        raise DesignError(f"target {config.target!r} is neither a sample shape ({', '.join(SAMPLE_SHAPES)}), "
                          f"a mesh file ({', '.join(MESH_SUFFIXES)}), a .csv curve, nor zero-order/accel:q=..")
    if mesh is None and analytic is None and curve is None:
        raise DesignError(f"target {config.target!r} is a CSV file: read it with design.files.targets_io.load_problem")
    lo = hi = None
    if mesh is not None:
        lo, hi = np.asarray(mesh.bounds[0], float), np.asarray(mesh.bounds[1], float)
    if config.domain_mm is not None:
        size = np.asarray(config.domain_mm, float)
    elif mesh is not None:
        size = (hi - lo) + 2.0 * config.margin * float(np.max(hi - lo))
        if config.space == "ico":  # the part stands on the build plate: no margin below it (section 3.6)
            size[BUILD_AXIS] -= config.margin * float(np.max(hi - lo))
        if config.space == "nfc":
            size = np.full(3, size.max())
    elif analytic is None:  # a CSV curve: a cube whose horizon T holds the whole release
        tau, c = curve
        size = np.full(3, max(DEFAULT_DOMAIN_MM, CSV_HORIZON_MARGIN * 2.0 * curve_end_mm(tau, c)))
    else:
        size = np.full(3, DEFAULT_DOMAIN_MM)
    dx = float(size.max()) / config.resolution
    full = [_even_ceil(s / dx - 1e-9) for s in size]
    # analytic fractions refer to the whole domain box, whatever the extrusion height
    box_volume = float(np.prod(full)) * dx ** 3
    box_time = total_time(tuple(n // 2 for n in full), dx, (True, True, True), config.anisotropy)
    height_vox = None
    if config.space == "extruded":
        height = config.height_mm or (config.height_fraction * float(size.max()) if config.height_fraction else None)
        height = height or (float(hi[BUILD_AXIS] - lo[BUILD_AXIS]) if mesh is not None else extrusion_height_mm(
            _curve_target(config, analytic, curve, box_time, box_volume, box_time), dx))
        if height is not None:
            height_vox = max(1, int(round(height / dx)))
            full[BUILD_AXIS] = max(full[BUILD_AXIS], height_vox)
    ico = IcoConfig(config.layers, config.ico_coarsen, config.stiffness_law)
    space: DesignSpace = build_space(config.space, SpaceRequest(tuple(full), dx, height_vox, ico))
    sim_full = list(space.grid_shape)
    for ax, mir in enumerate(space.mirror):
        sim_full[ax] *= 2 if mir else 1
    sim_full = tuple(sim_full)
    centre = 0.5 * (lo + hi) if mesh is not None else np.zeros(3)
    origin = centre - 0.5 * dx * np.asarray(sim_full, float)
    if config.space == "ico" and mesh is not None:
        origin[BUILD_AXIS] = lo[BUILD_AXIS]  # the source's base on the plate, z = 0 of the grid
    t_total = total_time(space.grid_shape, dx, space.mirror, config.anisotropy)
    domain_volume = float(np.prod(sim_full)) * dx ** 3
    source_solid = None
    target_error = target_seconds = None
    if mesh is not None:
        # the source's physical release (exact surface distances), not its release on the design grid
        grid_tau = tau_grid(t_total, config.samples)
        reference = source_release(mesh, grid_tau, design_lattice(config.resolution))
        target = Target(grid_tau, reference.released_mm3, f"mesh:{config.target}")
        target_error, target_seconds = reference.error_mm3, reference.seconds
        source_solid = voxelize(mesh, dx, origin_mm=origin, shape=sim_full) > 0.5
    else:
        target = _curve_target(config, analytic, curve, t_total, box_volume, box_time)
    _check_rate_span(target, config.target)
    ext = np.asarray(sim_full, float) * dx
    area = 2.0 * float(ext[0] * ext[1] + ext[1] * ext[2] + ext[0] * ext[2])
    feasibility = check_feasibility(target, domain_volume, dx_mm=dx, domain_area_mm2=area)
    log.info("design grid %s (reduced %s), dx = %.4g mm, T = %.4g mm; %s", sim_full, space.grid_shape, dx,
             t_total, feasibility.text())
    half_mm = 0.5 * (hi - lo) if mesh is not None else None
    radius_vox = _radius_vox(config, dx)
    warnings = (source_warnings(source_solid, config.allow_pieces)
                + rate_resolution_warnings(target, dx, config.w_rate, config.resolution))
    for warning in warnings:
        (log.warning if announce else log.debug)("%s", warning)
    return Problem(space, target, feasibility, dx, origin, sim_full, source_solid, radius_vox,
                   start_regions(space, target, half_mm, radius_vox * dx), warnings, mesh, target_error, target_seconds)
