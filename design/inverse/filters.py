"""Density filters of eq. (4): linear-decay smoothing and tanh threshold projection.

Both are differentiable maps with exact adjoints (vector-Jacobian products), so the
gradient of the objective with respect to the filtered density ``rho`` can be pulled
back to the design variables ``rho_hat``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import fft as sfft

from design.errors import DesignError
from design.threads import in_parts, thread_count

MAX_RADIUS_VOX = 64.0
"""The largest smoothing radius the filter takes, voxels (a cone kernel of up to 127 voxels a side)."""


def cone_kernel(radius_vox: float, ndim: int) -> np.ndarray:
    """Linear-decay ("cone") kernel of Bruns and Tortorelli (2001), eq. (4)'s ``smooth``.

    Parameters
    ----------
    radius_vox : float
        Smoothing radius r in voxels; weights are ``max(0, r - |d|)``.
    ndim : int
        Number of grid dimensions (2 or 3).

    Returns
    -------
    (2h+1,)*ndim ndarray of float
        Unnormalised weights, ``h = ceil(r) - 1``.
    """
    half = int(np.ceil(radius_vox)) - 1
    axes = np.meshgrid(*([np.arange(-half, half + 1)] * ndim), indexing="ij")
    dist = np.sqrt(sum(a.astype(float) ** 2 for a in axes))
    return np.maximum(radius_vox - dist, 0.0)


def _pad(x: np.ndarray, half: int, mirror: tuple[bool, ...], shape: tuple[int, ...]) -> np.ndarray:
    """Pad every axis by ``half``: reflected copy at a mirror plane (index-0 face), zeros elsewhere; in the leading
    corner of a zero array of ``shape`` (at least the padded size: the FFT's, so that it needs no copy).

    Axis by axis, so that a corner band reflects the bands of the axes padded before it."""
    out = np.zeros(shape)
    padded = out[tuple(slice(0, n + 2 * half) for n in x.shape)]
    padded[tuple(slice(half, half + n) for n in x.shape)] = x
    for ax, mir in enumerate(mirror):
        if mir:
            padded[_band(ax, 0, half)] = np.flip(padded[_band(ax, half, 2 * half)], axis=ax)
    return out


def _pad_adjoint(p: np.ndarray, half: int, mirror: tuple[bool, ...]) -> np.ndarray:
    """Adjoint of `_pad` (overwrites ``p``): fold the reflected bands back onto the voxels they copied, last axis
    first, and crop."""
    for ax in reversed(range(len(mirror))):
        if mirror[ax]:
            p[_band(ax, half, 2 * half)] += np.flip(p[_band(ax, 0, half)], axis=ax)
    return np.ascontiguousarray(p[tuple(slice(half, n - half) for n in p.shape)])


def _band(axis: int, start: int, stop: int) -> tuple[slice, ...]:
    """Index of the slab ``start:stop`` of ``axis``, every index of the other axes."""
    return (slice(None),) * axis + (slice(start, stop),)


@dataclass(frozen=True)
class SmoothingFilter:
    """Normalised linear-decay smoothing on a fixed grid, mirror-aware (eq. 4).

    ``smooth(x) = (K * P x) / (K * P 1)`` where ``P`` pads with the reflected field at
    mirror planes (so the filter sees the full symmetric object) and with zeros at
    the outer domain faces, and ``K`` is the cone kernel; dividing by the filtered
    ones keeps a uniform field uniform.

    Parameters
    ----------
    shape : tuple of int
        Grid shape of the fields to filter (2D or 3D).
    radius_vox : float
        Smoothing radius r in voxels, >= 1 (r = 1 is the identity).
    mirror : tuple of bool
        Per axis, True when a mirror plane lies at the index-0 face.
    """

    shape: tuple[int, ...]
    radius_vox: float
    mirror: tuple[bool, ...]
    _half: int = field(init=False, repr=False)
    _fshape: tuple[int, ...] = field(init=False, repr=False)
    _kernel_hat: np.ndarray = field(init=False, repr=False)
    _weights: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if len(self.shape) not in (2, 3) or min(self.shape) < 1:
            raise DesignError(f"filter shape must be 2D or 3D with positive sizes, got {self.shape}")
        if not 1.0 <= self.radius_vox <= MAX_RADIUS_VOX:
            raise DesignError(f"smoothing radius must be in [1, {MAX_RADIUS_VOX:g}] voxels, got {self.radius_vox}")
        if len(self.mirror) != len(self.shape):
            raise DesignError(f"mirror needs one flag per axis of {self.shape}, got {self.mirror}")
        half = int(np.ceil(self.radius_vox)) - 1
        if any(m and half > n for m, n in zip(self.mirror, self.shape)):
            raise DesignError(f"smoothing radius {self.radius_vox} voxels exceeds the grid {self.shape}")
        kernel = cone_kernel(self.radius_vox, len(self.shape))
        # One FFT size >= the padded grid serves both the 'valid' convolution and its
        # 'full' adjoint without wrap-around (the kernel is symmetric, so K^T = K).
        fshape = tuple(sfft.next_fast_len(n + 2 * half, real=True) for n in self.shape)
        object.__setattr__(self, "_half", half)
        object.__setattr__(self, "_fshape", fshape)
        object.__setattr__(self, "_kernel_hat", sfft.rfftn(kernel, fshape))
        object.__setattr__(self, "_weights", self._valid(_pad(np.ones(self.shape), half, self.mirror, fshape)))

    def _conv(self, x: np.ndarray) -> np.ndarray:
        workers = thread_count()
        spectrum = sfft.rfftn(x, self._fshape, workers=workers)
        spectrum *= self._kernel_hat
        return sfft.irfftn(spectrum, self._fshape, workers=workers)

    def _valid(self, padded: np.ndarray) -> np.ndarray:
        """'valid' convolution of a padded field, back on the original grid."""
        h = 2 * self._half
        return self._conv(padded)[tuple(slice(h, h + n) for n in self.shape)]

    def _valid_adjoint(self, y: np.ndarray) -> np.ndarray:
        """Adjoint of `_valid`: the 'full' convolution, on the padded grid."""
        return self._conv(y)[tuple(slice(0, n + 2 * self._half) for n in self.shape)]

    def apply(self, x: np.ndarray) -> np.ndarray:
        """Smoothed field ``(K * P x) / (K * P 1)``, same shape as ``x``."""
        return self._valid(_pad(x, self._half, self.mirror, self._fshape)) / self._weights

    def adjoint(self, g: np.ndarray) -> np.ndarray:
        """Vector-Jacobian product: gradient w.r.t. the input given ``g`` = gradient w.r.t. the output."""
        y = np.zeros(self._fshape)  # zero-padded to the FFT's shape in place, so that it needs no copy
        np.divide(g, self._weights, out=y[tuple(slice(0, n) for n in self.shape)])
        return _pad_adjoint(self._valid_adjoint(y), self._half, self.mirror)


def project(rho_tilde: np.ndarray, beta: float, eta: float = 0.5) -> np.ndarray:
    """Threshold projection of Wang et al. (2011) (eq. 4 at eta = 1/2).

    The paper prints ``(tanh(b/2) - tanh(b(x - 1/2))) / (2 tanh(b/2))``, which maps 0 to 1;
    the sign in front of the second tanh is a typo, we use the increasing map of Wang et al.:
    ``(tanh(b eta) + tanh(b (x - eta))) / (tanh(b eta) + tanh(b (1 - eta)))``, so 0 -> 0,
    eta -> about 1/2, 1 -> 1. Thresholds other than 1/2 give the eroded (eta > 1/2) and dilated
    (eta < 1/2) designs of the robust formulation (`design.inverse.objective`).

    Parameters
    ----------
    rho_tilde : ndarray of float
        Smoothed density in [0, 1].
    beta : float
        Steepness, > 0.
    eta : float
        Threshold in (0, 1).
    """
    a, b = np.tanh(beta * eta), np.tanh(beta * (1.0 - eta))
    x = np.asarray(rho_tilde, dtype=np.float64)
    out = np.empty(x.shape)
    flat_x, flat_out = x.reshape(-1), out.reshape(-1)

    def part(i: int, j: int) -> None:  # (a + tanh(beta (x - eta))) / (a + b), in place
        o = flat_out[i:j]
        np.subtract(flat_x[i:j], eta, out=o)
        np.multiply(beta, o, out=o)
        np.tanh(o, out=o)
        np.add(a, o, out=o)
        np.divide(o, a + b, out=o)
        # the clip only removes round-off (project(0) = -6e-17), the map itself stays in [0, 1]
        np.clip(o, 0.0, 1.0, out=o)

    in_parts(part, x.size)
    return out


def project_adjoint(rho_tilde: np.ndarray, beta: float, g: np.ndarray, eta: float = 0.5) -> np.ndarray:
    """Vector-Jacobian product of `project`: ``g * d project / d rho_tilde``."""
    x, g = np.broadcast_arrays(np.asarray(rho_tilde, dtype=np.float64), np.asarray(g, dtype=np.float64))
    out = np.empty(x.shape)
    flat_x, flat_g, flat_out = x.reshape(-1), g.reshape(-1), out.reshape(-1)
    scale = np.tanh(beta * eta) + np.tanh(beta * (1.0 - eta))

    def part(i: int, j: int) -> None:  # g beta (1 - tanh(beta (x - eta))^2) / scale
        th = np.subtract(flat_x[i:j], eta)
        np.multiply(beta, th, out=th)
        np.tanh(th, out=th)
        np.multiply(th, th, out=th)
        np.subtract(1.0, th, out=th)
        o = flat_out[i:j]
        np.multiply(flat_g[i:j], beta, out=o)
        np.multiply(o, th, out=o)
        np.divide(o, scale, out=o)

    in_parts(part, x.size)
    return out


def project_inverse(rho: float, beta: float) -> float:
    """The smoothed density that `project` maps to ``rho`` (used for uniform initialisation)."""
    t = np.tanh(beta / 2.0)
    return float(0.5 + np.arctanh(np.clip(2.0 * t * rho - t, -1 + 1e-15, 1 - 1e-15)) / beta)
