"""Conjugate gradients preconditioned by one geometric multigrid cycle (`design.fabrication.elasticity` grids).

Hierarchy. Each coarser level halves every axis whose element count is even (an odd axis is kept,
so slabs of any height coarsen), until the grid has at most `MAX_COARSE_NODES` nodes or no axis
can be halved. Transfer is trilinear interpolation of nodal vectors (prolongation P) and its
transpose (restriction). Coarse operators are Galerkin, ``K_c = P^T K P``, built element by
element: fine elements nest in coarse ones and P restricted to a child element depends only on its
parent's nodes, so each coarse element matrix is ``sum_children P_c^T K_child P_c`` (24 x 24
each). Averaging the SIMP moduli instead (rediscretisation) lets the PCG iteration count grow with
the grid on high-contrast designs; Galerkin operators keep it flat. The coarsest level is
factorised (scipy sparse LU) and solved directly.

Cycle. On each level forward nodal block Gauss-Seidel sweeps (`SWEEPS` on the finest level,
`COARSE_SWEEPS` on coarser ones), the coarse correction, then as many backward sweeps. The coarse
correction is `CYCLE_INDEX` cycles of the next level (a W-cycle for 2), the direct solve on the
coarsest. Every part is symmetric, so the cycle is a symmetric operator, as PCG needs. On
high-contrast designs a V-cycle with one sweep lets the PCG iteration count grow with the grid:
the Galerkin operators of the deeper levels of the finer grid carry the contrast with less
accuracy, which a two-grid cycle with an exact solve on the second level does not suffer. The
W-cycle and the extra coarse sweeps, which cost little since coarse levels are small, close most of
that gap together with `design.fabrication.deflation`; the iteration counts of the variants on
`benchmarks/bench_ico.py`'s void field: docs/benchmarks.md#incremental-compliance-term. A K-cycle
(two coarse cycles combined by CG steps, a nonlinear preconditioner) is no better on large grids
and far worse on a small grid with floating islands and no deflation.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Callable

import numba
import numpy as np
import scipy.sparse.linalg as sla

from design.errors import DesignError
from design.fabrication.deflation import Deflation
from design.fabrication.elasticity import UNIFORM, apply_stencil, assemble, free_mask, gauss_seidel, hex8_stiffness, stencil

log = logging.getLogger(__name__)

MAX_COARSE_NODES = 400
"""Coarsening stops at or below this many nodes; that level is solved directly."""
SWEEPS = 1
"""Gauss-Seidel sweeps before (forward) and after (backward) the coarse correction, finest level."""
COARSE_SWEEPS = 2
"""The same on coarser levels."""
CYCLE_INDEX = 2
"""Cycles of the next level per coarse correction (1: V-cycle, 2: W-cycle)."""
PCG_TOL = 3e-4
"""Relative residual ``|f - K u| / |f|`` at which PCG stops: tight enough that J_fab and its gradient
match a 1e-10 solve to far below the coarsening error (`benchmarks/bench_ico.py`,
docs/benchmarks.md#incremental-compliance-term)."""


class Scratch:
    """Memory reused by hierarchies that one thread builds one after another.

    The first touch of freshly allocated pages is slow (the fine-level stencil of a 128^3 design
    is 137 MB): a hierarchy built with a scratch takes over the arrays of the previous one
    built with it, which must no longer be in use.
    """

    def __init__(self) -> None:
        self._buffers: dict[tuple[int, str], np.ndarray] = {}

    def array(self, key: tuple[int, str], shape: tuple[int, ...]) -> np.ndarray:
        """An uninitialised float array of ``shape``, the memory kept under ``key``."""
        n = int(np.prod(shape))
        buf = self._buffers.get(key)
        if buf is None or buf.size < n:
            buf = self._buffers[key] = np.empty(n)
        return buf[:n].reshape(shape)


def _array(scratch: Scratch | None, key: tuple[int, str], shape: tuple[int, ...]) -> np.ndarray:
    return np.empty(shape) if scratch is None else scratch.array(key, shape)


@dataclass
class Level:
    """One grid of the hierarchy.

    Attributes
    ----------
    e_mod : (nz, ny, nx) ndarray of float
        Element moduli (finest level; on coarse levels only its shape is used).
    ke : (24, 24) ndarray of float
        Reference element stiffness at unit modulus (finest level).
    kel : (nz, ny, nx, 24, 24) ndarray of float
        Galerkin element matrices on coarse levels; `design.fabrication.elasticity.UNIFORM` on the finest.
    free : (nz + 1, ny + 1, nx + 1, 3) ndarray of float
        1 on free dofs, 0 on constrained ones.
    factors : tuple of 3 int or None
        Coarsening factor (1 or 2) per axis to the next level; None on the coarsest.
    solve : callable or None
        Direct solve ``r -> K^-1 r`` (constrained entries 0), on the coarsest level only.
    scratch : Scratch or None
        Where the stencil's memory comes from (fresh arrays if None).
    depth : int
        Index of the level in its hierarchy (its key in ``scratch``).
    s, dinv : ndarrays
        The operator's nodal stencil and inverse diagonal blocks (`design.fabrication.elasticity.stencil`).
    work : ndarray
        Output buffer of `apply`.
    """

    e_mod: np.ndarray
    ke: np.ndarray
    kel: np.ndarray
    free: np.ndarray
    factors: tuple[int, int, int] | None = None
    solve: Callable[[np.ndarray], np.ndarray] | None = None
    scratch: "Scratch | None" = field(default=None, repr=False)
    depth: int = 0
    s: np.ndarray = field(init=False, repr=False)
    dinv: np.ndarray = field(init=False, repr=False)
    work: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        nodes = self.free.shape[:3]
        self.s = _array(self.scratch, (self.depth, "s"), nodes + (27, 3, 3))
        self.dinv = _array(self.scratch, (self.depth, "dinv"), nodes + (3, 3))
        stencil(self.e_mod, self.ke, self.kel, self.free, self.s, self.dinv)
        self.work = np.empty_like(self.free)

    def apply(self, u: np.ndarray) -> np.ndarray:
        """``free * (K u)`` into this level's work buffer (overwritten by the next call)."""
        apply_stencil(self.s, u, self.work)
        return self.work

    def smooth(self, u: np.ndarray, f: np.ndarray, forward: bool) -> None:
        """One nodal block Gauss-Seidel sweep on ``K u = f``, in place (backward: colours reversed)."""
        gauss_seidel(self.s, self.dinv, u, f, forward)


def _child_weights(factors: tuple[int, int, int]) -> np.ndarray:
    """(fz, fy, fx, 8, 8) trilinear weights from a coarse element's nodes (columns) to each child's (rows).

    Child ``(oz, oy, ox)``'s prolongation of dofs is ``kron(w[oz, oy, ox], eye(3))``; local node
    index ``4 dk + 2 dj + di``.
    """
    def weights(f: int, o: int) -> np.ndarray:  # (fine local node d, coarse local node b)
        t = (o + np.arange(2)) / f
        return np.stack([1.0 - t, t], axis=1)
    w = np.empty(tuple(factors) + (8, 8))
    for oz in range(factors[0]):
        for oy in range(factors[1]):
            for ox in range(factors[2]):
                wz, wy, wx = weights(factors[0], oz), weights(factors[1], oy), weights(factors[2], ox)
                w[oz, oy, ox] = np.einsum("kK,jJ,iI->kjiKJI", wz, wy, wx).reshape(8, 8)
    return w


@numba.njit(cache=True, nogil=True)
def _galerkin_general(kel, w, out):
    """``out[E] = sum_children P_c^T kel[child] P_c`` with P_c = kron(w_c, I3), skipping zero weights."""
    fz, fy, fx = w.shape[0], w.shape[1], w.shape[2]
    nzc, nyc, nxc = out.shape[0], out.shape[1], out.shape[2]
    t = np.empty((8, 8, 3, 3))
    for kc in range(nzc):
        for jc in range(nyc):
            for ic in range(nxc):
                res = out[kc, jc, ic]
                res[:] = 0.0
                for oz in range(fz):
                    for oy in range(fy):
                        for ox in range(fx):
                            child = kel[kc * fz + oz, jc * fy + oy, ic * fx + ox]
                            wc = w[oz, oy, ox]
                            t[:] = 0.0  # t[a, B] = sum_a' K[a, a'] w[a', B] (3 x 3 blocks)
                            for a in range(8):
                                for a2 in range(8):
                                    for b2 in range(8):
                                        wv = wc[a2, b2]
                                        if wv != 0.0:
                                            for x in range(3):
                                                for y in range(3):
                                                    t[a, b2, x, y] += child[3 * a + x, 3 * a2 + y] * wv
                            for a in range(8):
                                for b in range(8):
                                    wv = wc[a, b]
                                    if wv != 0.0:
                                        for b2 in range(8):
                                            for x in range(3):
                                                for y in range(3):
                                                    res[3 * b + x, 3 * b2 + y] += wv * t[a, b2, x, y]


def _galerkin(level: "Level", factors: tuple[int, int, int]) -> np.ndarray:
    """Coarse element matrices ``sum_children P_c^T K_child P_c`` of the next coarser grid."""
    nz, ny, nx = level.e_mod.shape
    fz, fy, fx = factors
    kel = _array(level.scratch, (level.depth + 1, "kel"), (nz // fz, ny // fy, nx // fx, 24, 24))
    w = _child_weights(factors)
    if level.kel.shape[0]:
        _galerkin_general(level.kel, w, kel)
        return kel
    kel[:] = 0.0
    for oz in range(fz):
        for oy in range(fy):
            for ox in range(fx):
                p = np.kron(w[oz, oy, ox], np.eye(3))
                kel += level.e_mod[oz::fz, oy::fy, ox::fx][..., None, None] * (p.T @ level.ke @ p)
    return kel


def hierarchy(e_mod: np.ndarray, h: tuple[float, float, float], nu: float, mirror_x: bool, mirror_y: bool,
              max_coarse_nodes: int = MAX_COARSE_NODES, scratch: Scratch | None = None) -> list[Level]:
    """The multigrid levels for element moduli ``e_mod`` (nz, ny, nx) of size ``h`` (hz, hy, hx).

    ``mirror_x`` / ``mirror_y`` put symmetry conditions on the x = 0 / y = 0 node planes; z = 0 is
    clamped. Coarsening stops at ``max_coarse_nodes`` nodes or fewer. With ``scratch`` the levels'
    large arrays reuse its memory (and an earlier hierarchy built with it becomes invalid).
    """
    level = Level(np.ascontiguousarray(e_mod), hex8_stiffness(h, nu), UNIFORM,
                  free_mask(e_mod.shape, mirror_x, mirror_y), scratch=scratch)
    levels = [level]
    while True:
        shape = level.e_mod.shape
        nodes = int(np.prod([n + 1 for n in shape]))
        factors = tuple(2 if n % 2 == 0 else 1 for n in shape)
        if nodes <= max_coarse_nodes or factors == (1, 1, 1):
            break
        level.factors = factors
        kel = _galerkin(level, factors)
        level = Level(np.empty(kel.shape[:3]), level.ke, kel, free_mask(kel.shape[:3], mirror_x, mirror_y),
                      scratch=scratch, depth=level.depth + 1)
        levels.append(level)
    coarse = levels[-1]
    free = coarse.free.ravel() > 0
    if not free.any():
        raise DesignError(f"elasticity grid {e_mod.shape} has no free degrees of freedom")
    lu = sla.splu(assemble(coarse.e_mod, coarse.ke, coarse.kel)[free][:, free].tocsc())

    def solve(r: np.ndarray, lu=lu, free=free) -> np.ndarray:
        x = np.zeros(r.size)
        x[free] = lu.solve(r.ravel()[free])
        return x.reshape(r.shape)

    coarse.solve = solve
    if nodes > 20 * max_coarse_nodes:
        log.warning("multigrid coarsest level %s has %d nodes: the direct solve dominates", shape, nodes)
    return levels


def _along(axis: int, sl: slice) -> tuple:
    return (slice(None),) * axis + (sl,)


def prolong(xc: np.ndarray, factors: tuple[int, int, int]) -> np.ndarray:
    """Trilinear interpolation of a coarse nodal vector (nz, ny, nx, 3) onto the next finer grid."""
    x = xc
    for axis, f in enumerate(factors):
        if f == 1:
            continue
        shape = list(x.shape)
        shape[axis] = 2 * x.shape[axis] - 1
        fine = np.empty(shape)
        fine[_along(axis, slice(0, None, 2))] = x
        fine[_along(axis, slice(1, None, 2))] = 0.5 * (x[_along(axis, slice(0, -1))] + x[_along(axis, slice(1, None))])
        x = fine
    return x


def restrict(xf: np.ndarray, factors: tuple[int, int, int]) -> np.ndarray:
    """Transpose of `prolong`: a fine residual (nodal vector) onto the next coarser grid."""
    x = xf
    for axis, f in enumerate(factors):
        if f == 1:
            continue
        odd = 0.5 * x[_along(axis, slice(1, None, 2))]
        coarse = x[_along(axis, slice(0, None, 2))].copy()
        coarse[_along(axis, slice(0, -1))] += odd
        coarse[_along(axis, slice(1, None))] += odd
        x = coarse
    return x


def cycle(levels: list[Level], r: np.ndarray, depth: int = 0) -> np.ndarray:
    """Approximate ``K^-1 r`` by one multigrid cycle from level ``depth`` (zero initial guess)."""
    lev = levels[depth]
    if lev.solve is not None:
        return lev.solve(r)
    sweeps = SWEEPS if depth == 0 else COARSE_SWEEPS
    x = np.zeros_like(r)
    for _ in range(sweeps):
        lev.smooth(x, r, True)
    rc = restrict(r - lev.apply(x), lev.factors) * levels[depth + 1].free
    xc = cycle(levels, rc, depth + 1)
    if levels[depth + 1].solve is None:  # the coarsest level's solve is exact: once is enough
        for _ in range(CYCLE_INDEX - 1):
            xc += cycle(levels, rc - levels[depth + 1].apply(xc), depth + 1)
    x += prolong(xc, lev.factors) * lev.free
    for _ in range(sweeps):
        lev.smooth(x, r, False)
    return x


@numba.njit(cache=True, nogil=True)
def _dot(a, b):
    """Plain serial dot product of two arrays of the same shape (threaded BLAS spins when the cores are busy)."""
    a, b = a.ravel(), b.ravel()
    s = 0.0
    for i in range(a.size):
        s += a[i] * b[i]
    return s


def pcg(levels: list[Level], f: np.ndarray, u0: np.ndarray | None = None, tol: float = PCG_TOL,
        max_iter: int = 500, deflation: Deflation | None = None) -> tuple[np.ndarray, int]:
    """Solve ``K u = f`` on the finest level by multigrid-preconditioned conjugate gradients.

    With ``deflation`` the cycle is balanced by its coarse space (`design.fabrication.deflation.Deflation.precondition`).

    Parameters
    ----------
    levels : list of Level
        From `hierarchy`.
    f : (nz + 1, ny + 1, nx + 1, 3) ndarray of float
        Nodal forces (constrained entries are ignored).
    u0 : same shape, optional
        Initial guess (warm start); zero if None.
    tol : float
        Relative residual to reach.
    max_iter : int
    deflation : Deflation, optional
        Near-null modes to deflate (`design.fabrication.deflation.island_deflation`).

    Returns
    -------
    u : same shape as f
        Displacements, 0 on constrained dofs.
    iterations : int
        PCG iterations used (0 when the initial guess already satisfies the tolerance).

    Raises
    ------
    DesignError
        If the tolerance is not reached in ``max_iter`` iterations.
    """
    fine = levels[0]
    f = f * fine.free
    norm_f = np.sqrt(_dot(f, f))
    u = np.zeros_like(f) if u0 is None else u0 * fine.free
    if norm_f == 0.0:
        return np.zeros_like(f), 0
    def precondition(r: np.ndarray) -> np.ndarray:
        return cycle(levels, r) if deflation is None else deflation.precondition(r, lambda x: cycle(levels, x))

    r = f - fine.apply(u)
    z = precondition(r)
    p = z.copy()
    rz = _dot(r, z)
    for it in range(max_iter + 1):
        if np.sqrt(_dot(r, r)) <= tol * norm_f:
            return u, it
        if it == max_iter:
            break
        q = fine.apply(p)
        alpha = rz / _dot(p, q)
        u += alpha * p
        r -= alpha * q
        z = precondition(r)
        rz_new = _dot(r, z)
        p *= rz_new / rz
        p += z
        rz = rz_new
    raise DesignError(f"multigrid PCG did not reach relative residual {tol:g} in {max_iter} iterations "
                      f"(reached {np.sqrt(_dot(r, r)) / norm_f:.3g}) on grid {fine.e_mod.shape}")
