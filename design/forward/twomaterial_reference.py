"""The reference release of a two-material print: a drug solid and a barrier solid, exact distances, refracted paths.

The drug erodes at unit speed, the barrier at ``s`` times that (paper section 6; the continuum model that
:mod:`design.forward.twomaterial` discretises on a grid), void at once, and only the drug releases. The drug wins
where the two meshes overlap, so the barrier's region is the barrier mesh less the drug. With two speeds the
arrival time T is a refracted shortest path: straight within each material, bent where it crosses from one to
the other. Every such path is a chain of straight pieces between points of the material interfaces, so T is the
fixed point of two Huygens minima over the interface (the drug's surface subdivided to edges no longer than
`EDGE_CELLS` lattice spacings h of the quadrature; the wetting time w is linear over each triangle, given at its
vertices v, and each minimum over the triangles is exact for that w, :mod:`design.forward.linear_sources`):

    w_v = min( min_{q in B_bath} |v - q| / s,  min_{p covered} (w(p) + |v - p| / s),    (through barrier)
               min_{q open in its body} |v - q|,  min_{p covered in its body} (w(p) + |v - p|) )  (through drug)

for every vertex v whose triangles barrier covers (the point just outside each lies in the barrier), where B_bath
are the barrier's triangles facing the bath and "open" the drug's triangles facing the bath (w = 0 at their
vertices). The iteration starts from the straight paths and decreases to the fixed point in one pass per crossing
of an interface. Inside the drug, T(x) = min_p (w(p) + |x - p|) over the surface of x's own body: the exact
reference evaluator's quadrature with these wetting times (:mod:`design.forward.front_quadrature`: second order
where T is smooth, sub-cells at ridges). Linear wetting times are second order in the triangles' size where w
varies along a face (a constant time per triangle is first order, and early): a coat of varying thickness, or a
covered face wetted from an opening, needs no finer surface than the lattice. An insoluble barrier (s = 0) is
never crossed: T is the distance through drug and void, and a drug body with no open face is *sealed* (it never releases).

Straight pieces are exact where they stay in their material. A drug piece that crosses barrier inside its own
body's convex hull, or (s > 1) a barrier piece that crosses drug, would be faster than the true path; the result
then states it: ``straight`` counts the drug volume whose body's hull holds barrier (s <= 1) and the method names
the lower bound. Drug voids and barrier voids are not modelled (a drug mesh must be closed bodies without voids).

Error. The curve is the sum of each body's quadrature scaled to its exact volume; the stated error is
max_tau |C_h - C_2h| with both the lattice and the triangles' size doubled (so it covers the wetting times'
discretisation too), refined by :func:`design.forward.solid_lattice.choose` until it meets ``tolerance`` of the
drug volume. A barrier's thickness is measured exactly (point-triangle distances), never on the lattice: only the
drug's thickness sizes the lattice.
"""
from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import trimesh

from design._validate import check_positive
from design.errors import DesignError
from design.forward.distance import Surface
from design.forward.front_quadrature import front_curve
from design.forward.linear_sources import LinearSources
from design.forward.reference import SAMPLES, ReferenceRelease, _check_mesh, _until_dissolved, metric_mesh
from design.forward.solid_lattice import DEFAULT_TOLERANCE, choose
from design.forward.twomaterial import check_barrier_speed

log = logging.getLogger(__name__)

MAX_POINTS = 0.15e6
"""Most lattice points of one two-material evaluation (the one-material evaluator's budget is 10 million): a point
costs about 100 times more here (the arrival is a minimum over linear wetting times, and fronts that graze a coated
surface split many cells into sub-cells; 12 s of CPU for the 0.022 million points of the 1326 mm^3 pill in a coat),
so that a coated part is released within a minute on two cores, or kept at the best affordable lattice with its
stated error and a warning, or refused (:func:`design.forward.solid_lattice.choose`)."""
SEALED_MM = 1e12
"""Wetting time given to a drug vertex that no path reaches (behind an insoluble barrier), mm."""
QUANTUM_MM = 1e-9
"""Wetting times are rounded to this, so that a face of uniform cover carries one time exactly."""
PROBE = 1e-7
"""Step off a triangle, as a fraction of the bounding box's diagonal, to see which material lies beyond it."""
MAX_SWEEPS = 200
"""Passes of the fixed-point iteration at most (one per crossing of an interface along the slowest path)."""
EDGE_CELLS = 1.0
"""The drug's surface is subdivided to edges of this many lattice spacings h (the wetting time is linear over each
triangle: its error, second order in the edge, is then of the lattice's order and within the stated error, which
doubles both)."""
SETTLED_MM = 1e-7
"""The fixed-point iteration looks only for wetting times that fall by more than this, and stops when none does, mm
(a path that gains less is no other path: without the margin, the sources along a straight path to an opening all
bound a vertex's time exactly and none of them is pruned)."""
HULL_SLACK = 1e-6
"""Barrier volume inside a drug body's convex hull (beyond the body) under this fraction of the body's volume is
none (round-off of the boolean)."""


@dataclass(frozen=True)
class TwoMaterialReference(ReferenceRelease):
    """The drug's release from a drug/barrier print by exact distances (a :class:`ReferenceRelease` of the drug).

    ``volume_mm3`` is the drug's volume, sealed drug included; the curve ends at the unsealed drug's volume.

    Attributes
    ----------
    barrier_speed : float
        s, the barrier's erosion speed over the drug's (0: insoluble).
    sealed_mm3 : float
        Drug in bodies no path reaches (behind an insoluble barrier), mm^3.
    sealed_regions_mm3 : tuple of float
        Those bodies' volumes, largest first, mm^3.
    straight_mm3 : float
        Drug in bodies where a straight path may cross the other material (see the module docstring): 0 when the
        curve is exact to its stated error; otherwise the curve is a lower bound on the time there.
    barrier_volume_mm3 : float
        The barrier's region (its mesh less the drug), mm^3.
    """

    barrier_speed: float = 0.0
    sealed_mm3: float = 0.0
    sealed_regions_mm3: tuple[float, ...] = ()
    straight_mm3: float = 0.0
    barrier_volume_mm3: float = 0.0


@dataclass(frozen=True)
class _Interfaces:
    """The drug's bodies, their surfaces subdivided (the sources of the front) and which source triangles barrier
    covers, and the barrier's bath-facing triangles."""

    bodies: list[trimesh.Trimesh]
    sources: list[trimesh.Trimesh]
    covered: list[np.ndarray]
    bath_barrier: trimesh.Trimesh | None


def _subdivided(mesh: trimesh.Trimesh, edge: float) -> trimesh.Trimesh:
    v, f = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=edge, max_iter=40)
    return trimesh.Trimesh(v, f, process=False)


def _bodies(drug: trimesh.Trimesh) -> list[trimesh.Trimesh]:
    bodies = drug.split(only_watertight=False) if drug.body_count > 1 else [drug]
    for b in bodies:
        if b.volume <= 0 or not b.is_watertight:
            raise DesignError("two-material reference: the drug mesh has a void or an open shell; only closed bodies "
                              "without voids are modelled")
    return list(bodies)


def _interfaces(drug: trimesh.Trimesh, barrier: trimesh.Trimesh, edge: float) -> _Interfaces:
    """Subdivide the drug's surface to ``edge`` and classify its triangles and the barrier's by what lies beyond."""
    step = PROBE * float(np.linalg.norm(np.ptp(np.vstack([drug.bounds, barrier.bounds]), axis=0)))
    drug_surface, barrier_surface = Surface(drug), Surface(barrier)
    bodies, sources, covered = _bodies(drug), [], []
    for body in bodies:
        fine = _subdivided(body, edge)
        beyond = fine.triangles_center + step * fine.face_normals
        covered.append(barrier_surface.signed_distance(beyond)[0] > 0.0)
        sources.append(fine)
    # a barrier triangle inside the drug, or facing it, bounds no barrier region (the drug wins): only those that
    # reach into the drug are subdivided, to tell their parts apart
    inside = drug_surface.signed_distance(barrier.vertices)[0] > 0.0
    mixed = inside[barrier.faces].any(axis=1)
    parts = [barrier.submesh([np.flatnonzero(~mixed)], append=True)] if (~mixed).any() else []
    if mixed.any():
        parts.append(_subdivided(barrier.submesh([np.flatnonzero(mixed)], append=True), edge))
    fine = trimesh.util.concatenate(parts)
    centre = fine.triangles_center
    faces_bath = ((drug_surface.signed_distance(centre)[0] <= 0.0)
                  & (drug_surface.signed_distance(centre + step * fine.face_normals)[0] <= 0.0))
    bath = fine.submesh([np.flatnonzero(faces_bath)], append=True) if faces_bath.any() else None
    return _Interfaces(bodies, sources, covered, bath)


def _distance(mesh: trimesh.Trimesh | None, points: np.ndarray) -> np.ndarray:
    """Distance from each point to a set of triangles (inf without any)."""
    if mesh is None or not len(mesh.faces):
        return np.full(len(points), np.inf)
    return Surface(mesh).nearest_stored(np.ascontiguousarray(points), np.zeros(len(mesh.faces)))[0]


def _covered_mesh(sources: list[trimesh.Trimesh], covered: list[np.ndarray]) -> trimesh.Trimesh:
    """The covered triangles of every body as one mesh on all the bodies' vertices (in body order)."""
    first = np.cumsum([0] + [len(m.vertices) for m in sources])
    faces = np.vstack([m.faces[c] + first[k] for k, (m, c) in enumerate(zip(sources, covered))])
    return trimesh.Trimesh(np.vstack([m.vertices for m in sources]), faces, process=False)


def wetting_times(faces: _Interfaces, s: float) -> list[np.ndarray]:
    """Per body, per vertex of its subdivided surface, when the front reaches it: 0 on an open face, the fixed point
    of the module docstring where barrier covers every face around it, `SEALED_MM` where nothing reaches it."""
    sources, covered = faces.sources, faces.covered
    times = []
    for m, c in zip(sources, covered):
        w = np.full(len(m.vertices), SEALED_MM)
        w[m.faces[~c].ravel()] = 0.0
        times.append(w)
    todo = [np.flatnonzero(w > 0.0) for w in times]
    if not sum(t.size for t in todo):
        return times
    # paths straight from the bath: through the body's open faces, or through the barrier
    for m, c, w, k in zip(sources, covered, times, todo):
        straight = _distance(trimesh.Trimesh(m.vertices, m.faces[~c], process=False) if (~c).any() else None,
                             m.vertices[k])
        if s > 0.0:
            straight = np.minimum(straight, _distance(faces.bath_barrier, m.vertices[k]) / s)
        w[k] = np.minimum(straight, SEALED_MM)
    bodies = [LinearSources(trimesh.Trimesh(m.vertices, m.faces[c], process=False), w) if c.any() else None
              for m, c, w in zip(sources, covered, times)]
    every = _covered_mesh(sources, covered)
    through = LinearSources(every, s * np.concatenate(times)) if s > 0.0 else None
    points = np.vstack([m.vertices[k] for m, k in zip(sources, todo)])
    for sweep in range(MAX_SWEEPS):  # refracted paths: from covered face to covered face, through drug or barrier
        before = np.concatenate([w[k] for w, k in zip(times, todo)])
        for m, w, k, body in zip(sources, times, todo, bodies):
            if body is not None and k.size:
                body.set_times(w)
                better, tri, _ = body.arrival(m.vertices[k], w[k] - SETTLED_MM)
                w[k] = np.where(tri >= 0, better, w[k])
        if through is not None:
            through.set_times(s * np.concatenate(times))
            now = np.concatenate([w[k] for w, k in zip(times, todo)])
            better, tri, _ = through.arrival(points, s * (now - SETTLED_MM))
            now = np.where(tri >= 0, better / s, now)
            for w, k, lo, hi in zip(times, todo, *_pieces([k.size for k in todo])):
                w[k] = now[lo:hi]
        after = np.concatenate([w[k] for w, k in zip(times, todo)])
        if np.all(before - after <= SETTLED_MM):
            break
    log.debug("wetting times: %d covered vertices, %d sweeps", points.shape[0], sweep + 1)
    return [np.where(w >= SEALED_MM, SEALED_MM, np.round(w / QUANTUM_MM) * QUANTUM_MM) for w in times]


def _pieces(sizes: list[int]) -> tuple[list[int], list[int]]:
    """Start and end of consecutive pieces of the given sizes."""
    ends = np.cumsum(sizes).tolist()
    return [e - n for e, n in zip(ends, sizes)], ends


def _straight_paths(bodies: list[trimesh.Trimesh], barrier: trimesh.Trimesh, drug: trimesh.Trimesh, s: float
                    ) -> float:
    """Drug volume in bodies where a straight path of the fixed point may cross the other material, mm^3."""
    if s > 1.0:  # a barrier piece may cross drug inside the barrier's hull
        hull = barrier.convex_hull
        inside = _overlap(hull, drug) - _overlap(barrier, drug)
        return float(drug.volume) if inside > HULL_SLACK * float(drug.volume) else 0.0
    total = 0.0
    for body in bodies:
        hull = body.convex_hull
        if hull.volume - body.volume <= HULL_SLACK * body.volume:
            continue
        if _overlap(hull, barrier) - _overlap(body, barrier) > HULL_SLACK * body.volume:
            total += float(body.volume)
    return total


def _overlap(a: trimesh.Trimesh, b: trimesh.Trimesh) -> float:
    if not (np.all(a.bounds[0] <= b.bounds[1]) and np.all(b.bounds[0] <= a.bounds[1])):
        return 0.0
    both = trimesh.boolean.intersection([a, b], engine="manifold")
    return float(both.volume) if len(both.faces) else 0.0


class _Print:
    """A drug and a barrier in the isotropic metric: the drug's release on a lattice, its interfaces cached per
    spacing."""

    def __init__(self, drug: trimesh.Trimesh, barrier: trimesh.Trimesh, s: float, anisotropy: float) -> None:
        self.drug, self.barrier, self.s, self.a = drug, barrier, s, anisotropy
        self.faces_at: dict[float, tuple[_Interfaces, list[np.ndarray]]] = {}

    def state(self, h: float) -> tuple[_Interfaces, list[np.ndarray]]:
        if h not in self.faces_at:
            faces = _interfaces(self.drug, self.barrier, EDGE_CELLS * h)
            self.faces_at[h] = (faces, wetting_times(faces, self.s))
        return self.faces_at[h]

    def sealed_regions(self) -> list[float]:
        """Volumes of the drug bodies no path reaches, largest first, mm^3 (on the surfaces as meshed)."""
        faces, times = self.state(float(np.linalg.norm(np.ptp(self.drug.bounds, axis=0))) / EDGE_CELLS)
        return sorted((float(b.volume) * self.a for b, w in zip(faces.bodies, times) if np.all(w >= SEALED_MM)),
                      reverse=True)

    def curve(self, h: float, samples: np.ndarray) -> tuple[np.ndarray, float, float]:
        """(released drug at ``samples``, the latest arrival, the sealed volume) on a lattice of spacing h."""
        faces, times = self.state(h)
        total, end, sealed = np.zeros(samples.size), 0.0, 0.0
        for body, source, w in zip(faces.bodies, faces.sources, times):
            if np.all(w >= SEALED_MM):
                sealed += float(body.volume) * self.a
                continue
            c, est, last = front_curve(Surface(body), LinearSources(source, w), np.asarray(body.bounds), h, samples)
            total += c * (float(body.volume) * self.a / est)
            end = max(end, last)
        return total, end, sealed


def two_material_reference_release(drug_mesh: trimesh.Trimesh, barrier_mesh: trimesh.Trimesh, barrier_speed: float,
                                   tau_mm: np.ndarray | None = None, *, anisotropy: float = 1.0,
                                   tolerance: float = DEFAULT_TOLERANCE, max_points: float = MAX_POINTS,
                                   source: str = "the drug", progress: Callable[[str], None] | None = None
                                   ) -> TwoMaterialReference:
    """The drug's release from a drug solid and a barrier solid by exact distances, with its error estimate.

    Parameters
    ----------
    drug_mesh, barrier_mesh : trimesh.Trimesh
        Closed, consistently wound meshes in mm; the barrier's region is its mesh less the drug (the drug wins where
        they overlap), so a barrier box around the drug is a coat. The drug's bodies may be several, without voids.
    barrier_speed : float
        s >= 0: the barrier erodes at s times the drug's rate; 0 is insoluble.
    tau_mm : (K,) array_like of float, mm, optional
        Erosion depths (mm of drug); None: `SAMPLES` uniform depths up to where the unsealed drug is gone.
    anisotropy : float
        Build-direction (z) erosion rate over the in-plane rate, for both materials (the metric of
        :func:`design.forward.reference.metric_mesh`).
    tolerance : float
        The stated error aimed at, a fraction of the drug volume.
    max_points : float
        The most lattice points one evaluation may take.
    source : str
        Named in a refusal.
    progress : callable, optional
        Called with a line per lattice evaluated.

    Returns
    -------
    TwoMaterialReference

    Raises
    ------
    DesignError
        For an open or inconsistently wound mesh, a drug mesh with voids, a negative speed or a bad `tau_mm`.
    design.forward.solid_lattice.TooThinError
        For drug too thin to resolve within ``max_points``.

    Examples
    --------
    >>> import trimesh
    >>> drug = trimesh.creation.box((2.0, 2.0, 2.0))
    >>> ref = two_material_reference_release(drug, trimesh.creation.box((4.0, 4.0, 4.0)), 0.5, [0.0, 2.0, 2.5, 3.5])
    >>> [round(float(v), 2) for v in ref.released_mm3]
    [0.0, 0.0, 7.0, 8.0]
    """
    began = time.perf_counter()
    s = check_barrier_speed(barrier_speed)
    tau = None if tau_mm is None else np.asarray(tau_mm, dtype=np.float64)
    if tau is not None and (tau.ndim != 1 or not np.all(np.isfinite(tau))):
        raise DesignError(f"tau_mm must be a 1D array of finite depths, got shape {tau.shape}")
    a = check_positive("anisotropy", anisotropy)
    drug = metric_mesh(_check_mesh(drug_mesh), a)
    barrier = metric_mesh(_check_mesh(barrier_mesh), a)
    whole = _bodies(drug)
    volume = float(drug.volume) * a
    barrier_volume = (float(barrier.volume) - _overlap(barrier, drug)) * a
    straight = _straight_paths(whole, barrier, drug, s) * a
    found: dict[float, tuple] = {}
    curve = _Print(drug, barrier, s, a).curve

    def evaluate(h: float) -> float:
        nonlocal tau
        if tau is None:  # a scout on the coarse lattice finds where the unsealed drug is gone
            end = curve(2.0 * h, np.zeros(1))[1]
            tau = np.linspace(0.0, end + 1.25 * h, SAMPLES)
        fine, coarse = curve(h, tau), curve(2.0 * h, tau)
        error = float(np.abs(fine[0] - coarse[0]).max()) if tau.size else 0.0
        if found and tau.size:
            error = min(error, float(np.abs(fine[0] - found[min(found)][0]).max()))
        found[h] = (fine[0], error, fine[1], fine[2])
        return error / volume

    sealed_regions = _Print(drug, barrier, s, a).sealed_regions()
    open_volume = volume - sum(sealed_regions)
    if open_volume <= 1e-12 * volume:
        tau = np.zeros(1) if tau is None else tau
        released, error, total, h, lattice = np.zeros(tau.size), 0.0, math.inf, float("nan"), "all drug sealed"
    else:
        choice = choose(evaluate, np.asarray(drug.bounds), open_volume / a, float(drug.area), tolerance=tolerance,
                        max_points=max_points, source=source, say=progress)
        h, lattice = choice.spacing_mm, choice.reason
        released, error, total, _ = found[h]
        if tau_mm is None:
            tau, released = _until_dissolved(tau, released, open_volume)
    seconds = time.perf_counter() - began
    method = "exact-distance, two materials" + (", straight paths (lower bound in part)" if straight else "") + (
        f", anisotropy {a:g}" if a != 1.0 else "")
    log.debug("two-material reference: s = %g, h = %.4g mm, error %.3g mm^3, %.2f s", s, h, error, seconds)
    return TwoMaterialReference(tau_mm=tau, released_mm3=released, volume_mm3=volume, error_mm3=error, method=method,
                                cell_mm=h, total_time_mm=total, seconds=seconds, lattice=lattice, barrier_speed=s,
                                sealed_mm3=sum(sealed_regions), sealed_regions_mm3=tuple(sealed_regions),
                                straight_mm3=straight, barrier_volume_mm3=barrier_volume)
