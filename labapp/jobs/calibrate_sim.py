"""The simulation-to-bench calibration as a job: measured runs + meshes -> ``simcal.json`` (paper section 4.3).

:func:`calibrate_sim` is what ``sfr calibrate-sim`` and the GUI's calibration wizard call: it reads a set
file (``run,mesh,object_mass_g``), reads every run's physical curve (:mod:`labapp.records.curvefiles`), simulates
every mesh with the forward model (``design.forward.pipeline``), fits both calibration models and their
leave-one-out predictions (:mod:`analysis.simcal`) and writes ``simcal.json``, ``loo.csv`` and
``simcal.png``. :func:`load_simcal` reads the file back for ``sfr simulate --simcal`` and
``sfr design --simcal`` (:mod:`labapp.jobs.physical`).
"""
from __future__ import annotations

import csv
import dataclasses
import datetime as _dt
import hashlib
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis import AnalysisError, BenchCalibration, LooShape, ShapeRun, SimCal, fit_simcal, leave_one_out
from analysis.bands import ResidualModel, band_block
from analysis.simcal import (
    DEFAULT_MAX_OFFSET_S,
    DISCRETISATION_FACTOR,
    FIT_IDENTITY,
    FIT_PARAMETERS,
    LAG,
    MODELS,
    PHYSICS_CHOICES,
    PHYSICS_GRIDS,
    PHYSICS_IDENTITY,
    PHYSICS_PARAMETERS,
    PHYSICS_SETS,
    PhysicsFit,
    choose_physics,
    fit_physics,
    refit_physics,
    with_discretisation,
)
from labapp.errors import UsageError
from labapp.records import operators
from labapp.records.audit import Action
from labapp.records.audit import append as audit
from labapp.records.curvefiles import CurveFileError, PhysicalCurve, read_physical_curve
from labapp.records.jsonfile import read_format
from labapp.records.lock import folder_lock
from labapp.records.outpaths import FolderKind, check_out
from labapp.records.storage import FRAMES_CSV, atomic_write, sha256_file

FORMAT = "sfr-simcal/2"
"""``format`` of ``simcal.json``."""
OLD_FORMATS = ("sfr-simcal/1",)
"""Earlier formats :func:`load_simcal` reads by :func:`migrate` (version 1 had no print physics: the identity)."""
FORWARD_MODEL = "design.forward.simulator: fast marching, eqs. 2-10"
"""The simulator a calibration holds for; a file naming another is refused."""
RELEASE_METHOD = "grid+reference-bias"
"""How a mesh's simulated release is made (``simcal.json``'s ``release_method``): the forward model's grid release
with the print physics, plus the grid's bias against the reference evaluator's exact release (:func:`grid_bias`)."""
OLD_RELEASE_METHOD = "grid"
"""The grid release alone (at the print's exact volume): what a file without ``release_method`` was made with."""
RELEASE_METHODS = (RELEASE_METHOD, OLD_RELEASE_METHOD)
DEFAULT_RESOLUTION = 64
"""Voxels along each mesh's longest side when calibrating (``sfr simulate``'s default)."""
MIN_RESOLUTION, MAX_RESOLUTION = 8, 512
"""The resolutions a calibration accepts, voxels along each mesh's longest side."""
SET_COLUMNS = ("run", "mesh", "object_mass_g")
Progress = Callable[[float, str], None]


class SimCalError(UsageError):
    """A set file, run, mesh or calibration file that cannot be used; the message names it."""


@dataclass(frozen=True)
class SetRow:
    """One line of a calibration set file (row 1 = first data row)."""

    row: int
    run: Path
    mesh: Path
    object_mass_g: float | None
    water_g: float | None = None


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
    """

    cal: SimCal
    resolution: int
    voxel_size_mm: float
    water_g: float
    path: Path
    physics: dict = dataclasses.field(default_factory=lambda: dict(PHYSICS_IDENTITY))
    band: dict | None = None
    release_method: str = RELEASE_METHOD

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


@dataclass(frozen=True)
class SimCalRun:
    """What :func:`calibrate_sim` made.

    Attributes
    ----------
    doc : dict
        The content of ``simcal.json``.
    loo : tuple of analysis.LooShape
        The chosen model's leave-one-out predictions, in set order.
    path : Path
        ``simcal.json``.
    """

    doc: dict
    loo: tuple[LooShape, ...]
    path: Path


def read_set(path: str | Path) -> list[SetRow]:
    """Read a calibration set file: columns ``run,mesh,object_mass_g`` (and optionally ``water_g``), paths
    relative to the file.

    Raises
    ------
    SimCalError
        Missing columns, a missing run or mesh (file and row named), a mass that is not a positive number.
    """
    path = Path(path)
    try:
        with open(path, newline="") as fh:
            reader = csv.DictReader(fh)
            header = [h.strip() for h in reader.fieldnames or []]
            rows = list(reader)
    except OSError as exc:
        raise SimCalError(f"{path}: cannot read the set file ({exc.strerror or exc})") from exc
    missing = [c for c in SET_COLUMNS if c not in header]
    if missing:
        raise SimCalError(f"{path}: no column {', '.join(missing)}; expected {','.join(SET_COLUMNS)}")
    out = []
    for i, row in enumerate(rows, start=1):
        row = {k.strip(): (v or "").strip() for k, v in row.items() if k is not None}
        run, mesh = path.parent / row["run"], path.parent / row["mesh"]
        for what, p in (("run", run), ("mesh", mesh)):
            if not row[what] or not p.exists():
                raise SimCalError(f"{path}: row {i}: {what} {row[what]!r} does not exist (looked for {p})")
        grams = {}
        for column in ("object_mass_g", "water_g"):
            text = row.get(column, "")
            if not text:
                continue
            try:
                grams[column] = float(text)
            except ValueError:
                grams[column] = math.nan
            if not (math.isfinite(grams[column]) and grams[column] > 0):
                raise SimCalError(f"{path}: row {i}: {column} {text!r} is not a positive number of grams")
        out.append(SetRow(i, run, mesh, grams.get("object_mass_g"), grams.get("water_g")))
    if len(out) < 2:
        raise SimCalError(f"{path}: {len(out)} runs; a calibration needs at least 2 (4 or more recommended)")
    _refuse_repeated_runs(path, out)
    return out


def run_identity(run: Path) -> str:
    """SHA-256 of what identifies a run's measurement: a run folder's manifest (``frames.csv``, which lists every
    frame with its own SHA-256), for a folder without one all its files, for a curve file its bytes. Two copies
    of one run have the same identity wherever they lie."""
    if run.is_file():
        return sha256_file(run)
    if (run / FRAMES_CSV).is_file():
        return sha256_file(run / FRAMES_CSV)
    digest = hashlib.sha256()
    for p in sorted(q for q in run.rglob("*") if q.is_file() and not q.name.startswith(".")):
        digest.update(f"{p.relative_to(run)}\0{sha256_file(p)}\n".encode())
    return digest.hexdigest()


def _refuse_repeated_runs(path: Path, rows: list[SetRow]) -> None:
    """The same measured run twice (one path, or two copies with the same manifest) makes the leave-one-out
    meaningless: the left-out run is still in the fit."""
    by_path: dict[Path, SetRow] = {}
    by_content: dict[str, SetRow] = {}
    for row in rows:
        resolved = row.run.resolve()
        first = by_path.get(resolved)
        if first is not None:
            raise SimCalError(f"{path}: rows {first.row} and {row.row} list the same run {resolved}; each run may "
                              "be listed once (its leave-one-out would otherwise keep it in the fit)")
        by_path[resolved] = row
        try:
            identity = run_identity(row.run)
        except OSError as exc:
            raise SimCalError(f"{path}: row {row.row}: cannot read run {row.run} ({exc.strerror or exc})") from exc
        first = by_content.get(identity)
        if first is not None:
            what = "manifest (frames.csv)" if (row.run / FRAMES_CSV).is_file() else "content"
            raise SimCalError(f"{path}: rows {first.row} and {row.row} list the same run twice: {first.run} and "
                              f"{row.run} have an identical {what} (SHA-256 {identity[:12]}...); each run may be "
                              "listed once (its leave-one-out would otherwise keep it in the fit)")
        by_content[identity] = row


def _check_inputs(set_csv: Path, rows: list[SetRow], bench) -> dict:
    """Every mesh read and every run's calibration found before the first simulation: a bad row further down
    is refused at once, not after the rows above it were analysed and simulated. Returns the meshes."""
    from design.errors import DesignError
    from design.files.meshio import load_mesh

    meshes = {}
    for row in rows:
        where = f"{set_csv.name} row {row.row}"
        if bench is None and row.run.is_dir() and not (row.run / "calibration.json").is_file():
            raise SimCalError(f"{where}: the run folder {row.run} has no calibration.json of its own; give the bench "
                              "calibration with --calibration")
        if row.mesh not in meshes:
            try:
                meshes[row.mesh] = load_mesh(row.mesh)
            except DesignError as exc:
                raise SimCalError(f"{where}: {exc}") from exc
    return meshes


def print_volume_mm3(mesh, offset_mm: float = 0.0) -> float:
    """The volume of a mesh's print with its surface moved outward by ``offset_mm`` (inward if negative):
    Steiner's formula V + A o + M o^2 + (2 pi / 3) chi o^3, with A the area, M the integral of the mean
    curvature and chi the Euler characteristic of the closed mesh (trimesh). Exact for a convex solid (a box:
    L^3 + 6 L^2 o + 3 pi L o^2 + 4 pi o^3 / 3); for a non-convex one it is the first terms of the parallel body's
    volume, which for offsets of a few tenths of a mm on mm-sized features is far below a voxel's error."""
    o = float(offset_mm)
    volume = float(mesh.volume)
    if o == 0.0:
        return volume
    return (volume + float(mesh.area) * o + float(mesh.integral_mean_curvature) * o ** 2
            + 2.0 * math.pi / 3.0 * float(mesh.euler_number) * o ** 3)


def exact_volume_release(released_mm3: np.ndarray, mesh, offset_mm: float = 0.0) -> np.ndarray:
    """A simulated release of ``mesh`` rescaled to the print's exact volume (:func:`print_volume_mm3`): the
    fraction of the voxelised solid released times the exact volume. A binary voxelisation at 32-48 voxels
    misses a box's volume by up to 16 % when its sides are an odd number of voxels, which would go straight into
    the calibrated density and every predicted gram; the voxels keep the curve's shape, the mesh its volume.
    The one place where calibration (:func:`calibrate_sim`) and physical predictions
    (:func:`labapp.jobs.bands.source_simulator`, ``sfr simulate --simcal``) turn a mesh's voxels into mm^3.
    ``mesh`` None (a density array, which is its own solid) leaves the release as simulated."""
    released = np.asarray(released_mm3, float)
    if mesh is None or released.size == 0 or not released[-1] > 0:
        return released
    exact = print_volume_mm3(mesh, offset_mm)
    if not exact > 0:
        raise SimCalError(f"the mesh's print volume {exact:.4g} mm^3 at surface offset {offset_mm:g} mm is not "
                          "positive; expected a closed mesh in mm")
    return released * (exact / released[-1])


BIAS_SAMPLES = 1025
"""Erosion depths (uniform from 0 to past the end) at which a mesh's reference release is evaluated."""
SHELL_SAMPLES = 33
"""Erosion depths across a grown print's added shell (:func:`reference_fraction`)."""
_REFERENCE_CACHE: dict[tuple, tuple[np.ndarray, np.ndarray, object]] = {}
_BIAS_CACHE: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
_CACHE_SIZE = 256


def _remember(cache: dict, key: tuple, value):
    if len(cache) >= _CACHE_SIZE:
        cache.pop(next(iter(cache)))
    cache[key] = value
    return value


def _digest(*arrays) -> str:
    digest = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        digest.update(a.tobytes())
        digest.update(str((a.dtype, a.shape)).encode())
    return digest.hexdigest()


def _mesh_digest(mesh) -> str:
    return _digest(np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64))


def metric_offset_mm(mesh, anisotropy: float, offset_mm: float) -> float:
    """A print's surface offset as a distance in the metric of build-direction anisotropy a (z scaled by 1 / a, in
    which the anisotropic front is isotropic): a face with unit normal n moved ``offset_mm`` = o along n lies
    o / sqrt(nx^2 + ny^2 + a^2 nz^2) from where it was in that metric (o / a for a face across the build direction,
    o for one along it), and its area there is dA sqrt(nx^2 + ny^2 + a^2 nz^2) / a. The mean over the scaled
    surface's area is o A / integral sqrt(nx^2 + ny^2 + a^2 nz^2) dA: exact for a = 1 and for a print whose faces all
    have one such distance (a slab's faces, a column's sides), an area-weighted mean otherwise."""
    o = float(offset_mm)
    if o == 0.0 or anisotropy == 1.0:
        return o
    n = np.asarray(mesh.face_normals, float)
    area = np.asarray(mesh.area_faces, float)
    stretch = np.sqrt(n[:, 0] ** 2 + n[:, 1] ** 2 + (anisotropy * n[:, 2]) ** 2)
    return o * float(area.sum()) / float(np.sum(area * stretch))


def _reference(mesh, resolution: int, anisotropy: float) -> tuple[np.ndarray, np.ndarray, object]:
    """The reference evaluator's release of ``mesh`` as designed in the metric of anisotropy a: its release with z
    scaled by 1 / a (``design.forward.reference.reference_release`` on ``design_lattice(resolution)``), on
    `BIAS_SAMPLES` depths from 0 to half the scaled mesh's largest extent (no point lies deeper). Returns
    ``(tau_mm, released_mm3, scaled_mesh)``, volumes in the scaled space. Cached per mesh, resolution and a."""
    from design.forward.reference import design_lattice, metric_mesh, reference_release

    key = (_mesh_digest(mesh), int(resolution), round(float(anisotropy), 9), BIAS_SAMPLES)
    if key not in _REFERENCE_CACHE:
        scaled = metric_mesh(mesh, anisotropy)
        tau = np.linspace(0.0, 0.5 * float(np.max(scaled.extents)), BIAS_SAMPLES)
        ref = reference_release(scaled, tau, cells=design_lattice(resolution))
        _remember(_REFERENCE_CACHE, key, (tau, np.asarray(ref.released_mm3, float), scaled))
    return _REFERENCE_CACHE[key]


def reference_fraction(mesh, resolution: int, anisotropy: float = 1.0, offset_mm: float = 0.0
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The released fraction of a mesh's print by exact surface distances, with build-direction anisotropy a and
    the print's surface moved by ``offset_mm`` (:func:`_reference` of the mesh as designed, then the offset):

    - In the isotropic metric a solid grown by d (its Minkowski sum with a ball) has every inner point exactly d
      deeper (a point at depth r of K is at depth r + d of K + B_d), and the added shell releases first:
      ``R_d(tau) = V(d) - V(d - tau)`` for tau < d, ``V(d) - V + R(tau - d)`` after, V(s) the grown volume (Steiner,
      :func:`print_volume_mm3` of the scaled mesh). A solid shrunk by d keeps the points deeper than d, each d
      shallower: ``R_-d(tau) = R(tau + d) - R(d)``.
    - d is the offset in the metric (:func:`metric_offset_mm`): exact for a = 1, an area-weighted mean of the
      faces' distances otherwise.

    Returns
    -------
    tau_mm, fraction : (K,) ndarray of float
        Erosion depths (0 to the end) and the released fraction at them, non-decreasing to 1 at the end.
    """
    tau0, released0, scaled = _reference(mesh, resolution, anisotropy)
    d = metric_offset_mm(mesh, anisotropy, offset_mm)
    if d > 0:
        grown = print_volume_mm3(scaled, d)
        shell = np.linspace(0.0, d, SHELL_SAMPLES)[:-1]
        tau = np.concatenate([shell, tau0 + d])
        released = np.concatenate([[grown - print_volume_mm3(scaled, d - t) for t in shell],
                                   grown - float(scaled.volume) + released0])
    elif d < 0:
        keep = tau0 >= -d
        tau = np.concatenate([[0.0], tau0[keep] + d])
        start = float(np.interp(-d, tau0, released0))
        released = np.concatenate([[0.0], released0[keep] - start])
    else:
        tau, released = tau0, released0
    released = np.maximum.accumulate(released)   # monotone: the quadrature's rounding on the plateau
    return tau, released / released[-1]


def grid_bias(mesh, grid: tuple, resolution: int, anisotropy: float = 1.0, offset_mm: float = 0.0
              ) -> tuple[np.ndarray, np.ndarray]:
    """The first-order fast marching's discretisation bias of a mesh's print, as a fraction of its volume:
    ``b(tau) = F(tau) - G(tau) / G_end``, with G the forward model's release of ``grid`` (the print's voxels at the
    calibration's resolution, made with ``offset_mm``; no swelling) with build-direction anisotropy a (eq. 5 on
    spacings (dx, dx, dx / a)) and F the released fraction by exact surface distances in the same metric with the
    same offset (:func:`reference_fraction`). The bias is by shape (a curved print's grid front runs ahead of the
    exact one more than a box's), by anisotropy (the scaling changes the shape the grid sees) and by offset (the
    grid places a surface moved by less than a voxel only to within its voxels), so no time scale can absorb it.

    Evaluated once per mesh, grid, anisotropy and offset in a process (cached): the leave-one-out refits and the
    print physics scan reuse it.

    Returns
    -------
    tau_mm, fraction : (K,) ndarray of float
        Erosion depths (0 to past both curves' end, where b = 0) and b at them.
    """
    from design.forward.simulator import simulate

    anisotropy, offset_mm = float(anisotropy), float(offset_mm)
    rho, dx, mirror = grid
    key = (_mesh_digest(mesh), _digest(np.asarray(rho, np.float64)), round(float(dx), 12),
           tuple(bool(m) for m in mirror), int(resolution), round(anisotropy, 9), round(offset_mm, 9))
    if key in _BIAS_CACHE:
        return _BIAS_CACHE[key]
    grid_release = simulate(rho, dx, mirror=mirror, anisotropy=anisotropy)
    g_tau, g_vol = np.asarray(grid_release.tau_mm, float), np.asarray(grid_release.released_mm3, float)
    if not (g_vol.size and g_vol[-1] > 0):
        raise SimCalError("the mesh's voxel grid holds no solid; expected a closed mesh in mm")
    r_tau, r_fraction = reference_fraction(mesh, resolution, anisotropy, offset_mm)
    tau = np.union1d(r_tau, g_tau)
    fraction = np.interp(tau, r_tau, r_fraction) - np.interp(tau, g_tau, g_vol) / g_vol[-1]
    fraction[tau >= max(float(r_tau[-1]), float(g_tau[-1]))] = 0.0   # both curves whole: no bias
    return _remember(_BIAS_CACHE, key, (tau, fraction))


def bias_corrected_release(tau_mm: np.ndarray, released_mm3: np.ndarray, mesh, offset_mm: float, bias: tuple
                           ) -> tuple[np.ndarray, np.ndarray]:
    """A mesh's simulated release (with any print physics) corrected for the grid's bias (:func:`grid_bias`, made
    with the same anisotropy and offset): ``G_phys(tau) V_print / G_phys_end + b(tau) V_print`` on the union of both
    tau grids, V_print the print's exact volume (:func:`print_volume_mm3`), kept monotone within [0, V_print].
    Without swelling it is the exact release :func:`reference_fraction` times V_print at every node; with swelling,
    the grid's account of the shut channels plus the exact release's difference from the grid's without them."""
    tau_b, frac_b = bias
    tau_g, vol_g = np.asarray(tau_mm, float), exact_volume_release(released_mm3, mesh, offset_mm)
    if mesh is None or vol_g.size == 0 or not vol_g[-1] > 0:
        return tau_g, vol_g
    total = print_volume_mm3(mesh, offset_mm)
    tau = np.union1d(tau_g, tau_b)
    released = np.interp(tau, tau_g, vol_g) + np.interp(tau, tau_b, frac_b, right=0.0) * total
    return tau, np.clip(np.maximum.accumulate(released), 0.0, total)


def print_release(mesh, grid: tuple, resolution: int, physics: dict, release=None) -> tuple[np.ndarray, np.ndarray]:
    """A mesh's print release as a calibration of :data:`RELEASE_METHOD` makes it, mm^3 at the print's exact volume:
    ``grid`` the print's voxels (made with the physics' offset), ``physics`` the print physics. Without swelling the
    grid's release corrected for its bias is the exact release (:func:`bias_corrected_release`), so it is
    :func:`reference_fraction` times the print's volume and the grid is not simulated; with swelling it is the
    grid's release with the physics (``release``, a ``Release`` of ``grid``; simulated when None) corrected by
    :func:`grid_bias`."""
    from design.forward.simulator import simulate

    anisotropy, offset, swelling = (float(physics[p]) for p in ("anisotropy", "offset_mm", "swelling_mm"))
    if swelling == 0.0:
        tau, fraction = reference_fraction(mesh, resolution, anisotropy, offset)
        return tau, fraction * print_volume_mm3(mesh, offset)
    if release is None:
        rho, dx, mirror = grid
        release = simulate(rho, dx, mirror=mirror, anisotropy=anisotropy, swelling_mm=swelling)
    return bias_corrected_release(release.tau_mm, release.released_mm3, mesh, offset,
                                  grid_bias(mesh, grid, resolution, anisotropy, offset))


def _simulate(mesh, mesh_path: Path, resolution: int, physics: dict | None = None, grids: dict | None = None,
              method: str | None = None):
    """A mesh's simulated release with print physics: :func:`print_release` when ``method`` is
    :data:`RELEASE_METHOD`, else the grid's release at the print's exact volume (:func:`exact_volume_release`);
    ``grids`` caches voxelisations per (mesh, offset). Returns ``(tau_mm, released_mm3, dx_mm)``."""
    from design.errors import DesignError
    from design.files.pipeline import mesh_grid
    from design.forward.simulator import simulate

    physics = physics or PHYSICS_IDENTITY
    method = RELEASE_METHOD if method is None else method
    grids = {} if grids is None else grids
    try:
        key = (mesh_path, physics["offset_mm"])
        if key not in grids:
            grids[key] = mesh_grid(mesh, resolution=resolution, offset_mm=physics["offset_mm"])
        rho, dx, mirror = grids[key]
        if method == RELEASE_METHOD:
            return (*print_release(mesh, grids[key], resolution, physics), dx)
        release = simulate(rho, dx, mirror=mirror, anisotropy=physics["anisotropy"], swelling_mm=physics["swelling_mm"])
    except DesignError as exc:
        raise SimCalError(f"{mesh_path}: {exc}") from exc
    return release.tau_mm, exact_volume_release(release.released_mm3, mesh, physics["offset_mm"]), dx


def _make_out(out_dir: Path) -> None:
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SimCalError(f"cannot create {out_dir}: {exc.strerror or exc}") from exc


def _loo_summary(loo: tuple[LooShape, ...], rows: list[SetRow]) -> list[dict]:
    return [{"run": str(r.run), "mesh": str(r.mesh), "rel_rmse": s.rel_rmse,
             "seconds_per_mm": s.cal.seconds_per_mm,
             "saturation_g_per_kg": s.cal.saturation_g_per_kg} for s, r in zip(loo, rows)]


def calibrate_sim(set_csv: str | Path, bench_calibration: str | Path | None, out_dir: str | Path, *,
                  model: str = "auto", resolution: int = DEFAULT_RESOLUTION,
                  max_offset_s: float = DEFAULT_MAX_OFFSET_S, physics: str = "none", second_resolution: int | None = None,
                  progress: Progress | None = None) -> SimCalRun:
    """Calibrate the simulator against measured runs and write ``simcal.json``, ``loo.csv``, ``simcal.png``.

    Parameters
    ----------
    set_csv : str or Path
        ``run,mesh,object_mass_g`` rows; ``run`` is a run folder or a curve CSV, paths relative to the file;
        an empty mass is taken from the run's ``run.json``.
    bench_calibration : str or Path or None
        Bench calibration JSON to analyse run folders with (None: each run's own ``calibration.json``).
    out_dir : str or Path
        Output folder; refused if it already holds a calibration.
    model : {'auto', 'constant', 'saturation'}
        The model used for prediction; ``auto`` fits both and takes the one with the lower mean
        leave-one-out error (both are reported); a named model is the only one fitted.
    resolution : int
        Voxels along each mesh's longest side.
    max_offset_s : float
        Bound on each run's drop-time offset, s.
    second_resolution : int, optional
        The fitted print physics is refitted at this resolution too (default 1.5 x ``resolution``, at most
        the largest; 0: not): its estimated discretisation bias (:func:`analysis.simcal.with_discretisation`) is
        added in quadrature to each parameter's standard error, and recorded in ``physics.discretisation``.
    physics : str
        A set of ``analysis.simcal.PHYSICS_SETS`` (``none``, ``anisotropy``, ``offset``, ``swelling``, ``lag``,
        their combinations joined by ``+``, ``all``) or ``auto``: print physics to fit with the scales
        (:func:`analysis.simcal.fit_physics`): the build-direction anisotropy, the surface offset, the swelling
        width below which channels are shut, the wetting lag after the drop (shared by all runs; the per-run
        drop offsets of ``max_offset_s`` are then its jitter around it);
        ``none`` keeps the isotropic model of the mesh as designed; ``auto`` fits every subset and keeps the
        one leave-one-out prefers (a parameter must earn its place; the sets with the swelling width only when
        a shape has a channel the widest width searched would shut). The models of ``model`` are then
        fitted on the meshes simulated with the chosen physics.
    progress : callable, optional
        ``progress(fraction, message)`` before each run and each fit; it may raise ``KeyboardInterrupt`` to stop
        there (nothing is written into ``out_dir``).

    Returns
    -------
    SimCalRun

    Raises
    ------
    SimCalError
        Bad set file, run, mesh or calibration, with the file and row named; the same run listed twice.
    """
    say = progress or (lambda fraction, message: None)
    if model not in ("auto",) + MODELS:
        raise SimCalError(f"model {model!r} is not one of auto, {', '.join(MODELS)}")
    if physics not in PHYSICS_CHOICES:
        raise SimCalError(f"physics {physics!r} is not one of {', '.join(PHYSICS_CHOICES)}")
    if not MIN_RESOLUTION <= resolution <= MAX_RESOLUTION:
        raise SimCalError(f"resolution {resolution} is outside {MIN_RESOLUTION}..{MAX_RESOLUTION} voxels")
    second = (min(round(DISCRETISATION_FACTOR * resolution), MAX_RESOLUTION) if second_resolution is None
              else int(second_resolution))
    second = 0 if second == resolution and second_resolution is None else second   # at the largest resolution
    if second and not resolution < second <= MAX_RESOLUTION:
        raise SimCalError(f"second resolution {second} must be above the resolution {resolution} and at most "
                          f"{MAX_RESOLUTION} voxels (0: no discretisation term)")
    set_csv, out_dir = Path(set_csv), Path(out_dir)
    rows = read_set(set_csv)
    check_out(out_dir, FolderKind.SIMCAL, [set_csv, bench_calibration] + [p for r in rows for p in (r.run, r.mesh)],
              replace=False)
    operator = operators.require(f"calibrating the simulator into {out_dir}")
    bench = None
    if bench_calibration is not None:
        try:
            bench = BenchCalibration.load(bench_calibration)
        except (AnalysisError, OSError, ValueError, KeyError) as exc:
            raise SimCalError(f"{bench_calibration}: not a bench calibration ({exc})") from exc
    meshes = _check_inputs(set_csv, rows, bench)
    with folder_lock(out_dir):      # one writer (sfr calibrate-sim, the GUI's wizard); made here, after the checks
        _make_out(out_dir)
        return _fit_and_write(set_csv, rows, bench, bench_calibration, meshes, out_dir, model, resolution,
                              max_offset_s, say, operator, physics, second)


def _has_channels(grid: tuple) -> bool:
    """Whether a calibration shape's voxel grid has a channel the widest swelling width searched would shut."""
    from design.forward.swelling import shut_channels

    rho, dx, mirror = grid
    return bool(shut_channels(rho, dx, max(PHYSICS_GRIDS["swelling_mm"]), mirror).any())


def _physics_doc(fits: dict[str, PhysicsFit], chosen: str, rows: list[SetRow], discretisation: dict | None = None
                 ) -> dict:
    fit = fits[chosen]
    return {"fitted": list(fit.fitted), "choice": chosen, **{p: fit.values[p] for p in FIT_PARAMETERS},
            "uncertainty": dict(fit.uncertainty), **({"discretisation": discretisation} if discretisation else {}),
            "candidates": {name: {"fitted": list(f.fitted), "values": f.values, "uncertainty": f.uncertainty,
                                  "loss": f.loss, "loo_rel_rmse_mean": f.loo_rel_rmse_mean,
                                  "loo": [{"run": str(r.run), "rel_rmse": s.rel_rmse, "values": v}
                                          for s, r, v in zip(f.loo, rows, f.loo_values)]}
                           for name, f in fits.items()}}


def _fit_and_write(set_csv: Path, rows: list[SetRow], bench, bench_calibration, meshes: dict, out_dir: Path,
                   model: str, resolution: int, max_offset_s: float, say: Progress, operator,
                   physics: str = "none", second_resolution: int = 0) -> SimCalRun:
    """The work of :func:`calibrate_sim` on checked inputs, into the locked ``out_dir``."""
    measured = []
    n = len(rows)
    simulated: dict[tuple, tuple] = {}   # (mesh, anisotropy, offset, swelling) -> (tau, volume, dx)
    grids: dict[tuple, tuple] = {}       # (mesh, offset) -> voxel grid

    def simulation(row: SetRow, values: dict) -> tuple:
        key = (row.mesh, *(round(values[p], 9) for p in PHYSICS_PARAMETERS))
        if key not in simulated:
            simulated[key] = _simulate(meshes[row.mesh], row.mesh, resolution, values, grids)
        return simulated[key]

    def shapes_at(values: dict) -> list[ShapeRun]:
        out = []
        for row, (where, t, g, mass, water) in zip(rows, measured):
            tau, vol, _ = simulation(row, values)
            try:
                out.append(ShapeRun(f"{where} ({row.run.name}, {row.mesh.name})", tau, vol, t, g, mass, water))
            except AnalysisError as exc:
                raise SimCalError(str(exc)) from exc
        return out

    curves = []
    for k, row in enumerate(rows):
        where = f"{set_csv.name} row {row.row}"
        say(0.6 * k / n if physics == "none" else 0.1 * k / n,
            f"{where}: reading {row.run.name} and simulating {row.mesh.name} ...")
        try:
            curve = read_physical_curve(row.run, calibration=bench)
        except CurveFileError as exc:
            raise SimCalError(f"{where}: {exc}") from exc
        mass = row.object_mass_g or curve.object_mass_g
        if mass is None:
            raise SimCalError(f"{where}: object_mass_g is empty and {row.run} records no weighed mass")
        water = row.water_g or curve.water_g or (bench.water_g if bench is not None else None)
        if water is None:
            raise SimCalError(f"{where}: {row.run} records no water mass; give it in a water_g column or give "
                              "the bench calibration")
        keep = curve.t_s >= 0
        measured.append((where, curve.t_s[keep], curve.released_g[keep], float(mass), float(water)))
        curves.append(curve)
        simulation(row, PHYSICS_IDENTITY)
    physics_fits: dict[str, PhysicsFit] = {}
    chosen_physics = "none"
    if physics != "none":
        names = [m for m in PHYSICS_SETS if physics == "auto" or m in ("none", physics)]
        if physics == "auto" and not any(_has_channels(grids[(row.mesh, 0.0)]) for row in rows):
            # no shape has a channel the widest swelling width would shut: its release cannot tell the width
            names = [m for m in names if "swelling_mm" not in PHYSICS_SETS[m]]
        for j, name in enumerate(names):
            base, span = 0.1 + 0.5 * j / len(names), 0.5 / len(names)
            say(base, f"fitting print physics '{name}' and its leave-one-out ...")
            try:
                physics_fits[name] = fit_physics(
                    shapes_at, PHYSICS_SETS[name], max_offset_s=max_offset_s, offset_floor_mm=0.5 * float(
                        np.median([simulation(row, PHYSICS_IDENTITY)[2] for row in rows])),
                    progress=lambda done, total, name=name, base=base, span=span: say(
                        base + span * done / total, f"print physics '{name}': {done} of {total} fits"))
            except AnalysisError as exc:
                raise SimCalError(f"{set_csv}: {exc}") from exc
        chosen_physics = choose_physics(physics_fits) if physics == "auto" else physics
    values = physics_fits[chosen_physics].values if physics_fits else dict(FIT_IDENTITY)
    lag = bool(physics_fits) and LAG in physics_fits[chosen_physics].fitted
    discretisation = None
    if physics_fits and physics_fits[chosen_physics].fitted and second_resolution:
        say(0.6, f"print physics '{chosen_physics}' refitted at resolution {second_resolution} (discretisation) ...")
        fine: dict[tuple, tuple] = {}
        fine_grids: dict[tuple, tuple] = {}

        def fine_shapes_at(v: dict) -> list[ShapeRun]:
            out = []
            for row, (where, t, g, mass, water) in zip(rows, measured):
                key = (row.mesh, *(round(v[p], 9) for p in PHYSICS_PARAMETERS))
                if key not in fine:
                    fine[key] = _simulate(meshes[row.mesh], row.mesh, second_resolution, v, fine_grids)
                out.append(ShapeRun(f"{where} ({row.run.name}, {row.mesh.name})", *fine[key][:2], t, g, mass, water))
            return out

        fit_r = physics_fits[chosen_physics]
        try:
            refit = refit_physics(fine_shapes_at, fit_r.fitted, values, max_offset_s=max_offset_s)
        except AnalysisError as exc:
            raise SimCalError(f"{set_csv}: {exc}") from exc
        combined, bias = with_discretisation(fit_r.uncertainty, values, refit,
                                             second_resolution / resolution)
        discretisation = {"resolution": second_resolution, "values": {p: refit[p] for p in fit_r.fitted},
                          "bias": bias, "uncertainty_refits": dict(fit_r.uncertainty)}
        physics_fits[chosen_physics] = dataclasses.replace(fit_r, uncertainty=combined)
    shapes = shapes_at(values)
    dxs = [simulation(row, values)[2] for row in rows]
    fits, loos = {}, {}
    models = MODELS if model == "auto" else (model,)
    for j, name in enumerate(models):
        base, span = 0.6 + 0.35 * j / len(models), 0.35 / len(models)
        say(base, f"fitting the {name} model to all {n} runs ...")
        fits[name] = fit_simcal(shapes, name, max_offset_s=max_offset_s, lag=lag)
        loos[name] = leave_one_out(shapes, name, max_offset_s=max_offset_s, lag=lag,
                                   progress=lambda done, total, name=name, base=base, span=span: say(
                                       base + span * done / total, f"{name} model: left {done} of {total} out"))
    mean_loo = {m: float(np.mean([s.rel_rmse for s in loos[m]])) for m in models}
    chosen = min(models, key=mean_loo.get)
    fit = fits[chosen]
    doc = {
        "format": FORMAT,
        "forward_model": FORWARD_MODEL,
        "release_method": RELEASE_METHOD,
        "model": chosen,
        "seconds_per_mm": fit.cal.seconds_per_mm,
        "g_per_mm3": fit.cal.g_per_mm3,
        "density_g_per_cm3": fit.cal.g_per_mm3 * 1000.0,
        "saturation_g_per_kg": fit.cal.saturation_g_per_kg,
        "water_g": float(np.median([s.water_g for s in shapes])),
        "resolution": resolution,
        "voxel_size_mm": float(np.median(dxs)),
        "physics": (_physics_doc(physics_fits, chosen_physics, rows, discretisation) if physics_fits else
                    {"fitted": [], "choice": "none", **FIT_IDENTITY, "uncertainty": {}, "candidates": {}}),
        "loss": fit.loss,
        "loo": _loo_summary(loos[chosen], rows),
        "loo_rel_rmse_mean": mean_loo[chosen],
        "models": {m: {"seconds_per_mm": fits[m].cal.seconds_per_mm,
                       "saturation_g_per_kg": fits[m].cal.saturation_g_per_kg, "loss": fits[m].loss,
                       "loo_rel_rmse_mean": mean_loo[m], "loo": _loo_summary(loos[m], rows)} for m in models},
        "shapes": [{"run": str(r.run), "mesh": str(r.mesh), "object_mass_g": s.mass_g, "water_g": s.water_g,
                    "volume_mm3": s.volume_mm3, "g_per_mm3": g, "offset_s": o, "loss": L,
                    "measured_until_s": float(s.t_s[-1]),
                    "measured_fraction": float(np.max(s.released_g) / s.mass_g)}
                   for r, s, g, o, L in zip(rows, shapes, fit.g_per_mm3_per_shape, fit.offsets_s,
                                            fit.loss_per_shape)],
        "max_offset_s": max_offset_s,
        "inputs_sha256": _input_hashes(set_csv, bench_calibration, rows),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "operator": operator,
    }
    doc["physics"][LAG] = fit.cal.lag_s   # the prediction model's own lag (the same fit for the constant model)
    say(0.95, "error bands: each run's leave-one-out prediction against the band from the other runs ...")
    honest = physics_fits.get(chosen_physics)   # with print physics, the leave-one-out that refits it
    doc["band"] = band_block(honest.loo if honest else loos[chosen], shapes, honest.loo_values if honest else None,
                             doc["physics"]["uncertainty"], lambda i, values: simulation(rows[i], values)[:2])
    say(0.96, f"writing {out_dir} ...")
    atomic_write(out_dir / "simcal.json", (json.dumps(doc, indent=2) + "\n").encode())
    lines = ["run,mesh,model,rel_rmse,seconds_per_mm_without_it"]
    for m in models:
        lines += [f"{r.run},{r.mesh},{m},{s.rel_rmse:.6f},{s.cal.seconds_per_mm:.3f}" for s, r in zip(loos[m], rows)]
    atomic_write(out_dir / "loo.csv", ("\n".join(lines) + "\n").encode())
    plot_loo(loos[chosen], [f"{r.run.name}\n{r.mesh.name}" for r in rows], out_dir / "simcal.png",
             f"leave-one-out predictions ({chosen} model, {fit.cal.seconds_per_mm:.0f} s/mm, "
             f"{fit.cal.g_per_mm3 * 1000:.3f} g/cm^3)")
    audit(out_dir, Action.CALIBRATE, f"simulation calibration simcal.json from {n} runs of {set_csv.name}: "
          f"{chosen} model, {fit.cal.seconds_per_mm:.1f} s/mm", operator=operator)
    say(1.0, f"{chosen} model: {fit.cal.seconds_per_mm:.1f} s/mm, mean leave-one-out error "
             f"{100 * mean_loo[chosen]:.2f}% of the weighed mass")
    return SimCalRun(doc, loos[chosen], out_dir / "simcal.json")


def _input_hashes(set_csv: Path, bench_calibration, rows: list[SetRow]) -> dict[str, str]:
    files = [set_csv] + ([Path(bench_calibration)] if bench_calibration is not None else [])
    for r in rows:
        files.append(r.mesh)
        if r.run.is_dir():
            files += [p for p in (r.run / "frames.csv", r.run / "run.json", r.run / "calibration.json") if p.is_file()]
        else:
            files.append(r.run)
    return {str(p): sha256_file(p) for p in files}


def plot_loo(loo: tuple[LooShape, ...], labels: list[str], path: Path, title: str) -> None:
    """Each shape's measured release against its leave-one-out prediction, grams over hours (Fig. 8)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = min(len(loo), 3)
    nrows = math.ceil(len(loo) / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols, 3.2 * nrows), dpi=110, squeeze=False,
                             sharey=True)
    for ax, s, label in zip(axes.flat, loo, labels):
        ax.plot(s.t_s / 3600.0, s.measured_g, color="C0", lw=2, label="measured")
        ax.plot(s.t_s / 3600.0, s.predicted_g, "--", color="C3", lw=1.5, label="predicted (left out)")
        ax.set_title(f"{label}\nrel. RMSE {100 * s.rel_rmse:.2f}%", fontsize=8)
        ax.set_xlabel("time (h)")
        ax.grid(alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("released (g)")
    for ax in list(axes.flat)[len(loo):]:
        ax.axis("off")
    axes[0, 0].legend(loc="lower right", fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


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
    return SimCalFile(cal, resolution, dx, water, path, physics, band, method)


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
