"""Contour extraction, re-voxelisation, pieces and IoU."""
import numpy as np
import pytest

from design.errors import DesignError
from design.fabrication.extract import LEVEL_RANGE, centred_iou, count_pieces, density_mesh, mass_preserving_level, revoxelize


def _ball_density(n=20, radius=6.0):
    c = np.arange(n) - n / 2 + 0.5
    x, y, z = np.meshgrid(c, c, c, indexing="ij")
    r = np.sqrt(x ** 2 + y ** 2 + z ** 2)
    return np.clip(radius + 0.5 - r, 0.0, 1.0)  # a linear ramp crossing 1/2 at r = radius


def test_contour_is_a_watertight_ball_in_mm_at_the_right_place():
    dx, origin = 0.5, np.array([10.0, -5.0, 0.0])
    mesh = density_mesh(_ball_density(), dx, origin)
    assert mesh.is_watertight and mesh.volume > 0
    # radius 6 voxels = 3 mm; marching cubes on a linear ramp is within a few % of the true volume
    assert mesh.volume == pytest.approx(4 / 3 * np.pi * 3.0 ** 3, rel=0.03)
    assert np.allclose(mesh.centroid, origin + 10 * dx, atol=1e-6)


def test_revoxelised_contour_reproduces_the_thresholded_density():
    rho = _ball_density()
    dx, origin = 0.5, np.zeros(3)
    solid = revoxelize(density_mesh(rho, dx, origin), dx, origin, rho.shape)
    assert np.array_equal(solid, rho >= 0.5)


def test_pieces_and_centred_iou():
    a = np.zeros((10, 10, 10), bool)
    a[1:4, 1:4, 1:4] = True
    b = np.roll(a, 4, axis=0)
    assert count_pieces(a | b) == 2
    assert centred_iou(a, b) == 1.0
    c = a.copy()
    c[1:4, 1:4, 4] = True  # 9 extra voxels on 27
    assert centred_iou(a, c) == pytest.approx(27 / 36, abs=0.1)
    assert centred_iou(a, np.zeros_like(a)) == 0.0


def test_empty_density_is_rejected():
    with pytest.raises(DesignError, match="nothing to extract"):
        density_mesh(np.full((4, 4, 4), 0.2), 1.0, np.zeros(3))


@pytest.mark.parametrize("seed", range(5))
def test_densities_at_the_level_still_give_a_closed_solid(seed):
    # values exactly at (or within round-off of) 1/2 put marching-cubes vertices on grid points; the
    # coincident vertices would leave the contour open ("not watertight") without `extract.LEVEL_GAP`
    rng = np.random.default_rng(seed)
    rho = rng.choice([0.0, 0.5, 0.5 - 1e-13, 1.0, 0.3, 0.7], size=(12, 12, 12), p=[0.3, 0.2, 0.1, 0.2, 0.1, 0.1])
    mesh = density_mesh(rho, 0.25, np.zeros(3))
    assert mesh.is_watertight and mesh.volume > 0
    solid = revoxelize(mesh, 0.25, np.zeros(3), rho.shape)
    assert np.array_equal(solid, rho >= 0.5)


@pytest.mark.parametrize("seed", range(3))
def test_a_binary_density_with_edge_contacts_gives_a_closed_solid(seed):
    # solid-void checkerboard faces (voxels touching along an edge) have a bilinear centre value at the
    # level: the contour keeps such voxels apart, as count_pieces does
    rho = (np.random.default_rng(seed).random((10, 10, 10)) < 0.5).astype(float)
    mesh = density_mesh(rho, 0.25, np.zeros(3))
    assert mesh.is_watertight and mesh.volume > 0
    assert np.array_equal(revoxelize(mesh, 0.25, np.zeros(3), rho.shape), rho >= 0.5)


def test_mass_preserving_level_keeps_the_densitys_mass():
    # a ball with a linear boundary ramp: the 1/2 cut of a curved grey layer holds less than the density
    rho = _ball_density(n=24, radius=7.0)
    level = mass_preserving_level(rho)
    solid = rho >= level
    assert abs(int(solid.sum()) - rho.sum()) <= 0.5 + np.count_nonzero(rho == level)
    assert abs(int((rho >= 0.5).sum()) - rho.sum()) > 10  # the paper's cut differs here
    mesh = density_mesh(rho, 0.5, np.zeros(3), level=level)
    assert np.array_equal(revoxelize(mesh, 0.5, np.zeros(3), rho.shape), solid)


def test_mass_preserving_level_of_a_binary_density_keeps_it():
    rho = np.zeros((8, 8, 8))
    rho[2:6, 2:6, 2:5] = 1.0
    level = mass_preserving_level(rho)
    assert 0.4 <= level <= 0.6 and np.array_equal(rho >= level, rho == 1.0)


@pytest.mark.parametrize("grey, expected", [(0.2, LEVEL_RANGE[0]), (0.8, LEVEL_RANGE[1])])
def test_mass_preserving_level_stays_within_its_range(grey, expected):
    # a uniformly grey density would need a cut near its own value, far from 1/2
    rho = grey + 0.01 * np.random.default_rng(0).uniform(-1.0, 1.0, (10, 10, 10))
    assert mass_preserving_level(rho) == expected
