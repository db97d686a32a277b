"""Where the start designs of an extruded design hold material: the source's footprint, or for a curve target a
square, a cross and a ring (`start_regions`)."""
from __future__ import annotations

import numpy as np

from design.inverse.spaces import BUILD_AXIS, DesignSpace
from design.inverse.targets import Target, curve_end_mm

START_FILL = 2.0 / 3.0
"""Density of the compact start of an extruded design (`start_regions`): a target without a source starts
at it, and a start is hollowed only as far as its band still holds the target's volume at it."""


def start_regions(space: DesignSpace, target: Target, half_extent_mm: np.ndarray | None,
                  radius_mm: float) -> tuple[np.ndarray | None, ...]:
    """Where an extruded design may start with material (`DesignObjective.uniform_start`), the default first.

    A single run starts in the first; the starts of a multi-start take them in turn
    (`design.inverse.multistart.perturbed_start`). None stands for the whole domain.

    The outline is the source's footprint (its bounding box plus a voxel), or for a target without a
    source a centred square. Spreading the start over the whole domain footprint, as for the other
    spaces, leaves an extruded design far from the compact part and lets it split into one piece per
    quadrant (docs/design.md#extruded-start).

    When the extrusion is taller than twice the target's release end D, the start leaves out the
    outline's core deeper than 2 D from its edge. A point of a prism dissolves at min(in-plane distance
    to the nearest edge, distance to the top or bottom face), so the part's material must lie within D
    of an in-plane edge for its release to end by D; the band that remains has that width between the
    outline and the hole, and a start that holds the core solid gives the design a core that the
    projection then keeps (a ring's central hole never opens). The hole is cut only
    as far as the band that remains holds the target's volume at density `START_FILL`, and not at all
    when its half-width would be below the smoothing radius (the filter would keep it a grey pin-hole
    that the printed solid opens). A target without a source starts in the square that holds its
    volume at `START_FILL` throughout, so it has no room for a hole (a square ring start with the
    core's connectivity penalty closes up). When a solid square of its volume would release its core
    after D, two more outlines hold its volume within about D of an edge: a cross of arms about 2 D wide
    (`cross_region`) and a ring of that width (`ring_region`); which of the three the optimisation makes the
    best design of depends on the target, so its multi-start tries each.

    Returns
    -------
    tuple of (ndarray of bool, variable shape, or None)
    """
    if not space.extruded:
        return (None,)
    dx = space.dx_mm
    height_mm = space.grid_shape[BUILD_AXIS] * dx
    end_mm = curve_end_mm(target.tau_mm, target.released_mm3)
    need_cells = target.final_mm3 / (START_FILL * height_mm * dx * dx * space.multiplicity)
    late = end_mm < 0.5 * height_mm - 0.5 * dx  # the faces alone do not dissolve the core in time
    band_mm = 2.0 * end_mm + 0.5 * dx  # a band this wide releases by D from its two edges (half a voxel's ramp)
    alternatives: tuple[np.ndarray | None, ...] = ()
    if half_extent_mm is None:
        area = target.final_mm3 / (height_mm * START_FILL)
        if late and 0.5 * np.sqrt(target.final_mm3 / height_mm) > end_mm:  # a solid square's core releases after D
            outlines = (cross_region(space, area, end_mm), ring_region(space, area, band_mm, radius_mm))
            alternatives = tuple(outline for outline in outlines if outline is not None)
        half = np.full(2, 0.5 * np.sqrt(area))
    else:
        half = np.array([half_extent_mm[ax] for ax in range(3) if ax != BUILD_AXIS]) + dx
    half = np.minimum(half, np.asarray(space.var_shape, float) * dx)  # within the domain
    centres = [(np.arange(n) + 0.5) * dx for n in space.var_shape]
    depth = np.minimum.outer(half[0] - centres[0], half[1] - centres[1])  # to the outline's edge, mm
    region = depth > 0
    if late:
        inside = np.sort(depth[region])
        width = band_mm
        if np.count_nonzero(inside <= width) < need_cells:
            width = inside[min(int(np.ceil(need_cells)), inside.size - 1)]
        if inside[-1] - width >= radius_mm:
            region &= depth <= width
    return (region if region.any() and not region.all() else None,) + alternatives


def cross_region(space: DesignSpace, area_mm2: float, end_mm: float) -> np.ndarray | None:
    """A centred cross of two arms about 2 ``end_mm`` wide whose footprint is ``area_mm2`` (mm^2, all quadrants).

    Its material lies within ``end_mm`` of an edge (at the crossing within sqrt(2) ``end_mm`` of the corners), so
    it releases about when the target ends; arms longer than the domain allows are widened instead. The arms
    lie on the mirror planes, so each quadrant holds one connected L. Widths and lengths are whole cells.
    Returns the region in the variable's quadrant, or None (no cross fits the domain).
    """
    dx = space.dx_mm
    longest = min(space.var_shape) - 1  # cells from the symmetry centre, a cell short of the domain's edge
    width = max(1, int(round(end_mm / dx)))  # half-width, cells
    length = int(round((area_mm2 / dx ** 2 + 4.0 * width ** 2) / (8.0 * width)))  # 8 l w - 4 w^2 = area
    if length > longest:
        disc = 64.0 * longest ** 2 - 16.0 * area_mm2 / dx ** 2
        if disc < 0.0:
            return None
        length, width = longest, max(width, int(round((8.0 * longest - np.sqrt(disc)) / 8.0)))
    cells = [np.arange(n) for n in space.var_shape]
    region = np.logical_and.outer(cells[0] < length, cells[1] < width) | \
        np.logical_and.outer(cells[0] < width, cells[1] < length)
    return region if region.any() and not region.all() else None


def ring_region(space: DesignSpace, area_mm2: float, width_mm: float, radius_mm: float) -> np.ndarray | None:
    """A ring ``width_mm`` wide around the symmetry axis whose footprint is ``area_mm2`` (mm^2, all quadrants).

    A wall of even thickness releases at a rate that changes little (its inner face grows as its outer face
    shrinks) and its material ends at once, when the target ends for a width of twice its end (the band of
    `start_regions`): the outline of a curve that rises steadily and stops, a flat print's. Returns the region
    in the variable's quadrant, or None when the hole would be narrower than the smoothing radius ``radius_mm``
    (the filter would keep it a grey pin-hole) or the ring does not fit the domain with a cell to spare.
    """
    dx = space.dx_mm
    mean_radius = area_mm2 / (2.0 * np.pi * width_mm)
    inner, outer = mean_radius - 0.5 * width_mm, mean_radius + 0.5 * width_mm
    if inner < radius_mm or outer > (min(space.var_shape) - 1) * dx:
        return None
    centres = [(np.arange(n) + 0.5) * dx for n in space.var_shape]
    radius = np.hypot.outer(centres[0], centres[1])
    region = (radius >= inner) & (radius <= outer)
    return region if region.any() else None
