"""The connectivity penalty: zero for connected designs, the floating volume for pieces, exact gradient."""
import numpy as np
import pytest

from design.connectivity import Connectivity, _pool
from design.errors import DesignError


def _grid(shape):
    return np.meshgrid(*[np.arange(n) + 0.5 for n in shape], indexing="ij")


def _disc_and_blob(n=20):
    x, y = _grid((n, n))
    disc = ((x ** 2 + y ** 2) < 36).astype(float)
    blob = disc.copy()
    blob[12:16, 12:16] = 1.0  # 16 voxels away from the disc, across void
    return disc, blob


def _check_gradient(conn, rho, grad, picks, h=1e-6):
    """Central differences of J_conn at the entries ``picks`` against ``grad``."""
    scale = np.abs(grad).max()
    for idx in picks:
        up, down = rho.copy(), rho.copy()
        up[idx] += h
        down[idx] -= h
        fd = (conn(up, 2.0)[0] - conn(down, 2.0)[0]) / (2 * h)
        # J ~ 10-100: round-off of the difference ~1e-14 / h ~ 1e-8; the marcher's upwind choices are
        # locally constant, so the discrete map is smooth at a generic point
        assert abs(grad[idx] - fd) <= 1e-6 * scale, (idx, grad[idx], fd)


def test_connected_design_is_free_and_a_floating_piece_costs_its_volume():
    disc, blob = _disc_and_blob()
    conn = Connectivity(disc.shape, (True, True), 0.5)
    assert conn(disc, 1.0)[0] == 0.0
    assert conn(blob, 1.0)[0] == pytest.approx(16.0, rel=0.01)  # h -> 1 far beyond the allowance
    bridged = blob.copy()
    for i in range(16):  # a three-voxel-wide diagonal bridge joins the blob to the disc
        bridged[i, max(0, i - 1):i + 2] = 1.0
    assert conn(bridged, 1.0)[0] == 0.0


def test_a_quadrant_pillar_that_misses_the_mirror_planes_is_penalised():
    # in the full object its four mirror copies are four pieces; touching both planes makes one
    conn = Connectivity((20, 20), (True, True), 0.5)
    pillar = np.zeros((20, 20))
    pillar[8:14, 8:14] = 1.0
    assert conn(pillar, 1.0)[0] == pytest.approx(36.0, rel=0.01)
    cross = np.zeros((20, 20))
    cross[:3, :14] = cross[:14, :3] = 1.0  # arms along both mirror planes, through the centre
    assert conn(cross, 1.0)[0] == 0.0


def test_floating_piece_in_an_octant_and_the_coarse_distance():
    x, y, z = _grid((16, 16, 16))
    ball = ((x ** 2 + y ** 2 + z ** 2) < 64).astype(float)
    conn = Connectivity(ball.shape, (True, True, True), 0.5, coarsen=2)
    assert conn.coarse_shape == (8, 8, 8)
    assert conn(ball, 1.0)[0] < 0.02 * ball.sum()  # grey coarse voxels on the surface cost a little
    ball[12:16, 12:16, 12:16] = 1.0
    value, grad = conn(ball, 1.0)
    assert value == pytest.approx(64.0, rel=0.05) and grad.shape == ball.shape


@pytest.mark.parametrize("shape, mirror, coarsen", [((14, 12), (True, True), 1), ((12, 10, 8), (True, True, False), 2),
                                                    ((10, 10, 10), (True, True, True), 1)])
def test_gradient_matches_central_differences(shape, mirror, coarsen):
    rng = np.random.default_rng(7)
    grids = _grid(shape)
    rho = np.clip(0.15 + 0.7 * (sum(g ** 2 for g in grids) < 20) + rng.uniform(-0.1, 0.1, shape), 0, 1)
    far = tuple(slice(n - 3, n - 1) for n in shape)
    rho[far] = 0.9  # a floating blob, so that the penalty and its geodesic chain are active
    conn = Connectivity(shape, mirror, 0.3, coarsen=coarsen)
    value, grad = conn(rho, 2.0)
    assert value > 0
    _check_gradient(conn, rho, grad, [tuple(int(rng.integers(0, n)) for n in shape) for _ in range(12)])


def test_guards():
    with pytest.raises(DesignError, match="at least one mirror plane"):
        Connectivity((8, 8), (False, False), 1.0)
    with pytest.raises(DesignError, match="coarsen"):
        Connectivity((8, 8), (True, True), 1.0, coarsen=0)


def _ring(n=24, inner=5.0, outer=9.0):
    x, y = _grid((n, n))
    r = np.sqrt(x ** 2 + y ** 2)
    return ((r > inner) & (r < outer)).astype(float)


def test_a_part_hollow_at_the_core_is_rooted_on_its_axis_lines():
    ring = _ring()
    conn = Connectivity(ring.shape, (True, True), 0.5)
    # seen from the core alone, all of it would float; from its own wall a voxel or two of the far arc
    # just exceed the allowance
    assert conn(ring, 1.0)[0] < 1e-3 * ring.sum()
    blob = ring.copy()
    blob[17:21, 17:21] = 1.0  # 16 voxels beyond the ring, across void
    assert conn(blob, 1.0)[0] == pytest.approx(16.0, rel=0.02)
    x, y, z = _grid((16, 16, 16))
    r = np.sqrt(x ** 2 + y ** 2 + z ** 2)
    shell = ((r > 4) & (r < 8)).astype(float)
    assert Connectivity(shell.shape, (True, True, True), 0.5)(shell, 1.0)[0] < 1e-3 * shell.sum()


def test_a_piece_nested_in_a_hollow_part_or_off_a_mirror_plane_is_penalised():
    nested = _ring(inner=9.0, outer=12.0) + _ring(inner=2.0, outer=5.0)  # a floating ring in the cavity
    conn = Connectivity(nested.shape, (True, True), 0.5)
    assert conn(nested, 1.0)[0] > 0.9 * min(_ring(inner=9.0, outer=12.0).sum(), _ring(inner=2.0, outer=5.0).sum())
    lump = np.zeros((24, 24))
    lump[6:12, 0:4] = 1.0  # on the axis-0 line, clear of the other mirror plane: two pieces with its copy
    assert conn(lump, 1.0)[0] == pytest.approx(lump.sum(), rel=0.02)
    lump[0:12, 0:4] = 1.0  # reaching that plane: one piece
    assert conn(lump, 1.0)[0] == 0.0


@pytest.mark.parametrize("shape, mirror, coarsen", [((24, 24), (True, True), 1), ((12, 12, 12), (True, True, True), 1),
                                                    ((16, 16, 8), (True, True, False), 2)])
def test_gradient_matches_central_differences_with_seeds_on_the_axis_lines(shape, mirror, coarsen):
    # a grey hollow part: line seeds with gates strictly between 0 and 1, a floating blob
    rng = np.random.default_rng(3)
    grids = _grid(shape)
    r = np.sqrt(sum(g ** 2 for g, m in zip(grids, mirror) if m))
    rho = np.clip(np.where((r > 0.3 * shape[0]) & (r < 0.6 * shape[0]), 0.75, 0.05)
                  + rng.uniform(-0.05, 0.05, shape), 0, 1)
    far = tuple(slice(n - 3, n - 1) for n in shape)
    rho[far] = 0.9
    conn = Connectivity(shape, mirror, 0.3, coarsen=coarsen)
    value, grad = conn(rho, 2.0)
    assert len(conn._gated_seeds(np.flip(_pool(rho, coarsen), conn._flips))) > 1 and value > 0
    picks = [tuple(int(rng.integers(0, n)) for n in shape) for _ in range(10)]
    picks += [tuple(int(v) for v in np.unravel_index(int(np.argmax(np.abs(grad))), shape))]
    _check_gradient(conn, rho, grad, picks)
