"""Linear elasticity on a voxel grid: trilinear hexahedra, SIMP/RAMP moduli, self-weight load.

Used by the incremental-compliance term of section 3.6 (`design.fabrication.ico`). One 8-node (trilinear)
box element per grid cell, all cells of a grid the same size, so one reference stiffness ``Ke``
(Young's modulus 1) scaled by each element's modulus ``E_e`` gives every element matrix.

Layout. Arrays here are ordered (z, y, x) with z the slowest axis, so that the elements below a
height are a leading, contiguous slab: element moduli ``(nz, ny, nx)``, nodal vectors
``(nz + 1, ny + 1, nx + 1, 3)`` whose last axis holds the (x, y, z) components. Element-local
node ``a = di + 2 dj + 4 dk`` sits at node ``(k + dk, j + dj, i + di)``; its dofs are ``3 a + c``.

Boundary conditions. The nodes of the plane z = 0 (the build plate) are clamped. A mirror plane
through the x = 0 (y = 0) nodes has the symmetry condition u_x = 0 (u_y = 0) there, the tangential
components free. Constrained dofs are carried as zeros: ``free`` is 1 on free dofs, 0 on
constrained ones, and every operator here multiplies its result by it.

The operator is stored per node as a 27-point stencil of 3x3 blocks, assembled once per grid from
the element matrices; numba kernels apply it, smooth with it (nodal block Gauss-Seidel) and
compute element energies.
`assemble` builds the same matrix in scipy for direct solves.
"""
from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp

from design.errors import DesignError

POISSON_RATIO = 0.3
"""Poisson's ratio of the printed material (a typical value for printed thermoplastics)."""
E_MIN_RATIO = 1e-4
"""Void stiffness as a fraction of the solid's, E_min / E0 (section 3.6)."""
SIMP_P = 3.0
"""SIMP penalisation exponent p (section 3.6)."""
RAMP_Q = 3.0
"""RAMP penalisation parameter q."""
LAWS = ("simp", "ramp")

_GAUSS = np.array([-1.0, 1.0]) / np.sqrt(3.0)


def hex8_stiffness(h: tuple[float, float, float], nu: float = POISSON_RATIO) -> np.ndarray:
    """Stiffness matrix of a trilinear box element with Young's modulus 1 (2x2x2 Gauss rule).

    Parameters
    ----------
    h : (hz, hy, hx) floats
        Element edge lengths along z, y, x (any consistent length unit).
    nu : float
        Poisson's ratio, in (-1, 0.5).

    Returns
    -------
    (24, 24) ndarray of float
        Symmetric, dof ``3 a + c`` for local node a and component c (x, y, z).
    """
    if not -1.0 < nu < 0.5:
        raise DesignError(f"Poisson's ratio must be in (-1, 0.5), got {nu}")
    hz, hy, hx = (float(v) for v in h)
    lam = nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = 1.0 / (2.0 * (1.0 + nu))
    d = np.zeros((6, 6))
    d[:3, :3] = lam
    d[np.arange(3), np.arange(3)] += 2.0 * mu
    d[np.arange(3, 6), np.arange(3, 6)] = mu
    signs = np.array([[2 * (a & 1) - 1, 2 * ((a >> 1) & 1) - 1, 2 * ((a >> 2) & 1) - 1] for a in range(8)], float)
    ke = np.zeros((24, 24))
    for gx in _GAUSS:
        for gy in _GAUSS:
            for gz in _GAUSS:
                xi = np.array([gx, gy, gz])
                # dN_a/dx_c = s_ac / (4 h_c) prod_{c' != c} (1 + s_ac' xi_c') / 2 ... on [-1, 1]^3 with jacobian h/2
                one = 1.0 + signs * xi  # (8, 3)
                dn = np.empty((8, 3))
                for c, hc in enumerate((hx, hy, hz)):
                    others = [o for o in range(3) if o != c]
                    dn[:, c] = signs[:, c] * one[:, others[0]] * one[:, others[1]] / 8.0 * (2.0 / hc)
                b = np.zeros((6, 24))
                for a in range(8):
                    nx_, ny_, nz_ = dn[a]
                    b[0, 3 * a], b[1, 3 * a + 1], b[2, 3 * a + 2] = nx_, ny_, nz_
                    b[3, 3 * a + 1], b[3, 3 * a + 2] = nz_, ny_  # gamma_yz
                    b[4, 3 * a], b[4, 3 * a + 2] = nz_, nx_  # gamma_xz
                    b[5, 3 * a], b[5, 3 * a + 1] = ny_, nx_  # gamma_xy
                ke += b.T @ d @ b * (hx * hy * hz / 8.0)
    return 0.5 * (ke + ke.T)


def modulus(rho: np.ndarray, law: str = "simp", e_min: float = E_MIN_RATIO) -> tuple[np.ndarray, np.ndarray]:
    """Young's modulus E(rho) / E0 and its derivative.

    SIMP: ``E = E_min + rho^p (1 - E_min)``, p = `SIMP_P` (section 3.6).
    RAMP: ``E = E_min + rho / (1 + q (1 - rho)) (1 - E_min)``, q = `RAMP_Q`.
    """
    if law == "simp":
        return e_min + rho ** SIMP_P * (1.0 - e_min), SIMP_P * rho ** (SIMP_P - 1.0) * (1.0 - e_min)
    if law == "ramp":
        den = 1.0 + RAMP_Q * (1.0 - rho)
        return e_min + rho / den * (1.0 - e_min), (1.0 + RAMP_Q) / den ** 2 * (1.0 - e_min)
    raise DesignError(f"stiffness law must be one of {LAWS}, got {law!r}")


def free_mask(shape: tuple[int, int, int], mirror_x: bool, mirror_y: bool) -> np.ndarray:
    """1 on free dofs, 0 on constrained ones, for a grid of ``(nz, ny, nx)`` elements.

    Returns
    -------
    (nz + 1, ny + 1, nx + 1, 3) ndarray of float
    """
    nz, ny, nx = shape
    free = np.ones((nz + 1, ny + 1, nx + 1, 3))
    free[0] = 0.0  # build plate: clamped
    if mirror_x:
        free[:, :, 0, 0] = 0.0
    if mirror_y:
        free[:, 0, :, 1] = 0.0
    return free


def self_weight(load: np.ndarray, volume: float) -> np.ndarray:
    """Consistent nodal forces of a body force along -z, constant per element.

    Parameters
    ----------
    load : (nz, ny, nx) ndarray of float
        Body force per unit volume of each element (e.g. rho times the specific weight).
    volume : float
        Element volume.

    Returns
    -------
    (nz + 1, ny + 1, nx + 1, 3) ndarray of float
        Each element gives 1/8 of its weight to each of its nodes (trilinear shape functions).
    """
    nz, ny, nx = load.shape
    f = np.zeros((nz + 1, ny + 1, nx + 1, 3))
    share = -load * (volume / 8.0)
    for dk in (0, 1):
        for dj in (0, 1):
            for di in (0, 1):
                f[dk:dk + nz, dj:dj + ny, di:di + nx, 2] += share
    return f


def self_weight_adjoint(u: np.ndarray, shape: tuple[int, int, int], volume: float) -> np.ndarray:
    """``d(f . u) / d load`` for `self_weight`: minus the mean z displacement of each element's nodes."""
    nz, ny, nx = shape
    acc = np.zeros(shape)
    for dk in (0, 1):
        for dj in (0, 1):
            for di in (0, 1):
                acc += u[dk:dk + nz, dj:dj + ny, di:di + nx, 2]
    return -acc * (volume / 8.0)


@numba.njit(cache=True, nogil=True)
def _gather(u, k, j, i, ue):
    for a in range(8):
        kk, jj, ii = k + (a >> 2), j + ((a >> 1) & 1), i + (a & 1)
        for c in range(3):
            ue[3 * a + c] = u[kk, jj, ii, c]


UNIFORM = np.zeros((0, 0, 0, 24, 24))
"""The ``kel`` argument of `stencil` when every element matrix is ``e_mod[e] * ke``."""


@numba.njit(cache=True, nogil=True)
def stencil(e_mod, ke, kel, free, s, dinv):
    """The operator as a per-node 27-point stencil of 3x3 blocks, constraints applied, into ``s``, ``dinv``.

    Element e's matrix is ``e_mod[e] * ke`` when ``kel`` is `UNIFORM`, else ``kel[e]``
    (nz, ny, nx, 24, 24) with ``e_mod`` ignored (Galerkin coarse levels, `design.fabrication.multigrid`).

    Parameters
    ----------
    s : (nz + 1, ny + 1, nx + 1, 27, 3, 3) ndarray of float, overwritten
        ``s[n, q]`` couples node n to its neighbour n + (dk, dj, di), q = 9 (dk + 1) + 3 (dj + 1) + di + 1;
        rows and columns of constrained dofs are 0. 243 multiply-adds per node and product, against
        576 per element when applied element by element.
    dinv : (nz + 1, ny + 1, nx + 1, 3, 3) ndarray of float, overwritten
        Inverse of each node's diagonal block on its free dofs, 0 on constrained ones.
    """
    nz, ny, nx = e_mod.shape
    general = kel.shape[0] > 0
    s[:] = 0.0
    blk = np.empty((3, 3))
    for kn in range(nz + 1):
        for jn in range(ny + 1):
            for in_ in range(nx + 1):
                for dk in range(2):  # the (up to 8) elements around the node
                    k = kn - dk
                    if k < 0 or k >= nz:
                        continue
                    for dj in range(2):
                        j = jn - dj
                        if j < 0 or j >= ny:
                            continue
                        for di in range(2):
                            i = in_ - di
                            if i < 0 or i >= nx:
                                continue
                            e = 1.0 if general else e_mod[k, j, i]
                            m = kel[k, j, i] if general else ke
                            a = di + 2 * dj + 4 * dk  # the node's local index in element (k, j, i)
                            for b in range(8):
                                q = 9 * ((b >> 2) - dk + 1) + 3 * (((b >> 1) & 1) - dj + 1) + (b & 1) - di + 1
                                for c in range(3):
                                    for cc in range(3):
                                        s[kn, jn, in_, q, c, cc] += e * m[3 * a + c, 3 * b + cc]
                for q in range(27):
                    kk, jj, ii = kn + q // 9 - 1, jn + (q // 3) % 3 - 1, in_ + q % 3 - 1
                    if kk < 0 or kk > nz or jj < 0 or jj > ny or ii < 0 or ii > nx:
                        continue
                    for c in range(3):
                        for cc in range(3):
                            s[kn, jn, in_, q, c, cc] *= free[kn, jn, in_, c] * free[kk, jj, ii, cc]
                for c in range(3):
                    for cc in range(3):
                        blk[c, cc] = s[kn, jn, in_, 13, c, cc]
                    if free[kn, jn, in_, c] == 0.0:
                        blk[c, c] = 1.0
                _inverse3(blk, dinv[kn, jn, in_])
                for c in range(3):
                    for cc in range(3):
                        dinv[kn, jn, in_, c, cc] *= free[kn, jn, in_, c] * free[kn, jn, in_, cc]


@numba.njit(cache=True, nogil=True)
def _inverse3(a, out):
    """Inverse of a symmetric positive definite 3x3 matrix by cofactors."""
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[1, 2]
    c01 = a[0, 2] * a[1, 2] - a[0, 1] * a[2, 2]
    c02 = a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]
    c11 = a[0, 0] * a[2, 2] - a[0, 2] * a[0, 2]
    c12 = a[0, 1] * a[0, 2] - a[0, 0] * a[1, 2]
    c22 = a[0, 0] * a[1, 1] - a[0, 1] * a[0, 1]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
    out[0, 0], out[0, 1], out[0, 2] = c00 / det, c01 / det, c02 / det
    out[1, 0], out[1, 1], out[1, 2] = c01 / det, c11 / det, c12 / det
    out[2, 0], out[2, 1], out[2, 2] = c02 / det, c12 / det, c22 / det


@numba.njit(cache=True, inline="always")
def _row(s, u, kn, jn, in_, r, other_lines):
    """``r -= (s u)`` at node (kn, jn, in_), over the neighbours inside the grid; with ``other_lines``
    only those off the node's own x line."""
    nzn, nyn, nxn = u.shape[0], u.shape[1], u.shape[2]
    i0, i1 = max(in_ - 1, 0), min(in_ + 2, nxn)
    for kk in range(max(kn - 1, 0), min(kn + 2, nzn)):
        for jj in range(max(jn - 1, 0), min(jn + 2, nyn)):
            if other_lines and kk == kn and jj == jn:
                continue
            q0 = 9 * (kk - kn + 1) + 3 * (jj - jn + 1) + 1 - in_
            for ii in range(i0, i1):
                u0, u1, u2 = u[kk, jj, ii, 0], u[kk, jj, ii, 1], u[kk, jj, ii, 2]
                m = s[kn, jn, in_, q0 + ii]
                for c in range(3):
                    r[c] -= m[c, 0] * u0 + m[c, 1] * u1 + m[c, 2] * u2


@numba.njit(cache=True, nogil=True)
def apply_stencil(s, u, out):
    """``out = K u`` with the stencil of `stencil` (0 on constrained dofs)."""
    nzn, nyn, nxn = u.shape[0], u.shape[1], u.shape[2]
    r = np.empty(3)
    for kn in range(nzn):
        for jn in range(nyn):
            for in_ in range(nxn):
                r[:] = 0.0
                _row(s, u, kn, jn, in_, r, False)
                for c in range(3):
                    out[kn, jn, in_, c] = -r[c]


@numba.njit(cache=True, nogil=True)
def gauss_seidel(s, dinv, u, f, forward):
    """One lexicographic nodal block Gauss-Seidel sweep on ``K u = f``, in place.

    A forward sweep followed by a backward one is a symmetric smoother, as PCG needs. Each x line
    first gathers, in ascending memory order, its couplings to the other lines (fixed while the line
    is updated), then updates its nodes in the sweep's direction: a backward sweep reading the
    stencil in descending order would be several times slower. Serial on purpose: a multicolour
    order that threads could share costs several times as much per sweep (strided passes over the
    stencil).
    """
    nzn, nyn, nxn = u.shape[0], u.shape[1], u.shape[2]
    rest = np.empty((nxn, 3))
    step = 1 if forward else -1
    for kn in range(0 if forward else nzn - 1, nzn if forward else -1, step):
        for jn in range(0 if forward else nyn - 1, nyn if forward else -1, step):
            for in_ in range(nxn):
                r = rest[in_]
                r[0], r[1], r[2] = f[kn, jn, in_, 0], f[kn, jn, in_, 1], f[kn, jn, in_, 2]
                _row(s, u, kn, jn, in_, r, True)
            for in_ in range(0 if forward else nxn - 1, nxn if forward else -1, step):
                r = rest[in_]
                for ii in range(max(in_ - 1, 0), min(in_ + 2, nxn)):  # the line's own couplings
                    u0, u1, u2 = u[kn, jn, ii, 0], u[kn, jn, ii, 1], u[kn, jn, ii, 2]
                    m = s[kn, jn, in_, 13 + ii - in_]
                    for c in range(3):
                        r[c] -= m[c, 0] * u0 + m[c, 1] * u1 + m[c, 2] * u2
                d = dinv[kn, jn, in_]
                for c in range(3):
                    u[kn, jn, in_, c] += d[c, 0] * r[0] + d[c, 1] * r[1] + d[c, 2] * r[2]


@numba.njit(cache=True, nogil=True)
def element_energy(ke, u, out):
    """``out[e] = u_e^T Ke u_e`` for every element (twice the strain energy at unit modulus)."""
    nz, ny, nx = out.shape
    ue = np.empty(24)
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                _gather(u, k, j, i, ue)
                s = 0.0
                for a in range(24):
                    t = 0.0
                    for b in range(24):
                        t += ke[a, b] * ue[b]
                    s += ue[a] * t
                out[k, j, i] = s


def _element_dofs(shape: tuple[int, int, int]) -> np.ndarray:
    """(n_elements, 24) global dof numbers of every element (nodal vectors flattened C-order)."""
    nz, ny, nx = shape
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    cols = []
    for a in range(8):
        node = ((k + (a >> 2)) * (ny + 1) + j + ((a >> 1) & 1)) * (nx + 1) + i + (a & 1)
        cols += [3 * node.ravel() + c for c in range(3)]
    return np.stack(cols, axis=1)


def assemble(e_mod: np.ndarray, ke: np.ndarray, kel: np.ndarray = UNIFORM) -> sp.csr_matrix:
    """The global stiffness matrix, no constraints applied (element matrices as in `stencil`).

    Returns
    -------
    (3 N, 3 N) scipy.sparse.csr_matrix
        N = (nz + 1)(ny + 1)(nx + 1) nodes, dofs ordered like a flattened nodal vector.
    """
    dofs = _element_dofs(e_mod.shape)
    rows = np.repeat(dofs, 24, axis=1).ravel()
    cols = np.tile(dofs, (1, 24)).ravel()
    vals = (kel.reshape(-1) if kel.shape[0] else (e_mod.reshape(-1, 1) * ke.reshape(1, -1)).ravel())
    n = 3 * (e_mod.shape[0] + 1) * (e_mod.shape[1] + 1) * (e_mod.shape[2] + 1)
    return sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()
