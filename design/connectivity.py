"""One printable piece: a penalty on material that is reachable from the design's core only through void.

The core is the voxel at the centre of the symmetric design, where all its mirror planes meet (index 0
of every mirrored axis, the middle of the others). A geodesic distance d from the core is solved by the
same fast marching as the release (eq. 5, `design.fmm`) with the slowness

    s(rho) = 1 + (S_void - 1) (1 - rho)^2,

1 in solid and S_void in void, so a path through material is as long as it is, and a path that crosses
a void gap pays S_void - 1 extra per voxel of the gap. With ``d0`` the distance when every voxel is
solid, the excess ``e = d - d0 >= 0`` measures how much a voxel's best path to the core detours or
crosses void. A voxel counts as unreachable when its excess exceeds the allowance
``a = ALLOWANCE d0 + MARGIN_VOX dx`` (winding but solid paths are free); S_void is chosen so that a
single void voxel on the way exceeds the largest allowance. The penalty is

    J_conn = sum_i rho_i^2 h(e_i / a_i) dx^3 m,    h(t) = (t - 1)_+^2 / (1 + (t - 1)_+^2),

bounded by the solid volume (h < 1), zero for a design whose material all connects to the core, and
smooth (C1). Its gradient is exact: the chain runs through the fast-marching adjoint (eqs. 9-10).

A design connected to the core touches every mirror plane, so its mirror copies join into one piece;
a reduced piece that misses the core (the quadrant "pillar" of a four-piece design) is penalised.

Cost. The distance is solved on the density averaged over blocks of ``coarsen^D`` voxels (a
geodesic needs no more detail than the smoothing filter leaves: bridges are at least a filter radius
wide), so the extra solve costs about ``1 / coarsen^D`` of the release solve.

Seeding. The marcher (`design.fmm.march`) starts fronts from the grid's ordinary faces. The field is
flipped along its mirrored axes so that the core sits at the high corner, every low face is declared a
mirror (no front), and every high face gets one extra "gate" layer of slowness `GATE` that holds the
fronts back, except for a single opening next to the core.
"""
from __future__ import annotations

import logging

import numpy as np

from design.errors import DesignError
from design.fmm import MarchBuffers, march, march_adjoint

log = logging.getLogger(__name__)

ALLOWANCE = 0.5
"""Free detour of a solid path to the core, as a fraction of the straight (all-solid) distance."""
MARGIN_VOX = 2.0
"""Free excess distance next to the core, in (coarse) voxel edges."""
OPENING_SLOWNESS = 1e-6
"""Slowness of the gate voxel that lets the front in next to the core."""


def _pool(x: np.ndarray, c: int) -> np.ndarray:
    """Mean over blocks of ``c`` voxels per axis, blocks starting at index 0; the high end is zero-padded."""
    if c == 1:
        return x
    pad = [(0, -n % c) for n in x.shape]
    x = np.pad(x, pad)
    shape = []
    for n in x.shape:
        shape += [n // c, c]
    return x.reshape(shape).mean(axis=tuple(range(1, 2 * x.ndim, 2)))


def _pool_adjoint(g: np.ndarray, c: int, shape: tuple[int, ...]) -> np.ndarray:
    """Adjoint of `_pool`: each block's gradient spread evenly over its voxels, cropped to ``shape``."""
    if c == 1:
        return g
    out = g / c ** g.ndim
    for ax in range(g.ndim):
        out = np.repeat(out, c, axis=ax)
    return out[tuple(slice(0, n) for n in shape)]


class Connectivity:
    """J_conn of the module doc on a fixed grid, with its exact gradient.

    Parameters
    ----------
    shape : tuple of int
        Grid of the densities it is given (2D or 3D): the design variables' grid.
    mirror : tuple of bool
        Mirror planes of that grid (index-0 faces); at least one.
    dx_mm : float
        Voxel edge, mm.
    coarsen : int
        Block edge of the averaging before the distance solve, voxels (>= 1).
    """

    def __init__(self, shape: tuple[int, ...], mirror: tuple[bool, ...], dx_mm: float, coarsen: int = 1) -> None:
        if len(shape) not in (2, 3) or len(mirror) != len(shape):
            raise DesignError(f"connectivity needs a 2D or 3D grid with one mirror flag per axis, got {shape}, "
                              f"{mirror}")
        if not any(mirror):
            raise DesignError("the connectivity penalty measures paths to the symmetry centre and needs at least "
                              "one mirror plane; allow pieces for this design space")
        if coarsen < 1 or not dx_mm > 0:
            raise DesignError(f"need coarsen >= 1 and dx > 0, got {coarsen}, {dx_mm}")
        self.shape = tuple(int(n) for n in shape)
        self.mirror = tuple(bool(m) for m in mirror)
        self.coarsen = int(coarsen)
        self.dx_mm = float(dx_mm) * self.coarsen
        self.coarse_shape = tuple(-(-n // self.coarsen) for n in self.shape)
        flips = tuple(ax for ax, m in enumerate(self.mirror) if m)
        self._flips = flips
        # core in the flipped grid: high corner on mirrored axes, middle of the others
        self._core = tuple(n - 1 if m else n // 2 for n, m in zip(self.coarse_shape, self.mirror))
        gated = tuple(n + 1 for n in self.coarse_shape)
        self._buffers = MarchBuffers(gated)
        self._inner = tuple(slice(0, n) for n in self.coarse_shape)
        opening = list(self._core)
        opening[flips[0]] = self.coarse_shape[flips[0]]
        self._opening = tuple(opening)
        # all solid: every path inside is shorter than the gate's 10 (1 + sum of the gated sizes) voxels
        d0 = self._distance(np.ones(self.coarse_shape), gate=10.0 * (1.0 + sum(gated)))[0]
        self._allow = ALLOWANCE * d0 + MARGIN_VOX * self.dx_mm
        # one void voxel on a path must cost more than the largest allowance
        self.s_void = 1.0 + 2.0 * float(self._allow.max()) / self.dx_mm
        self._gate = 10.0 * self.s_void * sum(gated)
        self._d0 = d0

    def _distance(self, s: np.ndarray, gate: float):
        """Geodesic distance from the core for slowness ``s`` (coarse grid), and the solve."""
        n = np.full(tuple(k + 1 for k in self.coarse_shape), gate)
        n[self._inner] = np.flip(s, self._flips)
        n[self._opening] = OPENING_SLOWNESS
        marching = march(n, self.dx_mm, (True,) * len(self.shape), self._buffers)
        d = np.array(marching.interior(marching.u_pad)[self._inner])
        return np.flip(d, self._flips), marching

    def slowness(self, rho_coarse: np.ndarray) -> np.ndarray:
        """Geodesic slowness s(rho) of the module doc."""
        return 1.0 + (self.s_void - 1.0) * (1.0 - rho_coarse) ** 2

    def __call__(self, rho: np.ndarray, cell_mm3: float) -> tuple[float, np.ndarray]:
        """J_conn and dJ_conn/drho.

        Parameters
        ----------
        rho : ndarray of float, ``shape``
            Projected density in [0, 1].
        cell_mm3 : float
            Volume one voxel of ``rho`` stands for (all its copies, in the objective's units), mm^3.

        Returns
        -------
        value : float
        grad : ndarray of float, ``shape``
        """
        c = self.coarsen
        rc = _pool(rho, c)
        d, marching = self._distance(self.slowness(rc), gate=self._gate)
        t = (d - self._d0) / self._allow
        over = np.maximum(t - 1.0, 0.0)
        h = over ** 2 / (1.0 + over ** 2)
        dh_dt = 2.0 * over / (1.0 + over ** 2) ** 2
        cell = cell_mm3 * c ** len(self.shape)
        value = float(np.sum(rc ** 2 * h) * cell)
        # adjoint: d/dd of sum rc^2 h(t) through the marcher (in the flipped, gated frame)
        u_bar = np.zeros(tuple(k + 1 for k in self.coarse_shape))
        u_bar[self._inner] = np.flip(rc ** 2 * dh_dt / self._allow * cell, self._flips)
        n_bar = np.flip(march_adjoint(marching, u_bar)[self._inner], self._flips)
        ds_drho = -2.0 * (self.s_void - 1.0) * (1.0 - rc)
        g_coarse = 2.0 * rc * h * cell + n_bar * ds_drho
        return value, _pool_adjoint(g_coarse, c, self.shape)

    def distance(self, rho: np.ndarray) -> np.ndarray:
        """Geodesic distance from the core of every coarse voxel, mm (for reports and tests)."""
        return self._distance(self.slowness(_pool(rho, self.coarsen)), gate=self._gate)[0]
