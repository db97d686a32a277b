"""The connectivity penalty: zero for connected designs, the floating volume (once from the core, once from
the mirror planes) for pieces with the bounded h, a direction for hollow and nested designs, exact gradient."""
import numpy as np
import pytest

from design.errors import DesignError
from design.fabrication.connectivity import TAIL_SLOPE, Connectivity


def _grid(shape):
    return np.meshgrid(*[np.arange(n) + 0.5 for n in shape], indexing="ij")


def _disc_and_blob(n=20):
    x, y = _grid((n, n))
    disc = ((x ** 2 + y ** 2) < 36).astype(float)
    blob = disc.copy()
    blob[12:16, 12:16] = 1.0  # 16 voxels away from the disc, across void
    return disc, blob


def test_connected_design_is_free_and_a_floating_piece_costs_its_volume_twice():
    disc, blob = _disc_and_blob()
    bounded = Connectivity(disc.shape, (True, True), 0.5, tail_slope=0.0)
    conn = Connectivity(disc.shape, (True, True), 0.5)
    assert conn(disc, 1.0)[0] == bounded(disc, 1.0)[0] == 0.0
    # h -> 1 far beyond the allowance: 16 from the core and 16 from the mean over the two planes; the
    # tail adds to that
    assert bounded(blob, 1.0)[0] == pytest.approx(32.0, rel=0.01)
    assert conn(blob, 1.0)[0] > 32.5
    bridged = blob.copy()
    for i in range(16):  # a three-voxel-wide diagonal bridge joins the blob to the disc
        bridged[i, max(0, i - 1):i + 2] = 1.0
    assert conn(bridged, 1.0)[0] == 0.0


def test_a_quadrant_pillar_that_misses_the_mirror_planes_is_penalised():
    # in the full object its four mirror copies are four pieces; touching both planes makes one
    conn = Connectivity((20, 20), (True, True), 0.5, tail_slope=0.0)
    pillar = np.zeros((20, 20))
    pillar[8:14, 8:14] = 1.0
    assert conn(pillar, 1.0)[0] == pytest.approx(2 * 36.0, rel=0.01)
    cross = np.zeros((20, 20))
    cross[:3, :14] = cross[:14, :3] = 1.0  # arms along both mirror planes, through the centre
    assert conn(cross, 1.0)[0] == 0.0


def test_a_ring_hollow_at_the_centre_and_brackets_that_miss_a_plane():
    x, y = _grid((24, 24))
    r2 = x ** 2 + y ** 2
    ring = ((r2 > 8 ** 2) & (r2 < 12 ** 2)).astype(float)  # a quarter ring: its copies close the ring
    conn = Connectivity(ring.shape, (True, True), 0.5, tail_slope=0.0)
    # far from the void core, every voxel pays the core term; the planes see one piece
    assert conn(ring, 1.0)[0] == pytest.approx(ring.sum(), rel=0.02)
    # cut off plane 1 (y = 0): two brackets face each other across it, each reaching plane 0 only; the
    # plane term adds half their volume and, unlike the saturated core term, points to a bridge
    arc = ring * (y > 3)
    value, grad = conn(arc, 1.0)
    assert 1.4 * arc.sum() < value < 1.5 * arc.sum()
    gap = (r2 > 8 ** 2) & (r2 < 12 ** 2) & (y < 3)  # filling the gap to plane 1 lowers J
    assert grad[gap].mean() < 0


def _cross_in_a_frame(n=24, arm=10):
    """A cross whose arms lie along both mirror planes, inside a square frame: both pieces touch every
    plane, and only the core term sees the frame."""
    rho = np.zeros((n, n))
    rho[:3, :arm] = rho[:arm, :3] = 1.0
    rho[16:19, :19] = rho[:19, 16:19] = 1.0
    return rho


@pytest.mark.parametrize("slope, kept, steeper", [(TAIL_SLOPE, 0.92, 50.0), (0.1, 0.67, 100.0)])
def test_a_frame_around_a_cross_gets_a_direction_to_a_bridge_from_the_tail(slope, kept, steeper):
    nested, half_bridged = _cross_in_a_frame(), _cross_in_a_frame(arm=13)
    frame = nested.sum() - (2 * 3 * 10 - 9)
    gap = (slice(0, 3), slice(10, 16))  # along plane 0, between the arm's end and the frame
    bounded = Connectivity(nested.shape, (True, True), 0.5, tail_slope=0.0)
    value, grad = bounded(nested, 1.0)
    # saturated: the frame costs its volume, and halving the gap changes that by under 1%
    assert value == pytest.approx(frame, rel=0.01)
    assert bounded(half_bridged, 1.0)[0] > 0.99 * value
    conn = Connectivity(nested.shape, (True, True), 0.5, tail_slope=slope)
    tail_value, tail_grad = conn(nested, 1.0)
    # the tail pays for the gap's length: halving it lowers J (to 0.89 at the default slope, 0.62 at
    # 0.1, measured), and the gradient in the gap points to the bridge, far more steeply than the
    # bounded h's (71 and 705 times)
    assert conn(half_bridged, 1.0)[0] < kept * tail_value
    assert tail_grad[gap].mean() < steeper * grad[gap].mean() < 0


@pytest.mark.parametrize("slope, pin_cost", [(TAIL_SLOPE, 1.2), (0.1, 2.0)])
def test_the_tail_spares_a_ring_in_one_piece_but_not_a_ring_around_a_pin(slope, pin_cost):
    x, y = _grid((24, 24))
    r2 = x ** 2 + y ** 2
    ring = ((r2 > 8 ** 2) & (r2 < 12 ** 2)).astype(float)
    bounded = Connectivity(ring.shape, (True, True), 0.5, tail_slope=0.0)
    conn = Connectivity(ring.shape, (True, True), 0.5, tail_slope=slope)
    # far from the void core, but measured from its own innermost voxel: no tail, so nothing pushes the
    # hole to close
    assert conn(ring, 1.0)[0] == bounded(ring, 1.0)[0]
    pinned = ring.copy()
    pinned[:3, :3] = 1.0  # a pin at the centre: the ring is now a second piece around it
    assert conn(pinned, 1.0)[0] > pin_cost * bounded(pinned, 1.0)[0]  # 1.29 and 3.9 measured


def test_floating_piece_in_an_octant_and_the_coarse_distance():
    x, y, z = _grid((16, 16, 16))
    ball = ((x ** 2 + y ** 2 + z ** 2) < 64).astype(float)
    conn = Connectivity(ball.shape, (True, True, True), 0.5, coarsen=2, tail_slope=0.0)
    assert conn.coarse_shape == (8, 8, 8)
    assert conn(ball, 1.0)[0] < 0.02 * ball.sum()  # grey coarse voxels on the surface cost a little
    ball[12:16, 12:16, 12:16] = 1.0
    value, grad = conn(ball, 1.0)
    assert value == pytest.approx(2 * 64.0, rel=0.05) and grad.shape == ball.shape


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
    assert value > Connectivity(shape, mirror, 0.3, coarsen=coarsen, tail_slope=0.0)(rho, 2.0)[0] > 0  # tail on
    scale = np.abs(grad).max()
    for _ in range(12):
        idx = tuple(int(rng.integers(0, n)) for n in shape)
        h = 1e-6
        up, down = rho.copy(), rho.copy()
        up[idx] += h
        down[idx] -= h
        fd = (conn(up, 2.0)[0] - conn(down, 2.0)[0]) / (2 * h)
        # J ~ 10-100: round-off of the difference ~1e-14 / h ~ 1e-8; the marcher's upwind choices are
        # locally constant, so the discrete map is smooth at a generic point
        assert abs(grad[idx] - fd) <= 1e-6 * scale, (idx, grad[idx], fd)


def test_guards():
    with pytest.raises(DesignError, match="at least one mirror plane"):
        Connectivity((8, 8), (False, False), 1.0)
    with pytest.raises(DesignError, match="coarsen"):
        Connectivity((8, 8), (True, True), 1.0, coarsen=0)
    with pytest.raises(DesignError, match="tail_slope"):
        Connectivity((8, 8), (True, True), 1.0, tail_slope=-0.1)
