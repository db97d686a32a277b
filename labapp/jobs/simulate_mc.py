"""The Monte Carlo baseline as jobs: ``sfr simulate --model mc`` and its calibration file ``mc.json``.

The kinetic Monte Carlo model (:mod:`design.montecarlo.erosion`) runs in physical time: with tuned (A, E_a) its
clock is seconds. Its released volume becomes grams through the calibration's grams per mm^3 (the
calibration objects' weighed mass over their voxel volume), or the nominal print density (1.32 g/cm^3,
section 4.1) without one.
A simulation folder of the Monte Carlo model holds the same files as the forward model's:

- ``release.csv``: ``t_s,released_mm3,released_std_mm3`` (mean and spread over the seeds);
- ``release_physical.csv``: ``t_s,released_g,conc_g_per_kg,released_std_g`` (readable by ``sfr compare``);
- ``summary.json`` (parameters, seeds, time step, MDT, DE and model fits of the mean curve);
- ``release.png``: the mean curve with the seeds' spread.
"""
from __future__ import annotations

import datetime as _dt
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from design.errors import DesignError
from design.material import PRINT_DENSITY_G_PER_CM3
from design.montecarlo.erosion import DEFAULT_SEEDS, MonteCarloParams, simulate_mc
from design.montecarlo.tuning import McTuning
from labapp.acquisition.simbench import WATER_G
from labapp.errors import UsageError
from labapp.jobs.compare import release_summary
from labapp.jobs.physical import plot_physical
from labapp.jobs.simulate import (
    SimulationOutputs,  # labapp.jobs imports this module
    simulation_grid,
)
from labapp.records.fileio import atomic_write
from labapp.records.jsonfile import read_format
from labapp.records.outpaths import FolderKind, check_out

if TYPE_CHECKING:
    from labapp.jobs.simulate import SimulationOutputs


UNCALIBRATED = ("its parameters (A, E_a) are uncalibrated defaults, not tuned to any measurement: times are in units "
                "of 1/A; tune them with sfr evaluate and pass --mc-calibration")
"""What a Monte Carlo simulation without a calibration file says of itself (output and summary)."""
FORMAT = "sfr-mc-calibration/1"
"""``format`` of ``mc.json``."""


@dataclass(frozen=True)
class McCalibration:
    """A Monte Carlo calibration in physical units.

    Attributes
    ----------
    params : MonteCarloParams
        A (1/s), E_a (J/mol), T (K) and the voxel size they were tuned at.
    g_per_mm3 : float
        Released grams per mm^3 of simulated solid.
    water_g : float
        Bath water of the calibration runs, g.
    resolution : int or None
        Voxels along the longest side the objects were simulated at.
    path : Path or None
    """

    params: MonteCarloParams
    g_per_mm3: float = PRINT_DENSITY_G_PER_CM3 * 1e-3
    water_g: float = WATER_G
    resolution: int | None = None
    path: Path | None = None

    def describe(self) -> str:
        p = self.params
        return (f"Monte Carlo A = {p.a_per_s:.4g} 1/s, E_a = {p.ea_j_per_mol / 1000:.3g} kJ/mol at {p.temp_k - 273.15:.0f} C"
                + (f", tuned at {p.dx_mm:.3g} mm voxels" if p.dx_mm else ""))


def calibration_doc(tuning: McTuning, g_per_mm3: float, water_g: float, resolution: int | None,
                    sources: list[str]) -> dict[str, Any]:
    """The content of ``mc.json`` for a tuning."""
    return {"format": FORMAT, **tuning.params.to_dict(), "g_per_mm3": g_per_mm3, "water_g": water_g,
            "resolution": resolution, "rms": tuning.rms, "per_object_rms": list(tuning.per_object_rms),
            "seeds": list(tuning.seeds), "objects": sources,
            "grid": [{"a_per_s": g.a_per_s, "ea_j_per_mol": g.ea_j_per_mol, "rms": g.rms} for g in tuning.grid],
            "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}


def load_mc_calibration(path: str | Path) -> McCalibration:
    """Read ``mc.json``.

    Raises
    ------
    UsageError
        An unreadable file, another format, or a bad field (named).
    """
    path = Path(path)
    doc = read_format(path, FORMAT, "a Monte Carlo calibration", "make one with sfr evaluate")
    try:
        params = MonteCarloParams.from_dict(doc)
        g, water = float(doc["g_per_mm3"]), float(doc["water_g"])
        resolution = None if doc.get("resolution") is None else int(doc["resolution"])
    except (KeyError, TypeError, ValueError, DesignError) as exc:
        raise UsageError(f"{path}: bad or missing field ({exc})") from exc
    if not (np.isfinite(g) and g > 0 and np.isfinite(water) and water > 0):
        raise UsageError(f"{path}: g_per_mm3 and water_g must be positive numbers")
    return McCalibration(params, g, water, resolution, path)


def simulate_mc_job(source: str, out: str | Path, calibration: McCalibration, *, resolution: int | None = None,
                    voxel_size_mm: float | None = None, symmetry: str = "", units: str = "mm",
                    seeds: int = DEFAULT_SEEDS, water_g: float | None = None,
                    progress: Callable[[str], None] | None = None) -> SimulationOutputs:
    """Simulate a mesh, ``sample:NAME`` or density array with the Monte Carlo model into ``out``.

    Parameters
    ----------
    source : str
    out : str or Path
        Simulation folder (checked before any work).
    calibration : McCalibration
        Physical parameters; with a calibration tuned at another resolution A is rescaled to this voxel size.
    seeds : int
        Runs averaged (seeds 0 .. seeds-1).
    water_g : float, optional
        Bath water for ``conc_g_per_kg``, g (default: the calibration's).
    """
    if int(seeds) < 1:
        raise UsageError(f"--seeds {seeds}: give at least 1 run")
    say = progress or (lambda message: None)
    out = check_out(out, FolderKind.SIMULATION, [source])
    start = time.perf_counter()
    say(f"[1/3] loading and voxelising {source} ...")
    rho, dx, mirror, warnings = simulation_grid(source, resolution=resolution, voxel_size_mm=voxel_size_mm,
                                                symmetry=symmetry, units=units)
    say(f"[2/3] Monte Carlo erosion of {rho.size:,} voxels of {dx:.4g} mm, {seeds} seeds "
        f"({time.perf_counter() - start:.1f} s) ...")
    release = simulate_mc(rho, dx, calibration.params, mirror=mirror, seeds=int(seeds),
                          progress=lambda done, total: say(f"      seed {done}/{total}"))
    seconds = time.perf_counter() - start
    say(f"[3/3] writing {out}/ ({seconds:.1f} s)")
    out.mkdir(parents=True, exist_ok=True)
    water = water_g or calibration.water_g
    grams, spread_g = release.released_mm3 * calibration.g_per_mm3, release.released_std_mm3 * calibration.g_per_mm3
    table = "t_s,released_mm3,released_std_mm3\n" + "".join(
        f"{t:.6g},{v:.9g},{s:.9g}\n" for t, v, s in zip(release.t_s, release.released_mm3, release.released_std_mm3))
    atomic_write(out / "release.csv", table.encode())
    physical = "t_s,released_g,conc_g_per_kg,released_std_g\n" + "".join(
        f"{t:.2f},{g:.6f},{g / water * 1000.0:.6f},{s:.6f}\n" for t, g, s in zip(release.t_s, grams, spread_g))
    atomic_write(out / "release_physical.csv", physical.encode())
    summary = {"input": source, "model": "mc", "units": units, "calibration": calibration.describe(),
               "calibration_file": None if calibration.path is None else str(calibration.path),
               "calibrated": calibration.path is not None,
               "calibration_note": "tuned (A, E_a) from the calibration file" if calibration.path is not None
               else UNCALIBRATED,
               "params": release.params.to_dict(), "seeds": list(release.seeds), "dt_s": release.dt_s,
               "volume_mm3": release.volume_mm3, "voxels": int(rho.size), "grid_shape": list(rho.shape),
               "voxel_size_mm": dx, "mirror": list(mirror), "seconds": seconds, "warnings": warnings,
               "spread_max_g": float(spread_g.max()),
               "physical": {"mass_g": float(grams[-1]), "duration_s": float(release.t_s[-1]), "water_g": water,
                            "release": release_summary(release.t_s, grams, None, "Monte Carlo mean")}}
    atomic_write(out / "summary.json", (json.dumps(summary, indent=2) + "\n").encode())
    plot_physical(out / "release.png", [(release.t_s, grams, "Monte Carlo mean", "C2-")],
                  f"{source}: {calibration.describe()}" + ("" if calibration.path else " (uncalibrated defaults)"),
                  band=(release.t_s, grams - 2 * spread_g, grams + 2 * spread_g,
                        "+-2 standard deviations over the seeds"))

    return SimulationOutputs(release, summary, out, tuple(warnings))
