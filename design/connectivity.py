"""One printable piece: a penalty on material that is reachable from the part's core or main body only through void.

The distance is measured from the part's core, the voxel where all mirror planes meet (index 0 of every
mirrored axis, the middle of the others), as long as the core lies in the part's main body or no body
has formed yet (the grey start design). The main body is the heaviest face-connected component of the
material (density >= `BODY_DENSITY`) that touches every mirror plane of the symmetric design: its
mirror copies join into one piece, and a connected symmetric part must touch each of its mirror planes
(a piece that misses a plane has its copy on the other side of it). When the core is not in the main
body (a part hollow at the centre, or a piece at the centre apart from the body), the body itself is
the seed.

A geodesic distance d from the core (or the body) is solved by the same fast marching as the release
(eq. 5, `design.fmm`) with the slowness

    s(rho) = 1 + (S_void - 1) (1 - rho)^2,

1 in solid and S_void in void, so a path through material is as long as it is, and a path that crosses
a void gap pays S_void - 1 extra per voxel of the gap; a seeding body's own voxels have d = 0. The
excess ``e`` measures how much a voxel's best path detours or crosses void: ``e = d - d0`` from the
core, with ``d0`` the distance when every voxel is solid, and ``e = d`` from the body. A voxel counts as
unreachable when its excess exceeds the allowance ``a = ALLOWANCE d0 + MARGIN_VOX dx`` (winding but
solid paths are free); S_void is chosen so that a single void voxel on the way exceeds the largest
allowance. The penalty is

    J_conn = sum_i rho_i^2 h(e_i / a_i) dx^3 m,    h(t) = (t - 1)_+^2 / (1 + (t - 1)_+^2),

bounded by the solid volume (h < 1), zero for a design whose material all connects to the body, and
smooth (C1) while the seeds stay the same. Its gradient is exact: the chain runs through the
fast-marching adjoint (eqs. 9-10); a seeding body is a fixed set for the derivative (its voxels'
slowness does not depend on rho).

Why both seeds. Measured from an empty core, all the material of a part hollow at the centre (a
zero-order shell, an extruded tube) would count as floating, and the penalty would act as a uniform
pressure on the mass; the body seeds those. Measured from the body alone, nothing would hold the
centre of a compact part solid, and extruded designs then open grey, later hollow, centres (a
through-hole at the centre ends the release early). A piece at the centre inside a hollow body (a ball
in a shell), or one that touches a mirror plane away from the body, is penalised either way.

Cost. The distance is solved on the density averaged over blocks of ``coarsen^D`` voxels (a
geodesic needs no more detail than the smoothing filter leaves: bridges are at least a filter radius
wide), so the extra solve costs about ``1 / coarsen^D`` of the release solve.

Seeding. The marcher (`design.fmm.march`) starts fronts from the grid's ordinary faces. The field is
flipped along its mirrored axes so that the core sits at the high corner and the mirror planes are the
high faces, every low face is declared a mirror (no front), and every high face gets one extra "gate"
layer of a large slowness that holds the fronts back, except for openings next to the seeds: the core,
or the body's voxels on the first mirror plane (the body's voxels themselves get the opening's
near-zero slowness, so the front fills the whole body at once).
"""
from __future__ import annotations

import logging

import numpy as np
from scipy import ndimage

from design.errors import DesignError
from design.fmm import MarchBuffers, march, march_adjoint

log = logging.getLogger(__name__)

ALLOWANCE = 0.5
"""Free detour of a solid path to the core, as a fraction of the straight (all-solid) distance."""
MARGIN_VOX = 2.0
"""Free excess distance next to the core, in (coarse) voxel edges."""
OPENING_SLOWNESS = 1e-6
"""Slowness of the gate voxels that let the front in next to the seeds, and of the body's voxels."""
BODY_DENSITY = 0.5
"""(Coarse) density from which a voxel belongs to the material whose components can be the main body."""


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
        self._core_unflipped = tuple(0 if m else n // 2 for n, m in zip(self.coarse_shape, self.mirror))
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

    def _distance(self, s: np.ndarray, gate: float, body: np.ndarray | None = None):
        """Geodesic distance from the seeds (``body``, else the core) for slowness ``s`` (coarse grid), and the solve."""
        n = np.full(tuple(k + 1 for k in self.coarse_shape), gate)
        inner = n[self._inner]  # a view
        inner[...] = np.flip(s, self._flips)
        if body is None:
            n[self._opening] = OPENING_SLOWNESS
        else:
            flipped = np.flip(body, self._flips)
            inner[flipped] = OPENING_SLOWNESS
            ax = self._flips[0]  # open the gate where the body touches this mirror plane (the high face)
            gate_layer = list(self._inner)
            gate_layer[ax] = self.coarse_shape[ax]
            n[tuple(gate_layer)][np.take(flipped, -1, axis=ax)] = OPENING_SLOWNESS
        marching = march(n, self.dx_mm, (True,) * len(self.shape), self._buffers)
        d = np.array(marching.interior(marching.u_pad)[self._inner])
        return np.flip(d, self._flips), marching

    def main_body(self, rho_coarse: np.ndarray) -> np.ndarray | None:
        """The main body of the module doc (bool mask of the coarse grid), or None when no component qualifies."""
        labels, count = ndimage.label(rho_coarse >= BODY_DENSITY)
        if count == 0:
            return None
        ids = np.arange(1, count + 1)
        touching = np.ones(count, dtype=bool)
        for ax in self._flips:
            on_plane = np.zeros(count + 1, dtype=bool)
            on_plane[np.unique(np.take(labels, 0, axis=ax))] = True
            touching &= on_plane[1:]
        if not touching.any():
            return None
        mass = ndimage.sum_labels(rho_coarse, labels, ids)
        return labels == ids[np.argmax(np.where(touching, mass, -1.0))]

    def seed_body(self, rho_coarse: np.ndarray) -> np.ndarray | None:
        """The main body when it seeds the distance (the core is not in it), else None (the core seeds it)."""
        body = self.main_body(rho_coarse)
        return None if body is None or body[self._core_unflipped] else body

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
        body = self.seed_body(rc)
        d, marching = self._distance(self.slowness(rc), gate=self._gate, body=body)
        t = (d - (0.0 if body is not None else self._d0)) / self._allow
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
        if body is not None:  # the seeds' slowness is fixed
            ds_drho[body] = 0.0
        g_coarse = 2.0 * rc * h * cell + n_bar * ds_drho
        return value, _pool_adjoint(g_coarse, c, self.shape)

    def distance(self, rho: np.ndarray) -> np.ndarray:
        """Geodesic distance of every coarse voxel from the main body (else the core), mm (for reports and tests)."""
        rc = _pool(rho, self.coarsen)
        return self._distance(self.slowness(rc), gate=self._gate, body=self.seed_body(rc))[0]
