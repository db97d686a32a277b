"""calibrate-sim --plan with the wetting lag: its sensitivity is a shift of the time axis (no simulation)."""
import numpy as np
import pytest
import trimesh

from analysis.physics_grid import LAG
from labapp.jobs.plan import PLAN_SECONDS_PER_MM, expected_std, sensitivity


def _sphere_at(radius):
    def simulate_at(mesh, physics):
        tau = np.linspace(0.0, radius, 2001)
        return tau, 4.0 / 3.0 * np.pi * (radius ** 3 - (radius - tau) ** 3)
    return simulate_at


def test_the_lag_column_is_the_release_rate_over_the_time_scale():
    radius, points = 6.0, 12
    jac = sensitivity(trimesh.creation.icosphere(2, radius=radius), ("log_seconds", LAG), points=points,
                      simulate_at=_sphere_at(radius))
    x = np.linspace(0.0, 1.1 * radius, points + 1)[1:]
    # C(t) = V((t - lag) / s): dC/dlag = -C'(x) / s, C'(x) = 3 (1 - x / R)^2 / R inside the sphere, 0 after
    exact = -np.where(x < radius, 3.0 * (1.0 - x / radius) ** 2 / radius, 0.0) / PLAN_SECONDS_PER_MM
    np.testing.assert_allclose(jac[:, 1], exact, atol=2e-3 * np.max(np.abs(exact)))
    # two spheres of different sizes separate the lag from the time scale; one alone barely does
    other = sensitivity(trimesh.creation.icosphere(2, radius=2.0), ("log_seconds", LAG), points=points,
                        simulate_at=_sphere_at(2.0))
    one, two = (expected_std(("log_seconds", LAG), j, 0.01)[LAG] for j in ([jac], [jac, other]))
    assert two < 0.5 * one
    assert two == pytest.approx(expected_std(("log_seconds", LAG), [other, jac], 0.01)[LAG])
