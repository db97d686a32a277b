"""Arrival times from a surface wetted at times that vary linearly over each triangle: exact Huygens minima.

A surface whose point p is wetted at w(p), w linear over each triangle (given at the vertices), sends a front
through the solid that arrives at x at

    T(x) = min over the surface's points p of ( w(p) + |x - p| )                       (paper eq. 5, Huygens)

On one triangle, with g the gradient of w in its plane, z the distance from x to the plane and x0 the foot of x:
when |g| < 1 the minimiser is p* = x0 - |z| g / sqrt(1 - |g|^2) and T = w(x0) + |z| sqrt(1 - |g|^2) (a plane front
tilted by asin |g|); when p* falls outside the triangle (or |g| >= 1) the minimum is on an edge, where the same
one-dimensional problem has a closed form. Over the whole surface the minimum is searched by branch and bound
over the bounding-volume hierarchy of :class:`design.forward.distance.Surface` (a node's bound: its least vertex
time plus its distance bound).

A constant time per triangle (its centroid's) is first order in the triangle's size wherever w varies along the
surface, and always early (the least time of a triangle is taken at its nearest point); linear times are second
order, so the triangles can be as large as the lattice's cells.
"""
from __future__ import annotations

import numpy as np
import trimesh
from numba import njit

from design.forward.distance import Surface, _lower_bound, _node_floor, _push_children


@njit(cache=True, nogil=True, inline="always")
def _on_edge(px, py, pz, ax, ay, az, bx, by, bz, wa, wb):
    """min over p on segment ab of (w(p) + |x - p|), w linear from wa to wb: (value, qx, qy, qz)."""
    ex, ey, ez = bx - ax, by - ay, bz - az
    length = np.sqrt(ex * ex + ey * ey + ez * ez)
    rx, ry, rz = px - ax, py - ay, pz - az
    if length == 0.0:
        return wa + np.sqrt(rx * rx + ry * ry + rz * rz), ax, ay, az
    ex, ey, ez = ex / length, ey / length, ez / length
    slope = (wb - wa) / length
    t0 = rx * ex + ry * ey + rz * ez
    perp2 = max(rx * rx + ry * ry + rz * rz - t0 * t0, 0.0)
    if slope >= 1.0:
        t = 0.0
    elif slope <= -1.0:
        t = length
    else:
        t = min(max(t0 - slope * np.sqrt(perp2) / np.sqrt(1.0 - slope * slope), 0.0), length)
    value = wa + slope * t + np.sqrt(perp2 + (t - t0) * (t - t0))
    return value, ax + t * ex, ay + t * ey, az + t * ez


@njit(cache=True, nogil=True, inline="always")
def _on_triangle(px, py, pz, t, vx, wv, face_n, grad, dual):
    """min over p in triangle t of (w(p) + |x - p|): (value, qx, qy, qz)."""
    ax, ay, az = vx[t, 0, 0], vx[t, 0, 1], vx[t, 0, 2]
    gx, gy, gz = grad[t, 0], grad[t, 1], grad[t, 2]
    g2 = gx * gx + gy * gy + gz * gz
    if g2 < 1.0:
        nx, ny, nz = face_n[t, 0], face_n[t, 1], face_n[t, 2]
        rx, ry, rz = px - ax, py - ay, pz - az
        z = rx * nx + ry * ny + rz * nz
        fx, fy, fz = rx - z * nx, ry - z * ny, rz - z * nz      # x0 - a
        root = np.sqrt(1.0 - g2)
        k = abs(z) / root
        qx, qy, qz = fx - k * gx, fy - k * gy, fz - k * gz      # p* - a
        s = qx * dual[t, 0, 0] + qy * dual[t, 0, 1] + qz * dual[t, 0, 2]
        r = qx * dual[t, 1, 0] + qy * dual[t, 1, 1] + qz * dual[t, 1, 2]
        if s >= 0.0 and r >= 0.0 and s + r <= 1.0:
            return wv[t, 0] + gx * fx + gy * fy + gz * fz + abs(z) * root, ax + qx, ay + qy, az + qz
    best, bx, by, bz = _on_edge(px, py, pz, vx[t, 0, 0], vx[t, 0, 1], vx[t, 0, 2], vx[t, 1, 0], vx[t, 1, 1],
                                vx[t, 1, 2], wv[t, 0], wv[t, 1])
    for k0, k1 in ((1, 2), (2, 0)):
        v, qx, qy, qz = _on_edge(px, py, pz, vx[t, k0, 0], vx[t, k0, 1], vx[t, k0, 2], vx[t, k1, 0], vx[t, k1, 1],
                                 vx[t, k1, 2], wv[t, k0], wv[t, k1])
        if v < best:
            best, bx, by, bz = v, qx, qy, qz
    return best, bx, by, bz


@njit(cache=True, nogil=True, inline="always")
def _bound(px, py, pz, node, lo, hi, nrm, smin, smax, floor, plane):
    """A lower bound on T from the node's triangles, d its distance bound: its least time + d, and its plane
    l(p) = a + b . p under w (|b| <= 1): l(x) + (1 - |b|) d, tight where w is itself a distance along the surface."""
    d = _lower_bound(px, py, pz, node, lo, hi, nrm, smin, smax)
    lin = plane[node, 0] + plane[node, 1] * px + plane[node, 2] * py + plane[node, 3] * pz + plane[node, 4] * d
    return max(floor[node] + d, lin)


@njit(cache=True, nogil=True)
def _node_planes(vx, wv, grad, area, start, count, left):
    """Per node: (a, b, 1 - |b|) of a plane l(p) = a + b . p at most w on its triangles, b their area-weighted mean
    gradient shortened to length at most 1 (children have larger indices than their parent)."""
    m = start.shape[0]
    span = np.empty(m, dtype=np.int64)
    for node in range(m - 1, -1, -1):
        span[node] = start[node] + count[node] if count[node] > 0 else span[left[node] + 1]
    plane = np.empty((m, 5))
    for node in range(m):
        bx = by = bz = total = 0.0
        for t in range(start[node], span[node]):
            if np.isfinite(grad[t, 0]):
                bx += area[t] * grad[t, 0]
                by += area[t] * grad[t, 1]
                bz += area[t] * grad[t, 2]
                total += area[t]
        if total > 0.0:
            bx, by, bz = bx / total, by / total, bz / total
        norm = np.sqrt(bx * bx + by * by + bz * bz)
        if norm > 1.0:
            bx, by, bz, norm = bx / norm, by / norm, bz / norm, 1.0
        a = np.inf
        for t in range(start[node], span[node]):
            for k in range(3):
                a = min(a, wv[t, k] - bx * vx[t, k, 0] - by * vx[t, k, 1] - bz * vx[t, k, 2])
        plane[node, 0], plane[node, 1], plane[node, 2], plane[node, 3], plane[node, 4] = a, bx, by, bz, 1.0 - norm
    return plane


@njit(cache=True, nogil=True)
def _nearest_linear(points, vx, wv, face_n, grad, dual, lo, hi, nrm, smin, smax, left, start, count, floor, plane, cap):
    """Per point, min over triangles of min_p (w(p) + |x - p|): (value, triangle, foot p), by branch and bound;
    values of the point's ``cap`` or more are not searched for (cap, -1, the point)."""
    m = points.shape[0]
    value = np.empty(m)
    best_tri = np.empty(m, dtype=np.int64)
    foot = np.empty((m, 3))
    stack = np.empty(128, dtype=np.int64)
    seed = 0
    for i in range(m):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        best, fx, fy, fz = _on_triangle(px, py, pz, seed, vx, wv, face_n, grad, dual)
        tri_best = seed
        if best >= cap[i]:
            best, tri_best, fx, fy, fz = cap[i], -1, px, py, pz
        stack[0] = 0
        top = 1
        while top > 0:
            top -= 1
            node = stack[top]
            if _bound(px, py, pz, node, lo, hi, nrm, smin, smax, floor, plane) >= best:
                continue
            if count[node] > 0:
                for t in range(start[node], start[node] + count[node]):
                    val, qx, qy, qz = _on_triangle(px, py, pz, t, vx, wv, face_n, grad, dual)
                    if val < best:
                        best, tri_best, fx, fy, fz = val, t, qx, qy, qz
                continue
            a = left[node]
            da = _bound(px, py, pz, a, lo, hi, nrm, smin, smax, floor, plane)
            db = _bound(px, py, pz, a + 1, lo, hi, nrm, smin, smax, floor, plane)
            top = _push_children(stack, top, a, da, db, best)
        value[i] = best
        best_tri[i] = tri_best
        foot[i, 0], foot[i, 1], foot[i, 2] = fx, fy, fz
        if tri_best >= 0:
            seed = tri_best
    return value, best_tri, foot


class LinearSources:
    """A triangle mesh wetted at times linear over each triangle, answering T(x) and its minimiser.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The wetted triangles, mm (need not be closed).
    vertex_time : (V,) ndarray of float, mm
        w at each vertex of ``mesh`` (finite; a large value stands for never).

    Examples
    --------
    A square wetted at w = 0.6 y: below it, a plane front w(x0) + 0.8 |z|.

    >>> import trimesh
    >>> square = trimesh.Trimesh([[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]], [[0, 1, 2], [0, 2, 3]])
    >>> T, _, _ = LinearSources(square, 0.6 * square.vertices[:, 1]).arrival(np.array([[0.0, 1.0, -2.0]]))
    >>> round(float(T[0]), 6)
    2.2
    """

    def __init__(self, mesh: trimesh.Trimesh, vertex_time: np.ndarray) -> None:
        self.surface = s = Surface(mesh)
        vx = s.vx
        e1, e2 = vx[:, 1] - vx[:, 0], vx[:, 2] - vx[:, 0]
        normal = np.cross(e1, e2)
        n2 = np.einsum("ij,ij->i", normal, normal)
        self.flat = n2 > 0.0                    # a degenerate triangle: no interior, its edges only
        n2 = np.where(self.flat, n2, np.inf)
        self.dual = np.ascontiguousarray(np.stack([np.cross(e2, normal) / n2[:, None],
                                                   np.cross(normal, e1) / n2[:, None]], axis=1))
        self.unit_n = np.ascontiguousarray(np.nan_to_num(normal / np.sqrt(n2)[:, None]))
        self.area = 0.5 * np.sqrt(np.einsum("ij,ij->i", normal, normal))
        self.set_times(np.asarray(vertex_time, dtype=np.float64))

    def set_times(self, vertex_time: np.ndarray) -> None:
        """Set the vertex times, mm (the triangles' gradients of w and the hierarchy's bounds; the geometry stays)."""
        s = self.surface
        wv = np.ascontiguousarray(vertex_time[s.faces])
        dual = self.dual
        grad = (wv[:, 1] - wv[:, 0])[:, None] * dual[:, 0] + (wv[:, 2] - wv[:, 0])[:, None] * dual[:, 1]
        self.wv = wv
        self.grad = np.ascontiguousarray(np.where(self.flat[:, None], grad, np.inf))
        self.floor = _node_floor(wv.min(axis=1), s.start, s.count, s.left)
        self.plane = _node_planes(s.vx, wv, self.grad, self.area, s.start, s.count, s.left)

    def arrival(self, points: np.ndarray, cap: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """T at each point, its triangle (stored order; -1 where T >= the point's ``cap``, then T = cap) and the
        minimiser p*.

        Parameters
        ----------
        points : (M, 3) ndarray of float, mm
        cap : (M,) ndarray of float, mm, optional
            Values not searched for (none: inf).

        Returns
        -------
        T : (M,) ndarray of float, mm
        triangle : (M,) ndarray of int
        foot : (M, 3) ndarray of float, mm
        """
        s = self.surface
        points = np.ascontiguousarray(points, dtype=np.float64)
        cap = np.full(len(points), np.inf) if cap is None else np.ascontiguousarray(cap, dtype=np.float64)
        return _nearest_linear(points, s.vx, self.wv, self.unit_n, self.grad, self.dual, s.lo, s.hi, s.nrm, s.smin,
                               s.smax, s.left, s.start, s.count, self.floor, self.plane, cap)
