"""Input checks shared by the public functions of `design` (validate once, at the boundary)."""
from __future__ import annotations

import math

import numpy as np

from design.errors import DesignError

#: The input files `design` reads: triangle meshes in mm, and density arrays.
MESH_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".3mf")
DENSITY_SUFFIXES = (".npy", ".npz")


def _where(source: str | None) -> str:
    return f" in {source}" if source else ""


def check_density(rho: object, source: str | None = None) -> np.ndarray:
    """Return `rho` as a float64 array after checking it is a 2D/3D, finite, non-empty field in [0, 1]."""
    arr = np.asarray(rho, dtype=np.float64)
    if arr.ndim not in (2, 3):
        raise DesignError(f"density{_where(source)} must be 2D or 3D, got shape {arr.shape}")
    if arr.size == 0:
        raise DesignError(f"density{_where(source)} is empty (shape {arr.shape})")
    if not np.all(np.isfinite(arr)):
        first = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise DesignError(f"density{_where(source)} has {int(np.sum(~np.isfinite(arr)))} non-finite values, the "
                          f"first at index {first} ({arr[first]}); expected finite values in [0, 1]")
    lo, hi = float(arr.min()), float(arr.max())
    if lo < 0.0 or hi > 1.0:
        raise DesignError(f"density{_where(source)} must lie in [0, 1], got range [{lo:g}, {hi:g}]")
    return arr


def check_positive(name: str, value: object, source: str | None = None) -> float:
    """Return `value` as a float after checking it is finite and > 0."""
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise DesignError(f"{name}{_where(source)} must be a number, got {value!r}") from exc
    if not math.isfinite(x) or x <= 0.0:
        raise DesignError(f"{name}{_where(source)} must be finite and > 0, got {x:g}")
    return x


def check_mirror(mirror: tuple[bool, ...] | None, ndim: int) -> tuple[bool, ...]:
    """Return a per-axis tuple of bool; None means no mirror planes."""
    if mirror is None:
        return (False,) * ndim
    out = tuple(bool(m) for m in mirror)
    if len(out) != ndim:
        raise DesignError(f"mirror must have one flag per axis ({ndim}), got {mirror!r}")
    return out
