"""First-order fast marching for eq. (5) with a recorded visit order, and its exact adjoint sweep.

The grid is padded by one voxel on every side. Padding voxels on an ordinary face are known with
u = 0 at their centres (section 3.4); padding voxels on a mirror face (index 0 of a mirrored axis) are
excluded, because the mirror image of a voxel on that face is the voxel itself, whose term in eq. (5),
max(u_i - u_i, 0), vanishes; they are stored as known with u = inf, so they are never upwind. All
kernels work on the flattened padded grid with one stride per axis, so 2D and 3D share the same code
and no kernel needs bounds checks.

Memory layout: one 64-byte record per voxel, a row of `rec` aligned to a cache line: u, n with its
sign as the "known" flag (n < 0 once accepted; padding is known), the smallest known neighbour value
along each axis (the upwind candidates of eq. 5, updated when a neighbour is accepted) and, for a
trial voxel, its position in the heap. A trial voxel is then re-solved and re-keyed from its own
cache line instead of from six scattered neighbours and a separate position array: fast marching
visits voxels in the order of the front, not of memory, and scattered reads would be most of its
run time. Far voxels have u = inf and n > 0, trial voxels finite u and n > 0. When a voxel is accepted
its value is final; the marcher then appends its linearisation of eq. (5) to an array in visit
order, which the adjoint sweep streams backwards instead of revisiting the records: a sequential
read in place of scattered ones, for a little more work while marching. Timings:
docs/benchmarks.md#forward-simulator.

Anisotropic erosion (a build-direction speed ``anisotropy`` times the in-plane one) is the same
equation on a rectilinear grid of spacings (dx, dx, dx / anisotropy) in the travel-time metric: eq. (5)
becomes sum_d w_d max(u_i - u_N(i,d), u_i - u_N(i,-d), 0)^2 = (n_i dx)^2 with w_d = (dx / h_d)^2, so
w_z = anisotropy^2 on axis 2 (z) of a 3D grid, and its linearisation and adjoint sweep carry w_d along.
With anisotropy 1 the marcher runs the unweighted solve, so the isotropic results are unchanged.

Repeated solves on one grid (inverse design) pass a `MarchBuffers`: allocating the records (140 MB
for a 128^3 grid) afresh would cost page faults on every solve, a sizeable part of the solve.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from design.errors import DesignError


@dataclass(frozen=True)
class Marching:
    """The solved dissolution times on the padded grid and what the adjoint sweep needs.

    Attributes
    ----------
    rec : (P, 8) ndarray of float
        Per flattened padded voxel: u (mm; 0 on ordinary padding, inf on mirror padding), -n (the
        slowness of eq. 2, negated as the known flag; -1 on the padding), then per axis the smallest
        known neighbour value on that axis (its upwind candidate); column `HEAP_SLOT` is scratch.
    order : (N,) ndarray of int64
        Flat padded indices of the interior voxels in the order the marcher accepted them.
    coef : (N, 4) ndarray of float
        Per voxel in that order, the linearisation of eq. (5) the adjoint sweep applies: per axis
        w_d / W signed by the upwind neighbour's side (0 for no upwind term), then n dx^2 / W.
    strides : (D,) ndarray of int64
        Flat-index stride of each axis of the padded grid.
    padded_shape : tuple of int
    dx_mm : float
    weights : (D,) ndarray of float
        Per axis w_d = (dx / h_d)^2 of the anisotropic eq. (5): all 1 for isotropic erosion.
    """

    rec: np.ndarray
    order: np.ndarray
    coef: np.ndarray
    strides: np.ndarray
    padded_shape: tuple[int, ...]
    dx_mm: float
    buffers: MarchBuffers | None = None
    generation: int = 0
    weights: np.ndarray | None = None

    @property
    def u_pad(self) -> np.ndarray:
        """(P,) dissolution times on the flattened padded grid, mm (a view; see `check_current`)."""
        self.check_current()
        return self.rec[:, 0]

    def interior(self, flat: np.ndarray) -> np.ndarray:
        """The interior (unpadded) block of a flat padded array, as a view of shape (grid shape)."""
        return flat.reshape(self.padded_shape)[(slice(1, -1),) * len(self.padded_shape)]

    def check_current(self) -> None:
        """Raise `DesignError` if a later `march` has reused this solve's buffers."""
        if self.buffers is not None and self.buffers.generation != self.generation:
            raise DesignError("this fast-marching solve was overwritten by a later solve with the same "
                              "MarchBuffers; simulate again before taking its gradient")


class MarchBuffers:
    """Work arrays of `march` for one grid shape, reused by every solve that is given them.

    A `Marching` made with buffers stays valid until the next solve with the same buffers; after
    that its adjoint and its u raise `DesignError`. Not thread-safe: one owner at a time.

    Parameters
    ----------
    shape : tuple of int
        Grid shape (2D or 3D, unpadded).
    """

    def __init__(self, shape: tuple[int, ...]) -> None:
        self.shape = tuple(int(s) for s in shape)
        padded = int(np.prod([s + 2 for s in self.shape]))
        interior = int(np.prod(self.shape))
        if padded >= 2 ** 31:
            raise DesignError(f"grid {self.shape} has {padded} padded voxels; the marcher's int32 ids need < 2^31")
        self.rec = _aligned((padded, RECORD_WIDTH))
        self.keys = _aligned((interior + 7,))[7:]  # heap node 1, the root's first child, starts a cache line
        self.ids = np.empty(interior, dtype=np.int32)
        self.order = np.empty(interior, dtype=np.int64)
        self.coef = np.empty((interior, 4))
        self.ubar = np.empty(padded)
        self.nbar = np.empty(padded)
        self.generation = 0


RECORD_WIDTH = 8
"""Doubles per voxel record: one 64-byte cache line."""
HEAP_SLOT = 5
"""Record column holding a trial voxel's position in the heap."""


def _aligned(shape: tuple[int, ...]) -> np.ndarray:
    """An uninitialised float64 array whose data starts on a 64-byte cache-line boundary."""
    size = int(np.prod(shape))
    buf = np.empty(size + 8)
    start = (-buf.ctypes.data % 64) // 8
    return buf[start:start + size].reshape(shape)


# The priority queue is an 8-ary min-heap with keys (u) and voxel ids in separate arrays; each
# trial voxel's record holds its heap position for decrease-key. The eight children of node k, 8k+1..8k+8, have their keys in one
# cache line, and the heap is a third as deep as a binary one; the smallest child is found by a
# branch-free tournament, since the comparisons of a heap are unpredictable. Keys and ids in separate
# arrays and positions in the records keep the reads of a sift on as few cache lines as possible.

@njit(cache=True, nogil=True, inline="always")
def _smaller(key_a, a, key_b, b):
    """(key, index) of the smaller of two heap entries; a on ties."""
    take_b = key_b < key_a
    return (key_b if take_b else key_a), (b if take_b else a)


@njit(cache=True, nogil=True, inline="always")
def _smallest_of_eight(keys, f):
    k0, c0 = _smaller(keys[f], f, keys[f + 1], f + 1)
    k1, c1 = _smaller(keys[f + 2], f + 2, keys[f + 3], f + 3)
    k2, c2 = _smaller(keys[f + 4], f + 4, keys[f + 5], f + 5)
    k3, c3 = _smaller(keys[f + 6], f + 6, keys[f + 7], f + 7)
    k0, c0 = _smaller(k0, c0, k1, c1)
    k2, c2 = _smaller(k2, c2, k3, c3)
    return _smaller(k0, c0, k2, c2)


@njit(cache=True, nogil=True)
def _sift_up(keys, ids, rec, k):
    key = keys[k]
    idx = ids[k]
    while k > 0:
        parent = (k - 1) >> 3
        if keys[parent] <= key:
            break
        keys[k] = keys[parent]
        ids[k] = ids[parent]
        rec[ids[k], HEAP_SLOT] = k
        k = parent
    keys[k] = key
    ids[k] = idx
    rec[idx, HEAP_SLOT] = k


@njit(cache=True, nogil=True)
def _sift_down(keys, ids, rec, k, size):
    key = keys[k]
    idx = ids[k]
    while True:
        first = 8 * k + 1
        if first + 7 < size:
            child_key, child = _smallest_of_eight(keys, first)
        elif first < size:
            child_key, child = keys[first], first
            for j in range(first + 1, size):
                child_key, child = _smaller(child_key, child, keys[j], j)
        else:
            break
        if child_key >= key:
            break
        keys[k] = child_key
        ids[k] = ids[child]
        rec[ids[k], HEAP_SLOT] = k
        k = child
    keys[k] = key
    ids[k] = idx
    rec[idx, HEAP_SLOT] = k


@njit(cache=True, nogil=True)
def _push(keys, ids, rec, size, key, idx):
    keys[size] = key
    ids[size] = idx
    _sift_up(keys, ids, rec, size)
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
def _local_solve_weighted(rec, i, ndim, dx, weights):
    """Solve sum_d w_d (u - a_d)^2 = (n_i dx)^2 (eq. 5 on per-axis spacings) with consistent terms only."""
    a0 = rec[i, 2]
    w0 = weights[0]
    a1 = rec[i, 3]
    w1 = weights[1]
    a2 = np.inf
    w2 = 1.0
    if ndim == 3:
        a2 = rec[i, 4]
        w2 = weights[2]
    if a1 < a0:
        a0, a1, w0, w1 = a1, a0, w1, w0
    if a2 < a1:
        a1, a2, w1, w2 = a2, a1, w2, w1
        if a1 < a0:
            a0, a1, w0, w1 = a1, a0, w1, w0
    h = rec[i, 1] * dx
    v = h / np.sqrt(w0)
    if a0 + v <= a1:
        return a0 + v
    # in v = u - a0 (see _local_solve): (w0 + w1) v^2 - 2 w1 b1 v + w1 b1^2 - h^2 = 0
    b1 = a1 - a0
    total = w0 + w1
    v = (w1 * b1 + np.sqrt(max(total * h * h - w0 * w1 * b1 * b1, 0.0))) / total
    if a0 + v <= a2:
        return a0 + v
    b2 = a2 - a0
    total += w2
    s = w1 * b1 + w2 * b2
    v = (s + np.sqrt(max(s * s - total * (w1 * b1 * b1 + w2 * b2 * b2 - h * h), 0.0))) / total
    return a0 + v


@njit(cache=True, nogil=True)
def _march_kernel(rec, strides, dx, keys, ids, order, coef, weights, isotropic):
    ndim = strides.shape[0]
    size = 0
    # the initial front: unknown voxels with a finite upwind value (next to ordinary padding)
    for i in range(rec.shape[0]):
        if rec[i, 1] > 0.0:
            val = _local_solve(rec, i, ndim, dx) if isotropic else _local_solve_weighted(rec, i, ndim, dx, weights)
            if val < np.inf:
                rec[i, 0] = val
                size = _push(keys, ids, rec, size, val, i)
    count = 0
    while size > 0:
        i = np.int64(ids[0])
        size -= 1
        if size > 0:
            keys[0] = keys[size]
            ids[0] = ids[size]
            _sift_down(keys, ids, rec, 0, size)
        n_i = rec[i, 1]
        rec[i, 1] = -n_i  # accepted
        ui = rec[i, 0]
        order[count] = i
        _adjoint_coefficients(rec, i, ndim, strides, n_i * dx * dx, coef[count], weights)
        count += 1
        for d in range(ndim):
            for nb in (i - strides[d], i + strides[d]):
                if rec[nb, 1] < 0.0 or ui >= rec[nb, 2 + d]:
                    continue  # known or padding, or the new neighbour is not its best on this axis
                rec[nb, 2 + d] = ui
                if isotropic:
                    val = _local_solve(rec, nb, ndim, dx)
                else:
                    val = _local_solve_weighted(rec, nb, ndim, dx, weights)
                if rec[nb, 0] == np.inf:  # far -> trial
                    rec[nb, 0] = val
                    size = _push(keys, ids, rec, size, val, nb)
                elif val < rec[nb, 0]:  # decrease-key
                    rec[nb, 0] = val
                    k = np.int64(rec[nb, HEAP_SLOT])
                    keys[k] = val
                    _sift_up(keys, ids, rec, k)
    return order[:count]


@njit(cache=True, nogil=True, inline="always")
def _adjoint_coefficients(rec, i, ndim, strides, n_dx2, out, weights):
    """Linearisation of eq. (5) at a voxel being accepted, for the adjoint sweep (eq. 10).

    Differentiating sum_d c_d (u_i - a_d)^2 = (n_i dx)^2 (c_d the axis weights, 1 when isotropic)
    gives du_i = (sum_d w_d da_d + n_i dx^2 dn_i) / W with w_d = c_d (u_i - a_d) for strictly upwind
    axes (a_d < u_i; else 0) and W = sum_d w_d; a_d is the smaller neighbour on axis d (a trial
    neighbour is never below u_i). ``out`` gets w_d / W, negated when that neighbour is on the lower
    side, and n_i dx^2 / W.
    """
    ui = rec[i, 0]
    total = 0.0
    for d in range(ndim):
        lower = rec[i - strides[d], 0]
        upper = rec[i + strides[d], 0]
        a = min(lower, upper)
        w = (ui - a) * weights[d] if a < ui else 0.0  # exact for c_d = 1
        out[d] = w if upper < lower else -w
        total += w
    if total == 0.0:
        # u_i equals its upwind neighbours to float resolution (a huge slowness's step, e.g. an insoluble
        # barrier's, below one ulp of the arrival time): u_i follows its smallest neighbour alone
        best = 0
        for d in range(ndim):
            out[d] = 0.0
            if min(rec[i - strides[d], 0], rec[i + strides[d], 0]) < min(rec[i - strides[best], 0],
                                                                          rec[i + strides[best], 0]):
                best = d
        out[best] = 1.0 if rec[i + strides[best], 0] < rec[i - strides[best], 0] else -1.0
        out[3] = 0.0
        return
    inv = 1.0 / total
    for d in range(ndim):
        out[d] *= inv
    out[3] = n_dx2 * inv


@njit(cache=True, nogil=True)
def _adjoint_kernel(order, coef, strides, ubar, nbar):
    """Reverse sweep of eq. (10): push each voxel's adjoint to the upwind neighbours it used."""
    ndim = strides.shape[0]
    for c in range(order.shape[0] - 1, -1, -1):
        i = order[c]
        g = ubar[i]
        nbar[i] = g * coef[c, 3]
        for d in range(ndim):
            cd = coef[c, d]
            if cd > 0.0:
                ubar[i + strides[d]] += g * cd
            elif cd < 0.0:
                ubar[i - strides[d]] -= g * cd


@njit(cache=True, nogil=True)
def _fill_records(rec, n, cls0, cls1, cls2, ndim):
    """Fill the padded records in one pass; 2D grids come as (1, H, W) with ``cls0 = [0]``.

    ``cls_a[i]`` classifies index i of axis a: 0 interior, 1 interior next to ordinary padding on
    this axis (upwind candidate 0), 2 ordinary padding (u = 0), 3 mirror padding (u = inf).
    """
    off = 3 - ndim  # the loop's axis k is the grid's axis k - off (2D grids skip loop axis 0)
    for i0 in range(rec.shape[0]):
        c0 = cls0[i0]
        for i1 in range(rec.shape[1]):
            c1 = cls1[i1]
            for i2 in range(rec.shape[2]):
                c2 = cls2[i2]
                for c in range(2, rec.shape[3]):
                    rec[i0, i1, i2, c] = np.inf if c < 2 + ndim else 0.0  # scratch columns: 0
                if c0 >= 2 or c1 >= 2 or c2 >= 2:
                    rec[i0, i1, i2, 0] = np.inf if (c0 == 3 or c1 == 3 or c2 == 3) else 0.0
                    rec[i0, i1, i2, 1] = -1.0
                    continue
                rec[i0, i1, i2, 0] = np.inf
                rec[i0, i1, i2, 1] = n[i0 - 1 + off, i1 - 1, i2 - 1]
                for k, c in ((0, c0), (1, c1), (2, c2)):
                    if c == 1 and k >= off:
                        rec[i0, i1, i2, 2 + k - off] = 0.0


def _axis_classes(size: int, mirror: bool) -> np.ndarray:
    """Per padded index of one axis (interior `size`): the classes of `_fill_records`."""
    cls = np.zeros(size + 2, dtype=np.int8)
    cls[0] = 3 if mirror else 2
    cls[-1] = 2
    if not mirror:
        cls[1] = 1
    cls[-2] = 1
    return cls


def _fill(rec: np.ndarray, n: np.ndarray, mirror: tuple[bool, ...]) -> np.ndarray:
    """Fill ``rec`` (padded grid shape + (RECORD_WIDTH,)) from slowness ``n``; the axis strides."""
    classes = [_axis_classes(s, m) for s, m in zip(n.shape, mirror)]
    if n.ndim == 2:
        classes.insert(0, np.zeros(1, dtype=np.int8))
        _fill_records(rec[np.newaxis], n[np.newaxis], *classes, n.ndim)
    else:
        _fill_records(rec, n, *classes, n.ndim)
    return np.array(rec.strides[:-1], dtype=np.int64) // rec.strides[-2]


def axis_weights(ndim: int, anisotropy: float) -> np.ndarray:
    """Per-axis weights w_d = (dx / h_d)^2 of eq. (5) for z speed ``anisotropy`` x the in-plane speed.

    Raises
    ------
    DesignError
        For a non-positive or non-finite anisotropy, or anisotropy != 1 on a 2D grid (which has no z).
    """
    a = float(anisotropy)
    if not np.isfinite(a) or a <= 0:
        raise DesignError(f"anisotropy must be a positive number, got {anisotropy}")
    weights = np.ones(ndim)
    if a != 1.0:
        if ndim != 3:
            raise DesignError(f"anisotropy {a:g} needs a 3D grid (axis 2 is the build direction z); this grid is {ndim}D")
        weights[2] = a * a
    return weights


def march(n: np.ndarray, dx_mm: float, mirror: tuple[bool, ...], buffers: MarchBuffers | None = None,
          anisotropy: float = 1.0) -> Marching:
    """Solve the discrete Eikonal equation (5) by first-order fast marching.

    Parameters
    ----------
    n : (H, W) or (D, H, W) ndarray of float
        Slowness per voxel (eq. 2), strictly positive.
    dx_mm : float
        Voxel edge length, mm.
    mirror : tuple of bool
        Per axis, True for a mirror plane at the index-0 face instead of u = 0 padding.
    buffers : MarchBuffers, optional
        Work arrays for this grid shape to reuse; the previous solve made with them becomes stale.
    anisotropy : float
        Erosion speed along axis 2 (z) over the in-plane speed: the grid spacing on z is
        dx / anisotropy in the travel-time metric. 1 is the paper's isotropic model.

    Returns
    -------
    Marching
    """
    n = np.asarray(n, dtype=np.float64)
    weights = axis_weights(n.ndim, anisotropy)
    if buffers is None:
        buffers = MarchBuffers(n.shape)
        shared = None
    elif buffers.shape != n.shape:
        raise DesignError(f"MarchBuffers are for grid shape {buffers.shape}, got {n.shape}")
    else:
        shared = buffers
        buffers.generation += 1
    padded_shape = tuple(s + 2 for s in n.shape)
    strides = _fill(buffers.rec.reshape(padded_shape + (RECORD_WIDTH,)), n, mirror)
    order = _march_kernel(buffers.rec, strides, float(dx_mm), buffers.keys, buffers.ids, buffers.order,
                          buffers.coef, weights, bool(np.all(weights == 1.0)))
    return Marching(buffers.rec, order, buffers.coef[:order.size], strides, padded_shape, float(dx_mm), shared,
                    buffers.generation, weights)


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

    Raises
    ------
    DesignError
        If `marching`'s buffers have been reused by a later solve.
    """
    marching.check_current()
    size = marching.rec.shape[0]
    if marching.buffers is None:
        ubar, nbar = np.empty(size), np.empty(size)
    else:
        ubar, nbar = marching.buffers.ubar, marching.buffers.nbar
    # every interior voxel is in the visit order, so padding entries are written but never read
    marching.interior(ubar)[...] = u_bar
    _adjoint_kernel(marching.order, marching.coef, marching.strides, ubar, nbar)
    return np.array(marching.interior(nbar))


def upwind_spacing(marching: Marching) -> np.ndarray:
    """Per interior voxel, the metric spacing dx / sqrt(w_d) of its main upwind axis (smallest a_d), mm.

    The axis comes from the linearisation recorded while marching: |coef_d| / w_d is proportional to
    u_i - a_d. It is constant under small changes of the slowness (it changes only at ties of the
    upwind values), so it carries no gradient. dx everywhere for isotropic erosion.
    """
    marching.check_current()
    weights = np.ones(len(marching.padded_shape)) if marching.weights is None else marching.weights
    shape = tuple(s - 2 for s in marching.padded_shape)
    if np.all(weights == 1.0):
        return np.full(shape, marching.dx_mm)
    ndim = len(shape)
    axis = np.argmax(np.abs(marching.coef[:, :ndim]) / weights, axis=1)
    flat = np.empty(int(np.prod(marching.padded_shape)))
    flat[marching.order] = marching.dx_mm / np.sqrt(weights[axis])
    return np.array(marching.interior(flat))


def eikonal_residual(marching: Marching) -> np.ndarray:
    """Residual of eq. (5) at every interior voxel, as a length.

    Returns
    -------
    ndarray of float, grid shape, mm
        sqrt(sum_d w_d max(u_i - u_N(i,d), u_i - u_N(i,-d), 0)^2) - n_i dx. Round-off makes it of the
        order of the float spacing of u (~1e-16 u), however small n_i dx is.
    """
    shape = marching.padded_shape
    u = marching.u_pad.reshape(shape)
    inner = (slice(1, -1),) * len(shape)
    ui = u[inner]
    total = np.zeros(ui.shape)
    weights = np.ones(len(shape)) if marching.weights is None else marching.weights
    for axis in range(len(shape)):
        lo = list(inner)
        hi = list(inner)
        lo[axis] = slice(0, -2)
        hi[axis] = slice(2, None)
        total += weights[axis] * np.maximum(ui - np.minimum(u[tuple(lo)], u[tuple(hi)]), 0.0) ** 2
    return np.sqrt(total) + marching.interior(marching.rec[:, 1]) * marching.dx_mm  # n is stored negated
