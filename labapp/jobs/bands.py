"""Error bands on physical predictions: what ``calibrate-sim`` stores to make them, and the bands themselves.

The maths is :mod:`analysis.bands` (the leave-one-out residuals by released fraction, the parameter spread
as a floor, the mass scale's spread added, Student's t quantile). This module

- reads the ``band`` block of ``simcal.json`` (:func:`analysis.bands.band_block`): the residual model of the honest
  leave-one-out (print physics refitted without each run when it was fitted), the time and mass scales'
  relative standard errors (jackknife over the leave-one-out refits), the print physics' standard errors,
  and the leave-one-out coverage: for each held-out run, the band from the other runs, and the fraction of
  its measured points inside;
- makes the band of any prediction through a calibration (:func:`prediction_band`): ``sfr simulate --simcal``,
  ``sfr design --simcal``'s ``curves_physical.csv``, the demo's picture and the GUI's overlays. A print
  physics parameter's spread needs the shape simulated with that parameter one standard error up and down:
  the caller gives ``simulate_at(physics) -> (tau_mm, released_mm3)`` (:func:`source_simulator`).
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from analysis.bands import BAND_LEVEL, ResidualModel, SimulateAt, spread_g
from analysis.bands import band as _band
from analysis.physics_grid import PHYSICS_IDENTITY, PHYSICS_PARAMETERS
from labapp.records.simcal import SimCalError, SimCalFile

log = logging.getLogger(__name__)



def quantile_columns(level: float = BAND_LEVEL) -> tuple[str, str]:
    """Suffixes of a band's columns, named by their percentiles: ``q05``, ``q95`` for a 90% band."""
    tail = 50.0 * (1.0 - level)
    return f"q{tail:02.0f}", f"q{100.0 - tail:02.0f}"


def prediction_band(simcal: SimCalFile, tau_mm: np.ndarray, released_mm3: np.ndarray, t_s: np.ndarray,
                    water_g: float, simulate_at: SimulateAt | None = None, mass_g: float | None = None,
                    block: dict | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """The band of a prediction through ``simcal`` at times ``t_s`` (None if the file stores no band).

    Parameters
    ----------
    simcal : SimCalFile
    tau_mm, released_mm3 : (K,) ndarray of float
        The nominal simulation (with the calibration's print physics).
    t_s : (Q,) ndarray of float, s
    water_g : float
    simulate_at : callable, optional
        The shape simulated with other print physics; without it the physics' spread is left out.
    mass_g : float, optional
        A weighed mass (then the mass scale's spread is left out).
    block : dict, optional
        The calibration's band block (default: the file's, ``simcal.band``).

    Returns
    -------
    (lower_g, upper_g) or None
    """
    block = simcal.band if block is None else block
    if block is None:
        return None
    cal = simcal.cal
    nominal = cal.to_physical(tau_mm, released_mm3, t_s, water_g, mass_g=mass_g)
    final = float(mass_g if mass_g is not None else np.asarray(released_mm3, float)[-1] * cal.g_per_mm3)
    spread = spread_g(cal, tau_mm, released_mm3, t_s, water_g, mass_g, float(block["seconds_per_mm_rel_sd"]),
                      simcal.physics, block.get("physics_sd", {}), simulate_at)
    mass_sd = 0.0 if mass_g is not None else nominal * float(block["g_per_mm3_rel_sd"])
    return _band(nominal, final, ResidualModel.from_dict(block["residuals"]), level=float(block["level"]),
                 parameter_g=spread, mass_sd_g=mass_sd)


def _source_mesh_once(source: str, units: str, meshes: list):
    """The source's mesh (None for a density array), loaded on the first call into ``meshes``."""
    from labapp.jobs.simulate import _is_density, _source_mesh

    if not meshes:
        meshes.append(None if _is_density(source) else _source_mesh(source, units))
    return meshes[0]


def source_simulator(source: str, resolution: int, *, symmetry: str = "", units: str = "mm",
                     method: str | None = None) -> SimulateAt:
    """``simulate_at(physics)`` for a mesh, ``sample:NAME`` or density array at a calibration's resolution
    (``labapp.jobs.simulate.simulation_grid``; grids cached per surface offset), made as the calibration made its
    meshes' releases: with ``method`` ``simcal.RELEASE_METHOD`` (the default; give the calibration's
    ``release_method``) a mesh's :func:`labapp.jobs.printrelease.print_release`, otherwise (and for a density
    array, which has no mesh) the grid's release at the print's exact volume
    (:func:`labapp.jobs.printrelease.exact_volume_release`)."""
    from design.errors import DesignError
    from design.forward.simulator import simulate
    from labapp.jobs.printrelease import exact_volume_release, print_release
    from labapp.jobs.simulate import simulation_grid
    from labapp.records.simcal import RELEASE_METHOD

    method = RELEASE_METHOD if method is None else method
    grids: dict[float, tuple] = {}
    meshes: list = []

    def simulate_at(physics: dict) -> tuple[np.ndarray, np.ndarray]:
        offset = round(float(physics["offset_mm"]), 9)
        try:
            if offset not in grids:
                grids[offset] = simulation_grid(source, resolution=resolution, symmetry=symmetry, units=units,
                                                offset_mm=offset)[:3]
            mesh = _source_mesh_once(source, units, meshes)
            if mesh is not None and method == RELEASE_METHOD:
                return print_release(mesh, grids[offset], resolution, {**PHYSICS_IDENTITY, **physics})
            rho, dx, mirror = grids[offset]
            # the offset is in the grid; every other print physics parameter is the forward model's keyword (the
            # wetting lag is the calibration map's, not the simulation's)
            release = simulate(rho, dx, mirror=mirror, **{p: float(v) for p, v in physics.items()
                                                          if p in PHYSICS_PARAMETERS and p != "offset_mm"})
            return np.asarray(release.tau_mm, float), exact_volume_release(release.released_mm3, mesh, offset)
        except DesignError as exc:
            raise SimCalError(f"{source}: {exc}") from exc

    return simulate_at


def source_release_exact(source: str, release, physics: dict, units: str = "mm", *, resolution: int,
                         symmetry: str = "", method: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A ``Release`` already simulated from ``source`` (mesh, ``sample:NAME`` or density array) at ``resolution``
    with print ``physics``, made as :func:`source_simulator` makes it (a mesh's
    :func:`labapp.jobs.printrelease.print_release` with ``method`` ``simcal.RELEASE_METHOD``, the default;
    else at the print's exact volume). Returns ``(tau_mm, released_mm3)``."""
    from design.errors import DesignError
    from labapp.jobs.printrelease import exact_volume_release, print_release
    from labapp.jobs.simulate import simulation_grid
    from labapp.records.simcal import RELEASE_METHOD

    physics = {**PHYSICS_IDENTITY, **physics}
    try:
        mesh = _source_mesh_once(source, units, [])
        if mesh is None or (RELEASE_METHOD if method is None else method) != RELEASE_METHOD:
            return np.asarray(release.tau_mm, float), exact_volume_release(release.released_mm3, mesh,
                                                                            physics["offset_mm"])
        grid = simulation_grid(source, resolution=resolution, symmetry=symmetry, units=units,
                               offset_mm=physics["offset_mm"])[:3]
        return print_release(mesh, grid, resolution, physics, release)
    except DesignError as exc:
        raise SimCalError(f"{source}: {exc}") from exc


def band_series(t_s: np.ndarray, band: tuple[np.ndarray, np.ndarray] | None, level: float = BAND_LEVEL
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, str] | None:
    """A band as ``labapp.jobs.physical.plot_physical``'s shaded series (None stays None)."""
    if band is None:
        return None
    return np.asarray(t_s), band[0], band[1], f"{100 * level:.0f}% band (calibration uncertainty and leave-one-out)"


def band_summary(band: tuple[np.ndarray, np.ndarray], target_g: np.ndarray, level: float = BAND_LEVEL) -> dict:
    """A design's band in its ``summary.json``: the level, its columns, and how much of the target lies inside."""
    lo, hi = quantile_columns(level)
    target = np.asarray(target_g, float)
    inside = float(np.mean((target >= band[0]) & (target <= band[1])))
    return {"level": level, "columns": [f"design_released_g_{lo}", f"design_released_g_{hi}"],
            "target_inside_fraction": inside,
            "mean_half_width_g": float(np.mean(0.5 * (band[1] - band[0])))}


def design_band(design_dir: Path, simcal: SimCalFile, tau_mm: np.ndarray, released_mm3: np.ndarray, t_s: np.ndarray,
                water_g: float) -> tuple[np.ndarray, np.ndarray] | None:
    """The band of a design's predicted release: the print physics' spread from its ``design.stl`` simulated
    at the calibration's resolution (a design without one: the scales' spread and the residuals only)."""
    stl = Path(design_dir) / "design.stl"
    simulate_at = source_simulator(str(stl), simcal.resolution, method=simcal.release_method) if stl.is_file() else None
    try:
        return prediction_band(simcal, tau_mm, released_mm3, t_s, water_g, simulate_at)
    except SimCalError as exc:
        if simulate_at is None:
            raise
        log.warning("the band of %s leaves out the print physics' spread: %s", design_dir, exc)
        return prediction_band(simcal, tau_mm, released_mm3, t_s, water_g, None)
