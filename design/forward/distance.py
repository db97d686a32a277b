"""Exact distances to a closed triangle mesh: point-triangle distances over a bounding-volume hierarchy.

:class:`Surface` holds a closed, consistently wound mesh's triangles in the hierarchy's leaf order with their
angle-weighted pseudonormals, and answers per point: the least of (a triangle's offset + the distance to it)
(`Surface.nearest`), the signed distance and its gradient (`Surface.signed_distance`), and both on a lattice
with the points far outside only classified (`Surface.lattice_distance`). The kernels are numba-compiled; the
reference evaluator (:mod:`design.forward.reference`) and its quadrature (:mod:`design.forward.quadrature`)
call them.
"""
from __future__ import annotations

import numpy as np
import trimesh
from numba import njit
from scipy import ndimage

LEAF_SIZE = 4
"""Triangles per leaf of the bounding-volume hierarchy."""


# ---------------------------------------------------------------- exact point-triangle distance

@njit(cache=True, nogil=True, inline="always")
def closest_on_triangle(px, py, pz, tri, vx):
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
        qx, qy, qz, _ = closest_on_triangle(px, py, pz, seed, vx)
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
                    qx, qy, qz, _ = closest_on_triangle(px, py, pz, t, vx)
                    val = offset[t] + np.sqrt((px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2)
                    if val < best:
                        best = val
                        tri_best = t
                continue
            a = left[node]
            da = node_offset[a] + _lower_bound(px, py, pz, a, lo, hi, nrm, smin, smax)
            db = node_offset[a + 1] + _lower_bound(px, py, pz, a + 1, lo, hi, nrm, smin, smax)
            top = _push_children(stack, top, a, da, db, best)
        value[i] = best
        best_tri[i] = tri_best
        if tri_best >= 0:
            seed = tri_best
    return value, best_tri


@njit(cache=True, nogil=True, inline="always")
def _push_children(stack, top, a, da, db, best):
    """Push the children ``a`` and ``a + 1`` of a search-tree node whose bounds ``da``, ``db`` are below ``best``, the
    nearer last so that it is popped first; returns the stack's new top."""
    b = a + 1
    if da <= db:
        a, b = b, a
        da, db = db, da
    if da < best:
        stack[top] = a
        top += 1
    if db < best:
        stack[top] = b
        top += 1
    return top


@njit(cache=True, nogil=True)
def _node_floor(offset, start, count, left):
    """Smallest per-triangle value ``offset`` (an offset, a least vertex time) under each node (children have larger
    indices than their parent)."""
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
def inside_sign(px, py, pz, t, vx, face_n, edge_n, vert_n, faces):
    """+1.0 when p is inside, -1.0 outside, from the angle-weighted pseudonormal of the closest feature
    of its closest triangle t (Baerentzen and Aanaes, IEEE TVCG 11(3), 2005): exact for a closed,
    consistently oriented mesh. Returns (sign, qx, qy, qz), q the closest point."""
    qx, qy, qz, region = closest_on_triangle(px, py, pz, t, vx)
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
def sign_and_direction(points, tri, vx, face_n, edge_n, vert_n, faces):
    """Per point: +1 inside / -1 outside, and the unit gradient of the signed distance (pointing into
    the solid) from its closest triangle."""
    m = points.shape[0]
    sign = np.empty(m)
    grad = np.empty((m, 3))
    for i in range(m):
        t = tri[i]
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        sg, qx, qy, qz = inside_sign(px, py, pz, t, vx, face_n, edge_n, vert_n, faces)
        sign[i] = sg
        gx, gy, gz = px - qx, py - qy, pz - qz
        norm = np.sqrt(gx * gx + gy * gy + gz * gz)
        if norm > 0.0:
            grad[i, 0], grad[i, 1], grad[i, 2] = sg * gx / norm, sg * gy / norm, sg * gz / norm
        else:  # on the surface: the inward face normal
            grad[i, 0], grad[i, 1], grad[i, 2] = -face_n[t, 0], -face_n[t, 1], -face_n[t, 2]
    return sign, grad



class Surface:
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
        sign, grad = sign_and_direction(points, tri, self.vx, self.face_n, self.edge_n, self.vert_n, self.faces)
        return dist * sign, grad, tri

    def lattice_distance(self, centres: np.ndarray, shape: tuple[int, int, int],
                         band: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`signed_distance` at lattice points, in lattice order, searching only within `band` of the
        surface outside it: points farther out get -inf, a zero gradient and triangle -1.

        A point farther than `band` from the surface (whose neighbours differ from it by less than
        `band` in distance) has the sign of its face-connected region of such points, which the
        region's neighbours in the band tell (or, for a region with none, one of its points); only the regions
        inside are then searched in full.
        """
        zero = np.zeros(len(self.faces))
        dist, tri = self.nearest_stored(centres, zero, band)
        near = tri >= 0
        sign = np.zeros(len(centres))
        grad = np.zeros((len(centres), 3))
        sign[near], grad[near] = sign_and_direction(centres[near], tri[near], self.vx, self.face_n, self.edge_n,
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
        # a region no point of the band touches (a lattice wholly inside or far outside): one point's sign
        alone = np.flatnonzero(region_sign[1:] == 0.0) + 1
        if alone.size:
            flat = labels.ravel()
            order = np.argsort(flat, kind="stable")
            probe = order[np.searchsorted(flat[order], alone)]
            _, probe_tri = self.nearest_stored(centres[probe], zero)
            region_sign[alone] = sign_and_direction(centres[probe], probe_tri, self.vx, self.face_n, self.edge_n,
                                                    self.vert_n, self.faces)[0]
        far_in = ~near & (region_sign[labels.ravel()] > 0.0)
        dist[far_in], tri[far_in] = self.nearest_stored(centres[far_in], zero)
        sign[far_in], grad[far_in] = sign_and_direction(centres[far_in], tri[far_in], self.vx, self.face_n,
                                                         self.edge_n, self.vert_n, self.faces)
        f = dist * sign
        f[~near & ~far_in] = -np.inf
        return f, grad, tri
