"""The reference evaluator's quadrature: a lattice's cells' arrival-time ramps summed into a release curve.

Each cell of a cubic lattice of spacing h spreads its volume over arrival times [T_c - h/2, T_c + h/2] from its
exact signed distance (:class:`design.forward.distance.Surface`) and its fluid region's wetting time
(:mod:`design.forward.wetting`); a cell across a ridge of the arrival time or next to a void's wall is split
into `SPLIT`^3 sub-cells, and a sub-cell where fronts from opposite sides meet is two ramps (:func:`folded_ramps`;
see :mod:`design.forward.reference` for the error analysis).
"""
from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from numba import njit

from design.forward.distance import Surface, closest_on_triangle, inside_sign, sign_and_direction
from design.threads import thread_count

RIDGE_ANGLE_DEG = 20.0
"""A lattice cell whose arrival-time gradient differs from a face neighbour's by more than this straddles
a ridge of the arrival time and is split into sub-cells."""
SPLIT = 4
"""Sub-cells per axis of a ridge cell."""
OPPOSITE_COS = float(np.cos(np.radians(RIDGE_ANGLE_DEG)))
"""Two fronts whose directions are within `RIDGE_ANGLE_DEG` of opposite (cosine below -this) meet at a flat ridge."""
BAND = 2.0
"""Lattice spacings from the surface within which points outside are given exact distances; farther
out, they release nothing and are only classified."""
BLOCK = 32
"""Lattice cells per axis of a block, the unit of evaluation: only blocks that meet the solid are evaluated."""


@njit(cache=True, nogil=True)
def neighbour_candidates(tri_a, tri_b, ci, cj, ck, cand):
    """The distinct triangles of ``tri_a`` and ``tri_b`` (closest triangles per lattice cell, -1 for none) over
    cell (ci, cj, ck) and its 26 neighbours, written to the front of ``cand``; returns how many."""
    nx, ny, nz = tri_a.shape
    n_cand = 0
    for i in range(max(ci - 1, 0), min(ci + 2, nx)):
        for j in range(max(cj - 1, 0), min(cj + 2, ny)):
            for k in range(max(ck - 1, 0), min(ck + 2, nz)):
                for t in (tri_a[i, j, k], tri_b[i, j, k]):
                    seen = t < 0  # a cell far outside has none
                    for m in range(n_cand):
                        if cand[m] == t:
                            seen = True
                            break
                    if not seen:
                        cand[n_cand] = t
                        n_cand += 1
    return n_cand


@njit(cache=True, nogil=True)
def opposite_front(value, toward, n_cand, hs):
    """The candidate front that meets the leading one (least ``value``, arrival time at a sub-cell's centre) inside
    the sub-cell of side hs from the opposite side (its direction ``toward`` the centre within `RIDGE_ANGLE_DEG` of
    opposite, its arrival within hs of the leader's): a flat ridge of T, such as a plate's mid-plane. -1 if none."""
    lead = 0
    for m in range(n_cand):
        if value[m] < value[lead]:
            lead = m
    other = -1
    for m in range(n_cand):
        facing = toward[m, 0] * toward[lead, 0] + toward[m, 1] * toward[lead, 1] + toward[m, 2] * toward[lead, 2]
        if facing < -OPPOSITE_COS and value[m] < value[lead] + hs and (other < 0 or value[m] < value[other]):
            other = m
    return other


@njit(cache=True, nogil=True)
def folded_ramps(first, second, hs):
    """The two ramps (start, end, start2, end2) of a sub-cell of side hs that opposite fronts reach at times ``first``
    <= ``second`` at its centre: along their common normal T rises from each side to where they meet, so each side's
    part is a ramp of the plain one's slope ending there, not one ramp spreading half the sub-cell past the ridge
    (a first-order error in hs at a plate's mid-plane)."""
    meet = min(0.5 * (second - first), 0.5 * hs)
    return first - 0.5 * hs, first + meet, second - 0.5 * hs, second - meet


@njit(cache=True, nogil=True)
def _subcell_ramps(cells, base, tri_u, tri_t, first, h, split, vx, offset, face_n, edge_n, vert_n, faces):
    """Ramps of the split^3 sub-cells of each listed lattice cell, by exact distances to the triangles
    closest to the cell and its 26 neighbours (the candidates for its sub-cells' closest triangles).

    A sub-cell of spacing hs at signed distance f <= hs/2 from the bath's surface arrives at f and
    releases nothing before 0, unless another region's front reaches it first, at T = min_t (offset[t] +
    |p - t|): its solid fraction f / hs + 1/2 then releases around T. One as close to a void's wall (t its
    closest triangle, w = offset[t] > 0 the void's wetting time) releases its solid, f + hs/2 thick, from the
    wall's side at w + s and from the other side at (the other regions' T at its centre) + f - s, s the depth
    from the wall, whichever is first. Deeper, it arrives at T, as two ramps where a front from the opposite side
    meets the first in it (:func:`folded_ramps`). Returns (start, end, start2, end2) per sub-cell (start == end
    outside the solid; start2 == end2 but for the two ramps' second). `cells` index the arrays `tri_u`, `tri_t` of a
    block whose cell (0, 0, 0) is the lattice's cell `base`.
    """
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
        n_cand = neighbour_candidates(tri_u, tri_t, ci, cj, ck, cand)
        s = c * per
        for a in range(split):
            px = first[0] + (ci + base[0]) * h + (a + 0.5) * hs - 0.5 * h
            for b in range(split):
                py = first[1] + (cj + base[1]) * h + (b + 0.5) * hs - 0.5 * h
                for e in range(split):
                    pz = first[2] + (ck + base[2]) * h + (e + 0.5) * hs - 0.5 * h
                    best_d = np.inf
                    best_t = np.inf
                    near = cand[0]
                    for m in range(n_cand):
                        t = cand[m]
                        qx, qy, qz, _ = closest_on_triangle(px, py, pz, t, vx)
                        d = np.sqrt((px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2)
                        value[m] = offset[t] + d
                        if d > 0.0:
                            toward[m, 0] = (px - qx) / d
                            toward[m, 1] = (py - qy) / d
                            toward[m, 2] = (pz - qz) / d
                        if d < best_d:
                            best_d = d
                            near = t
                        best_t = min(best_t, value[m])
                    sg, _, _, _ = inside_sign(px, py, pz, near, vx, face_n, edge_n, vert_n, faces)
                    f = sg * best_d
                    w = offset[near]
                    if f <= -0.5 * hs:
                        start[s] = 0.0
                        end[s] = 0.0
                    elif f <= 0.5 * hs and w > 0.0:
                        # a void's wall: the solid, L = f + hs/2 thick, is reached by the void's front at
                        # w + s (s from the wall) and by any other region's at about a - s, a = that front's
                        # time at the centre + f (extrapolated to the wall along the normal)
                        other = np.inf
                        for m in range(n_cand):
                            if offset[cand[m]] != w:
                                other = min(other, value[m])
                        length = f + 0.5 * hs
                        reach = other + f
                        if reach <= w:  # the other front crosses it all before the void is wetted
                            start[s] = reach - length
                            end[s] = reach
                        else:  # the fronts meet at s* = (a - w) / 2 (or the void's front takes it all)
                            meet_at = w + min(0.5 * (reach - w), length)
                            start[s] = meet_at - length
                            end[s] = meet_at
                    elif f <= 0.5 * hs and best_t < w + abs(f) - 1e-9 * hs:
                        half = 0.5 * (f / hs + 0.5) * hs
                        start[s] = best_t - half
                        end[s] = best_t + half
                    elif f <= 0.5 * hs:
                        start[s] = max(offset[near] + f - 0.5 * hs, offset[near])
                        end[s] = offset[near] + f + 0.5 * hs
                    else:
                        other = opposite_front(value, toward, n_cand, hs)
                        if other < 0:
                            start[s] = best_t - 0.5 * hs
                            end[s] = best_t + 0.5 * hs
                        else:
                            start[s], end[s], start2[s], end2[s] = folded_ramps(best_t, value[other], hs)
                    s += 1
    return start, end, start2, end2


@njit(cache=True, nogil=True)
def _accumulate(tau_sorted, knots, weight, count, moment):
    """Bin ramp knots by the first sorted tau above them: a knot s adds weight (tau - s) to every later tau,
    recorded as `weight` in `count` and `weight * s` in `moment` at its bin (prefix sums finish the curve)."""
    for s in knots:
        j = np.searchsorted(tau_sorted, s, side="right")
        if j < tau_sorted.shape[0]:
            count[j] += weight
            moment[j] += weight * s


@dataclass
class Ramps:
    """Binned ramps of a lattice's cells: ``curve()`` is sum_c slope_c (r(tau - start_c) - r(tau - end_c)),
    r(x) = max(x, 0), at the requested tau (mm^3); `volume` the ramps' total volume, `end` the latest ramp end."""

    tau: np.ndarray
    order: np.ndarray
    count: np.ndarray
    moment: np.ndarray
    volume: float = 0.0
    end: float = 0.0

    @classmethod
    def empty(cls, tau: np.ndarray) -> Ramps:
        order = np.argsort(tau, kind="stable")
        return cls(np.ascontiguousarray(tau[order]), order, np.zeros(tau.size), np.zeros(tau.size))

    def add(self, start: np.ndarray, end: np.ndarray, slope: float) -> None:
        _accumulate(self.tau, np.ascontiguousarray(start), slope, self.count, self.moment)
        _accumulate(self.tau, np.ascontiguousarray(end), -slope, self.count, self.moment)
        self.volume += float(np.sum(end - start)) * slope
        self.end = max(self.end, float(end.max(initial=0.0)))

    def add_sub_cells(self, start: np.ndarray, end: np.ndarray, start2: np.ndarray, end2: np.ndarray,
                      slope: float) -> None:
        """Add sub-cells' ramps and, where ``start2 < end2``, their second ramps (:func:`folded_ramps`)."""
        self.add(start, end, slope)
        second = end2 > start2
        if np.any(second):
            self.add(start2[second], end2[second], slope)

    def merge(self, other: Ramps) -> None:
        self.count += other.count
        self.moment += other.moment
        self.volume += other.volume
        self.end = max(self.end, other.end)

    def curve(self) -> np.ndarray:
        out = np.empty(self.tau.size)
        out[self.order] = np.cumsum(self.count) * self.tau - np.cumsum(self.moment)
        return out


@dataclass(frozen=True)
class Lattice:
    """A cubic lattice of spacing `h` (mm) over a box: `n` cells per axis, cell (i, j, k) centred at first + h (i, j, k),
    cut into blocks of `BLOCK` cells per axis."""

    first: np.ndarray
    n: np.ndarray
    h: float

    @classmethod
    def over(cls, bounds: np.ndarray, h: float) -> Lattice:
        n = np.ceil((bounds[1] - bounds[0]) / h).astype(int) + 2
        return cls(0.5 * (bounds[0] + bounds[1]) - 0.5 * (n - 1) * h, n, float(h))

    def blocks(self) -> np.ndarray:
        """(B, 3) indices of every block's first cell."""
        axes = [np.arange(0, int(m), BLOCK) for m in self.n]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)

    def centres(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        axes = [self.first[a] + self.h * np.arange(lo[a], hi[a]) for a in range(3)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def ridge_cells(grad: np.ndarray, near: np.ndarray | None = None) -> np.ndarray:
    """The cells whose arrival-time gradient turns by more than `RIDGE_ANGLE_DEG` against a face neighbour: they
    straddle a ridge of T (the medial axis, or where fronts meet), where T is not linear.

    Parameters
    ----------
    grad : (I, J, K, 3) ndarray of float
        Unit gradient of T per cell.
    near : (I, J, K) ndarray of bool, optional
        The cells whose gradient is known; a pair is compared only when both are (None: all).

    Returns
    -------
    (I, J, K) ndarray of bool
    """
    ridge = np.zeros(grad.shape[:3], dtype=bool)
    cos_max = np.cos(np.radians(RIDGE_ANGLE_DEG))
    for a in range(3):
        below = [slice(None)] * 3
        above = [slice(None)] * 3
        below[a] = slice(0, -1)
        above[a] = slice(1, None)
        bent = np.einsum("...k,...k->...", grad[tuple(below)], grad[tuple(above)]) < cos_max
        if near is not None:
            bent &= near[tuple(below)] & near[tuple(above)]
        ridge[tuple(below)] |= bent
        ridge[tuple(above)] |= bent
    return ridge


def solid_blocks(surface: Surface, lattice: Lattice) -> np.ndarray:
    """The blocks of `lattice` (their first cells) that hold a cell inside the solid or within BAND + 1 spacings
    of its surface: a block whose centre is outside and farther than its half-diagonal plus that has none."""
    firsts = lattice.blocks()
    h = lattice.h
    size = np.minimum(BLOCK, lattice.n[None, :] - firsts)
    centre = lattice.first + h * (firsts + 0.5 * (size - 1))
    reach = 0.5 * h * np.linalg.norm(size - 1, axis=1) + (BAND + 1.0) * h
    dist, tri = surface.nearest_stored(centre, np.zeros(len(surface.faces)))
    sign = sign_and_direction(centre, tri, surface.vx, surface.face_n, surface.edge_n, surface.vert_n,
                              surface.faces)[0]
    return firsts[(sign > 0) | (dist <= reach)]


def block_ramps(surface: Surface, offset: np.ndarray, lattice: Lattice, block: np.ndarray, ramps: Ramps) -> None:
    """Add the ramps of one block's cells to `ramps`. The block is evaluated with a halo of one cell so that
    its cells' face neighbours are known (the ridge test)."""
    h = lattice.h
    lo = np.maximum(block - 1, 0)
    hi = np.minimum(block + BLOCK + 1, lattice.n)
    shape = tuple(int(v) for v in hi - lo)
    centres = lattice.centres(lo, hi)
    f, grad, tri_u = surface.lattice_distance(centres, shape, BAND * h)
    # near a surface (f <= h/2) the closest shell's fluid region sets the wetting time; deeper in, the
    # shortest path from any wetted region, whose wetting time is then below T - h/2
    floor = offset[tri_u]
    arrive = floor + f
    tri_t = tri_u.copy()
    deep = f > 0.5 * h
    meet = np.zeros(f.shape, dtype=bool)
    if np.any(offset > 0.0):
        # with sealed voids: where the closest surface faces the bath, T = f (every region's term is at
        # least its distance, and the bath's is f); elsewhere T by the shortest path from every wetted
        # region. The cells near a void's wall are split like ridges: a front from outside may erode
        # their solid side before the void is wetted
        wet = (f > -h) & (floor > 0.0)
        t_any, tri_any = surface.nearest_stored(centres[wet], offset)
        tri_t[wet] = tri_any
        far = wet & deep
        arrive[far] = t_any[deep[wet]]
        grad[far] = sign_and_direction(centres[far], tri_t[far], surface.vx, surface.face_n, surface.edge_n,
                                        surface.vert_n, surface.faces)[1]
        meet = wet & ~deep
    floor[deep] = -np.inf
    # a cell whose arrival-time gradient turns by more than RIDGE_ANGLE_DEG against a face neighbour
    # straddles a ridge of T (the medial axis, or where fronts meet): T is not linear there, so the
    # cell is split into SPLIT^3 sub-cells
    ridge = ridge_cells(grad.reshape(shape + (3,)))
    own = np.zeros(shape, dtype=bool)  # the block's cells, without the halo
    own[tuple(slice(int(block[a] - lo[a]), int(min(block[a] + BLOCK, lattice.n[a]) - lo[a])) for a in range(3))] = True
    own = own.ravel()
    ridge = own & ((ridge.ravel() & (f > -h)) | meet)
    plain = own & ~ridge & (f > -0.5 * h)
    ramps.add(np.maximum(arrive[plain] - 0.5 * h, floor[plain]), arrive[plain] + 0.5 * h, h * h)
    cells = np.argwhere(ridge.reshape(shape))
    if len(cells):
        sub_start, sub_end, fold_start, fold_end = _subcell_ramps(
            cells, lo.astype(np.int64), tri_u.reshape(shape), tri_t.reshape(shape), lattice.first, h, SPLIT, surface.vx,
            offset, surface.face_n, surface.edge_n, surface.vert_n, surface.faces)
        ramps.add_sub_cells(sub_start, sub_end, fold_start, fold_end, (h / SPLIT) ** 2)


def lattice_curve(surface: Surface, offset: np.ndarray, bounds: np.ndarray, h: float, tau: np.ndarray, *,
                  workers: int | None = None, progress: Callable[[float], None] | None = None
                  ) -> tuple[np.ndarray, float, float]:
    """Quadrature on a lattice of spacing h: (unnormalised curve at tau, its volume, the largest arrival).

    Only the blocks of `BLOCK`^3 cells that meet the solid (:func:`solid_blocks`) are evaluated, `workers`
    threads at a time (the kernels release the GIL), so that memory is bounded by a block and a thin part does
    not pay for its bounding box; the blocks' binned ramps are summed in block order (deterministic).
    `offset` is each stored triangle's wetting time (all 0 without sealed voids); `progress` is called with the
    fraction of blocks done.
    """
    lattice = Lattice.over(bounds, h)
    blocks = solid_blocks(surface, lattice)
    tau = np.asarray(tau, dtype=np.float64)

    def one(block: np.ndarray) -> Ramps:
        ramps = Ramps.empty(tau)
        block_ramps(surface, offset, lattice, block, ramps)
        return ramps

    total = Ramps.empty(tau)
    workers = workers or min(len(blocks), thread_count()) or 1
    with ThreadPoolExecutor(max_workers=workers) as pool:
        for k, ramps in enumerate(pool.map(one, blocks) if workers > 1 else map(one, blocks), 1):
            total.merge(ramps)
            if progress is not None:
                progress(k / len(blocks))
    return total.curve(), total.volume, total.end


def lattice_points(bounds: np.ndarray, h: float, volume_mm3: float, area_mm2: float) -> float:
    """About how many lattice points :func:`lattice_curve` evaluates at spacing h: the solid's cells and a shell of
    BAND + 1 spacings outside its surface (an estimate for choosing h, not a bound), at most the box's."""
    box = float(np.prod(np.ceil((bounds[1] - bounds[0]) / h) + 2))
    return min(box, volume_mm3 / h ** 3 + (BAND + 2.0) * area_mm2 / h ** 2)
