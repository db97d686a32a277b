"""One printable piece: a penalty on material that is reachable from the part's root only through void.

A geodesic distance d from a seed voxel is solved by the same fast marching as the release (eq. 5,
`design.fmm`) with the slowness

    s(rho) = 1 + (S_void - 1) (1 - rho)^2,

1 in solid and S_void in void, so a path through material is as long as it is, and a path that crosses
a void gap pays S_void - 1 extra per voxel of the gap. With ``d0`` the distance when every voxel is
solid, the excess ``e = d - d0 >= 0`` measures how much a voxel's best path to the seed detours or
crosses void. A voxel counts as unreachable when its excess exceeds the allowance
``a = ALLOWANCE d0 + MARGIN_VOX dx`` (winding but solid paths are free); S_void is chosen so that a
single void voxel on the way exceeds the largest allowance from the core. Seen from seed k,

    J_k = sum_i rho_i^2 h(e_i / a_i) dx^3 m,    h(t) = (t - 1)_+^2 / (1 + (t - 1)_+^2),

is bounded by the solid volume (h < 1), zero for a design whose material all connects to the seed, and
smooth (C1). Its gradient is exact: the chain runs through the fast-marching adjoint (eqs. 9-10).

Seeds. The core is the voxel where all mirror planes meet (index 0 of every mirrored axis, the middle
of the others). A design connected to it touches every mirror plane, so its mirror copies join into one
piece, and a reduced piece that misses the core (the quadrant "pillar" of a four-piece design) is
penalised. A part hollow at the centre (a shell around a cavity, a ring) has nothing at the core, and
seen from there all of it would float. The seeds are therefore the core and the voxels of the axis
lines (where all mirror planes but one meet) running out from it, up to the first solid voxel of each
line, and the penalty is their Boltzmann-weighted mean

    J_conn = sum_k w_k J_k,    w_k = g_k exp(-J_k / T) / sum_j g_j exp(-J_j / T),

close to the smallest J_k (a seed in the main body) and smooth in rho; T is `TEMPERATURE` of the
domain's volume. The core's gate is g = 1. A line seed's gate

    g_k = S(rho_k; SOLID) (1 - S(rho_core; HOLLOW)) prod_j (1 - S(rho_j; SOLID)),

S(.; (a, b)) a smoothstep from a to b of the coarse density and j over the line's voxels nearer the core,
switches the seed on as its voxel becomes solid and off once a voxel nearer the core is solid, and
leaves the core alone unless it is empty: a grey core is no cavity but a channel that the printed
solid turns into a hole or fills (a grey pin-hole along the axis of an extruded design fits the
density's release and not the solid's), so the core holds it solid. Seeds with g = 0 are not solved:
their terms and derivatives vanish. A design with a core denser than ``HOLLOW[1]`` has a single seed,
the core.

A line seed lies on every mirror plane but one, p; its part joins its mirror copy across p only if it
reaches p. Its J_k adds ``V h((D - D0) / A)``: V = sum rho^2 dx^3 m, D the geodesic distance from the
seed to the voxels next to p, D0 its all-solid value and A = ``PLANE_ALLOWANCE D0 + MARGIN_VOX dx``
(a quarter arc around a cavity is 1.57 D0).

Cost. The distance is solved on the density averaged over blocks of ``coarsen^D`` voxels (a
geodesic needs no more detail than the smoothing filter leaves: bridges are at least a filter radius
wide), so one seed's solve costs about ``1 / coarsen^D`` of the release solve; a hollow part adds
a few seeds (the rising edge of its first wall on each axis line).

Marching. The marcher (`design.fmm.march`) starts fronts from the grid's ordinary faces. The field
is flipped along its mirrored axes so that the core sits at the high corner, every low face is
declared a mirror (no front), and every high face gets one extra "gate" layer of slowness that holds
the fronts back, except for a single opening next to the seed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from design.errors import DesignError
from design.fmm import MarchBuffers, march, march_adjoint

ALLOWANCE = 0.5
"""Free detour of a solid path to its seed, as a fraction of the straight (all-solid) distance."""
MARGIN_VOX = 2.0
"""Free excess distance next to a seed, in (coarse) voxel edges."""
OPENING_SLOWNESS = 1e-6
"""Slowness of the gate voxel that lets the front in next to a seed."""
PLANE_ALLOWANCE = 0.75
"""Free detour of a line seed's path to its open mirror plane, as a fraction of the straight distance."""
SOLID = (0.5, 0.9)
"""Coarse densities over which a voxel of an axis line turns from void to solid enough to root a part."""
HOLLOW = (0.05, 0.25)
"""Coarse densities of the core below which a part counts as hollow at the centre (line seeds act)."""
TEMPERATURE = 0.002
"""Temperature of the mean over seeds, as a fraction of the domain's volume."""


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


def _smoothstep(x: float, ramp: tuple[float, float]) -> tuple[float, float]:
    """S(x) rising from 0 at ``ramp[0]`` to 1 at ``ramp[1]`` (C1), and S'(x)."""
    lo, hi = ramp
    t = min(max((x - lo) / (hi - lo), 0.0), 1.0)
    return t * t * (3.0 - 2.0 * t), 6.0 * t * (1.0 - t) / (hi - lo)


def _over(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """h(t) of the module doc and h'(t)."""
    over = np.maximum(t - 1.0, 0.0)
    return over ** 2 / (1.0 + over ** 2), 2.0 * over / (1.0 + over ** 2) ** 2


@dataclass
class _Seed:
    """One seed in the flipped coarse frame, with its all-solid distances and allowances."""

    voxel: tuple[int, ...]
    opening: tuple[int, ...]
    plane_axis: int | None  # the mirror plane a line seed does not lie on (None: the core)
    buffers: MarchBuffers
    d0: np.ndarray
    allow: np.ndarray
    plane_d0: float = 0.0
    plane_allow: float = 1.0


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
        self._flips = tuple(ax for ax, m in enumerate(self.mirror) if m)
        self._gated = tuple(n + 1 for n in self.coarse_shape)
        self._inner = tuple(slice(0, n) for n in self.coarse_shape)
        # core in the flipped grid: high corner on mirrored axes, middle of the others
        self._core_voxel = tuple(n - 1 if m else n // 2 for n, m in zip(self.coarse_shape, self.mirror))
        # all solid: every path inside is shorter than the gate's 10 (1 + sum of the gated sizes) voxels
        self._solid_gate = 10.0 * (1.0 + sum(self._gated))
        self._seeds: dict[tuple[int | None, int], _Seed] = {}
        core = self._seed(None, 0)
        self._max_allow = float(core.allow.max())
        # one void voxel on a path must cost more than the largest allowance from the core
        self.s_void = 1.0 + 2.0 * self._max_allow / self.dx_mm
        self._gate = 10.0 * self.s_void * sum(self._gated)
        self._temperature_cells = TEMPERATURE * float(np.prod(self.coarse_shape))

    def _seed(self, axis: int | None, m: int) -> _Seed:
        """The seed ``m`` voxels from the core along mirrored ``axis`` (None, 0: the core), made once."""
        key = (axis, m)
        if key in self._seeds:
            return self._seeds[key]
        voxel = list(self._core_voxel)
        if axis is None:
            through = self._flips[0]
        else:
            voxel[axis] -= m
            through = next(ax for ax in self._flips if ax != axis)
        opening = list(voxel)
        opening[through] = self.coarse_shape[through]
        seed = _Seed(tuple(voxel), tuple(opening), axis, MarchBuffers(self._gated), np.empty(0), np.empty(0))
        seed.d0 = self._march(np.ones(self.coarse_shape), self._solid_gate, seed)[0]
        seed.allow = ALLOWANCE * seed.d0 + MARGIN_VOX * self.dx_mm
        if axis is not None:
            seed.plane_d0 = float(self._plane(seed.d0, axis).min())
            seed.plane_allow = min(PLANE_ALLOWANCE * seed.plane_d0 + MARGIN_VOX * self.dx_mm, self._max_allow)
        self._seeds[key] = seed
        return seed

    def _plane(self, field: np.ndarray, axis: int) -> np.ndarray:
        """The voxels of a flipped-frame field next to the mirror plane of ``axis``."""
        return np.take(field, self.coarse_shape[axis] - 1, axis=axis)

    def _march(self, s_flipped: np.ndarray, gate: float, seed: _Seed):
        """Geodesic distance from ``seed`` for slowness ``s_flipped`` (flipped coarse frame), and the solve."""
        n = np.full(self._gated, gate)
        n[self._inner] = s_flipped
        n[seed.opening] = OPENING_SLOWNESS
        marching = march(n, self.dx_mm, (True,) * len(self.shape), seed.buffers)
        return np.array(marching.interior(marching.u_pad)[self._inner]), marching

    def slowness(self, rho_coarse: np.ndarray) -> np.ndarray:
        """Geodesic slowness s(rho) of the module doc."""
        return 1.0 + (self.s_void - 1.0) * (1.0 - rho_coarse) ** 2

    def _gated_seeds(self, rf: np.ndarray) -> list[tuple[_Seed, float, list[tuple[tuple[int, ...], float]]]]:
        """Seeds with g > 0: (seed, g, [(voxel, dg/drho at that voxel)]) in the flipped frame."""
        core = self._seeds[(None, 0)]
        active = [(core, 1.0, [])]
        s_core, ds_core = _smoothstep(float(rf[core.voxel]), HOLLOW)
        if len(self._flips) < 2 or s_core >= 1.0:  # no axis lines, or the core roots the part
            return active
        for axis in self._flips:
            factors = [(core.voxel, s_core, ds_core)]  # (voxel, S, S') of the voxels nearer the core
            for m in range(1, self.coarse_shape[axis]):
                voxel = list(self._core_voxel)
                voxel[axis] -= m
                s_m, ds_m = _smoothstep(float(rf[tuple(voxel)]), SOLID)
                rest = float(np.prod([1.0 - f[1] for f in factors]))
                if s_m > 0.0 and rest > 0.0:
                    seed = self._seed(axis, m)
                    grads = [(seed.voxel, ds_m * rest)]
                    for j, (v, s_j, ds_j) in enumerate(factors):
                        others = float(np.prod([1.0 - f[1] for i, f in enumerate(factors) if i != j]))
                        grads.append((v, -s_m * ds_j * others))
                    active.append((seed, s_m * rest, grads))
                factors.append((tuple(voxel), s_m, ds_m))
                if s_m >= 1.0:
                    break
        return active

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
        rf = np.flip(_pool(rho, c), self._flips)
        s = self.slowness(rf)
        cell = cell_mm3 * c ** len(self.shape)
        volume = float(np.sum(rf ** 2)) * cell
        temperature = self._temperature_cells * cell
        terms = []  # per seed: J_k, g_k, dg_k, u_bar, direct dJ_k/drho, marching
        for seed, g, dg in self._gated_seeds(rf):
            d, marching = self._march(s, self._gate, seed)
            h, dh = _over((d - seed.d0) / seed.allow)
            value = float(np.sum(rf ** 2 * h)) * cell
            u_bar = rf ** 2 * dh / seed.allow * cell
            direct = 2.0 * rf * h * cell
            if seed.plane_axis is not None:
                face = self._plane(d, seed.plane_axis)
                at = np.unravel_index(int(np.argmin(face)), face.shape)
                hp, dhp = _over(np.array((float(face[at]) - seed.plane_d0) / seed.plane_allow))
                value += volume * float(hp)
                where = list(at)
                where.insert(seed.plane_axis, self.coarse_shape[seed.plane_axis] - 1)
                u_bar[tuple(where)] += volume * float(dhp) / seed.plane_allow
                direct = direct + 2.0 * rf * cell * float(hp)
            terms.append((value, g, dg, u_bar, direct, marching))
        values = np.array([t[0] for t in terms])
        gates = np.array([t[1] for t in terms])
        boltzmann = np.exp(-(values - values.min()) / temperature)
        z = float(np.sum(gates * boltzmann))
        weights = gates * boltzmann / z
        total = float(np.sum(weights * values))
        grad = np.zeros(self.coarse_shape)
        ds_drho = -2.0 * (self.s_void - 1.0) * (1.0 - rf)
        for (value, g, dg, u_bar, direct, marching), w, e in zip(terms, weights, boltzmann):
            coef = w * (1.0 - (value - total) / temperature)  # dJ_conn / dJ_k
            if coef != 0.0:
                padded = np.zeros(self._gated)
                padded[self._inner] = u_bar * coef
                grad += direct * coef + march_adjoint(marching, padded)[self._inner] * ds_drho
            for voxel, dg_drho in dg:  # dJ_conn / dg_k times dg_k / drho
                grad[voxel] += e * (value - total) / z * dg_drho
        return total, _pool_adjoint(np.flip(grad, self._flips), c, self.shape)

    def distance(self, rho: np.ndarray) -> np.ndarray:
        """Geodesic distance from the core of every coarse voxel, mm (for reports and tests)."""
        rf = np.flip(_pool(rho, self.coarsen), self._flips)
        d = self._march(self.slowness(rf), self._gate, self._seeds[(None, 0)])[0]
        return np.flip(d, self._flips)
