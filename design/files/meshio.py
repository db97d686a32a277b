"""Loading simulation inputs from disk: triangle meshes (mm) and density arrays, with clear errors."""
from __future__ import annotations

import logging
import zipfile
import zlib
from pathlib import Path

import numpy as np
import trimesh

from design._validate import DENSITY_SUFFIXES, MESH_SUFFIXES, check_density, check_positive
from design.errors import DesignError
from design.geometry.bodies import solid_mesh

log = logging.getLogger(__name__)


def load_mesh(path: str | Path, mm_per_unit: float = 1.0) -> trimesh.Trimesh:
    """Load a closed triangle mesh (STL, OBJ, PLY, OFF, 3MF; multi-body files are merged), in mm: its coordinates
    times ``mm_per_unit`` (25.4 for a file drawn in inches), before its bodies are checked and united.

    Raises
    ------
    DesignError
        When the file is missing, unreadable, empty, has non-finite vertices or is not watertight;
        the message names the file.
    """
    path = Path(path)
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise DesignError(f"{path}: unsupported mesh format {path.suffix!r}; use one of {', '.join(MESH_SUFFIXES)}")
    if not path.is_file():
        raise DesignError(f"{path}: no such file")
    try:
        # unprocessed first: processing would silently drop non-finite vertices and leave a hole
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for a bad file
        raise DesignError(f"{path}: cannot read mesh ({exc})") from exc
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        kind = path.suffix[1:].upper()
        a_kind = ("an " if kind[0] in "SO" else "a ") + kind   # an STL, an OBJ, an OFF; a PLY, a 3MF
        raise DesignError(f"{path}: empty file; expected {a_kind} triangle mesh in mm" if path.stat().st_size == 0 else
                          f"{path}: not {a_kind} mesh (no triangles could be read from it); expected a closed "
                          f"triangle mesh in mm saved as {kind}")
    _check_finite(loaded.vertices, str(path), per_facet=path.suffix.lower() == ".stl")
    return checked_mesh(trimesh.Trimesh(loaded.vertices * mm_per_unit, loaded.faces, process=True), str(path))


def _check_finite(vertices: np.ndarray, source: str, per_facet: bool = False) -> None:
    """Refuse NaN/inf vertex coordinates, naming the first bad vertex (or STL facet) and how many there are."""
    bad = np.flatnonzero(~np.all(np.isfinite(vertices), axis=1))
    if bad.size:
        where = f"facet {bad[0] // 3 + 1}" if per_facet else f"vertex {bad[0] + 1}"
        raise DesignError(f"{source}: {where} has non-finite coordinates {vertices[bad[0]].tolist()} "
                          f"({bad.size} vertices in all); expected finite x, y, z in mm")


def checked_mesh(mesh: trimesh.Trimesh, source: str = "mesh") -> trimesh.Trimesh:
    """The solid `mesh` bounds (`design.geometry.bodies.solid_mesh`: overlapping bodies united, with a
    warning) after checking its vertices are finite and it is watertight.

    Raises
    ------
    DesignError
        For non-finite vertices, open edges, inconsistent or inward-facing normals, or a surface that
        passes through itself; the message names `source`.
    """
    _check_finite(mesh.vertices, source)
    if not mesh.is_watertight:
        mesh = _bodies_apart(mesh, source)
    solid, notes = solid_mesh(mesh, source)
    for note in notes:
        log.warning("%s", note)
    return solid


def _bodies_apart(mesh: trimesh.Trimesh, source: str) -> trimesh.Trimesh:
    """A mesh that is not watertight only because closed bodies share an edge (touching parts of one file, whose
    common edge then bounds four faces) as those bodies side by side, for `solid_mesh` to unite.

    Raises
    ------
    DesignError
        When a body is open, naming how many edges bound one face only (or more than two of one body).
    """
    bodies = mesh.split(only_watertight=False)
    if len(bodies) > 1 and all(body.is_watertight for body in bodies):
        return trimesh.util.concatenate(bodies)
    uses = np.unique(mesh.edges_sorted, axis=0, return_counts=True)[1]
    open_edges = int(np.count_nonzero(uses == 1))
    what = (f"it has {open_edges} open edges" if open_edges else
            f"{int(np.count_nonzero(uses > 2))} of its edges bound more than two faces of one body")
    raise DesignError(f"{source}: is not watertight ({what}), so its inside is undefined")


_UNREADABLE = (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error)
"""What reading an empty, truncated or foreign ``.npy``/``.npz`` raises."""


def _reason(exc: BaseException) -> str:
    text = str(exc) or type(exc).__name__
    return f"{text}: the file is empty, truncated or not a NumPy array file"


def load_density(path: str | Path, dx_mm: float | None = None) -> tuple[np.ndarray, float]:
    """Load a density array and its voxel size.

    Parameters
    ----------
    path : str or Path
        ``.npz`` with arrays ``rho`` and ``dx_mm``, or ``.npy`` holding rho alone.
    dx_mm : float, optional
        Voxel size, mm: required for ``.npy``; for ``.npz`` it must agree with the stored one if given.

    Returns
    -------
    rho : (H, W) or (D, H, W) ndarray of float in [0, 1]
    dx_mm : float

    Raises
    ------
    DesignError
        Missing file, missing keys, no voxel size, or an invalid array; the message names the file.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in DENSITY_SUFFIXES:
        raise DesignError(f"{path}: unsupported density format {path.suffix!r}; use .npy or .npz")
    if not path.is_file():
        raise DesignError(f"{path}: no such file")
    try:
        data = np.load(path, allow_pickle=False)
    except _UNREADABLE as exc:
        raise DesignError(f"{path}: cannot read array ({_reason(exc)})") from exc
    if suffix == ".npz":
        if not isinstance(data, np.lib.npyio.NpzFile):
            raise DesignError(f"{path}: not an .npz archive (it holds a single array); save rho and dx_mm with np.savez")
        with data:
            missing = {"rho", "dx_mm"} - set(data.files)
            if missing:
                raise DesignError(f"{path}: missing array(s) {sorted(missing)}; found {sorted(data.files)}")
            try:
                rho, stored_dx = data["rho"], data["dx_mm"]
            except _UNREADABLE as exc:
                raise DesignError(f"{path}: cannot read its arrays ({_reason(exc)})") from exc
            stored = check_positive("dx_mm", stored_dx, str(path))
        if dx_mm is not None and not np.isclose(check_positive("dx_mm", dx_mm), stored, rtol=1e-9):
            raise DesignError(f"{path}: stores dx_mm = {stored:g}, which contradicts the requested {dx_mm:g}")
        dx = stored
    else:
        if isinstance(data, np.lib.npyio.NpzFile):
            data.close()
            raise DesignError(f"{path}: an .npz archive named .npy; rename it to .npz (with arrays rho and dx_mm)")
        if dx_mm is None:
            raise DesignError(f"{path}: a .npy array has no voxel size; give one (--voxel-size)")
        rho, dx = data, check_positive("dx_mm", dx_mm, str(path))
    return check_density(rho, str(path)), dx
