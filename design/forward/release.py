"""The discrete release curve of eqs. (6)-(7) and its vector-Jacobian product.

Voxel i contributes w_i clamp((tau - u_i) / L_i + 1, 0, 1) with w_i = rho_i dx^3 and L_i = n_i dx
(eq. 6): it dissolves at a constant rate over (t0_i, u_i), t0_i = u_i - L_i. No voxel dissolves
before the bath touches the solid at tau = 0, so where eq. (6)'s ramp would start earlier
(0 < u_i < L_i: a voxel on an edge or corner of the solid, whose upwind neighbours on two or three
axes are the bath, so that eq. (5) gives u_i = L_i / sqrt(2) or L_i / sqrt(3)) the voxel dissolves
over (0, u_i) instead: t0_i = max(u_i - L_i, 0). With eq. (6) as written those voxels would release
part of themselves at tau = 0, about 1.7% of a sphere's volume at 64 voxels across.

Written with r(x) = max(x, 0), the ramp is w_i / l_i (r(tau - t0_i) - r(tau - u_i)) with
l_i = u_i - t0_i, and r sampled on the grid tau_k = k dtau has a second difference that is non-zero
at two samples only. Accumulating those second differences and summing twice gives the exact samples
of eq. (7) in O(N + K) (section 3.4). The adjoint uses prefix sums of the curve's cotangent, also
O(N + K).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from design.threads import in_parts


@njit(cache=True, nogil=True)
def _add_kink(acc, t, value, dtau):
    """Add value * r(tau_k - t) to the curve as second differences (index 0 folds in t < 0)."""
    x = t / dtau
    m = np.floor(x)
    f = x - m
    k_count = acc.shape[0]
    for j, v in ((m + 1.0, value * (1.0 - f) * dtau), (m + 2.0, value * f * dtau)):
        if j >= k_count:
            continue
        if j >= 0:
            acc[np.int64(j)] += v
        else:
            # a unit at index j < 0 equals (1 - j) at index 0 and j at index 1 after two cumsums
            acc[0] += v * (1.0 - j)
            if k_count > 1:
                acc[1] += v * j


@njit(cache=True, nogil=True, inline="always")
def _ramp_start(u, length):
    """t0 = u - L, or 0 where that would precede the bath's contact (0 < u < L)."""
    t0 = u - length
    return 0.0 if (t0 < 0.0 < u) else t0


@njit(cache=True, nogil=True)
def _second_differences(u, length, weight, dtau, k_count):
    acc = np.zeros(k_count)
    for i in range(u.shape[0]):
        if weight[i] == 0.0:
            continue
        t0 = _ramp_start(u[i], length[i])
        if u[i] - t0 <= 0.0:
            # a ramp below the float resolution of its time (a void's step far behind an insoluble barrier): a step
            j = np.int64(np.floor(u[i] / dtau)) + 1
            if 0 <= j < k_count:
                acc[j] += weight[i]
            if 0 <= j + 1 < k_count:
                acc[j + 1] -= weight[i]
            continue
        slope = weight[i] / (u[i] - t0)
        _add_kink(acc, t0, slope, dtau)
        _add_kink(acc, u[i], -slope, dtau)
    return acc


def ramp_release(u_mm: np.ndarray, length_mm: np.ndarray, weight_mm3: np.ndarray,
                 dtau_mm: float, k_count: int) -> np.ndarray:
    """Sample the release curve (7) at tau_k = k dtau, k = 0..K-1.

    Parameters
    ----------
    u_mm : (N,) ndarray of float, mm
        Dissolution time of each voxel.
    length_mm : (N,) ndarray of float, mm
        Ramp length n_i dx of each voxel (eq. 6), > 0; a ramp that would start before tau = 0 starts
        at 0 (module docstring).
    weight_mm3 : (N,) ndarray of float, mm^3
        Solid volume rho_i dx^3 of each voxel (times any mirror multiplicity).
    dtau_mm : float
        Time step, mm.
    k_count : int
        Number of samples K.

    Returns
    -------
    (K,) ndarray of float, mm^3
        Cumulative released volume.
    """
    acc = _second_differences(u_mm, length_mm, weight_mm3, float(dtau_mm), int(k_count))
    return np.cumsum(np.cumsum(acc))


@njit(cache=True, nogil=True)
def _prefix_sums(g):
    """p0[k] = sum_{j<k} g_j and p1[k] = sum_{j<k} j g_j, k = 0..K."""
    k_count = g.shape[0]
    p0 = np.zeros(k_count + 1)
    p1 = np.zeros(k_count + 1)
    for k in range(k_count):
        p0[k + 1] = p0[k] + g[k]
        p1[k + 1] = p1[k] + k * g[k]
    return p0, p1


@njit(cache=True, nogil=True)
def _vjp_kernel(u, length, weight, dtau, p0, p1, u_bar, length_bar, weight_bar):
    """The pullback at voxels ``0..len(u)-1`` of the given slices, written into the output slices."""
    k_count = p0.shape[0] - 1
    for i in range(u.shape[0]):
        t0 = _ramp_start(u[i], length[i])
        span = u[i] - t0
        # samples on the ramp: t0 < tau_k <= u_i; after it the ramp is 1
        ka = min(max(np.int64(np.floor(t0 / dtau)) + 1, 0), k_count)
        kb = min(max(np.int64(np.floor(u[i] / dtau)) + 1, 0), k_count)
        u_bar[i] = length_bar[i] = 0.0
        if span <= 0.0:
            weight_bar[i] = p0[k_count] - p0[kb]  # a step (see _second_differences): flat in u_i and L_i
            continue
        s0 = p0[kb] - p0[ka]
        s1 = p1[kb] - p1[ka]
        ramp = (dtau * s1 - t0 * s0) / span  # sum_k g_k s_k over the ramp
        weight_bar[i] = ramp + (p0[k_count] - p0[kb])
        if t0 == 0.0 and u[i] < length[i]:
            # s_k = tau_k / u_i on (0, u_i]: d s_k / d u_i = -s_k / u_i, independent of L_i
            u_bar[i] = -weight[i] / span * ramp
        else:
            # d s_k / d u_i = -1 / L_i and d s_k / d L_i = (1 - s_k) / L_i on the ramp (eq. 6)
            u_bar[i] = -weight[i] / span * s0
            length_bar[i] = weight[i] / span * (s0 - ramp)


def ramp_release_vjp(u_mm: np.ndarray, length_mm: np.ndarray, weight_mm3: np.ndarray,
                     dtau_mm: float, curve_bar: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pull a cotangent of the curve back to the per-voxel inputs of :func:`ramp_release`.

    Parameters
    ----------
    u_mm, length_mm, weight_mm3 : (N,) ndarray of float
        As for :func:`ramp_release`.
    dtau_mm : float
    curve_bar : (K,) ndarray of float
        dJ/dC_k, per mm^3.

    Returns
    -------
    u_bar, length_bar, weight_bar : (N,) ndarray of float
        dJ/du_i, dJ/dL_i (per mm) and dJ/dw_i (per mm^3).
    """
    u, length, weight = (np.ascontiguousarray(a, dtype=np.float64) for a in (u_mm, length_mm, weight_mm3))
    p0, p1 = _prefix_sums(np.asarray(curve_bar, dtype=np.float64))
    bars = np.empty((3, u.size))
    dtau = float(dtau_mm)

    def part(i: int, j: int) -> None:
        _vjp_kernel(u[i:j], length[i:j], weight[i:j], dtau, p0, p1, bars[0, i:j], bars[1, i:j], bars[2, i:j])

    in_parts(part, u.size)
    return bars[0], bars[1], bars[2]
