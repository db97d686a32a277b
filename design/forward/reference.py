"""The reference release of a closed solid: exact surface distances, independent of any design grid.

Water erodes the solid at unit speed from every wetted surface (the continuum model that eqs. (5)-(7)
discretise), so a point's dissolution time T(x) is the length of the shortest path from a wetted
surface through the solid, and released(tau) = volume{x in solid : T(x) <= tau}. For a solid whose
every boundary shell faces the bath, T(x) is exactly the Euclidean distance from x to the surface.
A shell enclosed by another (the wall of a sealed void, or a body inside such a void) is wetted only
once the front reaches the fluid region it faces; with w_R the wetting time of fluid region R (0 for
the bath) and d_R the distance to the shells bounding R,

    T(x) = min_R (w_R + d_R(x)),    w_R = min over wetted regions Q of (w_Q + dist(shells of Q, shells of R)),

a shortest-path problem over the few fluid regions (Dijkstra), exact because a straight segment from
a wetted surface is always a path the front can take: where it crosses a void, the void is wetted no
later than the front's arrival along the segment.

Quadrature. T is evaluated exactly (a bounding-volume hierarchy over the triangles with exact
point-triangle distances) at the centres of a cubic lattice of spacing h over the mesh's bounds (only its
blocks that meet the solid; h sized by the solid's thickness and the stated error unless the caller gives
cells along the bounding box: :mod:`design.forward.solid_lattice`). Each
cell spreads its volume h^3 uniformly over arrival times [T_c - h/2, T_c + h/2], which has the mean
and the variance (h^2 / 12) of the arrival times over a cube cut by planar level sets of any
orientation; the part of that ramp before the cell's wetting time (0 at the bath, w_R at a void's
wall, and negative signed distances outside the surface) is not solid and releases nothing. The
curve is therefore exactly 0 at tau = 0, and second-order in h where T is smooth: the first two
moments of each cell's arrival times are right. Where T is not smooth (on the medial axis, where two
fronts meet, next to a void's wall) a cell is split into SPLIT^3 sub-cells evaluated the same way; a
sub-cell that fronts from opposite sides reach within its size (a flat ridge: the mid-plane of a plate) is
two ramps, one per front, ending where they meet, since a ramp centred on its centre's T would spread up to
half of it past the ridge's time (a first-order error). The sum of the ramps
estimates the volume; the curve is scaled so that it ends at the mesh's exact volume (signed
tetrahedra). Lattice points more than BAND cells outside the solid are only classified, not measured.

Error estimate: the same quadrature on a lattice twice as coarse (one eighth of the cost). For a
second-order quadrature the fine curve's error is about a third of the difference between the two;
`ReferenceRelease.error_mm3` states the whole difference, max_tau |C_h - C_2h|, as the bound. A lattice sized
by the solid after a first one states the smaller of that and its difference from the previous, coarser
lattice (at least 1.4 times coarser): a lattice twice as coarse can be too coarse for a thin part's edges
when the fine one is not. The
validation shapes of docs/forward.md#reference-evaluator meet it with a margin.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import trimesh

from design._validate import check_positive
from design.errors import DesignError
from design.forward.distance import Surface
from design.forward.offset_lattice import PrintLattice
from design.forward.quadrature import lattice_curve
from design.forward.simulator import DEFAULT_STEPS
from design.forward.solid_lattice import DEFAULT_TOLERANCE, MAX_POINTS, choose
from design.forward.wetting import wetting

log = logging.getLogger(__name__)

DEFAULT_CELLS = 160
"""Lattice cells along the longest side of the mesh's bounding box where a caller sizes the lattice by its box
(the cap of `design_lattice`; without ``cells`` the lattice is sized by the solid, `design.forward.solid_lattice`)."""
SAMPLES = DEFAULT_STEPS + 1
"""Erosion depths of a release sampled without given depths: uniform from 0 to where the solid is gone."""
MIN_CELLS = 16
"""Fewest cells along the longest side: the coarse estimate's lattice must still resolve the solid."""
CELLS_PER_DESIGN_VOXEL = 4
"""`design_lattice`: lattice cells per voxel of a design grid whose target or print is evaluated."""


def design_lattice(resolution: int) -> int:
    """Lattice cells for the target and the print of a design at `resolution` voxels across its domain:
    `CELLS_PER_DESIGN_VOXEL` per voxel, at most `DEFAULT_CELLS` (reached from resolution 40 on) and at
    least `MIN_CELLS`, so that the small grids of quick runs and tests are not evaluated at the cost of
    a production one; the stated error says what that costs in accuracy."""
    return int(min(DEFAULT_CELLS, max(MIN_CELLS, CELLS_PER_DESIGN_VOXEL * int(resolution))))


@dataclass(frozen=True)
class ReferenceRelease:
    """The release of a closed solid by exact surface distances.

    Attributes
    ----------
    tau_mm : (K,) ndarray of float, mm
        The requested erosion depths.
    released_mm3 : (K,) ndarray of float, mm^3
        Released volume at each tau (0 at tau <= 0, the volume once every point has dissolved).
    volume_mm3 : float
        The solid's volume, exact for the mesh (signed tetrahedra), mm^3; a print with a surface offset: the
        quadrature's.
    error_mm3 : float
        Estimated bound on max |released error|: max |C_h - C_2h| between the lattice and one twice
        as coarse (plus ``unsure_mm3``), mm^3.
    method : str
        "exact-distance" (every shell faces the bath) or "exact-distance-voids" (sealed voids wetted
        when the front reaches them), followed by ", anisotropy a" for a release at anisotropy a.
    cell_mm : float
        Lattice spacing h, mm.
    total_time_mm : float
        The largest dissolution time: tau at which the solid is gone, mm.
    seconds : float
        Wall time of the evaluation, s.
    lattice : str
        How the lattice was sized (cells along the box, or the solid-sized choice and why).
    offset_mm : float
        The print's surface offset released, mm (0: the mesh itself).
    unsure_mm3 : float
        Of ``error_mm3``, the volume of a grown print whose arrival times are lower bounds (creases and gaps the
        offset fills: `design.forward.offset_lattice`), mm^3; 0 for the mesh itself and for a shrink.
    """

    tau_mm: np.ndarray
    released_mm3: np.ndarray
    volume_mm3: float
    error_mm3: float
    method: str
    cell_mm: float
    total_time_mm: float
    seconds: float
    lattice: str = ""
    offset_mm: float = 0.0
    unsure_mm3: float = 0.0

    @property
    def relative_error(self) -> float:
        """`error_mm3` as a fraction of the volume."""
        return self.error_mm3 / self.volume_mm3


def _check_mesh(mesh: object) -> trimesh.Trimesh:
    if not isinstance(mesh, trimesh.Trimesh):
        raise DesignError(f"reference release needs a trimesh.Trimesh, got {type(mesh).__name__}")
    if len(mesh.faces) == 0:
        raise DesignError("reference release: the mesh has no faces")
    if not mesh.is_watertight:
        raise DesignError(f"reference release: the mesh ({len(mesh.faces)} faces) is not closed (watertight); "
                          "only a closed solid has a release")
    if not mesh.is_winding_consistent:
        raise DesignError(f"reference release: the mesh ({len(mesh.faces)} faces) has inconsistent face winding")
    mesh = mesh.copy()
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def metric_mesh(mesh: trimesh.Trimesh, anisotropy: float) -> trimesh.Trimesh:
    """``mesh`` in the metric where a front moving at ``anisotropy`` along z (the build direction) and at 1 in
    the plane is isotropic: z scaled by 1 / anisotropy (a copy; the mesh itself for 1)."""
    return mesh if anisotropy == 1.0 else mesh.copy().apply_scale([1.0, 1.0, 1.0 / anisotropy])


def reference_release(mesh: trimesh.Trimesh, tau_mm: np.ndarray | None = None, *, cells: int | None = None,
                      anisotropy: float = 1.0, tolerance: float = DEFAULT_TOLERANCE, max_points: float = MAX_POINTS,
                      source: str = "the solid", progress: Callable[[str], None] | None = None,
                      offset_mm: float = 0.0) -> ReferenceRelease:
    """Release of a closed solid by exact surface distances, with its error estimate.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        A closed (watertight), consistently wound triangle mesh in mm; an inward-wound mesh is
        taken as its outward-wound copy. Overlapping bodies are not merged: pass their union.
    tau_mm : (K,) array_like of float, mm, optional
        Erosion depths to sample; None: uniform depths (`SAMPLES` from 0 to past the last ramp of a scout on the
        coarse lattice), ending at the first at which the whole solid has dissolved.
    cells : int, optional
        Lattice cells along the longest side of the bounding box (cost grows as its cube). None (the default):
        the lattice is sized by the solid (:mod:`design.forward.solid_lattice`): spacing from its thickness,
        refined until the stated error is within ``tolerance`` of the volume.
    anisotropy : float
        The print's build-direction (z) erosion rate over its in-plane rate, a > 0. A front moving at a along z
        is isotropic in the metric with z scaled by 1 / a: the release is that of the scaled mesh, its volumes
        times a (``method`` then names a).
    tolerance : float
        Without ``cells``: the stated error aimed at, a fraction of the volume.
    max_points : float
        Without ``cells``: the most lattice points one evaluation may take.
    source : str
        Named in a refusal.
    progress : callable, optional
        Called with a line per lattice evaluated.
    offset_mm : float
        The print's surface offset o, mm: the release is that of the print {x : signed distance > -o} (the mesh grown
        by o, shrunk by |o| if negative; :mod:`design.forward.offset_lattice`), its volume the quadrature's. Exact
        for a shrink and for a convex solid grown; a grown print's creases and gaps the offset fills are counted
        into ``error_mm3`` (``unsure_mm3``). Not with sealed voids.

    Returns
    -------
    ReferenceRelease

    Raises
    ------
    DesignError
        If the mesh is not closed or consistently wound, `tau_mm` is not a finite 1D array, `cells` <
        `MIN_CELLS`, or an offset is given for a mesh with sealed voids or leaves no print.
    design.forward.solid_lattice.TooThinError
        Without ``cells``, for a solid whose features need more than ``max_points`` lattice points.

    Examples
    --------
    >>> import trimesh
    >>> ref = reference_release(trimesh.creation.box((2.0, 2.0, 2.0)), [0.0, 0.5, 1.0], cells=32)
    >>> [round(float(v), 3) for v in ref.released_mm3]
    [0.0, 7.0, 8.0]
    """
    began = time.perf_counter()
    tau = None if tau_mm is None else np.asarray(tau_mm, dtype=np.float64)
    if tau is not None and (tau.ndim != 1 or not np.all(np.isfinite(tau))):
        raise DesignError(f"tau_mm must be a 1D array of finite depths, got shape {tau.shape}")
    if cells is not None and (int(cells) != cells or cells < MIN_CELLS):
        raise DesignError(f"cells must be an integer >= {MIN_CELLS}, got {cells!r}")
    a = check_positive("anisotropy", anisotropy)
    o = float(offset_mm)
    if not np.isfinite(o):
        raise DesignError(f"offset_mm must be a finite number of mm, got {offset_mm!r}")
    run = _Lattices(_check_mesh(mesh), a, o, source, tau)
    if cells is not None:
        h = float((run.bounds[1] - run.bounds[0]).max()) / int(cells)
        run.evaluate(h)
        lattice = f"{int(cells)} cells along the bounding box's longest side"
    else:
        box, solid = run.bounds, float(run.mesh.volume)
        if run.printed is not None:  # sized by the print: about V + A o (its own quadrature gives its volume)
            box, solid = run.printed.bounds(run.bounds), max(solid + float(run.mesh.area) * o, 0.05 * solid)
        choice = choose(run.evaluate, box, solid, float(run.mesh.area), tolerance=tolerance,
                        max_points=max_points, source=source, say=progress)
        h = choice.spacing_mm
        lattice = choice.reason
    released, error, total, volume, unsure = run.found[h]
    tau = run.tau
    if tau_mm is None:
        tau, released = _until_dissolved(tau, released, volume)
    seconds = time.perf_counter() - began
    method = ("exact-distance-voids" if run.n_voids else "exact-distance") \
        + (f", anisotropy {a:g}" if a != 1.0 else "") + (f", surface offset {o:+g} mm" if o != 0.0 else "")
    log.debug("reference release: %d faces, %d voids, h = %.4g mm, error %.3g mm^3 (%.3g%%), %.2f s",
              len(run.mesh.faces), run.n_voids, h, error, 100 * error / volume, seconds)
    return ReferenceRelease(tau_mm=tau, released_mm3=released, volume_mm3=volume, error_mm3=error + unsure,
                            method=method, cell_mm=check_positive("cell_mm", h), total_time_mm=total, seconds=seconds,
                            lattice=lattice, offset_mm=o, unsure_mm3=unsure)


class _Lattices:
    """The lattices of one reference release: the mesh in the metric of anisotropy a, its surface and wetting, the
    print of offset o (None without one), and each lattice evaluated (``found``: spacing -> (curve, stated error,
    latest arrival, volume, unsure volume)). ``tau`` is the requested depths, set by the first scout if None."""

    def __init__(self, checked: trimesh.Trimesh, a: float, o: float, source: str, tau: np.ndarray | None) -> None:
        self.a, self.o, self.source, self.tau = a, o, source, tau
        self.mesh = metric_mesh(checked, a)
        self.surface = Surface(self.mesh)
        wet, self.n_voids = wetting(self.mesh)
        if o != 0.0 and self.n_voids:
            raise DesignError(f"{source}: a surface offset with sealed voids ({self.n_voids}) is not modelled by the "
                              "exact evaluator (their walls' wetting in a print that shrinks or closes them)")
        self.printed = None if o == 0.0 else PrintLattice(self.surface, o, a, None if a == 1.0 else Surface(checked))
        self.offset = self.surface.stored(wet)
        self.bounds = np.asarray(self.mesh.bounds, dtype=np.float64)
        self.volume = float(self.mesh.volume) * a  # mm^3 of the print: the scaled mesh's volume times a
        self.found: dict[float, tuple] = {}

    def quadrature(self, h: float, tau: np.ndarray) -> tuple[np.ndarray, float, float, float]:
        """(curve in physical mm^3, its volume, the latest arrival, the unsure volume) on the lattice of spacing h."""
        if self.printed is None:
            curve, est, end = lattice_curve(self.surface, self.offset, self.bounds, h, tau)
            return curve * (self.volume / est), self.volume, end, 0.0
        got = self.printed.curve(self.bounds, h, tau)
        if not got.volume > 0.0:
            raise DesignError(f"{self.source}: the print is empty: a surface offset of {self.o:g} mm removes all of it")
        return got.curve * self.a, got.volume * self.a, got.end, got.unsure_mm3 * self.a

    def evaluate(self, h: float) -> float:
        """Evaluate the lattice of spacing h and one twice as coarse; the stated error as a fraction of the volume."""
        if self.tau is None:  # a scout on the coarse lattice finds where the solid is gone
            grow = 0.0 if self.printed is None else self.printed.grow
            upper = 0.5 * float((self.bounds[1] - self.bounds[0]).min()) + 4.0 * h + grow
            end = self.quadrature(2.0 * h, np.linspace(0.0, upper, 3))[2]
            # the fine lattice's last ramp ends within 1.25 h of the coarse one's (a coarse cell's half-diagonal
            # sqrt(3) h, less the coarse ramp's half-width h, plus the fine one's h / 2)
            self.tau = np.linspace(0.0, end + 1.25 * h, SAMPLES)
        tau = self.tau
        fine, coarse = (self.quadrature(s, tau) for s in (h, 2.0 * h))
        error = float(np.abs(fine[0] - coarse[0]).max()) if tau.size else 0.0
        if self.found and tau.size:  # a refinement: also against the previous (coarser) lattice, if that is closer
            error = min(error, float(np.abs(fine[0] - self.found[min(self.found)][0]).max()))
        self.found[h] = (fine[0], error, fine[2], fine[1], fine[3])
        return error / fine[1]


def _until_dissolved(tau: np.ndarray, released: np.ndarray, volume: float) -> tuple[np.ndarray, np.ndarray]:
    """The samples up to the first depth at which everything has dissolved."""
    done = np.flatnonzero(released >= volume * (1.0 - 1e-9))
    keep = int(done[0]) + 1 if done.size else tau.size
    return tau[:keep], released[:keep]


def signed_distance(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """Exact signed distance (mm, positive inside) from each point (N, 3) to a closed mesh's surface."""
    return Surface(_check_mesh(mesh)).signed_distance(np.asarray(points, dtype=np.float64).reshape(-1, 3))[0]
