"""Anisotropic erosion (z speed = anisotropy x in-plane speed): analytic releases, gradient, guards."""
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from design.forward.fmm import march, upwind_spacing
from design.forward.simulator import DesignError, release_gradient, simulate, total_time

CENTRE = (0.013, -0.021, 0.017)  # off the grid: no face or centre on a voxel boundary


def _centres(n, half_width=1.0):
    dx = 2 * half_width / n
    c = (np.arange(n) + 0.5) * dx - half_width
    x, y, z = np.meshgrid(c, c, c, indexing="ij")
    return dx, x - CENTRE[0], y - CENTRE[1], z - CENTRE[2]


BOX = (1.3, 0.9, 1.1)
RADIUS = 0.6


def _box(n, a):
    """Voxelised box and its release: the faces normal to z recede a times faster, so what remains at
    depth t is (Lx - 2t)(Ly - 2t)(Lz - 2 a t)."""
    dx, x, y, z = _centres(n)
    rho = ((np.abs(x) < BOX[0] / 2) & (np.abs(y) < BOX[1] / 2) & (np.abs(z) < BOX[2] / 2)).astype(float)
    lx, ly, lz = BOX

    def exact(t):
        return lx * ly * lz - np.clip(lx - 2 * t, 0, None) * np.clip(ly - 2 * t, 0, None) * np.clip(lz - 2 * a * t, 0, None)
    return rho, dx, exact


def _ellipsoid(n, a):
    """The ellipsoid with semi-axes (R, R, a R) is the ball of radius R in the travel-time metric (z / a),
    so at depth t the ellipsoid (R - t, R - t, a (R - t)) remains: C(t) = 4/3 pi a (R^3 - (R - t)^3)."""
    dx, x, y, z = _centres(n)
    rho = (x * x + y * y + (z / a) ** 2 < RADIUS ** 2).astype(float)

    def exact(t):
        return 4 / 3 * np.pi * a * (RADIUS ** 3 - np.clip(RADIUS - t, 0, None) ** 3)
    return rho, dx, exact


def _error(shape, n, a):
    rho, dx, exact = shape(n, a)
    r = simulate(rho, dx, anisotropy=a, total_time_mm=0.8)
    truth = exact(r.tau_mm)
    assert r.released_mm3[0] == 0.0  # the bath touches the solid at tau = 0
    return np.abs(r.released_mm3 - truth).max() / exact(10.0)


# observed at 48 voxels across (largest |C - C*| / V): box 1.32 % (a 0.6), 1.44 % (a 1.6), 1.25 % isotropic;
# ellipsoid 5.74 % (a 0.6: 8.6 voxels on its short semi-axis), 3.87 % (a 1.6), 3.86 % isotropic sphere.
# Bounds are 1.25 x those, so a regression fails.
BOUNDS = {("box", 0.6): 0.0165, ("box", 1.6): 0.018, ("ellipsoid", 0.6): 0.072, ("ellipsoid", 1.6): 0.0485}


@pytest.mark.parametrize("name, a", sorted(BOUNDS))
def test_release_matches_analytic(name, a):
    shape = {"box": _box, "ellipsoid": _ellipsoid}[name]
    fine = _error(shape, 48, a)
    assert fine < BOUNDS[name, a]
    if name == "ellipsoid":  # first-order convergence of a curved front (observed ratios 1.8-1.9)
        assert _error(shape, 24, a) / fine > 1.6
    if (name, a) != ("ellipsoid", 1.6):
        # the isotropic model on the same solid misses by far more: observed 5.7 % and 8.8 % (boxes),
        # 14.7 % (flat ellipsoid); on the tall ellipsoid its largest miss happens to be only 2.0 %
        rho, dx, exact = shape(48, a)
        iso = simulate(rho, dx, total_time_mm=0.8)
        assert np.abs(iso.released_mm3 - exact(iso.tau_mm)).max() / exact(10.0) > 2 * fine


@pytest.mark.parametrize("a", [0.6, 1.6])
def test_gradient_matches_central_differences(a):
    rng = np.random.default_rng(3)
    g = gaussian_filter(rng.standard_normal((10, 12, 9)), 1.5)
    g = (g - g.mean()) / g.std()
    rho = 0.001 + 0.998 / (1.0 + np.exp(-3.0 * (g + 0.5)))
    base = simulate(rho, 0.3, anisotropy=a, check=True)
    target = 0.9 * base.released_mm3
    w_u = rng.standard_normal(rho.shape)

    def J(x, release=None):
        r = release or simulate(x, 0.3, anisotropy=a, total_time_mm=base.total_time_mm)
        resid = r.released_mm3 - target
        return 0.5 * r.dtau_mm * np.sum(resid ** 2) / r.total_time_mm + np.sum(w_u * r.u_mm), resid * r.dtau_mm / r.total_time_mm

    grad = release_gradient(base, J(rho, base)[1], w_u)
    direction = gaussian_filter(rng.standard_normal(rho.shape), 1.0)
    eps = 1e-6
    fd = (J(rho + eps * direction)[0] - J(rho - eps * direction)[0]) / (2 * eps)
    # the isotropic test's bound (tests/design/forward/test_forward_gradient.py)
    assert abs(np.sum(grad * direction) - fd) <= 1e-5 * abs(fd)


def test_plane_fronts_and_total_time():
    # the middle of a wide slab erodes through its z faces only: layer k has u = k dx / a and its ramp
    # spans dx / a; the in-plane faces are 10 mm away
    m = march(np.ones((20, 20, 10)), 0.5, (True, True, False), anisotropy=2.0)
    u = m.interior(m.u_pad)[0, 0]
    np.testing.assert_allclose(u[:5], 0.25 * np.arange(1, 6), rtol=1e-14)
    np.testing.assert_allclose(upwind_spacing(m)[0, 0], 0.25)
    assert upwind_spacing(m)[-1, 0, 5] == 0.5  # next to an x face: the in-plane spacing
    # T of a thin all-solid slab: two layers from the z faces at half the in-plane speed
    assert total_time((40, 40, 4), 0.5, anisotropy=0.5) == pytest.approx(2.0, rel=1e-14)


def test_guards():
    with pytest.raises(DesignError, match="anisotropy"):
        simulate(np.ones((4, 4, 4)), 0.1, anisotropy=0.0)
    with pytest.raises(DesignError, match="3D grid"):
        simulate(np.ones((4, 4)), 0.1, anisotropy=1.2)
    # anisotropy 1 is the isotropic model itself
    rho = np.random.default_rng(0).uniform(0, 1, (6, 7, 8))
    a, b = simulate(rho, 0.2), simulate(rho, 0.2, anisotropy=1.0)
    assert np.array_equal(a.released_mm3, b.released_mm3) and np.array_equal(a.u_mm, b.u_mm)
