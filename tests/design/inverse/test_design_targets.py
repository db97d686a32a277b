"""Targets: CSV resampling, analytic families, mesh targets, feasibility report."""
import numpy as np
import pytest

from design.errors import DesignError
from design.files.targets_io import target_from_csv
from design.forward.simulator import simulate
from design.inverse.targets import (
    SPHERE_AREA_COEF,
    Target,
    check_feasibility,
    constant_acceleration,
    resample_monotone,
    target_from_density,
)


def test_zero_order_target_has_constant_rate_then_stops():
    t = constant_acceleration(10.0, 300.0, 4.0, rate_ratio=1.0)
    rate = np.diff(t.released_mm3) / np.diff(t.tau_mm)
    during = t.tau_mm[1:] <= 4.0
    assert np.allclose(rate[during], 75.0) and np.allclose(rate[t.tau_mm[:-1] >= 4.0], 0.0, atol=1e-9)
    assert t.final_mm3 == pytest.approx(300.0)


def test_constant_acceleration_rate_ratio():
    t = constant_acceleration(10.0, 300.0, 5.0, rate_ratio=3.0)
    c2 = np.diff(t.released_mm3, 2)[: 490]
    assert np.allclose(c2, c2[0], rtol=1e-6)  # C'' constant until the end (Fig. 7)
    rate = np.diff(t.released_mm3) / np.diff(t.tau_mm)
    assert rate[495] / rate[0] == pytest.approx(3.0, rel=0.01)


def test_csv_is_resampled_monotonically(tmp_path):
    path = tmp_path / "curve.csv"
    path.write_text("tau_mm,released_mm3\n0.5,10\n1,50\n2,51\n3,100\n")
    t = target_from_csv(path, 4.0, samples=401)
    assert t.released_mm3[0] == 0.0 and t.released_mm3[-1] == pytest.approx(100.0)
    assert np.all(np.diff(t.released_mm3) >= -1e-12)  # PCHIP preserves monotone data
    assert t.released_mm3[np.searchsorted(t.tau_mm, 1.0)] == pytest.approx(50.0)


def test_csv_errors_name_the_problem(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("tau_mm,released_mm3\n0,0\n1,5\n2,4\n")
    with pytest.raises(DesignError, match="decreases at tau = 2"):
        target_from_csv(bad, 4.0)
    with pytest.raises(DesignError, match="cannot read"):
        target_from_csv(tmp_path / "missing.csv", 4.0)
    with pytest.raises(DesignError, match="strictly increasing"):
        resample_monotone(np.array([0.0, 1.0, 1.0]), np.array([0.0, 1.0, 2.0]), np.linspace(0, 1, 5))


def test_sphere_release_is_feasible_and_fast_enough_release_is_not():
    n = 24
    c = np.arange(n) - n / 2 + 0.5
    x, y, z = np.meshgrid(c, c, c, indexing="ij")
    ball = (x ** 2 + y ** 2 + z ** 2 < 10 ** 2).astype(float)
    t = target_from_density(ball, 0.5, 6.0, "ball")
    area = 6 * (n * 0.5) ** 2
    report = check_feasibility(t, (n * 0.5) ** 3, dx_mm=0.5, domain_area_mm2=area)
    assert report.feasible, report.text()
    # the same total released at a constant rate over a long time violates the bound: a 500 mm^3
    # ball has area 305 mm^2, so 500 mm^3 over 5 mm (100 mm^2) is too slow at the start
    slow = constant_acceleration(6.0, 500.0, 5.0)
    report = check_feasibility(slow, (n * 0.5) ** 3)
    assert not report.feasible and "isoperimetric" in report.text()
    a, b, worst = report.iso_intervals[0]
    assert a == 0.0 and worst == pytest.approx(100.0 / (SPHERE_AREA_COEF * 500.0 ** (2 / 3)), rel=0.02)


def test_feasibility_reports_start_monotonicity_and_domain():
    tau = np.linspace(0, 1, 11)
    report = check_feasibility(Target(tau, 5.0 + tau, "offset"), 100.0)
    assert "start at 0" in report.text()
    report = check_feasibility(Target(tau, np.r_[tau[:6], tau[5:10] - 0.2] * 1e-3, "dip"), 100.0)
    assert "decreases" in report.text()
    report = check_feasibility(Target(tau, 500.0 * tau, "big"), 100.0)
    assert "exceeds the domain volume" in report.text()


def test_target_from_density_uses_the_design_grid():
    rho = np.zeros((8, 8, 8))
    rho[2:6, 2:6, 2:6] = 1.0
    t = target_from_density(rho, 1.0, 3.0, "cube", samples=301)
    ref = simulate(rho, 1.0, total_time_mm=3.0, dtau_mm=0.01)
    assert t.tau_mm.size == 301 and np.allclose(t.released_mm3, ref.released_mm3)
    assert t.final_mm3 == pytest.approx(64.0)
