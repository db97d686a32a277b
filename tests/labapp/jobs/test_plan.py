"""sfr calibrate-sim --plan: which shapes to print to separate print physics (labapp.jobs.plan)."""
import csv
import json
import math

import numpy as np
import pytest
import trimesh

from labapp.cli.main import main
from labapp.jobs.plan import STEPS, Candidate, choose, expected_std, plan_prints, sensitivity

RESOLUTION = 24


def _box_release(extents, anisotropy):
    """Exact release of a box eroding at unit in-plane speed and `anisotropy` along z (tau to full dissolution)."""
    lx, ly, lz = extents
    end = min(lx / 2, ly / 2, lz / (2 * anisotropy))
    tau = np.linspace(0.0, end, 2001)
    left = np.clip(lx - 2 * tau, 0, None) * np.clip(ly - 2 * tau, 0, None) * np.clip(lz - 2 * anisotropy * tau, 0, None)
    return tau, lx * ly * lz - left


def test_sensitivity_matches_the_analytic_box():
    # a 10 x 10 x 4 box: C(t) = 1 - (10 - 2x)^2 (4 - 2 a x) / 400 with x = t / s, so at a = 1
    # dC/d(log a) = 2 x (10 - 2x)^2 / 400 and dC/d(log s) = -x dC/dx
    box = trimesh.creation.box((10.0, 10.0, 4.0))
    jac = sensitivity(box, ("log_seconds", "anisotropy"), points=8,
                      simulate_at=lambda mesh, physics: _box_release(mesh.extents, physics["anisotropy"]))
    x = np.linspace(0.0, 1.1 * 2.0, 9)[1:]
    alive = x < 2.0 / math.exp(0.1)     # the box alive at both steps (the release has a kink where it ends)
    d_log_a = 2 * x * (10 - 2 * x) ** 2 / 400
    d_x = ((4 * (10 - 2 * x) * (4 - 2 * x)) + 2 * (10 - 2 * x) ** 2) / 400
    # central differences of half-step 0.1 in log a and 0.05 in log s: second order, observed within 0.17%
    assert jac[alive, 1] == pytest.approx(d_log_a[alive], rel=0.005)
    assert jac[alive, 0] == pytest.approx(-x[alive] * d_x[alive], rel=0.005)
    assert STEPS["anisotropy"] == 0.1


def test_anisotropy_is_planned_with_a_flat_and_a_tall_print_and_the_error_shrinks_with_more_prints(tmp_path):
    plan = plan_prints("anisotropy", tmp_path / "plan", prints=4, resolution=RESOLUTION)
    first_two = [s.name for s in plan.steps[:2]]
    assert set(first_two) == {"flat", "tall"}
    # their build-direction extents: one much shorter than its width, one much taller
    stds = [s.std["anisotropy"] for s in plan.steps]
    assert all(b <= a for a, b in zip(stds, stds[1:]))
    assert stds[-1] < 0.9 * stds[1] and stds[1] < 0.3 * stds[0]
    rows = list(csv.DictReader(open(tmp_path / "plan" / "plan.csv")))
    assert [r["shape"] for r in rows[:2]] == first_two
    for name in first_two:
        mesh = trimesh.load(tmp_path / "plan" / f"{name}.stl")
        height, width = mesh.extents[2], max(mesh.extents[:2])
        assert (height < 0.5 * width) if name == "flat" else (height > 1.5 * width)
    doc = json.loads((tmp_path / "plan" / "plan.json").read_text())
    assert doc["parameters"] == ["log_seconds", "anisotropy"] and doc["expected_std"] == pytest.approx(plan.std)


def test_expected_std_scales_with_the_noise_and_the_prints():
    rng = np.random.default_rng(0)
    jac = [rng.standard_normal((10, 2)) * 0.1 for _ in range(4)]
    small, large = (expected_std(("log_seconds", "anisotropy"), jac, noise) for noise in (0.001, 0.002))
    # the prior (sd 1) is negligible against this information: the Cramer-Rao bound is linear in the noise
    assert large["anisotropy"] == pytest.approx(2 * small["anisotropy"], rel=1e-3)
    # four copies of the same information halve the standard error
    one = expected_std(("log_seconds", "anisotropy"), jac[:1], 0.001)
    four = expected_std(("log_seconds", "anisotropy"), jac[:1] * 4, 0.001)
    assert four["anisotropy"] == pytest.approx(0.5 * one["anisotropy"], rel=1e-3)
    # the greedy choice takes the informative candidate first
    blank = Candidate("blank", None, "no information", np.zeros((10, 2)))
    rich = Candidate("rich", None, "informative", jac[0])
    assert [s.name for s in choose([blank, rich], ("log_seconds", "anisotropy"), 1, 0.01, 10).steps] == ["rich"]
    assert math.isclose(choose([blank, rich], ("log_seconds", "anisotropy"), 2, 0.01, 10).steps[-1].std["anisotropy"],
                        expected_std(("log_seconds", "anisotropy"), [jac[0]], 0.01)["anisotropy"])


def test_plan_command_and_its_guards(tmp_path, capsys):
    assert main(["calibrate-sim", "--plan", "--physics", "anisotropy", "--plan-prints", "2", "--resolution",
                 str(RESOLUTION), "--out", str(tmp_path / "p")]) == 0
    out = capsys.readouterr().out
    assert "std anisotropy" in out and "flat" in out and "tall" in out
    assert main(["calibrate-sim", str(tmp_path / "set.csv"), "--plan", "--out", str(tmp_path / "q")]) == 2
    assert "give no SET.csv" in capsys.readouterr().err
    assert main(["calibrate-sim", "--out", str(tmp_path / "q")]) == 2
    assert "SET.csv" in capsys.readouterr().err
    assert main(["calibrate-sim", "--plan", "--plan-prints", "99", "--out", str(tmp_path / "q")]) == 2
    assert "--plan-prints 99" in capsys.readouterr().err
