"""First-order fast marching for eq. (5) with a recorded visit order, and its exact adjoint sweep.

The grid is padded by one voxel on every side. Padding voxels on an ordinary face are known with
u = 0 at their centres (section 3.4); padding voxels on a mirror face (index 0 of a mirrored axis) are
excluded, because the mirror image of a voxel on that face is the voxel itself, whose term in eq. (5),
max(u_i - u_i, 0), vanishes. All kernels work on the flattened padded arrays with one stride per axis,
so 2D and 3D share the same code and no kernel needs bounds checks.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numba import njit

log = logging.getLogger(__name__)

_FAR, _TRIAL, _KNOWN, _EXCLUDED = 0, 1, 2, 3


@dataclass(frozen=True)
class Marching:
    """The solved dissolution times on the padded grid and what the adjoint sweep needs.

    Attributes
    ----------
    u_pad : (P,) ndarray of float, mm
        Dissolution times on the flattened padded grid (0 on the padding).
    n_pad : (P,) ndarray of float
        Slowness on the flattened padded grid (eq. 2); undefined on the padding.
    state : (P,) ndarray of int8
        2 for solved and ordinary padding voxels, 3 for the excluded mirror padding.
    order : (N,) ndarray of int64
        Flat padded indices of the interior voxels in the order the marcher accepted them.
    strides : (D,) ndarray of int64
        Flat-index stride of each axis of the padded grid.
    padded_shape : tuple of int
    dx_mm : float
    """

    u_pad: np.ndarray
    n_pad: np.ndarray
    state: np.ndarray
    order: np.ndarray
    strides: np.ndarray
    padded_shape: tuple[int, ...]
    dx_mm: float

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
def _local_solve(i, u, n, state, strides, dx):
    """Solve eq. (5) at voxel i from its known neighbours, using only consistent solutions."""
    ndim = strides.shape[0]
    a = np.empty(3)
    m = 0
    for d in range(ndim):
        s = strides[d]
        best = np.inf
        if state[i - s] == _KNOWN and u[i - s] < best:
            best = u[i - s]
        if state[i + s] == _KNOWN and u[i + s] < best:
            best = u[i + s]
        if best < np.inf:
            # insertion sort of the upwind values, ascending
            j = m
            while j > 0 and a[j - 1] > best:
                a[j] = a[j - 1]
                j -= 1
            a[j] = best
            m += 1
    h = n[i] * dx
    # one term: u = a0 + h; accept if it does not exceed the next upwind value
    if m == 1 or a[0] + h <= a[1]:
        return a[0] + h
    # Several terms, solved for v = u - a0 with b_d = a_d - a0 < h, which avoids the cancellation
    # that (u - a_d)^2 would suffer in void voxels, where h = n_min dx is tiny next to u.
    b1 = a[1] - a[0]
    v = 0.5 * (b1 + np.sqrt(2.0 * h * h - b1 * b1))
    if m == 2 or a[0] + v <= a[2]:
        return a[0] + v
    b2 = a[2] - a[0]
    s = b1 + b2
    v = (s + np.sqrt(s * s - 3.0 * (b1 * b1 + b2 * b2 - h * h))) / 3.0
    return a[0] + v


@njit(cache=True, nogil=True)
def _march_kernel(u, n, state, strides, dx, n_interior):
    size_pad = u.shape[0]
    ndim = strides.shape[0]
    pos = np.full(size_pad, -1, dtype=np.int32)
    heap = np.empty((n_interior, 2))  # rows of (u, flat index); indices are exact in float64
    order = np.empty(n_interior, dtype=np.int64)
    size = 0
    # the initial front: interior voxels next to ordinary (u = 0) padding
    for i in range(size_pad):
        if state[i] != _FAR:
            continue
        touches = False
        for d in range(ndim):
            s = strides[d]
            if state[i - s] == _KNOWN or state[i + s] == _KNOWN:
                touches = True
        if touches:
            u[i] = _local_solve(i, u, n, state, strides, dx)
            state[i] = _TRIAL
            size = _push(heap, pos, size, u[i], i)
    count = 0
    while size > 0:
        i = np.int64(heap[0, 1])
        size -= 1
        if size > 0:
            heap[0, 0] = heap[size, 0]
            heap[0, 1] = heap[size, 1]
            _sift_down(heap, pos, 0, size)
        state[i] = _KNOWN
        order[count] = i
        count += 1
        for d in range(ndim):
            for nb in (i - strides[d], i + strides[d]):
                st = state[nb]
                if st == _FAR:
                    u[nb] = _local_solve(nb, u, n, state, strides, dx)
                    state[nb] = _TRIAL
                    size = _push(heap, pos, size, u[nb], nb)
                elif st == _TRIAL:
                    val = _local_solve(nb, u, n, state, strides, dx)
                    if val < u[nb]:  # decrease-key
                        u[nb] = val
                        k = pos[nb]
                        heap[k, 0] = val
                        _sift_up(heap, pos, k)
    return order[:count]


@njit(cache=True, nogil=True)
def _adjoint_kernel(order, u, n, state, strides, dx, ubar):
    """Reverse sweep of eq. (10): push each voxel's adjoint to the upwind neighbours it used."""
    ndim = strides.shape[0]
    nbar = np.zeros(u.shape[0])
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
                if state[nb] == _KNOWN and u[nb] < best:
                    best = u[nb]
                    nbs[d] = nb
            # active term of eq. (5) iff the neighbour is strictly upwind
            w[d] = ui - best if best < ui else 0.0
            total += w[d]
        # differentiating sum_d (u_i - a_d)^2 = (n_i dx)^2:  du_i = (sum_d w_d da_d + n_i dx^2 dn_i) / sum_d w_d
        g = ubar[i] / total
        nbar[i] = g * n[i] * dx * dx
        for d in range(ndim):
            if w[d] > 0.0:
                ubar[nbs[d]] += g * w[d]
    return nbar


def _pad(n: np.ndarray, mirror: tuple[bool, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    padded = np.pad(n, 1)
    state = np.full(padded.shape, _FAR, dtype=np.int8)
    for axis in range(n.ndim):
        for side in (0, -1):
            index = [slice(None)] * n.ndim
            index[axis] = side
            state[tuple(index)] = _KNOWN
    for axis in range(n.ndim):  # mirror faces override, corners included
        if mirror[axis]:
            index = [slice(None)] * n.ndim
            index[axis] = 0
            state[tuple(index)] = _EXCLUDED
    strides = np.array(padded.strides, dtype=np.int64) // padded.itemsize
    u = np.where(state == _FAR, np.inf, 0.0)
    return u.ravel(), padded.ravel(), state.ravel(), strides


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
    u, n_pad, state, strides = _pad(np.asarray(n, dtype=np.float64), mirror)
    order = _march_kernel(u, n_pad, state, strides, float(dx_mm), int(np.prod(n.shape)))
    return Marching(u, n_pad, state, order, strides, tuple(s + 2 for s in n.shape), float(dx_mm))


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
    ubar = np.zeros(marching.u_pad.shape[0])
    marching.interior(ubar)[...] = u_bar
    nbar = _adjoint_kernel(marching.order, marching.u_pad, marching.n_pad, marching.state,
                           marching.strides, marching.dx_mm, ubar)
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
    u = np.where(marching.state == _EXCLUDED, np.inf, marching.u_pad).reshape(shape)
    inner = (slice(1, -1),) * len(shape)
    ui = u[inner]
    total = np.zeros(ui.shape)
    for axis in range(len(shape)):
        lo = list(inner)
        hi = list(inner)
        lo[axis] = slice(0, -2)
        hi[axis] = slice(2, None)
        total += np.maximum(ui - np.minimum(u[tuple(lo)], u[tuple(hi)]), 0.0) ** 2
    return np.sqrt(total) - marching.interior(marching.n_pad) * marching.dx_mm
