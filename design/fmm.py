"""First-order fast marching for eq. (5) with a recorded visit order, and its exact adjoint sweep.

The grid is padded by one voxel on every side. Padding voxels on an ordinary face are known with
u = 0 at their centres (section 3.4); padding voxels on a mirror face (index 0 of a mirrored axis) are
excluded, because the mirror image of a voxel on that face is the voxel itself, whose term in eq. (5),
max(u_i - u_i, 0), vanishes; they are stored as known with u = inf, so they are never upwind. All
kernels work on the flattened padded grid with one stride per axis, so 2D and 3D share the same code
and no kernel needs bounds checks.

Memory layout: one record per voxel, a row of `rec`: u, n with its sign as the "known" flag (n < 0
once accepted; padding is known), and the smallest known neighbour value along each axis (the
upwind candidates of eq. 5), updated when a neighbour is accepted. A trial voxel is then re-solved from
its own cache line instead of from six scattered neighbours: fast marching visits voxels in the order
of the front, not of memory, and scattered reads were most of its run time. Far voxels have u = inf
and n > 0, trial voxels finite u and n > 0.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numba import njit

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Marching:
    """The solved dissolution times on the padded grid and what the adjoint sweep needs.

    Attributes
    ----------
    rec : (P, W) ndarray of float
        Per flattened padded voxel: u (mm; 0 on ordinary padding, inf on mirror padding), -n (the
        slowness of eq. 2, negated as the known flag; -1 on the padding), then per axis the smallest
        known neighbour value on that axis (its upwind candidate); W = 4 (2D) or 8 (3D, one cache line).
    order : (N,) ndarray of int64
        Flat padded indices of the interior voxels in the order the marcher accepted them.
    strides : (D,) ndarray of int64
        Flat-index stride of each axis of the padded grid.
    padded_shape : tuple of int
    dx_mm : float
    """

    rec: np.ndarray
    order: np.ndarray
    strides: np.ndarray
    padded_shape: tuple[int, ...]
    dx_mm: float

    @property
    def u_pad(self) -> np.ndarray:
        """(P,) dissolution times on the flattened padded grid, mm (a view)."""
        return self.rec[:, 0]

    def interior(self, flat: np.ndarray) -> np.ndarray:
        """The interior (unpadded) block of a flat padded array, as a view of shape (grid shape)."""
        return flat.reshape(self.padded_shape)[(slice(1, -1),) * len(self.padded_shape)]


# The priority queue is a 4-ary min-heap of (key, voxel) rows with a position array for
# decrease-key; four children share one cache line and the heap is half as deep as a binary one,
# which matters because every level of a sift writes one random entry of `pos`.

@njit(cache=True, nogil=True)
def _sift_up(heap, pos, k):
    key = heap[k, 0]
    idx = heap[k, 1]
    while k > 0:
        parent = (k - 1) >> 2
        if heap[parent, 0] <= key:
            break
        heap[k, 0] = heap[parent, 0]
        heap[k, 1] = heap[parent, 1]
        pos[np.int64(heap[k, 1])] = k
        k = parent
    heap[k, 0] = key
    heap[k, 1] = idx
    pos[np.int64(idx)] = k


@njit(cache=True, nogil=True)
def _sift_down(heap, pos, k, size):
    key = heap[k, 0]
    idx = heap[k, 1]
    while True:
        first = 4 * k + 1
        if first >= size:
            break
        child = first
        for j in range(first + 1, min(first + 4, size)):
            if heap[j, 0] < heap[child, 0]:
                child = j
        if heap[child, 0] >= key:
            break
        heap[k, 0] = heap[child, 0]
        heap[k, 1] = heap[child, 1]
        pos[np.int64(heap[k, 1])] = k
        k = child
    heap[k, 0] = key
    heap[k, 1] = idx
    pos[np.int64(idx)] = k


@njit(cache=True, nogil=True)
def _push(heap, pos, size, key, idx):
    heap[size, 0] = key
    heap[size, 1] = idx
    _sift_up(heap, pos, size)
    return size + 1


@njit(cache=True, nogil=True)
def _local_solve(rec, i, ndim, dx):
    """Solve eq. (5) at voxel i from its per-axis upwind values, using only consistent solutions."""
    # upwind value per axis (inf when the axis has no known neighbour), sorted ascending in scalars
    a0 = rec[i, 2]
    a1 = rec[i, 3]
    a2 = rec[i, 4] if ndim == 3 else np.inf
    if a1 < a0:
        a0, a1 = a1, a0
    if a2 < a1:
        a1, a2 = a2, a1
        if a1 < a0:
            a0, a1 = a1, a0
    h = rec[i, 1] * dx
    # one term: u = a0 + h; accept if it does not exceed the next upwind value
    if a0 + h <= a1:  # also when a1 is inf: a single known axis
        return a0 + h
    # Several terms, solved for v = u - a0 with b_d = a_d - a0 < h, which avoids the cancellation
    # that (u - a_d)^2 would suffer in void voxels, where h = n_min dx is tiny next to u.
    b1 = a1 - a0
    v = 0.5 * (b1 + np.sqrt(2.0 * h * h - b1 * b1))
    if a0 + v <= a2:
        return a0 + v
    b2 = a2 - a0
    s = b1 + b2
    v = (s + np.sqrt(s * s - 3.0 * (b1 * b1 + b2 * b2 - h * h))) / 3.0
    return a0 + v


@njit(cache=True, nogil=True)
def _march_kernel(rec, strides, dx, pos, heap, order):
    ndim = strides.shape[0]
    size = 0
    # the initial front: unknown voxels with a finite upwind value (next to ordinary padding)
    for i in range(rec.shape[0]):
        if rec[i, 1] > 0.0:
            val = _local_solve(rec, i, ndim, dx)
            if val < np.inf:
                rec[i, 0] = val
                size = _push(heap, pos, size, val, i)
    count = 0
    while size > 0:
        i = np.int64(heap[0, 1])
        size -= 1
        if size > 0:
            heap[0, 0] = heap[size, 0]
            heap[0, 1] = heap[size, 1]
            _sift_down(heap, pos, 0, size)
        rec[i, 1] = -rec[i, 1]  # accepted
        ui = rec[i, 0]
        order[count] = i
        count += 1
        for d in range(ndim):
            for nb in (i - strides[d], i + strides[d]):
                if rec[nb, 1] < 0.0 or ui >= rec[nb, 2 + d]:
                    continue  # known or padding, or the new neighbour is not its best on this axis
                rec[nb, 2 + d] = ui
                val = _local_solve(rec, nb, ndim, dx)
                if rec[nb, 0] == np.inf:  # far -> trial
                    rec[nb, 0] = val
                    size = _push(heap, pos, size, val, nb)
                elif val < rec[nb, 0]:  # decrease-key
                    rec[nb, 0] = val
                    k = pos[nb]
                    heap[k, 0] = val
                    _sift_up(heap, pos, k)
    return order[:count]


@njit(cache=True, nogil=True)
def _adjoint_kernel(order, u, rec, strides, dx, ubar):
    """Reverse sweep of eq. (10): push each voxel's adjoint to the upwind neighbours it used."""
    ndim = strides.shape[0]
    nbar = np.zeros(rec.shape[0])
    nbs = np.empty(3, dtype=np.int64)
    w = np.empty(3)
    for c in range(order.shape[0] - 1, -1, -1):
        i = order[c]
        ui = u[i]
        total = 0.0
        for d in range(ndim):
            s = strides[d]
            best = np.inf
            nbs[d] = -1
            for nb in (i - s, i + s):
                if u[nb] < best:  # every voxel is known now; mirror padding has u = inf
                    best = u[nb]
                    nbs[d] = nb
            # active term of eq. (5) iff the neighbour is strictly upwind
            w[d] = ui - best if best < ui else 0.0
            total += w[d]
        # differentiating sum_d (u_i - a_d)^2 = (n_i dx)^2:  du_i = (sum_d w_d da_d + n_i dx^2 dn_i) / sum_d w_d
        g = ubar[i] / total
        nbar[i] = -g * rec[i, 1] * dx * dx
        for d in range(ndim):
            if w[d] > 0.0:
                ubar[nbs[d]] += g * w[d]
    return nbar


@njit(cache=True, nogil=True)
def _fill_records(rec, n, cls0, cls1, cls2, ndim):
    """Fill the padded records in one pass; 2D grids come as (1, H, W) with ``cls0 = [0]``.

    ``cls_a[i]`` classifies index i of axis a: 0 interior, 1 interior next to ordinary padding on
    this axis (upwind candidate 0), 2 ordinary padding (u = 0), 3 mirror padding (u = inf).
    """
    off = ndim - 2  # n's index shift on axis 0: 1 when that axis is padded (3D)
    for i0 in range(rec.shape[0]):
        c0 = cls0[i0]
        for i1 in range(rec.shape[1]):
            c1 = cls1[i1]
            for i2 in range(rec.shape[2]):
                c2 = cls2[i2]
                if c0 >= 2 or c1 >= 2 or c2 >= 2:
                    rec[i0, i1, i2, 0] = np.inf if (c0 == 3 or c1 == 3 or c2 == 3) else 0.0
                    rec[i0, i1, i2, 1] = -1.0
                    for c in range(2, 2 + ndim):
                        rec[i0, i1, i2, c] = np.inf
                else:
                    rec[i0, i1, i2, 0] = np.inf
                    rec[i0, i1, i2, 1] = n[i0 - off, i1 - 1, i2 - 1]
                    if ndim == 3:
                        rec[i0, i1, i2, 2] = 0.0 if c0 == 1 else np.inf
                    rec[i0, i1, i2, ndim] = 0.0 if c1 == 1 else np.inf
                    rec[i0, i1, i2, ndim + 1] = 0.0 if c2 == 1 else np.inf


def _axis_classes(size: int, mirror: bool) -> np.ndarray:
    """Per padded index of one axis (interior `size`): the classes of `_fill_records`."""
    cls = np.zeros(size + 2, dtype=np.int8)
    cls[0] = 3 if mirror else 2
    cls[-1] = 2
    if not mirror:
        cls[1] = 1
    cls[-2] = 1
    return cls


def _pad(n: np.ndarray, mirror: tuple[bool, ...]) -> tuple[np.ndarray, np.ndarray]:
    ndim = n.ndim
    rec = np.empty(tuple(s + 2 for s in n.shape) + (4 if ndim == 2 else 8,))
    classes = [_axis_classes(s, m) for s, m in zip(n.shape, mirror)]
    if ndim == 2:
        classes.insert(0, np.zeros(1, dtype=np.int8))
        _fill_records(rec[np.newaxis], n[np.newaxis], *classes, ndim)
    else:
        _fill_records(rec, n, *classes, ndim)
    strides = np.array(rec.strides[:-1], dtype=np.int64) // rec.strides[-2]
    return rec.reshape(-1, rec.shape[-1]), strides


def _aligned_heap(capacity: int) -> np.ndarray:
    """(capacity, 2) rows of (u, flat index) placed so each group of four siblings fills one cache line.

    The children of node k are 4k+1..4k+4, so row 1 must start on a 64-byte boundary. Indices up to
    2^53 are exact in float64.
    """
    buf = np.empty(2 * capacity + 8)
    shift = next(s for s in range(4) if (buf.ctypes.data + 16 * (s + 1)) % 64 == 0)
    return buf[2 * shift:2 * shift + 2 * capacity].reshape(capacity, 2)


def march(n: np.ndarray, dx_mm: float, mirror: tuple[bool, ...]) -> Marching:
    """Solve the discrete Eikonal equation (5) by first-order fast marching.

    Parameters
    ----------
    n : (H, W) or (D, H, W) ndarray of float
        Slowness per voxel (eq. 2), strictly positive.
    dx_mm : float
        Voxel edge length, mm.
    mirror : tuple of bool
        Per axis, True for a mirror plane at the index-0 face instead of u = 0 padding.

    Returns
    -------
    Marching
    """
    rec, strides = _pad(np.asarray(n, dtype=np.float64), mirror)
    # work arrays come from numpy, which requests transparent huge pages for large arrays; that helps
    # the marcher's scattered accesses along the front (heap positions fit int32 below 2^31 voxels)
    n_interior = int(np.prod(n.shape))
    pos = np.empty(rec.shape[0], dtype=np.int32)
    heap = _aligned_heap(n_interior)
    order = np.empty(n_interior, dtype=np.int64)
    order = _march_kernel(rec, strides, float(dx_mm), pos, heap, order)
    return Marching(rec, order, strides, tuple(s + 2 for s in n.shape), float(dx_mm))


def march_adjoint(marching: Marching, u_bar: np.ndarray) -> np.ndarray:
    """Vector-Jacobian product of the marcher: dJ/dn from dJ/du (eqs. 9-10).

    Parameters
    ----------
    marching : Marching
    u_bar : ndarray of float, grid shape
        dJ/du per interior voxel, 1/mm times the objective's unit.

    Returns
    -------
    ndarray of float, grid shape
        dJ/dn per interior voxel.
    """
    ubar = np.zeros(marching.rec.shape[0])
    marching.interior(ubar)[...] = u_bar
    # a compact copy of u: the sweep reads six neighbours per voxel, 8 bytes each instead of a record
    u = np.ascontiguousarray(marching.u_pad)
    nbar = _adjoint_kernel(marching.order, u, marching.rec, marching.strides, marching.dx_mm, ubar)
    return np.array(marching.interior(nbar))


def eikonal_residual(marching: Marching) -> np.ndarray:
    """Residual of eq. (5) at every interior voxel, as a length.

    Returns
    -------
    ndarray of float, grid shape, mm
        sqrt(sum_d max(u_i - u_N(i,d), u_i - u_N(i,-d), 0)^2) - n_i dx. Round-off makes it of the
        order of the float spacing of u (~1e-16 u), however small n_i dx is.
    """
    shape = marching.padded_shape
    u = marching.u_pad.reshape(shape)
    inner = (slice(1, -1),) * len(shape)
    ui = u[inner]
    total = np.zeros(ui.shape)
    for axis in range(len(shape)):
        lo = list(inner)
        hi = list(inner)
        lo[axis] = slice(0, -2)
        hi[axis] = slice(2, None)
        total += np.maximum(ui - np.minimum(u[tuple(lo)], u[tuple(hi)]), 0.0) ** 2
    return np.sqrt(total) + marching.interior(marching.rec[:, 1]) * marching.dx_mm  # n is stored negated
