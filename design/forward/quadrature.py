"""The reference evaluator's quadrature: a lattice's cells' arrival-time ramps summed into a release curve.

Each cell of a cubic lattice of spacing h spreads its volume over arrival times [T_c - h/2, T_c + h/2] from its
exact signed distance (:class:`design.forward.distance.Surface`) and its fluid region's wetting time
(:mod:`design.forward.wetting`); a cell across a ridge of the arrival time or next to a void's wall is split
into `SPLIT`^3 sub-cells (see :mod:`design.forward.reference` for the error analysis).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from design.forward.distance import Surface, closest_on_triangle, inside_sign, sign_and_direction

RIDGE_ANGLE_DEG = 20.0
"""A lattice cell whose arrival-time gradient differs from a face neighbour's by more than this straddles
a ridge of the arrival time and is split into sub-cells."""
SPLIT = 4
"""Sub-cells per axis of a ridge cell."""
BAND = 2.0
"""Lattice spacings from the surface within which points outside are given exact distances; farther
out, they release nothing and are only classified."""


@njit(cache=True, nogil=True)
def _subcell_ramps(cells, tri_u, tri_t, first, h, split, vx, offset, face_n, edge_n, vert_n, faces):
    """Ramps of the split^3 sub-cells of each listed lattice cell, by exact distances to the triangles
    closest to the cell and its 26 neighbours (the candidates for its sub-cells' closest triangles).

    A sub-cell of spacing hs at signed distance f <= hs/2 from the surface arrives at offset[t] + f,
    t its closest triangle, and releases nothing before offset[t] (its fluid region's wetting time),
    unless another region's front reaches it first, at T = min_t (offset[t] + |p - t|): its solid
    fraction f / hs + 1/2 then releases around T. Deeper, it arrives at T. Returns (start, end) per
    sub-cell (equal when the sub-cell lies outside the solid).
    """
    nx, ny, nz = tri_u.shape
    hs = h / split
    per = split ** 3
    start = np.zeros(cells.shape[0] * per)
    end = np.zeros(cells.shape[0] * per)
    cand = np.empty(54, dtype=np.int64)
    for c in range(cells.shape[0]):
        ci, cj, ck = cells[c, 0], cells[c, 1], cells[c, 2]
        n_cand = 0
        for i in range(max(ci - 1, 0), min(ci + 2, nx)):
            for j in range(max(cj - 1, 0), min(cj + 2, ny)):
                for k in range(max(ck - 1, 0), min(ck + 2, nz)):
                    for t in (tri_u[i, j, k], tri_t[i, j, k]):
                        seen = t < 0  # a cell far outside has none
                        for m in range(n_cand):
                            if cand[m] == t:
                                seen = True
                                break
                        if not seen:
                            cand[n_cand] = t
                            n_cand += 1
        s = c * per
        for a in range(split):
            px = first[0] + ci * h + (a + 0.5) * hs - 0.5 * h
            for b in range(split):
                py = first[1] + cj * h + (b + 0.5) * hs - 0.5 * h
                for e in range(split):
                    pz = first[2] + ck * h + (e + 0.5) * hs - 0.5 * h
                    best_d = np.inf
                    best_t = np.inf
                    near = cand[0]
                    for m in range(n_cand):
                        t = cand[m]
                        qx, qy, qz, _ = closest_on_triangle(px, py, pz, t, vx)
                        d = np.sqrt((px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2)
                        if d < best_d:
                            best_d = d
                            near = t
                        best_t = min(best_t, offset[t] + d)
                    sg, _, _, _ = inside_sign(px, py, pz, near, vx, face_n, edge_n, vert_n, faces)
                    f = sg * best_d
                    if f <= -0.5 * hs:
                        start[s] = 0.0
                        end[s] = 0.0
                    elif f <= 0.5 * hs and best_t < offset[near] + abs(f) - 1e-9 * hs:
                        half = 0.5 * (f / hs + 0.5) * hs
                        start[s] = best_t - half
                        end[s] = best_t + half
                    elif f <= 0.5 * hs:
                        start[s] = max(offset[near] + f - 0.5 * hs, offset[near])
                        end[s] = offset[near] + f + 0.5 * hs
                    else:
                        start[s] = best_t - 0.5 * hs
                        end[s] = best_t + 0.5 * hs
                    s += 1
    return start, end


def _release_at(tau: np.ndarray, start: np.ndarray, end: np.ndarray, slope: float) -> np.ndarray:
    """sum_c slope (r(tau - start_c) - r(tau - end_c)), r(x) = max(x, 0), at each tau (prefix sums)."""
    out = np.zeros(tau.shape)
    for knots, sign in ((np.sort(start), 1.0), (np.sort(end), -1.0)):
        prefix = np.concatenate([[0.0], np.cumsum(knots)])
        k = np.searchsorted(knots, tau, side="left")  # knots below tau
        out += sign * slope * (k * tau - prefix[k])
    return out


def lattice_curve(surface: Surface, offset: np.ndarray, bounds: np.ndarray, h: float,
                   tau: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Quadrature on a lattice of spacing h: (unnormalised curve at tau, its volume, the largest arrival).

    `offset` is each stored triangle's wetting time (all 0 without sealed voids).
    """
    n = np.ceil((bounds[1] - bounds[0]) / h).astype(int) + 2
    first = 0.5 * (bounds[0] + bounds[1]) - 0.5 * (n - 1) * h
    axes = [first[a] + h * np.arange(n[a]) for a in range(3)]
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    f, grad, tri_u = surface.lattice_distance(centres, tuple(n), BAND * h)
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
    grad = grad.reshape(tuple(n) + (3,))
    ridge = np.zeros(tuple(n), dtype=bool)
    cos_max = np.cos(np.radians(RIDGE_ANGLE_DEG))
    for a in range(3):
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[a] = slice(0, -1)
        hi[a] = slice(1, None)
        bent = np.einsum("...k,...k->...", grad[tuple(lo)], grad[tuple(hi)]) < cos_max
        ridge[tuple(lo)] |= bent
        ridge[tuple(hi)] |= bent
    ridge = (ridge.ravel() & (f > -h)) | meet
    plain = ~ridge & (f > -0.5 * h)
    start = np.maximum(arrive[plain] - 0.5 * h, floor[plain])
    end = arrive[plain] + 0.5 * h
    cells = np.argwhere(ridge.reshape(tuple(n)))
    sub_start, sub_end = _subcell_ramps(cells, tri_u.reshape(tuple(n)), tri_t.reshape(tuple(n)), first, h, SPLIT,
                                        surface.vx, offset, surface.face_n, surface.edge_n, surface.vert_n,
                                        surface.faces)
    hs = h / SPLIT
    curve = _release_at(tau, start, end, h * h) + _release_at(tau, sub_start, sub_end, hs * hs)
    volume = float(np.sum(end - start)) * h * h + float(np.sum(sub_end - sub_start)) * hs * hs
    return curve, volume, float(max(end.max(initial=0.0), sub_end.max(initial=0.0)))
