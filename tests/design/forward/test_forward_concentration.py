"""Appendix B time remapping against the closed form for a linear curve, and its derivatives."""
import numpy as np
import pytest

from design import DesignError
from design.forward.concentration import Saturation, release_at_times, release_at_times_vjp, remap_time, remap_time_vjp

SAT = Saturation(rate_mm_per_s=2e-4, capacity_mm3=2000.0)


def test_linear_release_matches_closed_form():
    # a planar front of area A: C = A tau, so d tau/dt = r (1 - A tau / cap) integrates to
    # t(tau) = -(cap / (r A)) ln(1 - A tau / cap); the remapping is exact for a linear curve
    area, tau = 1000.0, np.linspace(0.0, 1.5, 301)
    t = remap_time(tau, area * tau, SAT)
    exact = -SAT.capacity_mm3 / (SAT.rate_mm_per_s * area) * np.log1p(-area * tau / SAT.capacity_mm3)
    np.testing.assert_allclose(t, exact, rtol=1e-12, atol=1e-9)


def test_large_capacity_is_the_constant_rate_clock():
    tau = np.linspace(0.0, 2.0, 11)
    t = remap_time(tau, 50.0 * tau ** 2, Saturation(1e-3, 1e12))
    np.testing.assert_allclose(t, tau / 1e-3, rtol=1e-9)


def test_vjps_match_central_differences():
    rng = np.random.default_rng(0)
    tau = np.linspace(0.0, 6.0, 121)
    curve = 1300.0 * (1.0 - np.exp(-tau)) + 0.001 * tau  # flat tails exercise the series branch
    direction = rng.standard_normal(curve.size)
    t_bar = rng.standard_normal(curve.size)
    queries = np.linspace(-10.0, 30000.0, 57)
    q_bar = rng.standard_normal(queries.size)
    eps = 1e-4
    plus, minus = curve + eps * direction, curve - eps * direction
    fd_t = (t_bar @ remap_time(tau, plus, SAT) - t_bar @ remap_time(tau, minus, SAT)) / (2 * eps)
    # smooth in C (the series branch agrees with the exact one to 1e-12): 1e-7 covers round-off
    assert remap_time_vjp(tau, curve, SAT, t_bar) @ direction == pytest.approx(fd_t, rel=1e-7)
    fd_q = (q_bar @ release_at_times(queries, tau, plus, SAT)
            - q_bar @ release_at_times(queries, tau, minus, SAT)) / (2 * eps)
    exact_q = release_at_times_vjp(queries, tau, curve, SAT, q_bar) @ direction
    # piecewise linear in the breakpoints; no query sits near one, so differences are exact to round-off
    assert exact_q == pytest.approx(fd_q, rel=1e-6)


def test_guards():
    with pytest.raises(DesignError, match="the solvent saturates"):
        remap_time(np.linspace(0, 1, 5), np.linspace(0, 2500, 5), SAT)
    with pytest.raises(DesignError, match="capacity_mm3"):
        Saturation(1e-3, 0.0)
    sat = Saturation.from_solvent(1e-3, solvent_ml=100.0, saturation_g_per_ml=0.05, solid_density_g_per_cm3=1.25)
    assert sat.capacity_mm3 == pytest.approx(4000.0)  # 5 g of solid at 1.25 g/cm^3
