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
point-triangle distances) at the centres of a cubic lattice of spacing h over the mesh's bounds. Each
cell spreads its volume h^3 uniformly over arrival times [T_c - h/2, T_c + h/2], which has the mean
and the variance (h^2 / 12) of the arrival times over a cube cut by planar level sets of any
orientation; the part of that ramp before the cell's wetting time (0 at the bath, w_R at a void's
wall, and negative signed distances outside the surface) is not solid and releases nothing. The
curve is therefore exactly 0 at tau = 0, and second-order in h where T is smooth: the first two
moments of each cell's arrival times are right. Where T is not smooth (on the medial axis, where two
fronts meet, next to a void's wall) a cell is split into SPLIT^3 sub-cells evaluated the same way; a
flat ridge (the mid-plane of a plate) would otherwise cost a first-order error. The sum of the ramps
estimates the volume; the curve is scaled so that it ends at the mesh's exact volume (signed
tetrahedra). Lattice points more than BAND cells outside the solid are only classified, not measured.

Error estimate: the same quadrature on a lattice twice as coarse (one eighth of the cost). For a
second-order quadrature the fine curve's error is about a third of the difference between the two;
`ReferenceRelease.error_mm3` states the whole difference, max_tau |C_h - C_2h|, as the bound. The
validation shapes of docs/forward.md#reference-evaluator meet it with a margin.
"""
from __future__ import annotations

import heapq
import logging
import time
from dataclasses import dataclass

import numpy as np
import trimesh
from numba import njit
from scipy import ndimage

from design._validate import check_positive
from design.errors import DesignError

log = logging.getLogger(__name__)

DEFAULT_CELLS = 160
"""Lattice cells along the longest side of the mesh's bounding box (docs/forward.md#reference-evaluator:
0.2% of the volume or better on the validation shapes at this setting)."""
MIN_CELLS = 16
"""Fewest cells along the longest side: the coarse estimate's lattice must still resolve the solid."""
CELLS_PER_DESIGN_VOXEL = 4
"""`design_lattice`: lattice cells per voxel of a design grid whose target or print is evaluated."""
LEAF_SIZE = 4
"""Triangles per leaf of the bounding-volume hierarchy."""
RIDGE_ANGLE_DEG = 20.0
"""A lattice cell whose arrival-time gradient differs from a face neighbour's by more than this straddles
a ridge of the arrival time and is split into sub-cells."""
SPLIT = 4
"""Sub-cells per axis of a ridge cell."""
BAND = 2.0
"""Lattice spacings from the surface within which points outside are given exact distances; farther
out, they release nothing and are only classified."""


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
        The solid's volume, exact for the mesh (signed tetrahedra), mm^3.
    error_mm3 : float
        Estimated bound on max |released error|: max |C_h - C_2h| between the lattice and one twice
        as coarse, mm^3.
    method : str
        "exact-distance" (every shell faces the bath) or "exact-distance-voids" (sealed voids wetted
        when the front reaches them), followed by ", anisotropy a" for a release at anisotropy a.
    cell_mm : float
        Lattice spacing h, mm.
    total_time_mm : float
        The largest dissolution time: tau at which the solid is gone, mm.
    seconds : float
        Wall time of the evaluation, s.
    """

    tau_mm: np.ndarray
    released_mm3: np.ndarray
    volume_mm3: float
    error_mm3: float
    method: str
    cell_mm: float
    total_time_mm: float
    seconds: float

    @property
    def relative_error(self) -> float:
        """`error_mm3` as a fraction of the volume."""
        return self.error_mm3 / self.volume_mm3


# ---------------------------------------------------------------- exact point-triangle distance

@njit(cache=True, nogil=True, inline="always")
def _closest_on_triangle(px, py, pz, tri, vx):
    """Closest point of triangle `tri` to p: (qx, qy, qz, region).

    Region: 0 the face, 1..3 vertex a, b, c, 4..6 edge ab, bc, ca (Ericson, Real-Time Collision
    Detection, section 5.1.5).
    """
    a = vx[tri, 0]
    b = vx[tri, 1]
    c = vx[tri, 2]
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    apx, apy, apz = px - a[0], py - a[1], pz - a[2]
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return a[0], a[1], a[2], 1
    bpx, bpy, bpz = px - b[0], py - b[1], pz - b[2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return b[0], b[1], b[2], 2
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a[0] + v * abx, a[1] + v * aby, a[2] + v * abz, 4
    cpx, cpy, cpz = px - c[0], py - c[1], pz - c[2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return c[0], c[1], c[2], 3
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a[0] + w * acx, a[1] + w * acy, a[2] + w * acz, 6
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2]), 5
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return a[0] + abx * v + acx * w, a[1] + aby * v + acy * w, a[2] + abz * v + acz * w, 0


# ---------------------------------------------------------------- bounding-volume hierarchy

@njit(cache=True, nogil=True)
def _build_bvh(tlo, thi, cen, leaf_size):
    """Median-split hierarchy over triangle boxes; returns (lo, hi, left, start, count, span, perm).

    Node k holds triangles perm[start[k]:span[k]]; it is a leaf when count[k] > 0 (then
    count = span - start), otherwise its children are left[k] and left[k] + 1.
    """
    n = tlo.shape[0]
    cap = 2 * n + 1
    lo = np.empty((cap, 3))
    hi = np.empty((cap, 3))
    left = np.zeros(cap, dtype=np.int64)
    start = np.zeros(cap, dtype=np.int64)
    count = np.zeros(cap, dtype=np.int64)
    span = np.zeros(cap, dtype=np.int64)
    perm = np.arange(n)
    stack = np.empty((64, 3), dtype=np.int64)  # node, first, end
    stack[0, 0], stack[0, 1], stack[0, 2] = 0, 0, n
    top = 1
    nodes = 1
    while top > 0:
        top -= 1
        node, s, e = stack[top, 0], stack[top, 1], stack[top, 2]
        start[node] = s
        span[node] = e
        for d in range(3):
            lo[node, d] = np.inf
            hi[node, d] = -np.inf
        clo = np.full(3, np.inf)
        chi = np.full(3, -np.inf)
        for k in range(s, e):
            t = perm[k]
            for d in range(3):
                lo[node, d] = min(lo[node, d], tlo[t, d])
                hi[node, d] = max(hi[node, d], thi[t, d])
                clo[d] = min(clo[d], cen[t, d])
                chi[d] = max(chi[d], cen[t, d])
        if e - s <= leaf_size:
            count[node] = e - s
            continue
        axis = int(np.argmax(chi - clo))
        seg = perm[s:e].copy()
        order = np.argsort(cen[seg, axis])
        perm[s:e] = seg[order]
        mid = (s + e) // 2
        left[node] = nodes
        stack[top, 0], stack[top, 1], stack[top, 2] = nodes, s, mid
        stack[top + 1, 0], stack[top + 1, 1], stack[top + 1, 2] = nodes + 1, mid, e
        top += 2
        nodes += 2
    return lo[:nodes], hi[:nodes], left[:nodes], start[:nodes], count[:nodes], span[:nodes], perm


@njit(cache=True, nogil=True)
def _node_slabs(vx, area_n, start, span):
    """Per node: the unit mean normal of its triangles and the range of that normal's dot product with
    their vertices. The node lies in the slab between the two planes; from inside a smooth solid the
    distance to that slab bounds the distance to the node far more tightly than its box does."""
    m = start.shape[0]
    nrm = np.zeros((m, 3))
    smin = np.full(m, -np.inf)
    smax = np.full(m, np.inf)
    for node in range(m):
        sx = sy = sz = 0.0
        for t in range(start[node], span[node]):
            sx += area_n[t, 0]
            sy += area_n[t, 1]
            sz += area_n[t, 2]
        norm = np.sqrt(sx * sx + sy * sy + sz * sz)
        if norm == 0.0:
            continue
        sx, sy, sz = sx / norm, sy / norm, sz / norm
        lo_, hi_ = np.inf, -np.inf
        for t in range(start[node], span[node]):
            for v in range(3):
                d = sx * vx[t, v, 0] + sy * vx[t, v, 1] + sz * vx[t, v, 2]
                lo_ = min(lo_, d)
                hi_ = max(hi_, d)
        nrm[node, 0], nrm[node, 1], nrm[node, 2] = sx, sy, sz
        smin[node] = lo_
        smax[node] = hi_
    return nrm, smin, smax


@njit(cache=True, nogil=True, inline="always")
def _lower_bound(px, py, pz, node, lo, hi, nrm, smin, smax):
    """A lower bound on the distance from p to any triangle of the node: its box's and its slab's."""
    dx = max(lo[node, 0] - px, 0.0, px - hi[node, 0])
    dy = max(lo[node, 1] - py, 0.0, py - hi[node, 1])
    dz = max(lo[node, 2] - pz, 0.0, pz - hi[node, 2])
    along = nrm[node, 0] * px + nrm[node, 1] * py + nrm[node, 2] * pz
    return max(np.sqrt(dx * dx + dy * dy + dz * dz), along - smax[node], smin[node] - along)


@njit(cache=True, nogil=True)
def _nearest(points, vx, offset, lo, hi, nrm, smin, smax, left, start, count, node_offset, cap):
    """Per point, min over triangles of (offset[t] + |p - t|): (value, triangle), by branch and bound.

    Values of `cap` or more are not searched for: such a point gets (cap, -1). The previous point's
    best triangle seeds the bound (points come in lattice order, so neighbours share it); a node is
    skipped when its offset floor plus its distance bound cannot beat the bound.
    """
    m = points.shape[0]
    value = np.empty(m)
    best_tri = np.empty(m, dtype=np.int64)
    stack = np.empty(128, dtype=np.int64)
    seed = 0
    for i in range(m):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        qx, qy, qz, _ = _closest_on_triangle(px, py, pz, seed, vx)
        best = offset[seed] + np.sqrt((px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2)
        tri_best = seed
        if best >= cap:
            best = cap
            tri_best = -1
        stack[0] = 0
        top = 1
        while top > 0:
            top -= 1
            node = stack[top]
            if node_offset[node] + _lower_bound(px, py, pz, node, lo, hi, nrm, smin, smax) >= best:
                continue
            if count[node] > 0:
                for t in range(start[node], start[node] + count[node]):
                    qx, qy, qz, _ = _closest_on_triangle(px, py, pz, t, vx)
                    val = offset[t] + np.sqrt((px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2)
                    if val < best:
                        best = val
                        tri_best = t
                continue
            a = left[node]
            b = a + 1
            da = node_offset[a] + _lower_bound(px, py, pz, a, lo, hi, nrm, smin, smax)
            db = node_offset[b] + _lower_bound(px, py, pz, b, lo, hi, nrm, smin, smax)
            if da <= db:  # the nearer child is popped first
                a, b = b, a
                da, db = db, da
            if da < best:
                stack[top] = a
                top += 1
            if db < best:
                stack[top] = b
                top += 1
        value[i] = best
        best_tri[i] = tri_best
        if tri_best >= 0:
            seed = tri_best
    return value, best_tri


@njit(cache=True, nogil=True)
def _node_floor(offset, start, count, left):
    """Smallest triangle offset under each node (children have larger indices than their parent)."""
    floor = np.empty(start.shape[0])
    for node in range(start.shape[0] - 1, -1, -1):
        if count[node] > 0:
            f = np.inf
            for t in range(start[node], start[node] + count[node]):
                f = min(f, offset[t])
            floor[node] = f
        else:
            floor[node] = min(floor[left[node]], floor[left[node] + 1])
    return floor


@njit(cache=True, nogil=True, inline="always")
def _inside(px, py, pz, t, vx, face_n, edge_n, vert_n, faces):
    """+1.0 when p is inside, -1.0 outside, from the angle-weighted pseudonormal of the closest feature
    of its closest triangle t (Baerentzen and Aanaes, IEEE TVCG 11(3), 2005): exact for a closed,
    consistently oriented mesh. Returns (sign, qx, qy, qz), q the closest point."""
    qx, qy, qz, region = _closest_on_triangle(px, py, pz, t, vx)
    if region == 0:
        nx, ny, nz = face_n[t, 0], face_n[t, 1], face_n[t, 2]
    elif region <= 3:
        v = faces[t, region - 1]
        nx, ny, nz = vert_n[v, 0], vert_n[v, 1], vert_n[v, 2]
    else:
        e = region - 4
        nx, ny, nz = edge_n[t, e, 0], edge_n[t, e, 1], edge_n[t, e, 2]
    dot = (px - qx) * nx + (py - qy) * ny + (pz - qz) * nz
    return (1.0 if dot < 0.0 else -1.0), qx, qy, qz


@njit(cache=True, nogil=True)
def _sign_and_direction(points, tri, vx, face_n, edge_n, vert_n, faces):
    """Per point: +1 inside / -1 outside, and the unit gradient of the signed distance (pointing into
    the solid) from its closest triangle."""
    m = points.shape[0]
    sign = np.empty(m)
    grad = np.empty((m, 3))
    for i in range(m):
        t = tri[i]
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        sg, qx, qy, qz = _inside(px, py, pz, t, vx, face_n, edge_n, vert_n, faces)
        sign[i] = sg
        gx, gy, gz = px - qx, py - qy, pz - qz
        norm = np.sqrt(gx * gx + gy * gy + gz * gz)
        if norm > 0.0:
            grad[i, 0], grad[i, 1], grad[i, 2] = sg * gx / norm, sg * gy / norm, sg * gz / norm
        else:  # on the surface: the inward face normal
            grad[i, 0], grad[i, 1], grad[i, 2] = -face_n[t, 0], -face_n[t, 1], -face_n[t, 2]
    return sign, grad


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
                        qx, qy, qz, _ = _closest_on_triangle(px, py, pz, t, vx)
                        d = np.sqrt((px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2)
                        if d < best_d:
                            best_d = d
                            near = t
                        best_t = min(best_t, offset[t] + d)
                    sg, _, _, _ = _inside(px, py, pz, near, vx, face_n, edge_n, vert_n, faces)
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


class _Surface:
    """Triangles of a closed mesh with their hierarchy and pseudonormals; triangles are stored in leaf
    order (a leaf's triangles contiguous in memory), `perm[k]` the mesh's face number of stored k."""

    def __init__(self, mesh: trimesh.Trimesh) -> None:
        vx = np.asarray(mesh.vertices[mesh.faces], dtype=np.float64)  # (F, 3, 3)
        self.lo, self.hi, self.left, self.start, self.count, span, perm = _build_bvh(
            vx.min(axis=1), vx.max(axis=1), vx.mean(axis=1), LEAF_SIZE)
        self.perm = perm
        self.faces = np.ascontiguousarray(mesh.faces[perm], dtype=np.int64)
        self.vx = np.ascontiguousarray(vx[perm])
        face_n = np.asarray(mesh.face_normals, dtype=np.float64)
        self.face_n = np.ascontiguousarray(face_n[perm])
        area_n = self.face_n * np.asarray(mesh.area_faces, dtype=np.float64)[perm, None]
        self.nrm, self.smin, self.smax = _node_slabs(self.vx, area_n, self.start, span)
        # edge k of a face runs from its vertex k to vertex k + 1 (ab, bc, ca), as faces_unique_edges
        edge_sum = np.zeros((len(mesh.edges_unique), 3))
        np.add.at(edge_sum, mesh.faces_unique_edges.ravel(), np.repeat(face_n, 3, axis=0))
        self.edge_n = np.ascontiguousarray(edge_sum[mesh.faces_unique_edges[perm]])  # (F, 3, 3)
        vert_sum = np.zeros((len(mesh.vertices), 3))
        np.add.at(vert_sum, mesh.faces.ravel(), (face_n[:, None, :] * mesh.face_angles[:, :, None]).reshape(-1, 3))
        self.vert_n = vert_sum

    def stored(self, per_face: np.ndarray) -> np.ndarray:
        """A per-face array in the stored triangle order."""
        return np.ascontiguousarray(np.asarray(per_face, dtype=np.float64)[self.perm])

    def nearest_stored(self, points: np.ndarray, offset: np.ndarray,
                       cap: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
        """Per point, min over stored triangles t of (offset[t] + |p - t|), and that t; (cap, -1) where
        that is `cap` or more."""
        return _nearest(np.ascontiguousarray(points, dtype=np.float64), self.vx, offset, self.lo, self.hi,
                        self.nrm, self.smin, self.smax, self.left, self.start, self.count,
                        _node_floor(offset, self.start, self.count, self.left), float(cap))

    def nearest(self, points: np.ndarray, offset: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Per point, min over faces of (offset[face] + distance to the face), and that face."""
        stored = self.stored(np.zeros(len(self.faces)) if offset is None else offset)
        value, tri = self.nearest_stored(points, stored)
        return value, self.perm[tri]

    def signed_distance(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Signed distance (positive inside), its unit gradient and the closest stored triangle per point."""
        points = np.ascontiguousarray(points, dtype=np.float64)
        dist, tri = self.nearest_stored(points, np.zeros(len(self.faces)))
        sign, grad = _sign_and_direction(points, tri, self.vx, self.face_n, self.edge_n, self.vert_n, self.faces)
        return dist * sign, grad, tri

    def lattice_distance(self, centres: np.ndarray, shape: tuple[int, int, int],
                         band: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`signed_distance` at lattice points, in lattice order, searching only within `band` of the
        surface outside it: points farther out get -inf, a zero gradient and triangle -1.

        A point farther than `band` from the surface (whose neighbours differ from it by less than
        `band` in distance) has the sign of its face-connected region of such points, which the
        region's neighbours in the band tell; only the regions inside are then searched in full.
        """
        zero = np.zeros(len(self.faces))
        dist, tri = self.nearest_stored(centres, zero, band)
        near = tri >= 0
        sign = np.zeros(len(centres))
        grad = np.zeros((len(centres), 3))
        sign[near], grad[near] = _sign_and_direction(centres[near], tri[near], self.vx, self.face_n, self.edge_n,
                                                     self.vert_n, self.faces)
        labels, count = ndimage.label(~near.reshape(shape))
        region_sign = np.zeros(count + 1)
        sign3 = sign.reshape(shape)
        for a in range(3):
            for far, other in ((np.s_[:-1], np.s_[1:]), (np.s_[1:], np.s_[:-1])):
                lab = np.moveaxis(labels, a, 0)[far]
                sg = np.moveaxis(sign3, a, 0)[other]
                touch = (lab > 0) & (sg != 0.0)
                region_sign[lab[touch]] = sg[touch]
        far_in = ~near & (region_sign[labels.ravel()] > 0.0)
        dist[far_in], tri[far_in] = self.nearest_stored(centres[far_in], zero)
        sign[far_in], grad[far_in] = _sign_and_direction(centres[far_in], tri[far_in], self.vx, self.face_n,
                                                         self.edge_n, self.vert_n, self.faces)
        f = dist * sign
        f[~near & ~far_in] = -np.inf
        return f, grad, tri


# ---------------------------------------------------------------- shells, voids and wetting times

def _winding(points: np.ndarray, vx: np.ndarray) -> np.ndarray:
    """Winding number of closed triangles `vx` (F, 3, 3) at each point (van Oosterom and Strackee)."""
    out = np.empty(len(points))
    for i, p in enumerate(points):
        a, b, c = (vx[:, k, :] - p for k in range(3))
        la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
        det = np.einsum("ij,ij->i", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", b, c) * la
               + np.einsum("ij,ij->i", c, a) * lb)
        out[i] = np.arctan2(det, den).sum() / (2.0 * np.pi)
    return out


def _wetting(mesh: trimesh.Trimesh) -> tuple[np.ndarray, int]:
    """Per face, the time its fluid region is wetted (0 at the bath); the number of sealed voids."""
    labels = trimesh.graph.connected_component_labels(mesh.face_adjacency, node_count=len(mesh.faces))
    n_shells = int(labels.max()) + 1
    if n_shells == 1:
        return np.zeros(len(mesh.faces)), 0
    vx = mesh.vertices[mesh.faces]
    shells = [np.flatnonzero(labels == s) for s in range(n_shells)]
    # containment: the number of other shells around a vertex of each shell (its nesting depth)
    probe = np.array([mesh.vertices[mesh.faces[f[0], 0]] for f in shells])
    inside = np.zeros((n_shells, n_shells), dtype=bool)  # inside[s, r]: shell s lies within shell r
    for r in range(n_shells):
        wind = np.abs(_winding(probe, vx[shells[r]]))
        inside[:, r] = wind > 0.5
        inside[r, r] = False
    depth = inside.sum(axis=1)
    # fluid region of each shell: 0 the bath; an odd-depth shell bounds its own void; an even-depth
    # shell inside one faces the void of its innermost enclosing (odd-depth) shell
    region = np.zeros(n_shells, dtype=np.int64)
    voids = [s for s in range(n_shells) if depth[s] % 2 == 1]
    if not voids:  # separate bodies, every one facing the bath
        return np.zeros(len(mesh.faces)), 0
    for k, s in enumerate(voids):
        region[s] = k + 1
    for s in range(n_shells):
        if depth[s] > 0 and depth[s] % 2 == 0:
            parent = next(r for r in voids if inside[s, r] and depth[r] == depth[s] - 1)
            region[s] = region[parent]
    n_regions = len(voids) + 1
    # region-to-region distance: the closest approach of their shells, from vertices, edge midpoints
    # and face centroids of each shell to the exact surface of the other
    surfaces = {s: _Surface(mesh.submesh([shells[s]], append=True)) for s in range(n_shells)}
    samples = {s: np.concatenate([vx[shells[s]].reshape(-1, 3), vx[shells[s]].mean(axis=1),
                                  0.5 * (vx[shells[s]] + np.roll(vx[shells[s]], 1, axis=1)).reshape(-1, 3)])
               for s in range(n_shells)}
    gap = np.full((n_regions, n_regions), np.inf)
    for s in range(n_shells):
        for r in range(n_shells):
            if region[s] != region[r]:
                d = float(surfaces[r].nearest(samples[s])[0].min())
                a, b = region[s], region[r]
                gap[a, b] = gap[b, a] = min(gap[a, b], d)
    wet = np.full(n_regions, np.inf)
    wet[0] = 0.0
    heap = [(0.0, 0)]
    while heap:
        t, a = heapq.heappop(heap)
        if t > wet[a]:
            continue
        for b in range(n_regions):
            if t + gap[a, b] < wet[b]:
                wet[b] = t + gap[a, b]
                heapq.heappush(heap, (wet[b], b))
    return wet[region[labels]], len(voids)


# ---------------------------------------------------------------- quadrature

def _release_at(tau: np.ndarray, start: np.ndarray, end: np.ndarray, slope: float) -> np.ndarray:
    """sum_c slope (r(tau - start_c) - r(tau - end_c)), r(x) = max(x, 0), at each tau (prefix sums)."""
    out = np.zeros(tau.shape)
    for knots, sign in ((np.sort(start), 1.0), (np.sort(end), -1.0)):
        prefix = np.concatenate([[0.0], np.cumsum(knots)])
        k = np.searchsorted(knots, tau, side="left")  # knots below tau
        out += sign * slope * (k * tau - prefix[k])
    return out


def _lattice_curve(surface: _Surface, offset: np.ndarray, bounds: np.ndarray, h: float,
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
        grad[far] = _sign_and_direction(centres[far], tri_t[far], surface.vx, surface.face_n, surface.edge_n,
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


def reference_release(mesh: trimesh.Trimesh, tau_mm: np.ndarray, *, cells: int = DEFAULT_CELLS,
                      anisotropy: float = 1.0) -> ReferenceRelease:
    """Release of a closed solid by exact surface distances, with its error estimate.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        A closed (watertight), consistently wound triangle mesh in mm; an inward-wound mesh is
        taken as its outward-wound copy. Overlapping bodies are not merged: pass their union.
    tau_mm : (K,) array_like of float, mm
        Erosion depths to sample.
    cells : int
        Lattice cells along the longest side of the bounding box (cost grows as its cube).
    anisotropy : float
        The print's build-direction (z) erosion rate over its in-plane rate, a > 0. A front moving at a along z
        is isotropic in the metric with z scaled by 1 / a: the release is that of the scaled mesh, its volumes
        times a (``method`` then names a).

    Returns
    -------
    ReferenceRelease

    Raises
    ------
    DesignError
        If the mesh is not closed or consistently wound, `tau_mm` is not a finite 1D array, or
        `cells` < `MIN_CELLS`.

    Examples
    --------
    >>> import trimesh
    >>> ref = reference_release(trimesh.creation.box((2.0, 2.0, 2.0)), [0.0, 0.5, 1.0], cells=32)
    >>> [round(float(v), 3) for v in ref.released_mm3]
    [0.0, 7.0, 8.0]
    """
    began = time.perf_counter()
    tau = np.asarray(tau_mm, dtype=np.float64)
    if tau.ndim != 1 or not np.all(np.isfinite(tau)):
        raise DesignError(f"tau_mm must be a 1D array of finite depths, got shape {tau.shape}")
    if int(cells) != cells or cells < MIN_CELLS:
        raise DesignError(f"cells must be an integer >= {MIN_CELLS}, got {cells!r}")
    a = check_positive("anisotropy", anisotropy)
    mesh = metric_mesh(_check_mesh(mesh), a)
    volume = float(mesh.volume) * a  # mm^3 of the print: the scaled mesh's volume times a
    surface = _Surface(mesh)
    wet, n_voids = _wetting(mesh)
    offset = surface.stored(wet)
    bounds = np.asarray(mesh.bounds, dtype=np.float64)
    h = float((bounds[1] - bounds[0]).max()) / int(cells)
    curves = []
    for spacing in (h, 2.0 * h):
        curve, est, t_max = _lattice_curve(surface, offset, bounds, spacing, tau)
        curves.append(curve * (volume / est))
        if spacing == h:
            total = t_max
    released = curves[0]
    error = float(np.abs(curves[0] - curves[1]).max()) if tau.size else 0.0
    seconds = time.perf_counter() - began
    method = ("exact-distance-voids" if n_voids else "exact-distance") + (f", anisotropy {a:g}" if a != 1.0 else "")
    log.debug("reference release: %d faces, %d voids, h = %.4g mm, error %.3g mm^3 (%.3g%%), %.2f s",
              len(mesh.faces), n_voids, h, error, 100 * error / volume, seconds)
    return ReferenceRelease(tau_mm=tau, released_mm3=released, volume_mm3=volume, error_mm3=error, method=method,
                            cell_mm=check_positive("cell_mm", h), total_time_mm=total, seconds=seconds)


def signed_distance(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """Exact signed distance (mm, positive inside) from each point (N, 3) to a closed mesh's surface."""
    return _Surface(_check_mesh(mesh)).signed_distance(np.asarray(points, dtype=np.float64).reshape(-1, 3))[0]
