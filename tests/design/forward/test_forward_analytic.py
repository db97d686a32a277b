"""Release curves of simple solids against their analytic curves: first-order convergence (Fig. 3d)."""
import numpy as np
import pytest

from benchmarks.analytic import SHAPES, centres, release_error
from design.forward.simulator import simulate


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
    dx, (x, y, z) = centres(64, half_width)
    r = simulate(inside(x, y, z).astype(float), dx)
    assert r.released_mm3[0] == 0.0
    assert r.released_mm3[1] < 2 * r.dtau_mm * 4 * np.pi  # about area x dtau, not a jump
