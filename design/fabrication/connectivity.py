"""One printable piece: a penalty on material that reaches the design's core or a mirror plane only through void.

The reduced design is one corner of a mirror-symmetric object. Its mirror copies join into one piece
when the reduced design is one piece that touches every mirror plane; a piece that misses a plane
(the quadrant "pillar" of a four-piece design, or one of two brackets facing each other across a
plane) stays apart from its copy across that plane.

Geodesic distances are solved by the same fast marching as the release (eq. 5, `design.forward.fmm`) with the
slowness

    s(rho) = 1 + (S_void - 1) (1 - rho)^2,

1 in solid and S_void in void, so a path through material is as long as it is, and a path that crosses
a void gap pays S_void - 1 extra per voxel of the gap. Each distance d starts from a seed: the core
(the voxel where all mirror planes meet: index 0 of every mirrored axis, the middle of the others),
and each mirror plane p. With ``d0`` the seed's distance when every voxel is solid, the excess
``e = d - d0 >= 0`` measures how much a voxel's best path to the seed detours or crosses void. A voxel
counts as unreachable when its excess exceeds the allowance ``a = allowance d0 + MARGIN_VOX dx``
(`CORE_ALLOWANCE`, `PLANE_ALLOWANCE`: winding but solid paths are free); S_void is chosen so that a
single void voxel on the way exceeds the largest allowance. With P mirror planes the penalty is

    J_conn = sum_i rho_i^2 [h(e_core,i / a_core,i) + (1/P) sum_p h(e_p,i / a_p,i)] dx^3 m + J_tail,
    h(t) = u^2 / (1 + u^2),   u = (t - 1)_+,

zero for a design whose material all connects to the core, about the volume of a floating piece for
each of the two parts, and smooth (C1). Its gradient is exact: the chain runs through the
fast-marching adjoint (eqs. 9-10). The core term holds a compact part's centre solid; the plane term
keeps guiding when the centre is void (a ring, a tube, a shell), where every voxel is far from the
core and the core term is a uniform pressure on the mass without a direction
(docs/design.md#one-printable-piece).

Tail. h is bounded, so it saturates for a piece far beyond its allowance and gives no direction
there. The plane term supplies one for a piece that misses a plane, but not for pieces that each
touch every plane: a frame around a cross, a ring around a pin. For them the tail

    J_tail = k sum_i rho_i^2 (sqrt(1 + v_i^2) - 1) dx^3 m,   v_i = ((e_core,i - e_core,*) / a_core,i - 1)_+,

grows with the gap (slope k, `TAIL_SLOPE`, per allowance), so shortening the path (a bridge) always
lowers it. Excess is measured from e_core,* at the innermost solid voxel (the solid coarse voxel of
least core excess; block density at least `SOLID_LEVEL`): a hollow part in one piece (a ring whose
centre is void) is all at about the same excess and pays no tail, so the tail adds no pressure to close
its hole. The reference voxel changes only when the solid set does, so the gradient is exact between
such changes, as the marcher's is between changes of its upwind choices.

Cost. The distances are solved on the density averaged over blocks of ``coarsen^D`` voxels (a
geodesic needs no more detail than the smoothing filter leaves: bridges are at least a filter radius
wide), so each solve costs about ``1 / coarsen^D`` of the release solve (`block_edge`: half the radius).

Seeding. The marcher (`design.forward.fmm.march`) starts fronts from the grid's ordinary faces. The field is
flipped along its mirrored axes so that the mirror planes sit at the high faces, every low face is
declared a mirror (no front), and every high face gets one extra "gate" layer whose slowness holds the
fronts back, except for the seed's opening: one gate voxel next to the core, or the layer beyond
plane p's face.
"""
from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from design.errors import DesignError
from design.forward.fmm import MarchBuffers, march, march_adjoint
from design.threads import cores

CORE_ALLOWANCE = 0.5
"""Free detour of a solid path to the core, as a fraction of the straight (all-solid) distance."""
PLANE_ALLOWANCE = 1.0
"""Free detour of a solid path to a mirror plane, as a fraction of the straight distance (along a
quarter ring from one plane to the other the path is pi/2 times the straight distance)."""
MARGIN_VOX = 2.0
"""Free excess distance next to a seed, in (coarse) voxel edges."""
TAIL_SLOPE = 0.01
"""Slope k of the tail J_tail far beyond the allowance, per allowance (module doc); 0 = no tail."""
SOLID_LEVEL = 0.5
"""Block-averaged density from which a coarse voxel counts as solid for the tail's reference."""
OPENING_SLOWNESS = 1e-6
"""Slowness of the gate voxels that let the front in at a seed."""
SEED_WORKERS = min(4, cores())
"""Threads that solve the seeds' distances at the same time (`Connectivity.submit`): the cores this process may
use, at most 4 (one per seed of a 3D design with three mirror planes). The result does not depend on it."""

BLOCK_PER_RADIUS = 0.5
"""Block edge of the distance grid per smoothing radius in 3D (`block_edge`)."""


def block_edge(radius_vox: float, ndim: int) -> int:
    """The block edge of J_conn's distance grid for a smoothing radius, voxels (the ``coarsen`` of `Connectivity`).

    In 3D half the radius, rounded to the nearest whole voxel (at least 1): a bridge is at least a radius wide, so a
    block of half of it still sees every one, and the four distance solves of a 3D design cost ``1 / coarsen^3`` of
    the release's each (at resolution 128, radius 3.7 voxels: blocks of 2, each solve an eighth of the release's). In
    2D half the radius rounded down: the solves cost N^2 beside the release's N^3, so the full detail is kept.

    Parameters
    ----------
    radius_vox : float
        Smoothing radius, voxels of the design grid.
    ndim : int
        Dimensions of the design variables' grid (2 or 3).

    Returns
    -------
    int

    Examples
    --------
    >>> block_edge(3.69, 3), block_edge(3.69, 2), block_edge(1.85, 3)
    (2, 1, 1)
    """
    half = BLOCK_PER_RADIUS * radius_vox
    return max(1, int(np.floor(half + 0.5)) if ndim == 3 else int(np.floor(half)))


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
        Block edge of the averaging before the distance solves, voxels (>= 1).
    planes : bool
        Add the plane term; False = the core term alone (runs stored before the plane term).
    tail_slope : float
        Slope k of the tail J_tail (>= 0; 0 = no tail, as runs stored before it).
    """

    def __init__(self, shape: tuple[int, ...], mirror: tuple[bool, ...], dx_mm: float, coarsen: int = 1,
                 planes: bool = True, tail_slope: float = TAIL_SLOPE) -> None:
        if len(shape) not in (2, 3) or len(mirror) != len(shape):
            raise DesignError(f"connectivity needs a 2D or 3D grid with one mirror flag per axis, got {shape}, "
                              f"{mirror}")
        if not any(mirror):
            raise DesignError("the connectivity penalty measures paths to the symmetry centre and needs at least "
                              "one mirror plane; allow pieces for this design space")
        if coarsen < 1 or not dx_mm > 0 or not tail_slope >= 0:
            raise DesignError(f"need coarsen >= 1, dx > 0 and tail_slope >= 0, got {coarsen}, {dx_mm}, {tail_slope}")
        self.tail_slope = float(tail_slope)
        self.shape = tuple(int(n) for n in shape)
        self.mirror = tuple(bool(m) for m in mirror)
        self.coarsen = int(coarsen)
        self.dx_mm = float(dx_mm) * self.coarsen
        self.coarse_shape = tuple(-(-n // self.coarsen) for n in self.shape)
        self._flips = tuple(ax for ax, m in enumerate(self.mirror) if m)
        gated = tuple(n + 1 for n in self.coarse_shape)
        self._inner = tuple(slice(0, n) for n in self.coarse_shape)
        # seeds in the flipped, gated frame: the gate voxel next to the core (high corner on mirrored
        # axes, middle of the others), then each plane's whole gate layer; with their weights and allowances
        core = [n - 1 if m else n // 2 for n, m in zip(self.coarse_shape, self.mirror)]
        core[self._flips[0]] = self.coarse_shape[self._flips[0]]
        faces = [tuple(n if ax == p else slice(0, n) for ax, n in enumerate(self.coarse_shape)) for p in self._flips]
        faces = faces if planes else []
        self._openings = [tuple(core)] + faces
        self._weights = [1.0] + [1.0 / len(faces) for _ in faces]
        self._buffers = [MarchBuffers(gated) for _ in self._openings]  # one per seed: the seeds solve in parallel
        self._pool: ThreadPoolExecutor | None = None
        # all solid: every path inside is shorter than the gate's 10 (1 + sum of the gated sizes) voxels
        solid = np.ones(self.coarse_shape)
        self._d0 = [self._distance(solid, opening, gate=10.0 * (1.0 + sum(gated)))[0] for opening in self._openings]
        allowances = [CORE_ALLOWANCE] + [PLANE_ALLOWANCE] * len(faces)
        self._allow = [f * d0 + MARGIN_VOX * self.dx_mm for f, d0 in zip(allowances, self._d0)]
        # one void voxel on a path must cost more than the largest allowance
        self.s_void = 1.0 + 2.0 * max(float(a.max()) for a in self._allow) / self.dx_mm
        self._gate = 10.0 * self.s_void * sum(gated)

    def _distance(self, s: np.ndarray, opening: tuple, gate: float, buffers: MarchBuffers | None = None):
        """Geodesic distance from one seed for slowness ``s`` (coarse grid), and the solve (on ``buffers``, default
        the first seed's)."""
        n = np.full(tuple(k + 1 for k in self.coarse_shape), gate)
        n[self._inner] = np.flip(s, self._flips)
        n[opening] = OPENING_SLOWNESS
        marching = march(n, self.dx_mm, (True,) * len(self.shape), buffers or self._buffers[0])
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
        return self.submit(rho, cell_mm3).result()

    def submit(self, rho: np.ndarray, cell_mm3: float) -> "PendingConnectivity":
        """Start J_conn and its gradient (as `__call__`) in the worker threads and return at once: one seed's
        distance solve and adjoint per task, `SEED_WORKERS` at a time (the marcher releases the GIL), so that the
        caller can solve the release meanwhile. ``rho`` must not change until the result is taken."""
        c = self.coarsen
        rc = _pool(rho, c)
        s = self.slowness(rc)
        cell = cell_mm3 * c ** len(self.shape)
        if self._pool is not None:  # a call whose result was never taken (its caller raised) still holds the buffers
            self._pool.shutdown(wait=True)
        # threads of this call only, joined when its result is taken: no thread outlives an evaluation (a process
        # that forks afterwards copies no worker holding a lock)
        self._pool = ThreadPoolExecutor(max_workers=min(SEED_WORKERS, len(self._openings)),
                                        thread_name_prefix="connectivity")
        tasks = [self._pool.submit(self._seed, seed, rc, s, cell) for seed in range(len(self._openings))]
        self._pool.shutdown(wait=False)
        return PendingConnectivity(self, rc, cell, tasks, self._pool)

    def _seed(self, seed: int, rc: np.ndarray, s: np.ndarray, cell: float):
        """One seed's part of J_conn: its weighted h, its tail (the core's; value, gradient by rc) and its share of
        dJ/ds through its solve's adjoint (flipped, gated frame), on its own marcher buffers."""
        opening, weight, d0, allow = self._openings[seed], self._weights[seed], self._d0[seed], self._allow[seed]
        d, marching = self._distance(s, opening, gate=self._gate, buffers=self._buffers[seed])
        over = np.maximum((d - d0) / allow - 1.0, 0.0)
        h = weight * over ** 2 / (1.0 + over ** 2)
        dh_dt = 2.0 * over / (1.0 + over ** 2) ** 2
        e_bar = rc ** 2 * dh_dt / allow * weight * cell
        tail = None
        if seed == 0 and self.tail_slope > 0:
            value, tail_e_bar, tail_rc_bar = self._tail(rc, d - d0, allow)
            tail = (value * cell, tail_rc_bar * cell)
            e_bar = e_bar + tail_e_bar * cell
        u_bar = np.zeros(tuple(k + 1 for k in self.coarse_shape))
        u_bar[self._inner] = np.flip(e_bar, self._flips)
        return h, tail, np.flip(march_adjoint(marching, u_bar)[self._inner], self._flips)

    def _tail(self, rc: np.ndarray, excess: np.ndarray, allow: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """The core term's tail (module doc) per unit cell volume, and its partial derivatives by the
        excess and by the coarse density."""
        solid = rc >= SOLID_LEVEL
        if not solid.any():
            return 0.0, np.zeros_like(rc), np.zeros_like(rc)
        inner = np.unravel_index(np.argmin(np.where(solid, excess, np.inf)), rc.shape)
        over = np.maximum((excess - excess[inner]) / allow - 1.0, 0.0)
        root = np.sqrt(1.0 + over ** 2)
        k = self.tail_slope
        value = k * float(np.sum(rc ** 2 * (root - 1.0)))
        e_bar = k * rc ** 2 * over / root / allow
        e_bar[inner] -= e_bar.sum()  # every excess is measured from the innermost solid voxel's
        return value, e_bar, 2.0 * rc * k * (root - 1.0)

    def distance(self, rho: np.ndarray) -> np.ndarray:
        """Geodesic distance of every coarse voxel from each seed (the core, then each mirror plane), mm:
        shape (1 + planes, *coarse_shape)."""
        s = self.slowness(_pool(rho, self.coarsen))
        return np.stack([self._distance(s, opening, gate=self._gate)[0] for opening in self._openings])


class PendingConnectivity:
    """J_conn being computed in the worker threads (`Connectivity.submit`); `result` waits for it."""

    def __init__(self, term: Connectivity, rc: np.ndarray, cell: float, tasks: list[Future],
                 pool: ThreadPoolExecutor) -> None:
        self.term, self.rc, self.cell, self.tasks, self.pool = term, rc, cell, tasks, pool

    def result(self) -> tuple[float, np.ndarray]:
        """J_conn and dJ_conn/drho, as `Connectivity.__call__` returns them: the seeds' parts summed in seed order,
        so the sums do not depend on which thread finished first."""
        term, rc = self.term, self.rc
        h_sum = np.zeros(term.coarse_shape)  # sum over the seeds of weight * h
        value_tail, g_tail = 0.0, np.zeros(term.coarse_shape)
        s_bar = np.zeros(term.coarse_shape)
        for task in self.tasks:
            h, tail, s_bar_seed = task.result()
            h_sum += h
            if tail is not None:
                value_tail += tail[0]
                g_tail += tail[1]
            s_bar += s_bar_seed
        self.pool.shutdown(wait=True)  # every task is done: its threads end now
        value = float(np.sum(rc ** 2 * h_sum) * self.cell) + value_tail
        ds_drho = -2.0 * (term.s_void - 1.0) * (1.0 - rc)
        g_coarse = 2.0 * rc * h_sum * self.cell + s_bar * ds_drho + g_tail
        return value, _pool_adjoint(g_coarse, term.coarsen, term.shape)
