"""Hex8 elasticity and the multigrid PCG: element matrix, operators, direct-solve and analytic checks."""
import numpy as np
import pytest
import scipy.sparse.linalg as sla

from design.errors import DesignError
from design.fabrication.elasticity import (
    UNIFORM,
    apply_stencil,
    assemble,
    free_mask,
    gauss_seidel,
    hex8_stiffness,
    modulus,
    self_weight,
    stencil,
)
from design.fabrication.multigrid import hierarchy, pcg, prolong, restrict


def test_element_matrix_is_symmetric_with_six_rigid_modes():
    ke = hex8_stiffness((1.0, 0.5, 2.0), 0.3)
    assert np.allclose(ke, ke.T)
    eig = np.linalg.eigvalsh(ke)
    assert np.all(np.abs(eig[:6]) < 1e-12 * eig[-1]) and eig[6] > 1e-3 * eig[-1]
    with pytest.raises(DesignError, match="Poisson"):
        hex8_stiffness((1, 1, 1), 0.5)


def test_moduli_laws_and_guard():
    rho = np.array([0.0, 0.5, 1.0])
    e, de = modulus(rho, "simp", 1e-4)
    assert e == pytest.approx([1e-4, 1e-4 + 0.125 * (1 - 1e-4), 1.0])
    e_r, _ = modulus(rho, "ramp", 1e-4)
    assert e_r[0] == pytest.approx(1e-4) and e_r[-1] == pytest.approx(1.0) and e_r[1] < 0.5
    for law in ("simp", "ramp"):
        h = 1e-6
        assert modulus(rho[1:2], law)[1][0] == pytest.approx(
            (modulus(rho[1:2] + h, law)[0][0] - modulus(rho[1:2] - h, law)[0][0]) / (2 * h), rel=1e-6)
    with pytest.raises(DesignError, match="stiffness law"):
        modulus(rho, "hashin")


def test_matrix_free_operator_matches_assembly():
    rng = np.random.default_rng(0)
    shape = (3, 4, 5)
    e_mod = rng.random(shape) + 0.1
    ke = hex8_stiffness((1.0, 1.0, 1.0))
    free = free_mask(shape, True, False)
    u = rng.standard_normal(free.shape) * free
    out = np.empty_like(u)
    s, dinv = np.empty(free.shape[:3] + (27, 3, 3)), np.empty(free.shape[:3] + (3, 3))
    stencil(e_mod, ke, UNIFORM, free, s, dinv)
    apply_stencil(s, u, out)
    assert np.allclose(out.ravel(), free.ravel() * (assemble(e_mod, ke) @ u.ravel()), atol=1e-12)


def test_stencil_gauss_seidel_matches_a_block_sweep_on_the_assembled_matrix():
    """One stencil sweep equals nodal block Gauss-Seidel on the assembled matrix, nodes in flattened
    (z, y, x) order, forward and backward; constrained dofs stay 0."""
    rng = np.random.default_rng(3)
    shape = (4, 3, 5)
    e_mod, _ = modulus((rng.random(shape) > 0.5).astype(float))
    ke = hex8_stiffness((1.0, 0.5, 1.0))
    free = free_mask(shape, True, True)
    s, dinv = np.empty(free.shape[:3] + (27, 3, 3)), np.empty(free.shape[:3] + (3, 3))
    stencil(e_mod, ke, UNIFORM, free, s, dinv)
    f = rng.standard_normal(free.shape)
    k = assemble(e_mod, ke).toarray() * free.reshape(-1, 1) * free.reshape(1, -1)
    nodes = np.arange(free[..., 0].size)
    for forward in (True, False):
        u = rng.standard_normal(free.shape) * free
        expected = u.ravel().copy()
        for n in (nodes if forward else nodes[::-1]):
            dofs = 3 * n + np.flatnonzero(free.reshape(-1, 3)[n])
            r = f.ravel()[dofs] - k[dofs] @ expected
            expected[dofs] += np.linalg.solve(k[np.ix_(dofs, dofs)], r)
        gauss_seidel(s, dinv, u, f, forward)
        assert np.allclose(u.ravel(), expected, atol=1e-12 * np.abs(expected).max())
        assert np.all(u.ravel()[free.ravel() == 0] == 0.0)


def test_restriction_is_the_transpose_of_prolongation():
    rng = np.random.default_rng(1)
    for factors in ((2, 2, 2), (1, 2, 2), (2, 1, 1)):
        coarse = rng.standard_normal((3, 4, 5, 3))
        fine_shape = tuple(f * (n - 1) + 1 for f, n in zip(factors, coarse.shape[:3])) + (3,)
        fine = rng.standard_normal(fine_shape)
        assert np.vdot(prolong(coarse, factors), fine) == pytest.approx(np.vdot(coarse, restrict(fine, factors)))


@pytest.mark.parametrize("shape,mirror", [((8, 6, 6), (True, True)), ((12, 8, 10), (False, True)),
                                          ((6, 8, 4), (True, False))])
def test_multigrid_pcg_matches_a_sparse_direct_solve(shape, mirror):
    """A binary-ish SIMP design (contrast 1e-4) on a three-level hierarchy, semicoarsening included."""
    rng = np.random.default_rng(2)
    rho = (rng.random(shape) > 0.4).astype(float)
    e_mod, _ = modulus(rho)
    levels = hierarchy(e_mod, (0.5, 0.5, 0.5), 0.3, *mirror, max_coarse_nodes=40)
    assert len(levels) >= 2
    f = self_weight(np.ones(shape), 0.125)
    u, iterations = pcg(levels, f, tol=1e-11, max_iter=300)
    free = levels[0].free.ravel() > 0
    k = assemble(e_mod, levels[0].ke)[free][:, free]
    direct = sla.spsolve(k.tocsc(), f.ravel()[free])
    assert np.abs(u.ravel()[free] - direct).max() <= 1e-8 * np.abs(direct).max()
    assert np.all(u.ravel()[~free] == 0.0) and iterations > 1


def test_pcg_reports_non_convergence():
    e_mod = np.ones((8, 4, 4))
    levels = hierarchy(e_mod, (1, 1, 1), 0.3, True, True, max_coarse_nodes=20)
    with pytest.raises(DesignError, match="did not reach"):
        pcg(levels, self_weight(np.ones((8, 4, 4)), 1.0), tol=1e-14, max_iter=1)


def _column(nu: float, height: int = 32, width: int = 4):
    levels = hierarchy(np.ones((height, width, width)), (1.0, 1.0, 1.0), nu, True, True, max_coarse_nodes=200)
    u, _ = pcg(levels, self_weight(np.ones((height, width, width)), 1.0), tol=1e-11, max_iter=300)
    z = np.arange(height + 1.0)
    return u, -(height * z - z ** 2 / 2.0)  # u_z = -(w / E)(H z - z^2 / 2), w = E = 1


def test_column_under_self_weight_matches_the_analytic_displacement():
    """nu = 0: the 1D bar solution lies in the trilinear space, so nodal values are exact."""
    u, exact = _column(0.0)
    assert np.abs(u[..., 2] - exact[:, None, None]).max() <= 1e-9 * abs(exact[-1])
    assert np.abs(u[..., :2]).max() <= 1e-9 * abs(exact[-1])
    # nu = 0.3: the clamped base restrains the Poisson contraction; the top of an 8:1 column
    # moves 1.7% less than the bar solution (state: within 3%)
    u, exact = _column(0.3)
    assert u[-1, :, :, 2].mean() / exact[-1] == pytest.approx(0.983, abs=0.01)


def test_cantilever_converges_to_beam_theory():
    """A 2 x 2 x 20 mm post clamped at z = 0 under a lateral body force q along x (mirror in y only):
    Euler-Bernoulli tip deflection q A L^4 / (8 E I). Trilinear hexahedra are too stiff in bending
    (parasitic shear); the error falls about 4x per refinement: 12.5%, 3.6%, 0.9% at 1, 2, 4
    elements per mm. Checked at 2 per mm within 5%, and the second-order convergence."""
    b = d = 2.0
    length = 20.0
    nu = 0.3
    tips = []
    for per_mm in (1, 2):
        shape = (int(length * per_mm), int(d * per_mm) // 2, int(b * per_mm))
        h = 1.0 / per_mm
        levels = hierarchy(np.ones(shape), (h, h, h), nu, False, True, max_coarse_nodes=200)
        f = self_weight(np.ones(shape), h ** 3)
        f[..., 0], f[..., 2] = -f[..., 2], 0.0  # the same body force, turned to +x
        u, _ = pcg(levels, f, tol=1e-11, max_iter=500)
        tips.append(u[-1, :, :, 0].mean())
    euler_bernoulli = (b * d) * length ** 4 / (8.0 * (d * b ** 3 / 12.0))
    errors = [1.0 - t / euler_bernoulli for t in tips]
    assert errors[1] == pytest.approx(0.036, abs=0.01) and 0 < errors[1] < 0.05
    assert 3.0 < errors[0] / errors[1] < 4.5
