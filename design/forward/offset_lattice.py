"""The reference evaluator's quadrature for a print whose surface lies a distance off its mesh's (a surface offset).

A print with surface offset o is the solid P = {x : s(x) > -o}, s the exact signed distance to the mesh (positive
inside): o > 0 grows the mesh by o (its parallel body, edges rounded), o < 0 shrinks it by |o| (its erosion, edges
sharp). The definition is the grid model's (`design.files.pipeline.offset_solid`), in physical mm. Water erodes P at
unit speed in the plane and at the anisotropy a along z; in the metric with z scaled by 1 / a
(:func:`design.forward.reference.metric_mesh`) the front is isotropic and a point's arrival time T is its metric
distance to P's complement.

Isotropic (a = 1), T = s + o wherever the print is solid:

- o < 0: P's complement is the mesh's complement grown by |o|, and the distance to a set grown by a ball is the
  distance to the set less the radius: T = s - |o|, exact for any solid.
- o > 0: T >= s + o (a path from x to the bath leaves the mesh at depth >= s and still has o to go), with equality
  when y* = x - (s + o) grad s, the point o beyond x's closest surface point, is at least o from the mesh (the
  certificate): y* is then in P's complement. It holds everywhere on a convex solid and fails in the concave creases
  and the gaps narrower than 2o that the grown surface fills, where T is larger. There y* is pushed off the mesh
  along its distance's gradient until it is o from it (`PUSHES` at most); that point bounds T from above (exactly
  at a crease) and is the cell's arrival time. A cell's ramp moved by d changes the curve by at most min(d, h) h^2,
  and only while it is under way at one of the two times: the largest sum of those over the cells at one depth
  (`OffsetCurve.unsure_mm3`) bounds the curve's error from them and joins the stated error.

Anisotropic (a != 1), a face with metric unit normal m (physical normal m with m_z scaled by 1 / a) moves
k(m) = o |(m_x, m_y, m_z / a)| in the metric (o across a vertical face, o / a across a horizontal one). A point
inside the mesh takes T = min_t (|y - t| + k_t) over the triangles t, the distance to the nearest face plane moved
by its offset: exact wherever the print's nearest surface is a face's (a box's every interior point). A point of
the shell the print adds outside the mesh is in the print exactly when its physical distance d to the mesh is below
o (P's shape is exact), and takes T = (o - d) / |(n_x, n_y, a n_z)|, n the physical unit vector to its closest
point: exact off a face, first order in the o-neighbourhood of an edge or vertex, where the print's surface is the
edge swept by the ellipsoid of semi-axes (o, o, o / a). There T is within o |1 / a - 1| of the exact arrival time
(tests/design/forward/test_reference_offset.py measures it against a box's convex formula; docs/evidence/forward.md
the curve's error).

Quadrature as `design.forward.quadrature`: each lattice cell spreads its volume uniformly over [T - h/2, T + h/2],
the part before 0 (outside the print) releasing nothing; cells across a ridge of T are split into `SPLIT`^3
sub-cells. Every shell must face the bath (no sealed voids: their walls' wetting with an offset is not modelled).
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from numba import njit

from design.forward.distance import Surface, closest_on_triangle, inside_sign, sign_and_direction
from design.forward.quadrature import (
    BAND,
    BLOCK,
    SPLIT,
    Lattice,
    Ramps,
    folded_ramps,
    neighbour_candidates,
    opposite_front,
    ridge_cells,
)
from design.threads import thread_count

CERTIFICATE_TOLERANCE = 1e-7
"""A certificate point y* may lie this fraction of a lattice spacing closer than the offset to the mesh (round-off)."""
PUSHES = 4
"""Most pushes of a failed certificate's probe towards the offset surface (:meth:`PrintLattice.bounds_above`)."""
ON_SURFACE = 1e-9
"""A lattice point within this fraction of a spacing of the surface is on it: its distance's gradient (the unit vector
to its closest point) is round-off, and its face's normal is taken instead."""


def metric_offsets(normals: np.ndarray, offset_mm: float, anisotropy: float) -> np.ndarray:
    """k(m) = o |(m_x, m_y, m_z / a)|: the metric distance a surface with metric unit normal m (rows of ``normals``)
    moves when the physical surface moves ``offset_mm`` along its normal, mm (o for a = 1)."""
    n = np.asarray(normals, dtype=np.float64)
    return float(offset_mm) * np.sqrt(n[..., 0] ** 2 + n[..., 1] ** 2 + (n[..., 2] / anisotropy) ** 2)


def largest_offset(offset_mm: float, anisotropy: float) -> float:
    """The largest metric distance any face moves (o max(1, 1 / a)), mm; 0 for a shrink."""
    return max(float(offset_mm), 0.0) * max(1.0, 1.0 / anisotropy)


@dataclass(frozen=True)
class OffsetCurve:
    """A lattice's quadrature of a print: the curve at the requested depths (metric mm^3), the ramps' volume, the
    latest arrival (mm) and the volume of the cells whose certificate failed (metric mm^3; 0 for a shrink)."""

    curve: np.ndarray
    volume: float
    end: float
    unsure_mm3: float


@njit(cache=True, nogil=True)
def _subcell_ramps(cells, base, tri_a, tri_b, first, h, split, vx, vx_phys, k_face, o, aniso, face_n, edge_n, vert_n,
                   faces):
    """Ramps (start, end) of the split^3 sub-cells of each listed cell of a block (cell (0, 0, 0) is the lattice's
    cell `base`), by exact distances to the triangles closest to the cell and its 26 neighbours (`tri_a`: by
    distance, `tri_b`: by arrival time): T as :meth:`PrintLattice.arrival` gives it (``vx_phys`` the triangles in
    physical mm, ``k_face`` their metric offsets). A sub-cell inside the print where opposite fronts meet (a plate's
    mid-plane) is two ramps (:func:`design.forward.quadrature.folded_ramps`), returned in (start2, end2)."""
    hs = h / split
    per = split ** 3
    start = np.zeros(cells.shape[0] * per)
    end = np.zeros(cells.shape[0] * per)
    start2 = np.zeros(cells.shape[0] * per)
    end2 = np.zeros(cells.shape[0] * per)
    cand = np.empty(54, dtype=np.int64)
    value = np.empty(54)
    toward = np.empty((54, 3))
    for c in range(cells.shape[0]):
        ci, cj, ck = cells[c, 0], cells[c, 1], cells[c, 2]
        n_cand = neighbour_candidates(tri_a, tri_b, ci, cj, ck, cand)
        s = c * per
        for a in range(split):
            px = first[0] + (ci + base[0]) * h + (a + 0.5) * hs - 0.5 * h
            for b in range(split):
                py = first[1] + (cj + base[1]) * h + (b + 0.5) * hs - 0.5 * h
                for e in range(split):
                    pz = first[2] + (ck + base[2]) * h + (e + 0.5) * hs - 0.5 * h
                    best_d = np.inf
                    near = -1
                    t_in = np.inf
                    for m in range(n_cand):
                        t = cand[m]
                        qx, qy, qz, _ = closest_on_triangle(px, py, pz, t, vx)
                        d = np.sqrt((px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2)
                        if d < best_d:
                            best_d = d
                            near = t
                        value[m] = d + k_face[t]
                        if d > 0.0:
                            toward[m, 0] = (px - qx) / d
                            toward[m, 1] = (py - qy) / d
                            toward[m, 2] = (pz - qz) / d
                        t_in = min(t_in, value[m])
                    if near < 0:
                        s += 1
                        continue
                    sg, _, _, _ = inside_sign(px, py, pz, near, vx, face_n, edge_n, vert_n, faces)
                    if aniso == 1.0:
                        arrive = sg * best_d + o
                    elif sg > 0.0:
                        arrive = t_in
                    else:  # outside the mesh: (o - physical distance) over the metric gradient's length
                        zx, zy, zz = px, py, aniso * pz
                        dp = np.inf
                        gx, gy, gz = 0.0, 0.0, 1.0
                        for m in range(n_cand):
                            qx, qy, qz, _ = closest_on_triangle(zx, zy, zz, cand[m], vx_phys)
                            d = np.sqrt((zx - qx) ** 2 + (zy - qy) ** 2 + (zz - qz) ** 2)
                            if d < dp:
                                dp = d
                                if d > 0.0:
                                    gx, gy, gz = (qx - zx) / d, (qy - zy) / d, (qz - zz) / d
                        arrive = (o - dp) / np.sqrt(gx * gx + gy * gy + (aniso * gz) ** 2)
                    other = opposite_front(value, toward, n_cand, hs) if sg > 0.0 and arrive > 0.5 * hs else -1
                    if other >= 0:
                        start[s], end[s], start2[s], end2[s] = folded_ramps(arrive, value[other], hs)
                    elif arrive > -0.5 * hs:
                        start[s] = max(arrive - 0.5 * hs, 0.0)
                        end[s] = arrive + 0.5 * hs
                    s += 1
    return start, end, start2, end2


class PrintLattice:
    """The print of a metric-scaled mesh with a surface offset, evaluated block by block on a lattice.

    Parameters
    ----------
    surface : Surface
        The mesh in the metric (z scaled by 1 / a); every shell faces the bath.
    offset_mm : float
        The physical surface offset o, mm.
    anisotropy : float
        a, the build direction's erosion rate over the in-plane rate.
    """

    def __init__(self, surface: Surface, offset_mm: float, anisotropy: float, physical: Surface | None = None
                 ) -> None:
        self.surface = surface
        self.physical = surface if physical is None else physical
        self.offset = float(offset_mm)
        self.anisotropy = float(anisotropy)
        self.scale = np.array([1.0, 1.0, self.anisotropy])  # metric to physical coordinates
        self.k_face = metric_offsets(surface.face_n, self.offset, anisotropy)  # stored order
        self.vx_phys = np.ascontiguousarray(surface.vx * self.scale)
        self.grow = largest_offset(self.offset, anisotropy)

    def bounds(self, bounds: np.ndarray) -> np.ndarray:
        """The mesh's (metric) bounds widened by the largest outward offset: the print's."""
        return np.asarray(bounds, dtype=np.float64) + np.array([[-1.0], [1.0]]) * self.grow

    def blocks(self, lattice: Lattice) -> np.ndarray:
        """The blocks (first cells) holding a cell of the print or within `BAND` + 1 spacings of its surface."""
        firsts = lattice.blocks()
        h = lattice.h
        size = np.minimum(BLOCK, lattice.n[None, :] - firsts)
        centre = lattice.first + h * (firsts + 0.5 * (size - 1))
        reach = 0.5 * h * np.linalg.norm(size - 1, axis=1) + (BAND + 1.0) * h + self.grow
        s = self.surface
        dist, tri = s.nearest_stored(centre, np.zeros(len(s.faces)))
        sign = sign_and_direction(centre, tri, s.vx, s.face_n, s.edge_n, s.vert_n, s.faces)[0]
        return firsts[(sign > 0) | (dist <= reach)]

    def arrival(self, centres: np.ndarray, shape: tuple[int, int, int], h: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per lattice point (metric): the arrival time T (-inf far outside), its unit gradient (into the print),
        the closest triangle, the triangle that sets T (-1 far outside) and the certificate's probe y* in physical
        mm (module docstring)."""
        s = self.surface
        f, grad, tri = s.lattice_distance(centres, shape, BAND * h + self.grow + h)
        on = np.abs(f) <= ON_SURFACE * h  # a point on the surface: its gradient is its face's inward normal
        grad[on] = -s.face_n[tri[on]]
        arrive = f + self.offset
        by = tri.copy()
        inside = f > 0.0
        probe = (centres - np.where(np.isfinite(arrive), arrive, 0.0)[:, None] * grad) * self.scale
        if self.anisotropy == 1.0:
            return arrive, grad, tri, by, probe
        arrive[inside], by[inside] = s.nearest_stored(centres[inside], self.k_face)
        grad[inside] = sign_and_direction(centres[inside], by[inside], s.vx, s.face_n, s.edge_n, s.vert_n, s.faces)[1]
        probe[inside] = (centres[inside] - arrive[inside, None] * grad[inside]) * self.scale
        shell = np.isfinite(f) & ~inside
        if shell.any():  # the print's shell beyond the mesh: {physical distance < o}, T to first order from it
            p = self.physical
            x = centres[shell] * self.scale
            d, t = p.nearest_stored(x, np.zeros(len(p.faces)))
            n_in = sign_and_direction(x, t, p.vx, p.face_n, p.edge_n, p.vert_n, p.faces)[1]
            n_in[d <= ON_SURFACE * h] = -p.face_n[t[d <= ON_SURFACE * h]]
            metric = n_in * self.scale
            length = np.linalg.norm(metric, axis=1)
            arrive[shell] = (self.offset - d) / length
            grad[shell] = metric / length[:, None]
            probe[shell] = x - (self.offset - d)[:, None] * n_in
        return arrive, grad, tri, by, probe

    def bounds_above(self, centres: np.ndarray, probe: np.ndarray, h: float) -> np.ndarray:
        """Per print cell (metric centres, certificate probes y* in physical mm): an upper bound on its arrival time,
        NaN where the certificate holds (T is exact) and inf where none was found. A failed probe is pushed off the
        mesh to the offset surface along its distance's gradient (`PUSHES` times at most); the first point at
        least o from the mesh is in the print's complement, so its metric distance bounds T from above (exact at
        a concave crease, where two pushes reach the crease's offset line)."""
        upper = np.full(len(probe), np.nan)
        if self.offset <= 0.0 or not len(probe):
            return upper
        p = self.physical
        zero = np.zeros(len(p.faces))
        floor = self.offset - CERTIFICATE_TOLERANCE * h
        todo = np.flatnonzero(p.nearest_stored(np.ascontiguousarray(probe), zero)[0] < floor)
        upper[todo] = np.inf
        y = probe[todo]
        for _ in range(PUSHES):
            if not len(todo):
                break
            d, t = p.nearest_stored(np.ascontiguousarray(y), zero)
            sign, grad = sign_and_direction(y, t, p.vx, p.face_n, p.edge_n, p.vert_n, p.faces)
            grad[d <= ON_SURFACE * h] = -p.face_n[t[d <= ON_SURFACE * h]]
            y = y - (self.offset + sign * d)[:, None] * grad
            d = p.nearest_stored(np.ascontiguousarray(y), zero)[0]
            done = d >= floor
            upper[todo[done]] = np.linalg.norm(y[done] / self.scale - centres[todo[done]], axis=1)
            todo, y = todo[~done], y[~done]
        return upper

    def block_ramps(self, lattice: Lattice, block: np.ndarray, ramps: Ramps) -> np.ndarray:
        """Add one block's ramps to ``ramps``; returns (lower, upper, weight) rows of its cells whose certificate
        failed: the depths over which the curve may be off by their weight (metric mm^3, :func:`_most_unsure`)."""
        h = lattice.h
        lo = np.maximum(block - 1, 0)
        hi = np.minimum(block + BLOCK + 1, lattice.n)
        shape = tuple(int(v) for v in hi - lo)
        centres = lattice.centres(lo, hi)
        arrive, grad, tri, by, probe = self.arrival(centres, shape, h)
        ridge = ridge_cells(grad.reshape(shape + (3,)))
        own = np.zeros(shape, dtype=bool)
        own[tuple(slice(int(block[a] - lo[a]), int(min(block[a] + BLOCK, lattice.n[a]) - lo[a]))
                  for a in range(3))] = True
        own = own.ravel()
        ridge = own & ridge.ravel() & (arrive > -h)
        solid = np.flatnonzero(own & (arrive > -0.5 * h))
        upper = self.bounds_above(centres[solid], probe[solid], h)
        failed = ~np.isnan(upper)
        # a cell's ramp over [T - h/2, T + h/2] moved by d changes the curve by at most min(d, h) h^2, and only
        # while the ramp at either arrival time is under way
        low, high = arrive[solid][failed], upper[failed]
        unsure = np.column_stack([low - 0.5 * h, high + 0.5 * h, np.clip(low / h + 0.5, 0.0, 1.0) * h * h
                                  * np.minimum(high - low, h)])
        pushed = solid[failed & np.isfinite(upper)]
        arrive[pushed] = upper[failed & np.isfinite(upper)]  # the upper bound: exact at a crease
        plain = own & ~ridge & (arrive > -0.5 * h)
        ramps.add(np.maximum(arrive[plain] - 0.5 * h, 0.0), arrive[plain] + 0.5 * h, h * h)
        cells = np.argwhere(ridge.reshape(shape))
        if len(cells):
            s = self.surface
            sub_start, sub_end, fold_start, fold_end = _subcell_ramps(
                cells, lo.astype(np.int64), tri.reshape(shape), by.reshape(shape), lattice.first, h, SPLIT, s.vx,
                self.vx_phys, self.k_face, self.offset, self.anisotropy, s.face_n, s.edge_n, s.vert_n, s.faces)
            ramps.add_sub_cells(sub_start, sub_end, fold_start, fold_end, (h / SPLIT) ** 2)
        return unsure

    def curve(self, bounds: np.ndarray, h: float, tau: np.ndarray, workers: int | None = None) -> OffsetCurve:
        """Quadrature on a lattice of spacing h over the print's bounds (``bounds`` the mesh's, metric)."""
        lattice = Lattice.over(self.bounds(bounds), h)
        blocks = self.blocks(lattice)
        tau = np.asarray(tau, dtype=np.float64)

        def one(block: np.ndarray) -> tuple[Ramps, np.ndarray]:
            ramps = Ramps.empty(tau)
            return ramps, self.block_ramps(lattice, block, ramps)

        total = Ramps.empty(tau)
        unsure = []
        workers = workers or min(len(blocks), thread_count()) or 1
        with ThreadPoolExecutor(max_workers=workers) as pool:
            for ramps, bad in (pool.map(one, blocks) if workers > 1 else map(one, blocks)):
                total.merge(ramps)
                unsure.append(bad)
        return OffsetCurve(total.curve(), total.volume, total.end, _most_unsure(np.concatenate(unsure or [np.zeros((0, 3))])))


def _most_unsure(rows: np.ndarray) -> float:
    """max over tau of the weight of the (lower, upper, weight) rows with lower <= tau < upper: the most the curve
    can be off at one depth from the cells whose arrival time is uncertain."""
    if not len(rows):
        return 0.0
    times = np.concatenate([rows[:, 0], rows[:, 1]])
    steps = np.concatenate([rows[:, 2], -rows[:, 2]])
    order = np.lexsort((-steps, times))  # at equal times, open before close: conservative
    return float(np.cumsum(steps[order]).max(initial=0.0))

