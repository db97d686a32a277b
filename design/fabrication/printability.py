"""Printability facts of a designed solid: print mass, narrowest open channel, enclosed voids,
overhangs, slicer profile.

The paper prints with AquaSys 120 on a Prusa i3 MK3s (section 4.1): measured print density
1.32 g/cm^3, 100% concentric infill, 0.1 mm layers, 0.2 mm lines, 245/85 C. Its one large
measured mismatch (Fig. 10) came from narrow internal channels that clogged as the material
swelled, hence the channel check. An enclosed void traps air (the dose form may float) and, in
the model of eqs. (5)-(7), opens at once when its wall dissolves, a jump in the release rate.
Overhangs are measured along the build direction +z (array
axis 2, z = 0 on the build plate), the one the ICO space designs for (section 3.6).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from design.errors import DesignError
from design.material import PRINT_DENSITY_G_PER_CM3


@dataclass(frozen=True)
class Printability:
    """Printability facts of one solid.

    Attributes
    ----------
    volume_mm3 : float
    mass_g : float
        At `PRINT_DENSITY_G_PER_CM3`.
    min_channel_mm : float or None
        Width of the narrowest passage leading from the outside into a wider void region;
        None when there is none narrower than the search limit.
    enclosed_voids : int
        Void regions the medium cannot reach from outside (`enclosed_voids`).
    enclosed_void_mm3 : float
        Their total volume, mm^3.
    overhang_fraction : float
        Share of solid voxels with nothing below them (`overhangs`).
    max_overhang_run_mm : float
        Longest straight horizontal run of such voxels, mm.
    warnings : tuple of str
    """

    volume_mm3: float
    mass_g: float
    min_channel_mm: float | None
    enclosed_voids: int
    enclosed_void_mm3: float
    overhang_fraction: float
    max_overhang_run_mm: float
    warnings: tuple[str, ...]


def print_mass_g(volume_mm3: float, density_g_per_cm3: float = PRINT_DENSITY_G_PER_CM3) -> float:
    """Mass of a print of the given solid volume, g (1 cm^3 = 1000 mm^3)."""
    return float(volume_mm3) * density_g_per_cm3 / 1000.0


def enclosed_voids(solid: np.ndarray) -> tuple[int, int]:
    """``(count, voxels)`` of the void regions of a voxel solid not connected to the grid's border.

    Void is connected 6-wise, as water flows; the grid's border is open medium.
    """
    void = np.pad(~np.asarray(solid, bool), 1, constant_values=True)
    labels, count = ndimage.label(void)
    enclosed = labels[1:-1, 1:-1, 1:-1] != labels[0, 0, 0]
    enclosed &= labels[1:-1, 1:-1, 1:-1] > 0
    return count - 1, int(np.count_nonzero(enclosed))


def narrowest_channel_mm(solid: np.ndarray, dx_mm: float, max_width_mm: float) -> float | None:
    """Narrowest open channel: the tightest passage from the outside into a wider void region.

    The void connected to the outside (6-connected, as water flows) gets its Euclidean
    distance D to the nearest wall. Raising a level t in steps of dx/2, the region D >= t
    splits: a piece that loses its link to the outside while still reaching D >= t + dx is a
    chamber entered through a passage of width about ``2 t_prev - dx / 2``, within dx / 2 (a
    channel w voxels wide has centre-line D = (w + 1) dx / 2 for odd w, w dx / 2 for even w, with
    D measured between voxel centres). Through-channels of constant width contain
    no wider chamber and are not reported.

    Parameters
    ----------
    solid : (D, H, W) ndarray of bool
        The full solid (True = material).
    dx_mm : float
        Voxel edge, mm.
    max_width_mm : float
        Widest channel to look for, mm.

    Returns
    -------
    float or None
        Channel width, mm; None when no channel up to ``max_width_mm`` exists.
    """
    if solid.ndim != 3 or not dx_mm > 0 or not max_width_mm > 0:
        raise DesignError(f"need a 3D solid, dx > 0 and a positive width limit; got {solid.shape}, "
                          f"{dx_mm}, {max_width_mm}")
    t_max = 0.5 * (max_width_mm + dx_mm)
    pad = int(np.ceil(t_max / dx_mm)) + 2
    # the solid's bounding box: beyond it the void is the outside's, and the padding (wider than any level) joins it
    # all around at every level, as the whole grid's void would
    solid = np.asarray(solid, dtype=bool)
    if solid.any():
        spans = [np.flatnonzero(solid.any(axis=tuple(a for a in range(3) if a != ax))) for ax in range(3)]
        solid = solid[tuple(slice(int(i[0]), int(i[-1]) + 1) for i in spans)]
    void = np.pad(~solid, pad, constant_values=True)
    labels, _ = ndimage.label(void)
    outside = labels == labels[0, 0, 0]
    del labels, void
    # float32 distances halve the memory of a 256^3 design's padded grid; D = sqrt(integer) dx, and
    # distinct values below 20 dx differ by >= dx / 40, so a 1e-3 dx tolerance absorbs the float32
    # rounding (< 2e-6 dx there) without merging neighbouring distance levels
    dist = ndimage.distance_transform_edt(outside, sampling=dx_mm).astype(np.float32)
    del outside
    tol = 1e-3 * dx_mm
    levels = dx_mm * (1.0 + 0.5 * np.arange(1, int(np.ceil(2 * (t_max / dx_mm - 1))) + 1))
    prev = dx_mm
    for level in levels:
        lab, count = ndimage.label(dist >= level - tol)
        if count > 1:
            # the pieces that still reach D >= level + dx; any but the outside one is a chamber
            deep = np.unique(lab[dist >= level + dx_mm - tol])
            if np.any(deep != lab[0, 0, 0]):
                return float(2.0 * prev - 0.5 * dx_mm)
        prev = level
    return None


def overhangs(solid: np.ndarray) -> np.ndarray:
    """Solid voxels printed over void: the voxel below and its four side neighbours are all void.

    The part is printed as it lies, resting on the plate: its lowest solid layer is on the plate
    (which counts as solid), whatever empty layers the grid has below it.

    Parameters
    ----------
    solid : (X, Y, Z) ndarray of bool
        The full solid, z (axis 2) the build direction.

    Returns
    -------
    (X, Y, Z) ndarray of bool
    """
    solid = np.asarray(solid, dtype=bool)
    if solid.ndim != 3:
        raise DesignError(f"need a 3D solid, got shape {solid.shape}")
    below = np.zeros_like(solid)
    below[:, :, 1:] = solid[:, :, :-1]
    support = below.copy()
    support[1:] |= below[:-1]
    support[:-1] |= below[1:]
    support[:, 1:] |= below[:, :-1]
    support[:, :-1] |= below[:, 1:]
    layers = np.flatnonzero(solid.any(axis=(0, 1)))
    support[:, :, layers[0] if layers.size else 0] = True  # the build plate under the lowest layer
    return solid & ~support


def _longest_run(mask: np.ndarray, axis: int) -> int:
    """Longest run of consecutive True values along ``axis``."""
    m = np.moveaxis(mask, axis, -1).reshape(-1, mask.shape[axis]).astype(np.int8)
    edges = np.diff(np.pad(m, ((0, 0), (1, 1))), axis=1)
    _, starts = np.nonzero(edges == 1)
    _, ends = np.nonzero(edges == -1)  # row-major order pairs each start with its end
    return int((ends - starts).max()) if starts.size else 0


def overhang_stats(solid: np.ndarray, dx_mm: float) -> tuple[float, float]:
    """``(overhang_fraction, max_overhang_run_mm)`` of a voxel solid (`overhangs`).

    The fraction is over solid voxels (0 for an empty solid); the run is the longest straight
    line of overhang voxels along x or y within one layer, mm.
    """
    over = overhangs(solid)
    count = int(np.count_nonzero(solid))
    fraction = float(np.count_nonzero(over)) / count if count else 0.0
    return fraction, float(max(_longest_run(over, 0), _longest_run(over, 1))) * dx_mm


def assess(solid: np.ndarray, dx_mm: float, *, warn_channel_mm: float = 1.0,
           density_g_per_cm3: float = PRINT_DENSITY_G_PER_CM3) -> Printability:
    """Print mass, narrowest channel, enclosed voids and overhangs of a voxel solid, with warnings.

    Parameters
    ----------
    solid : (D, H, W) ndarray of bool
        The full solid.
    dx_mm : float
        Voxel edge, mm.
    warn_channel_mm : float
        Warn when a channel is narrower than this, mm (paper Fig. 10: narrow channels clog).
    """
    if not warn_channel_mm > 0:
        raise DesignError(f"channel warning width must be > 0 mm, got {warn_channel_mm}")
    volume = float(np.count_nonzero(solid)) * dx_mm ** 3
    channel = narrowest_channel_mm(solid, dx_mm, 3.0 * warn_channel_mm)
    warnings = []
    if channel is not None and channel < warn_channel_mm:
        warnings.append(f"narrowest open channel is {channel:.2f} mm, below {warn_channel_mm:g} mm: it may "
                        f"clog as the material swells (paper Fig. 10)")
    voids, void_voxels = enclosed_voids(solid)
    void_mm3 = void_voxels * dx_mm ** 3
    if voids:
        warnings.append(f"the solid encloses {voids} void(s) of {void_mm3:.4g} mm^3 in all: they trap air, and "
                        f"each opens at once when its wall dissolves (a jump in the release rate)")
    fraction, run_mm = overhang_stats(solid, dx_mm)
    return Printability(volume, print_mass_g(volume, density_g_per_cm3), channel, voids, void_mm3, fraction,
                        run_mm, tuple(warnings))


PRUSA_SETTINGS: dict[str, str] = {
    # section 4.1: 0.2 mm nozzle, 0.2 mm lines, 0.1 mm layers, 100% concentric infill, 245/85 C,
    # 200 mm/s; support material is set per design by `prusa_profile`
    "nozzle_diameter": "0.2",
    "layer_height": "0.1",
    "first_layer_height": "0.1",
    "extrusion_width": "0.2",
    "first_layer_extrusion_width": "0.2",
    "perimeter_extrusion_width": "0.2",
    "external_perimeter_extrusion_width": "0.2",
    "infill_extrusion_width": "0.2",
    "solid_infill_extrusion_width": "0.2",
    "top_infill_extrusion_width": "0.2",
    "fill_density": "100%",
    "fill_pattern": "concentric",
    "top_fill_pattern": "concentric",
    "bottom_fill_pattern": "concentric",
    "temperature": "245",
    "first_layer_temperature": "245",
    "bed_temperature": "85",
    "first_layer_bed_temperature": "85",
    "perimeter_speed": "200",
    "external_perimeter_speed": "200",
    "infill_speed": "200",
    "solid_infill_speed": "200",
    "top_solid_infill_speed": "200",
    "support_material": "0",
    "filament_type": "PVA",
    "filament_notes": "AquaSys 120 (Infinite Material Solutions), water-soluble",
}


def prusa_profile(name: str = "shape-from-release", supports: bool = False) -> str:
    """A PrusaSlicer .ini profile with the paper's print settings (section 4.1).

    ``supports`` turns support material on; ICO and extruded designs print without (section 3.6),
    the build direction being the STL's +z.
    """
    lines = [f"# PrusaSlicer profile {name}: print settings of Panetta et al. 2022, section 4.1",
             "# load with File > Import > Import Config; the STL's +z is the build direction"]
    settings = dict(PRUSA_SETTINGS, support_material="1" if supports else "0")
    lines += [f"{key} = {value}" for key, value in settings.items()]
    return "\n".join(lines) + "\n"
