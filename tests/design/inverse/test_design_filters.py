"""Smoothing and projection filters of eq. (4): adjoints against finite differences."""
import numpy as np
import pytest

from design.errors import DesignError
from design.inverse.filters import SmoothingFilter, cone_kernel, project, project_adjoint, project_inverse


def test_cone_kernel_decays_linearly_to_zero():
    k = cone_kernel(2.0, 2)
    # r = 2: weights 2 - |d| on the 3x3 stencil: centre 2, faces 1, corners 2 - sqrt(2)
    assert k.shape == (3, 3)
    assert k[1, 1] == 2.0 and k[0, 1] == 1.0
    assert k[0, 0] == pytest.approx(2.0 - np.sqrt(2.0))
    assert np.array_equal(cone_kernel(1.0, 3), np.ones((1, 1, 1)))


@pytest.mark.parametrize("shape, mirror", [((7, 8, 9), (True, False, True)), ((10, 6), (False, False)),
                                           ((6, 6, 6), (True, True, True))])
def test_smoothing_adjoint_is_exact_transpose(shape, mirror):
    rng = np.random.default_rng(1)
    f = SmoothingFilter(shape, 3.5, mirror)
    x, g = rng.random(shape), rng.random(shape)
    # <S x, g> = <x, S^T g>; both sides are O(100) sums of products, so 1e-10 is round-off
    assert np.dot(f.apply(x).ravel(), g.ravel()) == pytest.approx(np.dot(x.ravel(), f.adjoint(g).ravel()), rel=1e-10)


def test_smoothing_keeps_uniform_fields_uniform():
    f = SmoothingFilter((9, 5, 7), 4.0, (True, False, False))
    assert np.allclose(f.apply(np.full((9, 5, 7), 0.3)), 0.3, atol=1e-12)


def test_mirror_filter_equals_filtering_the_full_object():
    rng = np.random.default_rng(2)
    half = rng.random((6, 9, 8))
    full = np.concatenate([half[::-1], half])
    whole = SmoothingFilter(full.shape, 3.2, (False, False, False)).apply(full)
    reduced = SmoothingFilter(half.shape, 3.2, (True, False, False)).apply(half)
    assert np.abs(whole[6:] - reduced).max() < 1e-12


def test_smoothing_matches_direct_sum_at_a_zero_padded_corner():
    rng = np.random.default_rng(3)
    x = rng.random((5, 6))
    r = 2.5
    y = SmoothingFilter(x.shape, r, (False, False)).apply(x)
    num = den = 0.0
    for i in range(5):
        for j in range(6):
            w = max(r - np.hypot(i, j), 0.0)
            num += w * x[i, j]
            den += w
    assert y[0, 0] == pytest.approx(num / den, rel=1e-12)


def test_projection_maps_unit_interval_onto_itself_and_has_exact_derivative():
    beta = 3.0
    assert np.allclose(project(np.array([0.0, 0.5, 1.0]), beta), [0.0, 0.5, 1.0])
    x = np.linspace(0.05, 0.95, 7)
    h = 1e-6
    fd = (project(x + h, beta) - project(x - h, beta)) / (2 * h)
    # central differences of a smooth tanh: error O(h^2 beta^3) ~ 1e-11
    assert np.allclose(project_adjoint(x, beta, np.ones_like(x)), fd, atol=1e-8)
    assert project(np.array(project_inverse(0.27, beta)), beta) == pytest.approx(0.27, abs=1e-12)


@pytest.mark.parametrize("eta", [0.4, 0.6])
def test_eroded_and_dilated_projections_keep_the_ends_and_move_the_threshold(eta):
    beta = 8.0
    assert np.allclose(project(np.array([0.0, 1.0]), beta, eta), [0.0, 1.0], atol=1e-15)
    x = np.linspace(0.05, 0.95, 7)
    h = 1e-6
    fd = (project(x + h, beta, eta) - project(x - h, beta, eta)) / (2 * h)
    assert np.allclose(project_adjoint(x, beta, np.ones_like(x), eta), fd, atol=1e-8)
    # a higher threshold removes material (eroded), a lower one adds it (dilated)
    mid = np.array([0.5])
    assert (project(mid, beta, eta) < 0.5) == (eta > 0.5)


def test_smoothing_guards():
    with pytest.raises(DesignError, match="radius"):
        SmoothingFilter((8, 8, 8), 0.5, (False,) * 3)
    with pytest.raises(DesignError, match="one flag per axis"):
        SmoothingFilter((8, 8, 8), 2.0, (False,) * 2)
    with pytest.raises(DesignError, match="exceeds the grid"):
        SmoothingFilter((2, 8, 8), 5.0, (True, False, False))


def test_smoothing_and_projection_are_the_same_in_parts_as_in_one_pass(monkeypatch):
    # fields of 2^18 voxels are split over two threads (design.threads.MIN_PART); one thread gives the same values
    rng = np.random.default_rng(5)
    shape, mirror = (64, 64, 64), (True, False, True)
    x, g = rng.random(shape), rng.standard_normal(shape)

    def outputs():
        f = SmoothingFilter(shape, 3.7, mirror)
        return [f.apply(x), f.adjoint(g), project(x, 6.0, 0.4), project_adjoint(x, 6.0, g, 0.6)]

    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    parts = outputs()
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    for split, whole in zip(parts, outputs()):
        assert np.array_equal(split, whole)
