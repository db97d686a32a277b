"""One-call simulation of a mesh or an input file: voxelise, then simulate (what `sfr simulate` runs)."""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import trimesh

from design._validate import check_positive
from design.errors import DesignError
from design.files.meshio import DENSITY_SUFFIXES, checked_mesh, load_density, load_mesh
from design.forward.simulator import Release, simulate
from design.geometry.bodies import mirror_mismatch
from design.geometry.shapes import sample_shape
from design.geometry.voxelize import DEFAULT_RESOLUTION, grid_for, voxelize

log = logging.getLogger(__name__)

SAMPLE_PREFIX = "sample:"
_AXES = "xyz"
SYMMETRY_TOLERANCE = 0.005
"""Largest fraction of a solid's volume, voxelised, that may lack a mirror image about a claimed mirror
plane: the release error a mirrored simulation then makes is of this order, below the simulation's
own discretisation error at its default resolution."""


def parse_symmetry(symmetry: str, ndim: int = 3) -> tuple[bool, ...]:
    """Mirror flags from axis letters, e.g. ``"xz"`` -> (True, False, True); axis a is x, y, z."""
    letters = symmetry.lower()
    unknown = set(letters) - set(_AXES[:ndim])
    if unknown:
        raise DesignError(f"symmetry {symmetry!r} names unknown axes {sorted(unknown)}; use letters of {_AXES[:ndim]!r}")
    return tuple(axis in letters for axis in _AXES[:ndim])


OFFSET_BAND_VOXELS = 3
"""Voxels within this many voxels of the offset surface (by the voxelisation's own distance transform) are
classified by the mesh's exact signed distance; the distance transform's error is below one voxel."""


def offset_solid(mesh: trimesh.Trimesh, dx_mm: float, offset_mm: float, mirror: tuple[bool, ...]
                 ) -> np.ndarray:
    """Voxel centres inside the mesh grown by ``offset_mm`` (shrunk if negative): {signed distance > -offset}.

    The grid is the one :func:`voxelize` would use on the mesh's bounds widened by ``max(offset, 0)`` on
    every side (same centre, so mirror planes stay put). Near the offset surface the mesh's exact signed
    distance (:func:`design.forward.reference.signed_distance`) decides; elsewhere the voxelisation's
    distance transform, whose sign there is certain.
    """
    from scipy import ndimage

    from design.forward.reference import signed_distance

    grow = max(float(offset_mm), 0.0)
    lo, hi = mesh.bounds
    origin, shape = grid_for(np.array([lo - grow, hi + grow]), dx_mm, mirror)
    inside = voxelize(mesh, dx_mm, origin_mm=origin, shape=shape)
    if offset_mm == 0.0:
        return inside
    # one voxel of bath around the grid (none across a mirror plane): a solid that fills its grid (a box shrunk by
    # the offset) has outside voxels for the transform to measure from
    pad = [(0 if m else 1, 1) for m in mirror]
    core = tuple(slice(p[0], p[0] + n) for p, n in zip(pad, inside.shape))
    padded = np.pad(inside, pad)
    rough = np.where(inside, ndimage.distance_transform_edt(padded, sampling=dx_mm)[core],
                     -ndimage.distance_transform_edt(~padded, sampling=dx_mm)[core])
    # a half grid's transform is exact: for a point on the kept side of a mirror plane the nearest voxel of
    # the other kind is never only across the plane, since its mirror image on this side is no farther
    band = np.abs(rough + offset_mm) <= OFFSET_BAND_VOXELS * dx_mm
    solid = rough > -offset_mm
    centres = origin + (np.argwhere(band) + 0.5) * dx_mm
    solid[band] = signed_distance(mesh, centres) > -offset_mm
    return solid


def offset_mesh(mesh: trimesh.Trimesh, offset_mm: float, dx_mm: float) -> trimesh.Trimesh:
    """The closed surface the mesh's grows to when moved ``offset_mm`` outward (inward if negative).

    The solid {signed distance > -offset} is sampled at the centres of a grid of edge ``dx_mm`` (the mesh's exact
    signed distance within `OFFSET_BAND_VOXELS` of the new surface, :func:`offset_solid`'s), and its surface is
    the marching-cubes contour of that distance, placed to within a small fraction of ``dx_mm`` where the
    surface is smooth (edges and corners round off by the offset, as a ball rolled over them).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Closed mesh, mm.
    offset_mm : float
        Outward offset, mm (negative: shrink; a shrink of half the thinnest wall or more removes that wall).
    dx_mm : float
        Sampling edge, mm.

    Returns
    -------
    trimesh.Trimesh
        Watertight, outward normals.
    """
    from scipy import ndimage

    from design.fabrication.extract import density_mesh
    from design.forward.reference import signed_distance

    dx = check_positive("dx_mm", dx_mm)
    offset = float(offset_mm)
    lo, hi = mesh.bounds
    grow = max(offset, 0.0) + 2.0 * dx
    origin, shape = grid_for(np.array([lo - grow, hi + grow]), dx)
    inside = voxelize(mesh, dx, origin_mm=origin, shape=shape)
    sd = np.where(inside, ndimage.distance_transform_edt(inside, sampling=dx),
                  -ndimage.distance_transform_edt(~inside, sampling=dx))
    band = np.abs(sd + offset) <= OFFSET_BAND_VOXELS * dx
    sd[band] = signed_distance(mesh, origin + (np.argwhere(band) + 0.5) * dx)
    # a field linear in the distance across the surface: its 1/2 contour is {signed distance = -offset}
    return density_mesh(np.clip(0.5 + (sd + offset) / dx, 0.0, 1.0), dx, origin, level=0.5)


def mesh_grid(mesh: trimesh.Trimesh, *, resolution: int | None = None, voxel_size_mm: float | None = None,
              symmetry: str = "", offset_mm: float = 0.0) -> tuple[np.ndarray, float, tuple[bool, ...]]:
    """Voxelise a closed mesh at its voxel centres (parameters as for :func:`simulate_mesh`).

    With ``offset_mm`` the solid voxelised is the mesh's surface moved outward by that distance (inward if
    negative): a print larger or smaller than its mesh. The voxel size still follows the mesh's own extent.

    Returns
    -------
    rho : (X, Y, Z) ndarray of float in {0, 1}
    dx_mm : float
    mirror : tuple of bool
    """
    mesh = checked_mesh(mesh)
    if resolution is not None and voxel_size_mm is not None:
        raise DesignError("give either resolution or voxel_size_mm, not both")
    if voxel_size_mm is None:
        n = DEFAULT_RESOLUTION if resolution is None else int(resolution)
        if n < 2:
            raise DesignError(f"resolution must be >= 2 voxels, got {resolution}")
        dx = float(mesh.extents.max()) / n
    else:
        dx = check_positive("voxel_size_mm", voxel_size_mm)
    mirror = parse_symmetry(symmetry)
    if any(mirror):
        check_symmetric(mesh, dx, mirror)
    offset = float(offset_mm)
    if not np.isfinite(offset) or offset <= -0.5 * float(mesh.extents.min()):
        raise DesignError(f"offset_mm {offset_mm} must be finite and above -half the mesh's thinnest extent")
    rho = (voxelize(mesh, dx, mirror=mirror) if offset == 0.0 else offset_solid(mesh, dx, offset, mirror)).astype(np.float64)
    log.info("voxelised to %s voxels of %.4g mm (mirror %s, offset %g mm)", rho.shape, dx, mirror, offset)
    return rho, dx, mirror


def check_symmetric(mesh: trimesh.Trimesh, dx_mm: float, mirror: tuple[bool, ...]) -> None:
    """Refuse mirror planes (through the bounding-box centre) that the mesh is not symmetric about.

    Raises
    ------
    DesignError
        When more than `SYMMETRY_TOLERANCE` of the solid's volume, voxelised at `dx_mm`, has no mirror
        image about a claimed plane; the message says how far off each such plane is.
    """
    full = voxelize(mesh, dx_mm)
    centre = mesh.bounds.mean(axis=0)
    off = []
    for axis, m in enumerate(mirror):
        if m:
            miss = mirror_mismatch(full, tuple(a == axis for a in range(3)))
            if miss > SYMMETRY_TOLERANCE:
                off.append(f"{_AXES[axis]} = {centre[axis]:.4g} mm ({miss:.1%} of the volume has no mirror image)")
    if off:
        raise DesignError(f"--symmetry {''.join(_AXES[a] for a in range(3) if mirror[a])}: the shape is not "
                          f"symmetric about the plane {'; nor about '.join(off)}; at most {SYMMETRY_TOLERANCE:.1%} "
                          "may differ. Drop the axes it is not symmetric about")


def simulate_mesh(mesh: trimesh.Trimesh, *, resolution: int | None = None, voxel_size_mm: float | None = None,
                  symmetry: str = "", anisotropy: float = 1.0, offset_mm: float = 0.0,
                  swelling_mm: float = 0.0) -> Release:
    """Voxelise a closed mesh at its voxel centres and simulate its release.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Watertight mesh, mm.
    resolution : int, optional
        Voxels along the longest bounding-box side (default 64 when `voxel_size_mm` is not given).
    voxel_size_mm : float, optional
        Voxel edge length, mm; exclusive with `resolution`.
    symmetry : str
        Axis letters (``"x"``, ``"xy"``, ``"xyz"``) with a mirror plane through the bounding-box centre;
        only the half/quadrant/octant above the planes is simulated. Use it only for shapes that are
        symmetric about those planes.
    anisotropy : float
        Erosion speed along z over the in-plane speed (``design.forward.simulator.simulate``).
    offset_mm : float
        The printed surface lies this far outside the mesh's (inside if negative), mm.
    swelling_mm : float
        Channels of the print narrower than this are shut until their walls dissolve, mm
        (``design.forward.simulator.simulate``).

    Returns
    -------
    Release
        Its `released_mm3` is always the full object's (mirror copies included).
    """
    rho, dx, mirror = mesh_grid(mesh, resolution=resolution, voxel_size_mm=voxel_size_mm, symmetry=symmetry,
                                offset_mm=offset_mm)
    return simulate(rho, dx, mirror=mirror, anisotropy=anisotropy, swelling_mm=swelling_mm)


def input_grid(spec: str, *, resolution: int | None = None, voxel_size_mm: float | None = None,
               symmetry: str = "", offset_mm: float = 0.0) -> tuple[np.ndarray, float, tuple[bool, ...]]:
    """The density grid of ``sample:NAME``, a mesh file or a density array file.

    ``offset_mm`` moves a mesh's surface outward (:func:`mesh_grid`); a density array is its own solid and
    takes no offset.

    For a density array (``.npy`` needs `voxel_size_mm`; ``.npz`` stores ``dx_mm``), the array is the
    simulated grid itself and `symmetry` puts mirror planes at the index-0 faces of the named axes.

    Returns
    -------
    rho : ndarray of float in [0, 1]
    dx_mm : float
    mirror : tuple of bool
    """
    if spec.startswith(SAMPLE_PREFIX):
        return mesh_grid(sample_shape(spec[len(SAMPLE_PREFIX):]), resolution=resolution,
                         voxel_size_mm=voxel_size_mm, symmetry=symmetry, offset_mm=offset_mm)
    if Path(spec).suffix.lower() in DENSITY_SUFFIXES:
        if resolution is not None:
            raise DesignError(f"{spec}: --resolution applies to meshes; a density array has its own grid")
        rho, dx = load_density(spec, voxel_size_mm)
        return rho, dx, parse_symmetry(symmetry, rho.ndim)
    return mesh_grid(load_mesh(spec), resolution=resolution, voxel_size_mm=voxel_size_mm, symmetry=symmetry,
                     offset_mm=offset_mm)
