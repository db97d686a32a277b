"""A calibration mesh's print release: the print's exact volume and the grid's bias against the exact release.

The release a simulation calibration (:mod:`labapp.jobs.calibrate_sim`) fits and a physical prediction
(:mod:`labapp.jobs.bands`) makes from a mesh, with the print physics (build-direction anisotropy, surface offset,
swelling width): the forward model's grid release rescaled to the print's exact volume (:func:`print_volume_mm3`,
:func:`exact_volume_release`), plus, for ``simcal.json``'s ``release_method`` ``grid+reference-bias``, the grid's
discretisation bias against the reference evaluator's release by exact surface distances (:func:`grid_bias`,
:func:`print_release`). :func:`mesh_release` makes either for one mesh.
"""
from __future__ import annotations

import hashlib
import math
import threading
from pathlib import Path

import numpy as np

from analysis.physics_grid import PHYSICS_GRIDS, PHYSICS_IDENTITY
from labapp.records.simcal import RELEASE_METHOD, SimCalError


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
    The one place where calibration (:func:`labapp.jobs.calibrate_sim.calibrate_sim`) and physical predictions
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
_CACHE_LOCK = threading.Lock()   # the meshes of a calibration are released on several threads


def _remember(cache: dict, key: tuple, value):
    with _CACHE_LOCK:
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


def _reference(mesh, resolution: int, anisotropy: float, interpolated: bool = False
               ) -> tuple[np.ndarray, np.ndarray, object]:
    """The reference evaluator's release of ``mesh`` as designed in the metric of anisotropy a: its release with z
    scaled by 1 / a (``design.forward.reference.reference_release`` on ``design_lattice(resolution)``), on
    `BIAS_SAMPLES` depths from 0 to half the scaled mesh's largest extent (no point lies deeper). Returns
    ``(tau_mm, released_mm3, scaled_mesh)``, volumes in the scaled space. Cached per mesh, lattice and a.

    With ``interpolated``, an a between the calibration's anisotropy grid points (``PHYSICS_GRIDS``) is not
    evaluated: its released fraction is the quadratic interpolation in log a of the three nearest grid points'
    (:func:`_interpolated_reference`)."""
    from design.forward.reference import design_lattice, metric_mesh, reference_release

    a = float(anisotropy)
    if interpolated and _off_grid(a):
        return _interpolated_reference(mesh, resolution, a)
    cells = design_lattice(resolution)
    key = (_mesh_digest(mesh), int(cells), round(a, 9), BIAS_SAMPLES)
    hit = _REFERENCE_CACHE.get(key)
    if hit is None:
        scaled = metric_mesh(mesh, a)
        tau = np.linspace(0.0, 0.5 * float(np.max(scaled.extents)), BIAS_SAMPLES)
        ref = reference_release(scaled, tau, cells=cells)
        hit = _remember(_REFERENCE_CACHE, key, (tau, np.asarray(ref.released_mm3, float), scaled))
    return hit


def _off_grid(anisotropy: float) -> bool:
    """Whether an anisotropy lies strictly inside the calibration's grid and on none of its points."""
    grid = PHYSICS_GRIDS["anisotropy"]
    return grid[0] < anisotropy < grid[-1] and min(abs(math.log(anisotropy / g)) for g in grid) > 1e-9


def _interpolated_reference(mesh, resolution: int, anisotropy: float) -> tuple[np.ndarray, np.ndarray, object]:
    """:func:`_reference` at an anisotropy between grid points: the released fractions of the three grid points
    nearest in log a, on this a's depths, combined by Lagrange's quadratic in log a, times the scaled mesh's
    volume. The grid's step is a factor 1.12; against the evaluated release of the demo's spinner_top and csg at
    a = 0.74, 0.84 and 0.95 the interpolation differs by at most 0.06 % of the volume (0.01 % RMS), which is the
    quadrature's own noise at 80 cells: a calibration's search and leave-one-out refits evaluate the grid only."""
    from design.forward.reference import metric_mesh

    grid = [math.log(g) for g in PHYSICS_GRIDS["anisotropy"]]
    x = math.log(anisotropy)
    i = min(max(int(np.argmin([abs(x - g) for g in grid])), 1), len(grid) - 2)
    xs = grid[i - 1:i + 2]
    scaled = metric_mesh(mesh, anisotropy)
    tau = np.linspace(0.0, 0.5 * float(np.max(scaled.extents)), BIAS_SAMPLES)
    fraction = np.zeros_like(tau)
    for j, xj in enumerate(xs):
        weight = math.prod((x - xk) / (xj - xk) for k, xk in enumerate(xs) if k != j)
        tau_j, released_j, scaled_j = _reference(mesh, resolution, math.exp(xj))
        fraction += weight * np.interp(tau, tau_j, released_j / float(scaled_j.volume))
    return tau, fraction * float(scaled.volume), scaled


def exact_print(mesh, resolution: int, anisotropy: float, offset_mm: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The release of a mesh's print with a surface offset by the reference evaluator
    (``design.forward.reference.reference_release`` with ``offset_mm``: the print {signed distance > -o} released
    by exact surface distances at anisotropy a, on ``design_lattice(resolution)``), on `BIAS_SAMPLES` depths from 0
    to past its end. Returns ``(tau_mm, released_mm3, volume_mm3)``, the volume the quadrature's. Cached per mesh,
    lattice, a and offset."""
    from design.forward.offset_lattice import largest_offset
    from design.forward.reference import design_lattice, metric_mesh, reference_release

    a, o = float(anisotropy), float(offset_mm)
    cells = design_lattice(resolution)
    key = (_mesh_digest(mesh), int(cells), round(a, 9), round(o, 9), BIAS_SAMPLES, "print")
    hit = _REFERENCE_CACHE.get(key)
    if hit is None:
        end = 0.5 * float(np.max(metric_mesh(mesh, a).extents)) + largest_offset(o, a)
        tau = np.linspace(0.0, end, BIAS_SAMPLES)
        ref = reference_release(mesh, tau, cells=cells, anisotropy=a, offset_mm=o)
        released = np.maximum.accumulate(np.asarray(ref.released_mm3, float))
        hit = _remember(_REFERENCE_CACHE, key, (tau, released, float(released[-1])))
    return hit


def reference_fraction(mesh, resolution: int, anisotropy: float = 1.0, offset_mm: float = 0.0,
                       interpolated: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The released fraction of a mesh's print by exact surface distances, with build-direction anisotropy a and
    the print's surface moved by ``offset_mm``. Without ``interpolated`` (a prediction) it is :func:`exact_print`'s:
    the print released by the reference evaluator itself. With it (a calibration's search and leave-one-out refits,
    which try many offsets) it is :func:`_reference` of the mesh as designed, then the offset applied by formula,
    which needs no evaluation per offset; on the demo's calibration prints the two agree within 0.25% of the volume
    at offsets of +-0.1-0.2 mm and anisotropies 0.75-1.3 (docs/evidence/forward.md):

    - In the isotropic metric a solid grown by d (its Minkowski sum with a ball) has every inner point exactly d
      deeper (a point at depth r of K is at depth r + d of K + B_d), and the added shell releases first:
      ``R_d(tau) = V(d) - V(d - tau)`` for tau < d, ``V(d) - V + R(tau - d)`` after, V(s) the grown volume (Steiner,
      :func:`print_volume_mm3` of the scaled mesh). A solid shrunk by d keeps the points deeper than d, each d
      shallower: ``R_-d(tau) = R(tau + d) - R(d)``.
    - d is the offset in the metric (:func:`metric_offset_mm`): exact for a = 1, an area-weighted mean of the
      faces' distances otherwise.

    ``interpolated``: an anisotropy between the calibration's grid points is interpolated (:func:`_reference`).

    Returns
    -------
    tau_mm, fraction : (K,) ndarray of float
        Erosion depths (0 to the end) and the released fraction at them, non-decreasing to 1 at the end.
    """
    if float(offset_mm) != 0.0 and not interpolated:
        tau, released, volume = exact_print(mesh, resolution, anisotropy, offset_mm)
        return tau, released / volume
    tau0, released0, scaled = _reference(mesh, resolution, anisotropy, interpolated)
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


def grid_bias(mesh, grid: tuple, resolution: int, anisotropy: float = 1.0, offset_mm: float = 0.0,
              interpolated: bool = False) -> tuple[np.ndarray, np.ndarray]:
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
           tuple(bool(m) for m in mirror), int(resolution), round(anisotropy, 9), round(offset_mm, 9), interpolated)
    hit = _BIAS_CACHE.get(key)
    if hit is not None:
        return hit
    grid_release = simulate(rho, dx, mirror=mirror, anisotropy=anisotropy)
    g_tau, g_vol = np.asarray(grid_release.tau_mm, float), np.asarray(grid_release.released_mm3, float)
    if not (g_vol.size and g_vol[-1] > 0):
        raise SimCalError("the mesh's voxel grid holds no solid; expected a closed mesh in mm")
    r_tau, r_fraction = reference_fraction(mesh, resolution, anisotropy, offset_mm, interpolated)
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


def print_release(mesh, grid: tuple, resolution: int, physics: dict, release=None, interpolated: bool = False
                  ) -> tuple[np.ndarray, np.ndarray]:
    """A mesh's print release as a calibration of :data:`RELEASE_METHOD` makes it, mm^3 at the print's exact volume:
    ``grid`` the print's voxels (made with the physics' offset), ``physics`` the print physics. Without swelling the
    grid's release corrected for its bias is the exact release (:func:`bias_corrected_release`), so it is
    :func:`reference_fraction` times the print's volume (a prediction's print with an offset: :func:`exact_print`,
    its volume the evaluator's) and the grid is not simulated; with swelling it is the
    grid's release with the physics (``release``, a ``Release`` of ``grid``; simulated when None) corrected by
    :func:`grid_bias`. ``interpolated``: an anisotropy between the calibration's grid points is interpolated
    (:func:`_reference`)."""
    from design.forward.simulator import simulate

    anisotropy, offset, swelling = (float(physics[p]) for p in ("anisotropy", "offset_mm", "swelling_mm"))
    if swelling == 0.0 and offset != 0.0 and not interpolated:
        return exact_print(mesh, resolution, anisotropy, offset)[:2]
    if swelling == 0.0:
        tau, fraction = reference_fraction(mesh, resolution, anisotropy, offset, interpolated)
        return tau, fraction * print_volume_mm3(mesh, offset)
    if release is None:
        rho, dx, mirror = grid
        release = simulate(rho, dx, mirror=mirror, anisotropy=anisotropy, swelling_mm=swelling)
    return bias_corrected_release(release.tau_mm, release.released_mm3, mesh, offset,
                                  grid_bias(mesh, grid, resolution, anisotropy, offset, interpolated))


def mesh_release(mesh, mesh_path: Path, resolution: int, physics: dict | None = None, grids: dict | None = None,
                 method: str | None = None, interpolated: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    """A mesh's simulated release with print physics: :func:`print_release` when ``method`` is
    :data:`RELEASE_METHOD`, else the grid's release at the print's exact volume (:func:`exact_volume_release`).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The designed mesh, mm.
    mesh_path : Path
        Its file: the key of its grids in ``grids`` and its name in messages.
    resolution : int
        Voxels along the mesh's longest side.
    physics : dict, optional
        Print physics (``anisotropy``, ``offset_mm``, ``swelling_mm``); None: the identity.
    grids : dict, optional
        Voxelisations cached per (mesh, offset), filled here.
    method : str, optional
        A ``release_method`` of ``simcal.json``; None: :data:`RELEASE_METHOD`.
    interpolated : bool
        An anisotropy between the calibration's grid points is interpolated from theirs (:func:`_reference`):
        what a calibration's search and leave-one-out refits use.

    Returns
    -------
    tau_mm, released_mm3 : (K,) ndarray of float
        Erosion depths, mm, and the released volume at them, mm^3.
    dx_mm : float
        The grid's voxel edge, mm.

    Raises
    ------
    SimCalError
        The mesh's file named, when its grid cannot be made or simulated.
    """
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
            return (*print_release(mesh, grids[key], resolution, physics, interpolated=interpolated), dx)
        release = simulate(rho, dx, mirror=mirror, anisotropy=physics["anisotropy"], swelling_mm=physics["swelling_mm"])
    except DesignError as exc:
        raise SimCalError(f"{mesh_path}: {exc}") from exc
    return release.tau_mm, exact_volume_release(release.released_mm3, mesh, physics["offset_mm"]), dx

