"""Mesh units and sizes before any grid is allocated: scale to mm, warn about implausible sizes, refuse
what would not fit in memory.

A printed object is between about 1 mm^3 and 1e6 mm^3 (a 10 cm cube); a mesh outside that range was
almost always exported in other units (metres, centimetres, inches). Mesh files carry no units, so
``--units`` says what they are; the default is mm.
"""
from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import psutil

from labapp.errors import UsageError

log = logging.getLogger(__name__)

__all__ = ["MIN_RESOLUTION", "MM_PER_UNIT", "check_memory", "design_memory_bytes", "grid_shape", "require_memory",
           "load_mesh_mm", "size_warnings"]

MM_PER_UNIT = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
PLAUSIBLE_VOLUME_MM3 = (1.0, 1e6)
TYPICAL_VOLUME_MM3 = 3e3        # a pill-sized print; ranks the candidate units of an implausible mesh
MIN_VOXELS_ACROSS = 4
MIN_RESOLUTION = 8
"""Fewest voxels along the longest side a simulation of a mesh takes (``sfr simulate --resolution``): at fewer,
a typical part is under two voxels thick and voxelises to nothing or a few voxels."""
MIN_LENGTH_MM = 3.0
"""Shortest longest side plausible for a printed object, mm: a pill drawn in cm reads 2.3 mm long (and its
volume, over 1 mm^3, looks plausible)."""
TYPICAL_LENGTH_MM = 20.0
"""A pill's length; ranks the candidate units of a mesh too small in its longest side."""
#: Peak bytes per voxel of one forward simulation: the fast-marching and adjoint work arrays (traced with
#: tracemalloc) and the density grid itself, rounded up.
SIMULATE_BYTES_PER_VOXEL = 200
BASE_MEMORY_BYTES = 250_000_000
"""Resident memory of a process before its first design: interpreter, numpy, numba kernels, bytes."""
DESIGN_BYTES_PER_SIMULATED_VOXEL = (2.37e9 - BASE_MEMORY_BYTES) / 128**3
"""Peak memory of a design per simulated voxel, bytes: the peak resident memory of a design on a 128^3
simulated grid, output writing included, less `BASE_MEMORY_BYTES` (`benchmarks/bench_design.py` prints the
peak; docs/benchmarks.md, "Inverse design")."""
MIRRORS = {"nfc": 8, "extruded": 4, "ico": 4}
"""How many mirror copies of the simulated grid make the full domain, per design space: nfc mirrors all
three axes, the printable spaces only the two build-plate axes (section 5.2)."""
MEMORY_FRACTION = 0.8


def load_mesh_mm(path: str | Path, units: str = "mm"):
    """Load a mesh file and scale its vertices to mm.

    Raises
    ------
    UsageError
        For an unknown unit.
    design.DesignError
        For an unreadable mesh or non-finite vertices (the message names the file and the vertex).
    """
    from design.files.meshio import load_mesh

    if units not in MM_PER_UNIT:
        raise UsageError(f"--units {units!r}: expected one of {', '.join(MM_PER_UNIT)}")
    return load_mesh(path, MM_PER_UNIT[units])


def _likely_unit(volume_mm3: float) -> str:
    """The units (of :data:`MM_PER_UNIT`) that would make ``volume_mm3`` plausible, most likely first."""
    lo, hi = PLAUSIBLE_VOLUME_MM3
    fits = sorted((abs(math.log10(volume_mm3 * MM_PER_UNIT[u] ** 3 / TYPICAL_VOLUME_MM3)), u)
                  for u in ("in", "cm", "m") if lo <= volume_mm3 * MM_PER_UNIT[u] ** 3 <= hi) if volume_mm3 > 0 else []
    if fits:
        return "it is probably in " + " or ".join(
            f"{u} ({volume_mm3 * MM_PER_UNIT[u] ** 3:.3g} mm^3 if so: --units {u})" for _, u in fits) + ", not mm"
    if volume_mm3 > hi:
        return "it was probably exported in micrometres or scaled up: check the export units and scale it to mm"
    return "check the units it was exported in (--units m|cm|mm|in)"


def _likely_length_unit(longest_mm: float) -> str:
    """The larger units that would make a longest side of ``longest_mm`` plausible, most likely first."""
    fits = sorted((abs(math.log10(longest_mm * MM_PER_UNIT[u] / TYPICAL_LENGTH_MM)), u) for u in ("cm", "in")
                  if longest_mm * MM_PER_UNIT[u] >= MIN_LENGTH_MM)
    return "if it was drawn in " + " or ".join(
        f"{'inches' if u == 'in' else u} ({longest_mm * MM_PER_UNIT[u]:.3g} mm long if so: --units {u})" for _, u in fits)


def size_warnings(extents_mm: np.ndarray, volume_mm3: float, dx_mm: float | None = None,
                  source: str = "mesh") -> list[str]:
    """Warnings for a mesh whose size is implausible for a printed object, naming the likely unit error.

    Parameters
    ----------
    extents_mm : (3,) ndarray of float
        Bounding-box size, mm.
    volume_mm3 : float
        Enclosed volume, mm^3.
    dx_mm : float, optional
        Voxel edge at the chosen resolution, mm; warns when the thinnest side is under
        :data:`MIN_VOXELS_ACROSS` voxels.

    A volume outside :data:`PLAUSIBLE_VOLUME_MM3`, or a longest side under :data:`MIN_LENGTH_MM`, is warned
    about with the units that would make it plausible.
    """
    lo, hi = PLAUSIBLE_VOLUME_MM3
    out = []
    if not lo <= abs(volume_mm3) <= hi:
        out.append(f"{source}: volume {abs(volume_mm3):.3g} mm^3 is outside {lo:g}..{hi:g} mm^3, implausible for a "
                   f"printed object; {_likely_unit(abs(volume_mm3))}")
    longest = float(np.max(extents_mm))
    if 0 < longest < MIN_LENGTH_MM and lo <= abs(volume_mm3):
        out.append(f"{source}: its longest side is {longest:.3g} mm, implausibly small for a printed object; "
                   f"{_likely_length_unit(longest)}")
    if dx_mm is not None and float(np.min(extents_mm)) / dx_mm < MIN_VOXELS_ACROSS:
        out.append(f"{source}: its thinnest side ({float(np.min(extents_mm)):.3g} mm) is under {MIN_VOXELS_ACROSS} "
                   f"voxels of {dx_mm:.3g} mm; raise --resolution or check the mesh units")
    return out


def grid_shape(extents_mm: np.ndarray, dx_mm: float) -> tuple[int, ...]:
    """The voxel grid covering a bounding box of ``extents_mm`` at edge ``dx_mm`` (one voxel of margin)."""
    return tuple(int(math.ceil(float(e) / dx_mm)) + 2 for e in extents_mm)


def design_memory_bytes(resolution: int, space: str = "nfc") -> int:
    """Peak memory of one design of ``resolution`` voxels along its longest side, bytes (cubic domain bound)."""
    voxels = resolution**3 / MIRRORS.get(space, 1)
    return int(BASE_MEMORY_BYTES + DESIGN_BYTES_PER_SIMULATED_VOXEL * voxels)


def check_memory(shape: tuple[int, ...], bytes_per_voxel: float, what: str) -> int:
    """Refuse a grid that would not fit in the memory available now; returns the estimate in bytes.

    Raises
    ------
    UsageError
        With the estimate and the memory available.
    """
    need = int(np.prod(np.array(shape, dtype=float)) * bytes_per_voxel)
    return require_memory(need, f"{what}: a grid of {' x '.join(map(str, shape))} voxels")


def require_memory(need: int, what: str) -> int:
    """Refuse ``need`` bytes when they exceed the memory usable now; returns ``need``.

    Raises
    ------
    UsageError
        Naming ``what``, the estimate and the memory available.
    """
    have = int(psutil.virtual_memory().available * MEMORY_FRACTION)
    log.debug("%s needs ~%.2f GiB (%.2f GiB usable)", what, need / 2**30, have / 2**30)
    if need > have:
        raise UsageError(f"{what} needs about {need / 2**30:.1f} GiB, only {have / 2**30:.1f} GiB of memory is "
                         f"available; lower --resolution (or check the mesh units)")
    return need
