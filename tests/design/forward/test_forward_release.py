"""The ramp release curve (eqs. 6-7) by second differences, against the literal O(N K) sum."""
import numpy as np
import pytest

from design.forward.release import ramp_release, ramp_release_vjp


def _literal(u, length, weight, tau):
    # eq. (6)-(7) summed term by term, each ramp starting no earlier than tau = 0
    start = np.where((u > 0) & (u < length), 0.0, u - length)
    s = (tau[None, :] - start[:, None]) / (u - start)[:, None]
    return (weight[:, None] * np.clip(s, 0.0, 1.0)).sum(axis=0)


def _cases():
    rng = np.random.default_rng(2)
    u = rng.uniform(0.0, 3.0, 200)
    length = rng.uniform(1e-7, 0.5, 200)
    u[:5] = [0.0113, 0.2037, 2.5013, 3.4011, 1.00042]  # off the tau grid (kinks)
    length[:5] = [0.3, 0.25, 1.0, 0.5, 1e-6]  # the first two would start before tau = 0
    u[5], length[5] = -0.2, 0.1  # wholly before tau = 0: released at the first sample
    weight = rng.uniform(0.0, 2.0, 200)
    weight[7] = 0.0
    return u, length, weight


@pytest.mark.parametrize("k_count", [2, 31, 1001])
def test_double_cumsum_equals_literal_sum(k_count):
    u, length, weight = _cases()
    dtau = 3.0 / (k_count - 1)
    tau = np.arange(k_count) * dtau
    # same piecewise-linear function; a ramp of length L = 1e-7 has slope w / L, so the float spacing
    # of u (~4e-16 mm) alone moves samples on it by ~ w 4e-16 / 1e-7 ~ 1e-8 w: hence atol 1e-8
    np.testing.assert_allclose(ramp_release(u, length, weight, dtau, k_count),
                               _literal(u, length, weight, tau), rtol=0, atol=1e-8)


def test_vjp_matches_central_differences():
    u, length, weight = _cases()
    # steep void-like ramps make the curve ~1e-8 uncertain (see above), too noisy for differences
    length = np.maximum(length, 0.01)
    k_count, dtau = 301, 0.01
    g = np.random.default_rng(3).standard_normal(k_count)
    u_bar, length_bar, weight_bar = ramp_release_vjp(u, length, weight, dtau, g)
    d = np.random.default_rng(4).standard_normal((3, u.size))
    d[1] *= 0.1 * length  # keep lengths positive

    def J(uu, ll, ww):
        return float(g @ ramp_release(uu, ll, ww, dtau, k_count))

    eps = 1e-6
    fd = (J(u + eps * d[0], length + eps * d[1], weight + eps * d[2])
          - J(u - eps * d[0], length - eps * d[1], weight - eps * d[2])) / (2 * eps)
    exact = u_bar @ d[0] + length_bar @ d[1] + weight_bar @ d[2]
    # piecewise-linear in (u, L): central differences are exact away from kinks; 1e-6 covers round-off
    assert exact == pytest.approx(fd, rel=1e-6)


def test_no_ramp_releases_before_tau_zero():
    # ramps of eq. (6) that would start before 0 (u < L) start at 0: nothing is released at tau = 0,
    # and each such voxel is released linearly over (0, u)
    u = np.array([0.05, 0.3, 0.7])
    length = np.array([0.1, 1.0, 0.5])
    weight = np.array([1.0, 2.0, 4.0])
    curve = ramp_release(u, length, weight, 0.05, 21)
    assert curve[0] == 0.0
    np.testing.assert_allclose(curve[[1, 2, 6, 10, 14]],
                               [1.0 + 2 * 0.05 / 0.3, 1.0 + 2 * 0.1 / 0.3, 3.0 + 4 * 0.1 / 0.5, 3.0 + 4 * 0.3 / 0.5, 7.0],
                               rtol=1e-12)
