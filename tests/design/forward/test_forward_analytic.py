"""Release curves of simple solids against their analytic curves: first-order convergence (Fig. 3d)."""
import numpy as np
import pytest

from design.forward.simulator import simulate


def _centres(n, half_width):
    dx = 2 * half_width / n
    c = (np.arange(n) + 0.5) * dx - half_width
    return dx, np.meshgrid(c, c, c, indexing="ij")


def _ball(tau, r):
    return 4 / 3 * np.pi * (r ** 3 - np.clip(r - tau, 0, None) ** 3)


# Each shape: (inside test on voxel centres, analytic C(tau), half width of the box, T used).
SHAPES = {
    "sphere": (lambda x, y, z: x * x + y * y + z * z < 1.0, lambda t: _ball(t, 1.0), 1.0, 1.1),
    # cylinder of radius 1, height 2 (z in [-1, 1]): what remains at depth t is radius 1 - t, height 2 - 2t
    "cylinder": (lambda x, y, z: (x * x + y * y < 1.0) & (np.abs(z) < 1.0),
                 lambda t: np.pi * (2.0 - np.clip(1 - t, 0, None) ** 2 * np.clip(2 - 2 * t, 0, None)), 1.0, 1.1),
    # the cube fills its box, so its faces lie on voxel faces at every resolution
    "cube": (lambda x, y, z: np.ones(x.shape, dtype=bool),
             lambda t: 1.6 ** 3 - np.clip(1.6 - 2 * t, 0, None) ** 3, 0.8, 0.9),
    # Fig. 2: a ball of radius 0.4 inside a shell 0.6 < r < 1 with void between; the void dissolves at
    # once when the front reaches it at tau = 0.4, then the ball dissolves
    "nested": (lambda x, y, z: (np.sqrt(x * x + y * y + z * z) < 0.4)
               | ((x * x + y * y + z * z > 0.36) & (x * x + y * y + z * z < 1.0)),
               lambda t: _ball(np.minimum(t, 0.4), 1.0) + _ball(np.clip(t - 0.4, 0, None), 0.4), 1.0, 0.9),
}


def release_error(name, n):
    """Largest |C - C*| over tau in [0, T], relative to the analytic volume, at n voxels across."""
    inside, exact, half_width, t_end = SHAPES[name]
    dx, (x, y, z) = _centres(n, half_width)
    r = simulate(inside(x, y, z).astype(float), dx, total_time_mm=t_end)
    truth = exact(r.tau_mm)
    return np.abs(r.released_mm3 - truth).max() / truth[-1]


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_first_order_convergence(name):
    coarse, fine = release_error(name, 24), release_error(name, 48)
    # observed at 48 voxels across: sphere 2.30 %, cylinder 1.13 %, nested 2.71 %, cube 0.20 %;
    # the bounds are 1.25 x those, so a regression fails
    assert fine < {"sphere": 0.029, "cylinder": 0.0141, "cube": 0.0025, "nested": 0.034}[name]
    # halving dx halves the error of the curved solids (observed ratios 2.0-2.25); the cube's planar
    # fronts are exact and only its corners err, so it converges faster (ratio 3.7)
    ratio = coarse / fine
    assert ratio > 1.6 and (name == "cube" or ratio < 2.6)


def test_release_starts_at_zero():
    # the bath touches the solid at tau = 0: nothing is released then (eq. 6's ramps start no earlier)
    inside, _, half_width, _ = SHAPES["sphere"]
    dx, (x, y, z) = _centres(64, half_width)
    r = simulate(inside(x, y, z).astype(float), dx)
    assert r.released_mm3[0] == 0.0
    assert r.released_mm3[1] < 2 * r.dtau_mm * 4 * np.pi  # about area x dtau, not a jump
