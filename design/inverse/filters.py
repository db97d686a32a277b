"""Density filters of eq. (4): linear-decay smoothing and tanh threshold projection.

Both are differentiable maps with exact adjoints (vector-Jacobian products), so the
gradient of the objective with respect to the filtered density ``rho`` can be pulled
back to the design variables ``rho_hat``.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np
from scipy import fft as sfft

from design.errors import DesignError

MAX_RADIUS_VOX = 64.0
"""The largest smoothing radius the filter takes, voxels (a cone kernel of up to 127 voxels a side)."""


def fft_workers() -> int:
    """Threads for the smoothing FFTs: ``OMP_NUM_THREADS`` when the process is granted a count (a Dask
    worker's nanny sets it to 1, so that side-by-side designs do not oversubscribe the cores), else all
    cores (-1, scipy.fft's convention)."""
    try:
        return max(1, int(os.environ["OMP_NUM_THREADS"]))
    except (KeyError, ValueError):
        return -1


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


def _pad(x: np.ndarray, half: int, mirror: tuple[bool, ...]) -> np.ndarray:
    """Pad every axis by ``half``: reflected copy at a mirror plane (index-0 face), zeros elsewhere."""
    for ax, mir in enumerate(mirror):
        zeros_shape = list(x.shape)
        zeros_shape[ax] = half
        hi = np.zeros(zeros_shape)
        lo = np.flip(np.take(x, np.arange(half), axis=ax), axis=ax) if mir else np.zeros(zeros_shape)
        x = np.concatenate([lo, x, hi], axis=ax)
    return x


def _pad_adjoint(p: np.ndarray, half: int, mirror: tuple[bool, ...]) -> np.ndarray:
    """Adjoint of `_pad`: crop, and fold the reflected band back onto the voxels it copied."""
    for ax in reversed(range(len(mirror))):
        n = p.shape[ax] - 2 * half
        core = np.take(p, np.arange(half, half + n), axis=ax)
        if mirror[ax]:
            band = np.flip(np.take(p, np.arange(half), axis=ax), axis=ax)
            idx = [slice(None)] * p.ndim
            idx[ax] = slice(0, half)
            core[tuple(idx)] += band
        p = core
    return p


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
        object.__setattr__(self, "_weights", self._valid(_pad(np.ones(self.shape), half, self.mirror)))

    def _conv(self, x: np.ndarray) -> np.ndarray:
        workers = fft_workers()
        return sfft.irfftn(sfft.rfftn(x, self._fshape, workers=workers) * self._kernel_hat, self._fshape,
                           workers=workers)

    def _valid(self, padded: np.ndarray) -> np.ndarray:
        """'valid' convolution of a padded field, back on the original grid."""
        h = 2 * self._half
        return self._conv(padded)[tuple(slice(h, h + n) for n in self.shape)]

    def _valid_adjoint(self, y: np.ndarray) -> np.ndarray:
        """Adjoint of `_valid`: the 'full' convolution, on the padded grid."""
        return self._conv(y)[tuple(slice(0, n + 2 * self._half) for n in self.shape)]

    def apply(self, x: np.ndarray) -> np.ndarray:
        """Smoothed field ``(K * P x) / (K * P 1)``, same shape as ``x``."""
        return self._valid(_pad(x, self._half, self.mirror)) / self._weights

    def adjoint(self, g: np.ndarray) -> np.ndarray:
        """Vector-Jacobian product: gradient w.r.t. the input given ``g`` = gradient w.r.t. the output."""
        return _pad_adjoint(self._valid_adjoint(g / self._weights), self._half, self.mirror)


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
    # the clip only removes round-off (project(0) = -6e-17), the map itself stays in [0, 1]
    return np.clip((a + np.tanh(beta * (rho_tilde - eta))) / (a + b), 0.0, 1.0)


def project_adjoint(rho_tilde: np.ndarray, beta: float, g: np.ndarray, eta: float = 0.5) -> np.ndarray:
    """Vector-Jacobian product of `project`: ``g * d project / d rho_tilde``."""
    th = np.tanh(beta * (rho_tilde - eta))
    return g * beta * (1.0 - th * th) / (np.tanh(beta * eta) + np.tanh(beta * (1.0 - eta)))


def project_inverse(rho: float, beta: float) -> float:
    """The smoothed density that `project` maps to ``rho`` (used for uniform initialisation)."""
    t = np.tanh(beta / 2.0)
    return float(0.5 + np.arctanh(np.clip(2.0 * t * rho - t, -1 + 1e-15, 1 - 1e-15)) / beta)
