"""A disk cache of the simulated bench's print releases (`labapp.acquisition.printworld.world_release`).

A print's release on the simulated bench takes seconds to a minute to compute (exact surface distances and
scikit-fmm on a 128-voxel grid), and the same sample printed with the same hidden physics is released again
at every Connect of the simulated bench and every demo. The cache keeps each release under a key of
everything it depends on: the mesh's vertices and faces, the physics, the resolution and samples, and the
source of the modules that compute it (so a changed method never returns an old answer).

Folder: ``$SFR_CACHE``, else ``$XDG_CACHE_HOME/shape-from-release``, else ``~/.cache/shape-from-release``;
releases sit in its ``world/`` folder, one ``.npz`` each, written to a temporary file and renamed. A file that
does not read is computed again; a cache that cannot be written (read-only, full disk) is logged and skipped.
"""
from __future__ import annotations

import dataclasses
import hashlib
import logging
import os
import tempfile
from pathlib import Path

import numpy as np
import skfmm
import trimesh

import design.forward.distance
import design.forward.quadrature
import design.forward.reference
import design.forward.wetting
import design.geometry.voxelize
from labapp.acquisition import printworld
from labapp.acquisition.printworld import WORLD_RESOLUTION, PrintPhysics, WorldRelease, world_release

log = logging.getLogger(__name__)

_METHOD_MODULES = (printworld, design.forward.reference, design.forward.distance, design.forward.quadrature,
                   design.forward.wetting, design.geometry.voxelize)
"""The modules whose source the release depends on: part of every key."""


def cache_dir() -> Path:
    """The cache's folder (see the module's docstring)."""
    if os.environ.get("SFR_CACHE"):
        return Path(os.environ["SFR_CACHE"])
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "shape-from-release"


def _key(mesh: trimesh.Trimesh, physics: PrintPhysics, resolution: int, samples: int) -> str:
    digest = hashlib.sha256()
    digest.update(np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes())
    digest.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
    digest.update(repr((dataclasses.asdict(physics), int(resolution), int(samples), skfmm.__version__)).encode())
    for module in _METHOD_MODULES:
        digest.update(Path(module.__file__).read_bytes())
    return digest.hexdigest()


def cached_world_release(mesh: trimesh.Trimesh, physics: PrintPhysics, *, resolution: int = WORLD_RESOLUTION,
                         samples: int = 401) -> WorldRelease:
    """`world_release` of ``mesh`` printed with ``physics``, from the cache when it holds it (else computed and
    stored)."""
    path = cache_dir() / "world" / f"{_key(mesh, physics, resolution, samples)}.npz"
    try:
        with np.load(path) as data:
            return WorldRelease(tau_mm=data["tau_mm"], released_mm3=data["released_mm3"],
                                volume_mm3=float(data["volume_mm3"]), voxel_mm=float(data["voxel_mm"]))
    except FileNotFoundError:
        pass
    except Exception as exc:                    # a torn or foreign file: computed again and replaced
        log.warning("print release cache %s does not read (%s: %s); computing it again", path,
                    type(exc).__name__, exc)
    release = world_release(mesh, physics, resolution=resolution, samples=samples)
    _store(path, release)
    return release


def _store(path: Path, release: WorldRelease) -> None:
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".npz")
        with os.fdopen(fd, "wb") as f:
            np.savez(f, tau_mm=release.tau_mm, released_mm3=release.released_mm3,
                     volume_mm3=release.volume_mm3, voxel_mm=release.voxel_mm)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        log.warning("print release not cached in %s (%s); it is computed again next time", path.parent, exc)
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
