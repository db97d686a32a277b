"""Design spaces: shapes, replication adjoint, building by name."""
import numpy as np
import pytest

from design.errors import DesignError
from design.inverse.spaces import (
    BUILD_AXIS,
    SPACE_CHOICES,
    SpaceRequest,
    available_spaces,
    build_space,
)


def test_nfc_is_an_octant():
    space = build_space("nfc", SpaceRequest((16, 16, 16), 0.5))
    assert space.var_shape == space.grid_shape == (8, 8, 8)
    assert space.mirror == (True, True, True) and space.multiplicity == 8


def test_extruded_replicates_over_height_and_adjoint_sums():
    space = build_space("extruded", SpaceRequest((12, 10, 20), 0.5, 7))
    assert space.var_shape == (6, 5) and space.grid_shape[BUILD_AXIS] == 7
    rng = np.random.default_rng(0)
    x, g = rng.random(space.var_shape), rng.random(space.grid_shape)
    grid = space.to_grid(x)
    assert np.all(grid == x[:, :, None])
    assert np.dot(grid.ravel(), g.ravel()) == pytest.approx(np.dot(x.ravel(), space.to_grid_adjoint(g).ravel()))


def test_unfold_builds_the_mirrored_object():
    space = build_space("nfc", SpaceRequest((4, 4, 4), 1.0))
    half = np.arange(8.0).reshape(2, 2, 2)
    full = space.unfold(half)
    assert full.shape == (4, 4, 4)
    assert np.array_equal(full, full[::-1, ::-1, ::-1]) and np.array_equal(full[2:, 2:, 2:], half)


def test_ico_is_a_quadrant_with_its_fabrication_term_and_unknown_names_fail():
    assert "ico" in SPACE_CHOICES and "ico" in available_spaces()
    space = build_space("ico", SpaceRequest((8, 6, 16), 1.0))
    assert space.grid_shape == (4, 3, 16) and space.mirror == (True, True, False) and space.fab_term is not None
    assert build_space("nfc", SpaceRequest((8, 8, 8), 1.0)).fab_term is None
    with pytest.raises(DesignError, match="8 layers need at least as many elasticity elements along z, got 5"):
        build_space("ico", SpaceRequest((8, 6, 10), 1.0))  # 10 voxels, 2 per element
    with pytest.raises(DesignError, match="unknown design space 'lattice'; available: extruded, ico, nfc"):
        build_space("lattice", SpaceRequest((8, 8, 8), 1.0))


def test_space_guards():
    with pytest.raises(DesignError, match="even voxel count"):
        build_space("nfc", SpaceRequest((9, 8, 8), 1.0))
    with pytest.raises(DesignError, match="extrusion height"):
        SpaceRequest((8, 8, 8), 1.0, 9)
    with pytest.raises(DesignError, match="voxel size"):
        SpaceRequest((8, 8, 8), 0.0)
