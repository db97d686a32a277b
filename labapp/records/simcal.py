"""The simulation calibration's record, ``simcal.json``: its format, the typed loader and the error of its job.

``sfr calibrate-sim`` (:func:`labapp.jobs.calibrate_sim.calibrate_sim`) writes the file; :func:`load_simcal` reads
it back for ``sfr simulate --simcal`` and ``sfr design --simcal`` (:mod:`labapp.jobs.physical`), the GUI and the
sweeps, refusing a file of another format, forward model or calibration model, and :func:`migrate` reads the
earlier format. :class:`SimCalError` is what a bad set file, run, mesh or calibration file raises.
"""
from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path

from analysis import AnalysisError, SimCal
from analysis.bands import ResidualModel
from analysis.physics_grid import FIT_IDENTITY, LAG, PHYSICS_IDENTITY, PHYSICS_PARAMETERS
from analysis.simcal import MODELS
from labapp.errors import UsageError
from labapp.records.curvefiles import CurveFileError, PhysicalCurve, read_physical_curve
from labapp.records.jsonfile import read_format

FORMAT = "sfr-simcal/2"
"""``format`` of ``simcal.json``."""
OLD_FORMATS = ("sfr-simcal/1",)
"""Earlier formats :func:`load_simcal` reads by :func:`migrate` (version 1 had no print physics: the identity)."""
FORWARD_MODEL = "design.forward.simulator: fast marching, eqs. 2-10"
"""The simulator a calibration holds for; a file naming another is refused."""
RELEASE_METHOD = "grid+reference-bias"
"""How a mesh's simulated release is made (``simcal.json``'s ``release_method``): the forward model's grid release
with the print physics, plus the grid's bias against the reference evaluator's exact release
(:func:`labapp.jobs.printrelease.grid_bias`)."""
OLD_RELEASE_METHOD = "grid"
"""The grid release alone (at the print's exact volume): what a file without ``release_method`` was made with."""
RELEASE_METHODS = (RELEASE_METHOD, OLD_RELEASE_METHOD)


class SimCalError(UsageError):
    """A set file, run, mesh or calibration file that cannot be used; the message names it."""


@dataclass(frozen=True)
class SimCalFile:
    """A loaded ``simcal.json``.

    Attributes
    ----------
    cal : analysis.SimCal
        The map used for prediction (the file's ``model``).
    resolution : int
        Voxels along the longest side the calibration meshes were simulated at.
    voxel_size_mm : float
        Median voxel edge of those simulations, mm.
    water_g : float
        Water mass of the calibration runs (median), g: the default bath for predictions.
    path : Path
    physics : dict
        The forward model's print physics (``anisotropy``, ``offset_mm``, ``swelling_mm``) predictions simulate with;
        the wetting lag is the map's (``cal.lag_s``).
    band : dict or None
        The file's ``band`` block (checked), what a prediction's error band is made from; None for a file made
        without one.
    release_method : str
        How the calibration made each mesh's release (:data:`RELEASE_METHODS`), and so how its predictions do: a
        file without the field was made by the grid alone (:data:`OLD_RELEASE_METHOD`).
    barrier : dict or None
        The file's ``barrier`` block (``speed``, ``error``: the barrier's relative speed fitted from coated prints,
        :mod:`labapp.jobs.calibrate_barrier`); None for a calibration without coated prints.
    """

    cal: SimCal
    resolution: int
    voxel_size_mm: float
    water_g: float
    path: Path
    physics: dict = dataclasses.field(default_factory=lambda: dict(PHYSICS_IDENTITY))
    band: dict | None = None
    release_method: str = RELEASE_METHOD
    barrier: dict | None = None

    def describe(self) -> str:
        """One line for reports and GUI labels."""
        sat = "" if self.cal.saturation_g_per_kg is None else f", c_sat {self.cal.saturation_g_per_kg:.3g} g/kg"
        phys = "".join(f", {k} {v:.3g}" for k, v in self.physics.items() if v != PHYSICS_IDENTITY[k])
        phys += f", wetting lag {self.cal.lag_s:.0f} s" if self.cal.lag_s else ""
        return (f"{self.path.name}: {self.cal.model} model, {self.cal.seconds_per_mm:.1f} s/mm, "
                f"{self.cal.g_per_mm3 * 1000:.4g} g/cm^3{sat}{phys}, resolution {self.resolution}")

    def simulate_options(self) -> dict:
        """Keyword arguments of ``design.files.pipeline.simulate_mesh`` for this calibration's physics."""
        return {p: self.physics[p] for p in PHYSICS_PARAMETERS}


def migrate(doc: dict) -> dict:
    """A ``simcal.json`` of an earlier format as the current one: version 1 had no print physics (the identity)."""
    if doc.get("format") == "sfr-simcal/1":
        doc = dict(doc, format=FORMAT, physics={"fitted": [], "choice": "none", **FIT_IDENTITY,
                                                "uncertainty": {}, "candidates": {}})
    return doc


def load_simcal(path: str | Path) -> SimCalFile:
    """Read ``simcal.json``, refusing a file of another format, forward model or calibration model.

    Raises
    ------
    SimCalError
        Naming the file and the field.
    """
    path = Path(path)
    try:
        found = json.loads(path.read_text()).get("format")
    except (OSError, ValueError, AttributeError):
        found = None
    fmt = found if found in OLD_FORMATS else FORMAT
    doc = migrate(read_format(path, fmt, "a simulation calibration", "make one with sfr calibrate-sim", SimCalError))
    if doc.get("forward_model") != FORWARD_MODEL:
        raise SimCalError(f"{path}: calibrated for the simulator {doc.get('forward_model')!r}, this one is "
                          f"{FORWARD_MODEL!r}; recalibrate with sfr calibrate-sim")
    if doc.get("model") not in MODELS:
        raise SimCalError(f"{path}: model {doc.get('model')!r} is not one of {', '.join(MODELS)}")
    try:
        # a physics block written before the wetting lag was fitted has none (0)
        lag = float(doc["physics"].get(LAG, FIT_IDENTITY[LAG]))
        if not (math.isfinite(lag) and lag >= 0):
            raise SimCalError(f"{path}: physics.{LAG} must be a number of seconds >= 0, got {lag}")
        cal = SimCal(doc["model"], float(doc["seconds_per_mm"]), float(doc["g_per_mm3"]),
                     None if doc.get("saturation_g_per_kg") is None else float(doc["saturation_g_per_kg"]), lag)
        resolution, dx, water = int(doc["resolution"]), float(doc["voxel_size_mm"]), float(doc["water_g"])
        # a physics block written before the swelling width was fitted has none (0)
        physics = {p: float(doc["physics"].get(p, PHYSICS_IDENTITY[p]) if p == "swelling_mm" else doc["physics"][p])
                   for p in PHYSICS_PARAMETERS}
    except (KeyError, TypeError, ValueError, AnalysisError) as exc:
        raise SimCalError(f"{path}: bad or missing field ({exc})") from exc
    if not (resolution > 0 and dx > 0 and water > 0):
        raise SimCalError(f"{path}: resolution, voxel_size_mm and water_g must be positive")
    if not (math.isfinite(physics["anisotropy"]) and physics["anisotropy"] > 0 and math.isfinite(physics["offset_mm"])):
        raise SimCalError(f"{path}: physics.anisotropy must be a positive number and physics.offset_mm a finite one, "
                          f"got {physics}")
    if not (math.isfinite(physics["swelling_mm"]) and physics["swelling_mm"] >= 0):
        raise SimCalError(f"{path}: physics.swelling_mm must be a number >= 0 (mm), got {physics['swelling_mm']}")
    method = doc.get("release_method", OLD_RELEASE_METHOD)
    if method not in RELEASE_METHODS:
        raise SimCalError(f"{path}: release_method {method!r} is not one of {', '.join(RELEASE_METHODS)}")
    band = doc.get("band")
    if band is not None:
        try:
            ResidualModel.from_dict(band["residuals"])
            float(band["seconds_per_mm_rel_sd"]), float(band["g_per_mm3_rel_sd"]), float(band["level"])
        except (KeyError, TypeError, ValueError) as exc:
            raise SimCalError(f"{path}: bad band block ({exc}); recalibrate with sfr calibrate-sim") from exc
    barrier = doc.get("barrier")
    if barrier is not None:
        try:
            speed, error = float(barrier["speed"]), float(barrier["error"])
        except (KeyError, TypeError, ValueError) as exc:
            raise SimCalError(f"{path}: bad barrier block ({exc}); expected speed and error") from exc
        if not (math.isfinite(speed) and speed >= 0 and error >= 0):
            raise SimCalError(f"{path}: barrier.speed must be a number >= 0 with an error >= 0, got {speed}, {error}")
    return SimCalFile(cal, resolution, dx, water, path, physics, band, method, barrier)


def check_resolution(simcal: SimCalFile, resolution: int | None) -> int:
    """The resolution to simulate at: the calibration's, or ``resolution`` if it is the same.

    Raises
    ------
    SimCalError
        If ``resolution`` differs: the time scale holds for the grid it was fitted on.
    """
    if resolution is not None and resolution != simcal.resolution:
        raise SimCalError(f"{simcal.path} was calibrated at resolution {simcal.resolution}, not {resolution}: "
                          f"drop --resolution or recalibrate at {resolution}")
    return simcal.resolution


def curve_of(path: str | Path, bench_calibration=None) -> PhysicalCurve:
    """A physical curve for a design target or an overlay, as a :class:`SimCalError` on bad input."""
    try:
        return read_physical_curve(path, calibration=bench_calibration)
    except CurveFileError as exc:
        raise SimCalError(str(exc)) from exc
