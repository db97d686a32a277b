"""Two-material prints on the simulated bench, and the barrier speed recovered from runs of coated prints."""
import numpy as np
import pytest
import trimesh

from analysis.barrier_fit import CoatedRun, fit_barrier_runs
from analysis.errors import AnalysisError
from design.forward.reference import reference_release
from labapp.acquisition.simbench import Material, sample_release

MATERIAL = Material(seconds_per_mm=1500.0, density_g_per_cm3=1.3, barrier_speed=0.3)
COAT_MM = 0.5


def _prints():
    drug = trimesh.creation.box((4.0, 4.0, 2.0))
    coat = trimesh.creation.box((4.0 + 2 * COAT_MM, 4.0 + 2 * COAT_MM, 2.0 + 2 * COAT_MM))
    return drug, coat


@pytest.mark.slow
def test_a_coated_print_releases_its_drug_only_after_the_coat():
    drug, coat = _prints()
    plain = sample_release("box", 0, material=MATERIAL, mesh=drug)
    coated = sample_release("box", 0, material=MATERIAL, mesh=drug, barrier=coat)
    # the clear barrier adds no mass: the same drug mass, all of it behind a delay of c / s = 1.667 mm of drug
    assert coated.mass_g == pytest.approx(plain.mass_g, rel=1e-6)
    k = coated.truth["seconds_per_mm"]
    assert coated.conc_g_per_kg(0.99 * k * COAT_MM / 0.3) == 0.0 and coated.truth["barrier_speed"] == 0.3
    assert coated.duration_s == pytest.approx(plain.duration_s + k * COAT_MM / 0.3, rel=0.01)


@pytest.mark.slow
def test_the_barrier_speed_is_recovered_from_three_coated_prints():
    drug, coat = _prints()
    rng = np.random.default_rng(3)
    runs = []
    for index in range(3):   # each print has its own rate and density, as on the bench
        run = sample_release("box", index, material=MATERIAL, mesh=drug, barrier=coat)
        t = np.arange(0.0, run.duration_s * 1.05, 30.0)
        mass = np.interp(t, run.t_s, run.released_g) + rng.normal(0.0, 0.002 * run.mass_g, t.size)
        runs.append((t, mass))
    model = reference_release(drug, np.linspace(0.0, 1.2, 241))
    runs = [CoatedRun(t, m, COAT_MM, model.tau_mm, model.released_mm3) for t, m in runs]
    seconds_per_mm, g_per_mm3 = MATERIAL.seconds_per_mm, MATERIAL.density_g_per_cm3 * 1e-3
    fit = fit_barrier_runs(runs, seconds_per_mm, g_per_mm3)
    assert abs(fit.speed - 0.3) <= 3 * fit.error and fit.error < 0.01
    assert len(fit.per_run) == 3 and all(abs(s - 0.3) < 0.01 for s in fit.per_run)
    with pytest.raises(AnalysisError, match="no runs"):
        fit_barrier_runs([], seconds_per_mm, g_per_mm3)
