"""Deflation of floating islands' rigid-body modes in the multigrid PCG (design.fabrication.deflation)."""
import numpy as np
import pytest
import scipy.sparse.linalg as sla

from design.fabrication.deflation import floating_islands, island_deflation
from design.fabrication.elasticity import assemble, modulus, self_weight
from design.fabrication.multigrid import hierarchy, pcg


def _islands() -> np.ndarray:
    """(z, y, x) density: a post on the plate, a floating block, two blocks hinged along an edge,
    one of them hinged at a corner to the post's top, and a block on the x mirror plane."""
    rho = np.zeros((12, 8, 8))
    rho[:4, :3, :3] = 1.0  # on the plate
    rho[4, 3, 3] = 1.0  # corner-hinged to the post
    rho[5:7, 5:7, 5:7] = 1.0  # floating
    rho[8:10, 4:6, 4:6] = 1.0
    rho[10:12, 6:8, 4:6] = 1.0  # shares only an edge with the block below
    rho[6:8, 1:3, 0:2] = 1.0  # on the x = 0 mirror plane
    return rho


def test_floating_islands_are_face_connected_clusters_off_the_plate():
    e_mod, _ = modulus(_islands())
    labels, m = floating_islands(e_mod)
    assert m == 5 and labels[0, 0, 0] == -1 and labels[5, 5, 5] >= 0
    assert labels[8, 4, 4] != labels[10, 6, 4]  # an edge is a hinge, not a bond
    _, m_nodes = floating_islands(e_mod, faces_only=False)
    assert m_nodes == 3  # through shared nodes the hinged pair is one, the corner block joins the post
    assert floating_islands(np.full((4, 4, 4), 0.05))[1] == 0  # grey everywhere: nothing to deflate


@pytest.mark.parametrize("mirror", [(True, True), (False, False)])
def test_deflated_pcg_matches_a_sparse_direct_solve_in_fewer_iterations(mirror):
    """The deflated solve is exact to the PCG tolerance, cold and warm, and the islands' near-rigid
    modes (energy ~ E_min) do not slow it down: it needs less than half the iterations of the
    undeflated solve."""
    rho = _islands()
    e_mod, _ = modulus(rho)
    h = (0.5, 0.5, 0.5)
    levels = hierarchy(e_mod, h, 0.3, *mirror, max_coarse_nodes=40)
    deflation = island_deflation(e_mod, h, levels[0].s, levels[0].free)
    assert deflation.islands == 5
    free = levels[0].free.ravel() > 0
    k = assemble(e_mod, levels[0].ke)[free][:, free]
    assert abs(k @ deflation.z[free] - deflation.kz[free]).max() <= 1e-12  # K Z from the stencil
    f = self_weight(rho + 0.01, 0.125)
    direct = sla.spsolve(k.tocsc(), f.ravel()[free])
    u_plain, it_plain = pcg(levels, f, tol=1e-10, max_iter=500)
    u, it = pcg(levels, f, tol=1e-10, max_iter=500, deflation=deflation)
    for x in (u_plain, u):
        assert np.abs(x.ravel()[free] - direct).max() <= 1e-8 * np.abs(direct).max()
    assert it < 0.5 * it_plain
    start = u + 1e-3 * np.abs(u).max() * np.random.default_rng(0).standard_normal(u.shape)
    u_warm, it_warm = pcg(levels, f, start, tol=1e-10, max_iter=500, deflation=deflation)
    assert np.abs(u_warm.ravel()[free] - direct).max() <= 1e-8 * np.abs(direct).max()
    assert np.all(u_warm.ravel()[~free] == 0.0)


def test_a_hinged_mechanism_lies_in_the_deflation_space():
    """Two blocks sharing an edge, each turning rigidly about that edge: the motion is in span(Z)
    (shared nodes carry each island's mode with weight 1/2)."""
    rho = np.zeros((8, 6, 6))
    rho[2:4, 1:3, 1:3] = 1.0
    rho[4:6, 3:5, 1:3] = 1.0  # shares the edge z = 4, y = 3 (x from 1 to 3)
    e_mod, _ = modulus(rho)
    levels = hierarchy(e_mod, (1.0, 1.0, 1.0), 0.3, False, False, max_coarse_nodes=40)
    deflation = island_deflation(e_mod, (1.0, 1.0, 1.0), levels[0].s, levels[0].free)
    assert deflation.islands == 2
    nodes = np.zeros((9, 7, 7, 3))
    k, j = np.meshgrid(np.arange(9.0), np.arange(7.0), indexing="ij")
    turn = np.stack([np.zeros_like(k), -(k - 4.0), j - 3.0], axis=-1)  # about the x axis through the edge
    for lo, hi, sign in (((2, 1), (5, 4), 1.0), ((4, 3), (7, 6), -1.0)):  # opposite turns
        nodes[lo[0]:hi[0], lo[1]:hi[1], 1:4] = sign * turn[lo[0]:hi[0], lo[1]:hi[1], None]
    v = nodes.ravel()
    coef = sla.lsqr(deflation.z, v, atol=1e-14, btol=1e-14)[0]
    assert np.abs(deflation.z @ coef - v).max() <= 1e-9 * np.abs(v).max()
