"""Reference releases kept in the process: a release asked for again (the same mesh, tau grid and settings) is not
computed again.

A multi-start's coarse starts prepare the same source target (`design.inverse.problem.source_release`), and a design's
outputs release the print its last correction round judged (`design.inverse.defect.check_print`,
`design.files.printed.print_release`), each at a reference release's cost. `KEPT` releases are kept, the oldest
dropped; a `ReferenceRelease` holds curves only.
"""
from __future__ import annotations

import hashlib
import threading

import numpy as np
import trimesh

from design.forward.reference import ReferenceRelease, reference_release

KEPT = 8
"""Releases kept in the process (the source targets of a run and its prints)."""
_kept: dict[tuple, ReferenceRelease] = {}
_lock = threading.Lock()


def _key(mesh: trimesh.Trimesh, tau_mm: np.ndarray | None, settings: dict) -> tuple:
    digest = hashlib.sha256(np.ascontiguousarray(mesh.vertices, float).tobytes())
    digest.update(np.ascontiguousarray(mesh.faces, np.int64).tobytes())
    tau = b"" if tau_mm is None else np.ascontiguousarray(tau_mm, float).tobytes()
    return digest.hexdigest(), hashlib.sha256(tau).hexdigest(), tuple(sorted(settings.items()))


def cached_reference_release(mesh: trimesh.Trimesh, tau_mm: np.ndarray | None = None, **settings) -> ReferenceRelease:
    """`design.forward.reference.reference_release` of ``mesh`` on ``tau_mm`` with keyword ``settings`` (``cells``,
    ``anisotropy``, ...), computed once per process for the same mesh (vertices and faces), tau grid and settings."""
    key = _key(mesh, tau_mm, settings)
    with _lock:
        kept = _kept.get(key)
    if kept is not None:
        return kept
    release = reference_release(mesh, tau_mm, **settings)
    with _lock:
        while len(_kept) >= KEPT:
            _kept.pop(next(iter(_kept)))
        _kept[key] = release
    return release
