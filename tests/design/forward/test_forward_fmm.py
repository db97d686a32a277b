"""Fast marching (eq. 5) and its adjoint sweep (eq. 10), against exact solutions and scikit-fmm."""
import numpy as np
import pytest
import skfmm
from scipy.ndimage import gaussian_filter

from design.errors import DesignError
from design.forward.fmm import MarchBuffers, eikonal_residual, march, march_adjoint


def _field(shape, seed):
    rng = np.random.default_rng(seed)
    g = gaussian_filter(rng.standard_normal(shape), 1.5)
    g = (g - g.mean()) / g.std()
    rho = 1.0 / (1.0 + np.exp(-4.0 * (g + 0.5)))
    return rho + (1.0 - rho) * 1e-6


def test_plane_front_is_exact_distance_to_far_face():
    # a slab thin in x, wide in y and z: near the middle the front is planar and eq. (5) is exact,
    # u_k = (k + 1) dx counted from the nearer x face
    m = march(np.ones((7, 41, 41)), 0.5, (False,) * 3)
    u = m.interior(m.u_pad)[:, 20, 20]
    np.testing.assert_allclose(u, 0.5 * np.minimum(np.arange(1, 8), np.arange(7, 0, -1)), rtol=0, atol=1e-15)


def test_mirror_face_does_not_dissolve():
    m = march(np.ones((3, 41, 41)), 1.0, (True, False, False))
    np.testing.assert_allclose(m.interior(m.u_pad)[:, 20, 20], [3.0, 2.0, 1.0], rtol=0, atol=1e-15)


def test_corner_voxel_uses_three_terms():
    # the corner voxel of a cube touches padding on three axes: 3 (u - 0)^2 = dx^2
    m = march(np.ones((3, 3, 3)), 1.0, (False,) * 3)
    assert m.interior(m.u_pad)[0, 0, 0] == pytest.approx(1 / np.sqrt(3), abs=1e-15)


@pytest.mark.parametrize("shape, mirror", [((40, 37), (False, False)), ((40, 37), (True, False)),
                                           ((18, 20, 17), (False, False, False)),
                                           ((18, 20, 17), (True, False, True))])
def test_residual_of_eq5_is_round_off(shape, mirror):
    m = march(_field(shape, 3), 0.2, mirror)
    # the residual is a length; round-off of u (~4 mm here) is ~1e-15 mm, so 1e-12 mm leaves margin
    # while a wrong stencil (an error of order n dx = 0.2 mm, or 2e-7 mm in void) would fail it
    assert np.abs(eikonal_residual(m)).max() < 1e-12
    assert np.all(np.diff(m.u_pad[m.order]) >= 0), "visit order must be ascending in u"


def test_matches_skfmm_first_order_on_a_void_free_field():
    # phi = 0 on the padding centres and 1 inside reproduces our boundary condition exactly
    n = 0.5 + 0.5 * _field((24, 22, 20), 5)
    phi = np.pad(np.ones(n.shape), 1)
    ref = skfmm.travel_time(phi, np.pad(1.0 / n, 1, constant_values=1.0), dx=0.1, order=1)[1:-1, 1:-1, 1:-1]
    m = march(n, 0.1, (False,) * 3)
    # both solve the same quadratic per voxel; away from void/solid corners they agree to round-off
    np.testing.assert_allclose(m.interior(m.u_pad), ref, rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize("shape, mirror", [((15, 13), (False, False)), ((15, 13), (True, False)),
                                           ((9, 8, 10), (False, False, False)), ((9, 8, 10), (True, True, False))])
def test_adjoint_matches_central_differences(shape, mirror):
    n = _field(shape, 7)
    rng = np.random.default_rng(8)
    w = rng.standard_normal(shape)
    d = rng.standard_normal(shape) * n  # relative perturbation, keeps void voxels positive
    m = march(n, 0.3, mirror)
    grad = march_adjoint(m, w)

    def J(x):
        mm = march(x, 0.3, mirror)
        return float(np.sum(w * mm.interior(mm.u_pad)))

    eps = 1e-6
    fd = (J(n * (1 + eps * d / n)) - J(n * (1 - eps * d / n))) / (2 * eps)
    # central differences of a piecewise-smooth function: O(eps^2) plus round-off ~1e-10/eps
    assert abs(fd - np.sum(grad * d)) <= 1e-6 * abs(fd)


def test_reused_buffers_give_identical_solves_and_gradients():
    shape, mirror = (12, 11, 10), (True, False, True)
    buffers = MarchBuffers(shape)
    w = np.random.default_rng(2).standard_normal(shape)
    for seed in (1, 2):  # the second solve reuses everything the first one wrote
        n = _field(shape, seed)
        fresh = march(n, 0.2, mirror)
        reused = march(n, 0.2, mirror, buffers)
        assert reused.rec.ctypes.data % 64 == 0, "records must start on a cache line"
        np.testing.assert_array_equal(reused.interior(reused.u_pad), fresh.interior(fresh.u_pad))
        np.testing.assert_array_equal(march_adjoint(reused, w), march_adjoint(fresh, w))


def test_a_solve_overwritten_by_a_later_one_refuses_its_adjoint():
    shape = (6, 7, 8)
    buffers = MarchBuffers(shape)
    first = march(_field(shape, 1), 0.2, (False,) * 3, buffers)
    march(_field(shape, 2), 0.2, (False,) * 3, buffers)
    with pytest.raises(DesignError, match="overwritten"):
        march_adjoint(first, np.ones(shape))
    with pytest.raises(DesignError, match="overwritten"):
        _ = first.u_pad
    with pytest.raises(DesignError, match=r"grid shape \(6, 7, 8\)"):
        march(np.ones((6, 7, 9)), 0.2, (False,) * 3, buffers)
