"""Deflation of the near-rigid modes of floating solid islands, for the multigrid PCG of `design.fabrication.multigrid`.

A solid island that reaches the build plate only through void (E_min = 1e-4 E0, section 3.6) moves
almost as a rigid body: its six rigid-body modes have energies of order E_min, far below the rest
of the spectrum, and geometric coarse grids cannot represent them when the island is smaller than
a coarse cell. With Z the rigid-body modes of every island (6 columns per island, supported on the
island's nodes) and the small Galerkin matrix E = Z^T K Z, the balancing preconditioner
``P^T M P + Z E^-1 Z^T`` (P = I - K Z E^-1 Z^T, M the multigrid cycle) solves span(Z) exactly and
leaves the rest to M (rigid-body deflation spaces for high-contrast composites: Jönsthövel, van
Gijzen, Vuik et al., SIAM J. Sci. Comput. 35, 2013; the balancing form: Tang, Nabben, Vuik and
Erlangga, J. Sci. Comput. 39, 2009).

Islands are the face-connected components of stiff elements (modulus >= `ISLAND_MODULUS` E0) that
contain no element of the bottom row (on the plate). Elements that share only an edge or a corner
are hinged, not bonded, so they are separate islands; such a shared node carries the modes of
every island at it with a partition-of-unity weight (`rigid_modes`).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Callable

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from scipy import ndimage

log = logging.getLogger(__name__)

ISLAND_MODULUS = 0.02
"""Elements at least this stiff (E / E0; SIMP rho = 0.27) form islands, softer ones count as void.
Chosen within 0.001-0.4 for the fewest PCG iterations on `benchmarks/bench_ico.py`'s void field
(docs/benchmarks.md#incremental-compliance-term). A design grey everywhere is one cluster on the
plate: nothing to deflate."""


def floating_islands(e_mod: np.ndarray, threshold: float = ISLAND_MODULUS, faces_only: bool = True
                     ) -> tuple[np.ndarray, int]:
    """Label the stiff element clusters that do not stand on the plate.

    Parameters
    ----------
    e_mod : (nz, ny, nx) ndarray of float
        Element moduli E / E0, z = 0 the row on the build plate.
    threshold : float
        Modulus from which an element counts as solid.
    faces_only : bool
        Elements are connected through shared faces (True) or through any shared node.

    Returns
    -------
    labels : (nz, ny, nx) ndarray of int
        Island number 0 .. m - 1 of each element, -1 outside islands.
    m : int
        Number of islands.
    """
    structure = ndimage.generate_binary_structure(3, 1 if faces_only else 3)
    comp, n = ndimage.label(e_mod >= threshold, structure=structure)
    keep = np.ones(n + 1, dtype=bool)
    keep[0] = False
    keep[np.unique(comp[0])] = False  # components on the plate
    number = np.full(n + 1, -1)
    number[keep] = np.arange(int(keep.sum()))
    return number[comp], int(keep.sum())


def _node_pairs(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every (node, island) pair of an island element's node, sorted by node then island.

    Returns flattened node numbers (of the (nz + 1, ny + 1, nx + 1) node grid) and island numbers.
    """
    nz, ny, nx = labels.shape
    k, j, i = np.nonzero(labels >= 0)
    lab = labels[k, j, i]
    m = int(lab.max()) + 1
    keys = np.concatenate([((k + dk) * (ny + 1) + j + dj) * (nx + 1) + i + di
                           for dk in (0, 1) for dj in (0, 1) for di in (0, 1)]) * m + np.tile(lab, 8)
    keys = np.unique(keys)
    return keys // m, keys % m


def rigid_modes(nodes: np.ndarray, islands: np.ndarray, m: int, shape: tuple[int, int, int],
                h: tuple[float, float, float], free: np.ndarray) -> np.ndarray:
    """The six rigid-body modes of each island at its nodes, shared nodes weighted by a partition of unity.

    Parameters
    ----------
    nodes, islands : (P,) ndarrays of int
        (node, island) pairs from `_node_pairs`, sorted by node.
    m : int
        Number of islands.
    shape : (nz, ny, nx)
        Elements of the grid.
    h : (hz, hy, hx) floats
        Element edge lengths.
    free : (nz + 1, ny + 1, nx + 1, 3) ndarray of float
        1 on free dofs, 0 on constrained ones (mirror planes): modes are 0 on constrained dofs.

    Returns
    -------
    (P, 3, 6) ndarray of float
        Mode t of the pair's island at its node (x, y, z components): translations along x, y, z,
        then rotations about x, y, z through the island's centroid, scaled by the island's radius
        of gyration so that all six have the size of a translation. A node shared by islands
        that touch along an edge or a corner (a hinge) weights each by 1 / (their number): a
        motion rigid on each island and continuous at the hinges (a mechanism) is in the span.
    """
    nz, ny, nx = shape
    k, rest = np.divmod(nodes, (ny + 1) * (nx + 1))
    j, i = np.divmod(rest, nx + 1)
    xyz = np.stack([i * h[2], j * h[1], k * h[0]], axis=1)  # (x, y, z) coordinates
    count = np.bincount(islands, minlength=m)
    centre = np.stack([np.bincount(islands, xyz[:, c], minlength=m) for c in range(3)], axis=1) / count[:, None]
    d = xyz - centre[islands]
    radius = np.sqrt(np.bincount(islands, (d ** 2).sum(axis=1), minlength=m) / count)
    d /= radius[islands, None]
    modes = np.zeros((nodes.size, 3, 6))
    modes[:, [0, 1, 2], [0, 1, 2]] = 1.0
    modes[:, 1, 3], modes[:, 2, 3] = -d[:, 2], d[:, 1]  # about x: (0, -z, y)
    modes[:, 0, 4], modes[:, 2, 4] = d[:, 2], -d[:, 0]  # about y: (z, 0, -x)
    modes[:, 0, 5], modes[:, 1, 5] = -d[:, 1], d[:, 0]  # about z: (-y, x, 0)
    share = 1.0 / np.bincount(nodes)[nodes]
    return modes * (share[:, None] * free.reshape(-1, 3)[nodes])[:, :, None]


@numba.njit(cache=True, nogil=True)
def _stencil_times_modes(s, start, islands, modes, rows, cols, vals, fill):
    """Entries of K Z as COO triplets (row dof, column 6 island + t); returns their count.

    ``start[node] .. start[node + 1]`` index the node's (island, mode) pairs. With ``fill`` False
    only counts. Each node's row block gathers the stencil couplings to each island's nodes among
    its 27 neighbours.
    """
    nzn, nyn, nxn = s.shape[0], s.shape[1], s.shape[2]
    seen = np.empty(27 * 8, dtype=np.int64)
    acc = np.empty((27 * 8, 3, 6))
    count = 0
    for kn in range(nzn):
        for jn in range(nyn):
            for in_ in range(nxn):
                distinct = 0
                for q in range(27):
                    kk, jj, ii = kn + q // 9 - 1, jn + (q // 3) % 3 - 1, in_ + q % 3 - 1
                    if kk < 0 or kk >= nzn or jj < 0 or jj >= nyn or ii < 0 or ii >= nxn:
                        continue
                    other = (kk * nyn + jj) * nxn + ii
                    for pair in range(start[other], start[other + 1]):
                        lab = islands[pair]
                        slot = -1
                        for t in range(distinct):
                            if seen[t] == lab:
                                slot = t
                        if slot < 0:
                            slot = distinct
                            seen[slot] = lab
                            distinct += 1
                            acc[slot] = 0.0
                        if fill:
                            blk = s[kn, jn, in_, q]
                            z = modes[pair]
                            for c in range(3):
                                for t in range(6):
                                    acc[slot, c, t] += blk[c, 0] * z[0, t] + blk[c, 1] * z[1, t] + blk[c, 2] * z[2, t]
                if fill:
                    node = (kn * nyn + jn) * nxn + in_
                    for slot in range(distinct):
                        for c in range(3):
                            for t in range(6):
                                rows[count] = 3 * node + c
                                cols[count] = 6 * seen[slot] + t
                                vals[count] = acc[slot, c, t]
                                count += 1
                else:
                    count += 18 * distinct
    return count


@dataclass
class Deflation:
    """The deflation space of a grid's floating islands and its Galerkin matrix.

    Attributes
    ----------
    z : (n, 6 m) scipy.sparse.csr_matrix
        Rigid-body modes, n = 3 x nodes (dofs of a flattened nodal vector).
    kz : (n, 6 m) scipy.sparse.csr_matrix
        K Z (constrained rows and columns of K zero).
    islands : int
        m.
    """

    z: sp.csr_matrix
    kz: sp.csr_matrix
    islands: int

    def __post_init__(self) -> None:
        e = (self.z.T @ self.kz).tocsc()
        self._lu = sla.splu(0.5 * (e + e.T).tocsc())

    def precondition(self, r: np.ndarray, smooth: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """The balancing preconditioner ``P^T M P r + Z E^-1 Z^T r`` around ``M = smooth``.

        P = I - K Z E^-1 Z^T removes the deflation space from the residual before ``smooth``, and
        ``P^T`` removes it from the result; E^-1 solves it exactly. Symmetric positive definite
        when ``smooth`` is, so CG works from any start, and, unlike deflating the iteration itself
        (which stalled at a relative residual of 3e-11 and then diverged on a small test grid),
        round-off in the coarse space is corrected at every iteration (Tang, Nabben, Vuik and
        Erlangga, J. Sci. Comput. 39, 2009).
        """
        mu = self._lu.solve(self.z.T @ r.ravel())
        y = smooth((r.ravel() - self.kz @ mu).reshape(r.shape))
        nu = self._lu.solve(self.kz.T @ y.ravel())
        return y + (self.z @ (mu - nu)).reshape(r.shape)


def island_deflation(e_mod: np.ndarray, h: tuple[float, float, float], s: np.ndarray, free: np.ndarray
                     ) -> Deflation | None:
    """The deflation space of the floating islands of a grid, or None if it has none.

    Parameters
    ----------
    e_mod : (nz, ny, nx) ndarray of float
        Element moduli E / E0.
    h : (hz, hy, hx) floats
        Element edge lengths.
    s : (nz + 1, ny + 1, nx + 1, 27, 3, 3) ndarray of float
        The grid's operator as a nodal stencil, constraints applied (`design.fabrication.elasticity.stencil`).
    free : (nz + 1, ny + 1, nx + 1, 3) ndarray of float
        1 on free dofs, 0 on constrained ones.
    """
    labels, m = floating_islands(e_mod)
    if m == 0:
        return None
    nodes, islands = _node_pairs(labels)
    modes = rigid_modes(nodes, islands, m, e_mod.shape, h, free)
    n = free.size
    rows = (3 * nodes[:, None, None] + np.arange(3)[None, :, None]).repeat(6, axis=2)
    cols = (6 * islands[:, None, None] + np.arange(6)[None, None, :]).repeat(3, axis=1)
    z = sp.csr_matrix((modes.ravel(), (rows.ravel(), cols.ravel())), shape=(n, 6 * m))
    start = np.searchsorted(nodes, np.arange(n // 3 + 1))
    args = (s, start, islands, modes)
    size = _stencil_times_modes(*args, np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0), False)
    krows, kcols, kvals = np.empty(size, np.int64), np.empty(size, np.int64), np.empty(size)
    _stencil_times_modes(*args, krows, kcols, kvals, True)
    kz = sp.csr_matrix((kvals, (krows, kcols)), shape=(n, 6 * m))
    try:
        return Deflation(z, kz, m)
    except RuntimeError as exc:  # E singular: PCG still converges without deflation, only slower
        log.warning("island deflation skipped on grid %s (%d islands): %s", e_mod.shape, m, exc)
        return None
