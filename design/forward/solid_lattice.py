"""The reference evaluator's lattice chosen from the solid, not its bounding box.

A lattice sized by cells along the bounding box's longest side leaves a long rod or a thin plate a few cells
thick. Here the spacing comes from the solid's own thickness and the evaluator's stated error
(:mod:`design.forward.reference`, max_tau |C_h - C_2h|):

1. The solid's mean half-thickness m = V / A (volume over surface area: t / 2 for a plate of thickness t, r / 2
   for a rod of radius r, r / 3 for a ball) sets the first spacing, h = m / `CELLS_PER_THICKNESS`, or the finest
   affordable one up to m / `MIN_CELLS_PER_THICKNESS` when that would take more than `MAX_POINTS` points.
2. The release and its stated error E are evaluated at h (and 2h). While E exceeds `DEFAULT_TOLERANCE` of the
   volume, h shrinks by (`TARGET_MARGIN` tolerance V / E)^(1 / `ORDER`), at most `MAX_PASSES` times.
3. A spacing whose lattice would hold more than `MAX_POINTS` points (the solid's cells and a shell around its
   surface: `design.forward.quadrature.lattice_points`) is not attempted: the finest affordable lattice is tried
   instead if it is clearly finer than the last; otherwise the best lattice so far is kept (with its stated
   error, above the tolerance) if it states at most `REFUSE_FRACTION` of the volume, and the solid is refused
   with :class:`TooThinError` if not, naming its thickness and the spacing it would need.

Only the blocks of the lattice that meet the solid are evaluated (`design.forward.quadrature.lattice_curve`),
so the cost is that of the solid's volume and surface at h, not of its box.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from design.errors import DesignError
from design.forward.quadrature import lattice_points

DEFAULT_TOLERANCE = 0.004
"""Stated error (max over the curve of |C_h - C_2h|) a solid-sized reference release meets, as a fraction of the
volume: within the 0.5% that ``sfr simulate`` promises (RMS over the curve), with margin, since the error of C_h
itself is a third to a fifth of the stated one (docs/evidence/forward.md: measured errors on hard parts)."""
CELLS_PER_THICKNESS = 4.0
"""First spacing: the mean half-thickness V / A over this (a slab 8 cells thick): coarser first lattices (5 cells
across a 1.5 mm wall) miss the thick edges of thin-walled parts in both lattices, unseen by the stated error."""
MIN_CELLS_PER_THICKNESS = 1.5
"""Coarsest spacing tried when the first one would take too many points: V / A over this (a slab 3 cells thick);
its stated error still decides whether it is kept."""
TARGET_MARGIN = 0.6
"""A refined spacing aims at this fraction of the tolerance, so that one refinement usually suffices."""
ORDER = 1.5
"""Order in h assumed when refining: the quadrature is second order where T is smooth, but the error of faceted
curved parts (prisms, tori) falls more slowly at coarse spacings; a lower order shrinks h further per step."""
SHRINK_RANGE = (0.25, 0.7)
"""Least and largest factor by which one refinement shrinks the spacing."""
MAX_PASSES = 5
"""Lattices tried at most (the first and four refinements: each has at least 1 / 0.7^3 = 2.9 times the points of the
last, so the last dominates the cost)."""
REFUSE_FRACTION = 0.01
"""A solid whose best affordable lattice states more than this fraction of the volume is refused; between the
tolerance and this, its release is given with its stated error and a warning."""
MAX_POINTS = 10e6
"""Most lattice points of one evaluation (the fine lattice; the coarse one and the first scout have an eighth each):
2-4 microseconds of CPU per point (docs/evidence/forward.md), so under a minute on two cores."""


class TooThinError(DesignError):
    """A solid whose features are too thin for the reference evaluator within `MAX_POINTS` lattice points.

    Attributes
    ----------
    thickness_mm : float
        The solid's mean thickness 2 V / A, mm.
    spacing_mm : float
        The lattice spacing its stated error needs, mm.
    points : float
        About how many lattice points that spacing takes.
    """

    def __init__(self, message: str, thickness_mm: float, spacing_mm: float, points: float) -> None:
        super().__init__(message)
        self.thickness_mm = thickness_mm
        self.spacing_mm = spacing_mm
        self.points = points


@dataclass(frozen=True)
class Choice:
    """How a solid-sized lattice was chosen: its spacing h (mm), the passes tried (spacing, stated error as a
    fraction of the volume) and a sentence saying why."""

    spacing_mm: float
    passes: tuple[tuple[float, float], ...]
    reason: str


def mean_half_thickness(volume_mm3: float, area_mm2: float) -> float:
    """V / A, mm: t / 2 for a plate of thickness t, r / 2 for a long rod of radius r, r / 3 for a ball."""
    return volume_mm3 / area_mm2


def choose(evaluate: Callable[[float], float], bounds: np.ndarray, volume_mm3: float, area_mm2: float, *,
           tolerance: float = DEFAULT_TOLERANCE, max_points: float = MAX_POINTS, source: str = "the solid",
           say: Callable[[str], None] | None = None) -> Choice:
    """Refine a lattice spacing until ``evaluate(h)`` (the stated error at spacing h, a fraction of the volume)
    meets ``tolerance``; returns the last spacing tried with every pass.

    Raises
    ------
    TooThinError
        When no lattice within ``max_points`` points resolves the thickness, or the best affordable one states more
        than `REFUSE_FRACTION` of the volume.
    """
    m = mean_half_thickness(volume_mm3, area_mm2)
    h = m / CELLS_PER_THICKNESS
    passes: list[tuple[float, float]] = []
    for k in range(MAX_PASSES):
        points = lattice_points(bounds, h, volume_mm3, area_mm2)
        if points > max_points:
            # the finest affordable lattice, if it is finer than the last one and still resolves the thickness
            cheapest = _affordable(bounds, volume_mm3, area_mm2, max_points, h)
            if cheapest > m / MIN_CELLS_PER_THICKNESS or (passes and cheapest > SHRINK_RANGE[1] * passes[-1][0]):
                if not passes or min(e for _, e in passes) > REFUSE_FRACTION:
                    raise _too_thin(source, m, h, points, max_points, passes, tolerance)
                break
            h, points = cheapest, lattice_points(bounds, cheapest, volume_mm3, area_mm2)
        if say is not None:
            say(f"lattice {k + 1}: spacing {h:.4g} mm, about {points / 1e6:.2g} million points")
        error = evaluate(h)
        passes.append((h, error))
        if error <= tolerance:
            return Choice(h, tuple(passes), f"mean half-thickness V/A = {m:.4g} mm; stated error {100 * error:.3g}% "
                                            f"of the volume meets {100 * tolerance:.3g}% at spacing {h:.4g} mm "
                                            f"(lattice {k + 1} of at most {MAX_PASSES})")
        if k + 1 < MAX_PASSES:
            h *= float(np.clip((TARGET_MARGIN * tolerance / error) ** (1.0 / ORDER), *SHRINK_RANGE))
    h, error = min(passes, key=lambda p: p[1])
    if error > REFUSE_FRACTION:
        raise _too_thin(source, m, h, lattice_points(bounds, h, volume_mm3, area_mm2), max_points, passes, tolerance)
    return Choice(h, tuple(passes), f"mean half-thickness V/A = {m:.4g} mm; stated error {100 * error:.3g}% of the "
                                    f"volume at spacing {h:.4g} mm, the best of {len(passes)} lattices within "
                                    f"{max_points / 1e6:.0f} million points, above the {100 * tolerance:.3g}% aimed at")


def _affordable(bounds: np.ndarray, volume_mm3: float, area_mm2: float, max_points: float, h: float) -> float:
    """The smallest spacing above ``h`` whose lattice takes at most ``max_points`` points (bisection; the count
    falls as the spacing grows)."""
    lo, hi = h, h
    while lattice_points(bounds, hi, volume_mm3, area_mm2) > max_points:
        lo, hi = hi, 2.0 * hi
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if lattice_points(bounds, mid, volume_mm3, area_mm2) > max_points else (lo, mid)
    return hi


def _too_thin(source: str, m: float, h: float, points: float, max_points: float, passes: list, tolerance: float
              ) -> TooThinError:
    done = (f" (spacing {passes[-1][0]:.3g} mm stated {100 * passes[-1][1]:.2g}% of the volume)" if passes else "")
    return TooThinError(
        f"{source}: its features are too thin for the exact evaluator: mean thickness 2V/A = {2 * m:.3g} mm; "
        f"an error within {100 * tolerance:.2g}% of the volume needs a lattice spacing of about {h:.3g} mm{done}, "
        f"about {points / 1e6:.0f} million points, over the {max_points / 1e6:.0f} million it evaluates; "
        "simulate it with the grid model (--model grid, first order, its error stated) or check the mesh units",
        2 * m, h, points)
