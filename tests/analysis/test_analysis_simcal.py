"""analysis.simcal: hidden time and mass scales recovered from synthetic runs of analytic shapes.

The shapes' simulated releases are exact (sphere, box, cylinder, tube: a uniformly receding surface), so
every deviation comes from the hidden per-object spread (1.5% rate, 2% density, seeded), the 0.2%-of-mass
measurement noise, an early stop or a drop-time error. Tolerances are the acceptance figures: scales
within 2%, leave-one-out within 3% RMS of the final mass.
"""
import math

import numpy as np
import pytest

from analysis import AnalysisError, ShapeRun, SimCal, fit_simcal, leave_one_out


def _sphere(r):
    tau = np.linspace(0.0, r, 801)
    return tau, 4.0 / 3.0 * np.pi * (r ** 3 - (r - tau) ** 3)


def _box(a, b, c):
    tau = np.linspace(0.0, min(a, b, c) / 2.0, 801)
    return tau, a * b * c - (a - 2 * tau) * (b - 2 * tau) * (c - 2 * tau)


def _cylinder(r, h):
    tau = np.linspace(0.0, min(r, h / 2.0), 801)
    return tau, np.pi * (r * r * h - (r - tau) ** 2 * (h - 2 * tau))


def _tube(r_out, r_in, h):
    tau = np.linspace(0.0, min((r_out - r_in) / 2.0, h / 2.0), 801)
    return tau, np.pi * ((r_out ** 2 - r_in ** 2) * h - ((r_out - tau) ** 2 - (r_in + tau) ** 2) * (h - 2 * tau))


SHAPES = {"sphere": _sphere(6.8), "slab": _box(20.0, 12.0, 5.5), "rod": _cylinder(4.0, 28.0),
          "tube": _tube(9.0, 5.0, 14.0)}
TRUTH = SimCal("constant", 1450.0, 1.27e-3)


def _runs(truth=TRUTH, stop_fraction=None, offset_s=0.0, water=(500.0, 500.0, 500.0, 500.0), seed=1, interval_s=30.0):
    """One measured run per shape on the hidden truth; the second stopped early, the third's drop shifted."""
    rng = np.random.default_rng(seed)
    runs = []
    for i, (name, (tau, vol)) in enumerate(SHAPES.items()):
        cal = SimCal(truth.model, truth.seconds_per_mm * (1 + 0.015 * rng.standard_normal()),
                     truth.g_per_mm3 * (1 + 0.02 * rng.standard_normal()), truth.saturation_g_per_kg)
        mass = cal.g_per_mm3 * vol[-1]
        end = cal.clock_s(tau, vol * cal.g_per_mm3, water[i])[-1]
        t = np.arange(interval_s, 1.15 * end, interval_s)
        grams = cal.to_physical(tau, vol, t, water[i]) + 0.002 * mass * rng.standard_normal(t.size)
        if stop_fraction is not None and i == 1:
            keep = grams < stop_fraction * mass
            t, grams = t[keep], grams[keep]
        if i == 2:
            t = t + offset_s
        runs.append(ShapeRun(name, tau, vol, t, grams, mass, water[i]))
    return runs


def _check(runs, model="constant", truth=TRUTH):
    fit = fit_simcal(runs, model)
    assert fit.cal.seconds_per_mm == pytest.approx(truth.seconds_per_mm, rel=0.02)
    assert fit.cal.g_per_mm3 == pytest.approx(truth.g_per_mm3, rel=0.02)
    loo = leave_one_out(runs, model)
    assert [s.name for s in loo] == list(SHAPES)
    assert max(s.rel_rmse for s in loo) < 0.03
    return fit, loo


def test_complete_runs_recover_both_scales_and_predict_within_3_percent():
    fit, loo = _check(_runs())
    assert max(abs(o) for o in fit.offsets_s) < 15.0
    assert fit.g_per_mm3_per_shape[0] == pytest.approx(_runs()[0].mass_g / SHAPES["sphere"][1][-1])


def test_a_run_stopped_at_80_percent_and_a_30_s_drop_error_still_calibrate():
    runs = _runs(stop_fraction=0.8, offset_s=30.0)
    assert runs[1].released_g.max() < 0.8 * runs[1].mass_g
    fit, _ = _check(runs)
    assert fit.offsets_s[2] == pytest.approx(30.0, abs=15.0)   # the object's own 1.5% rate spread shifts it too


def test_without_offsets_the_drop_error_biases_only_its_own_run():
    fit = fit_simcal(_runs(offset_s=30.0), max_offset_s=0.0)
    assert fit.offsets_s == (0.0, 0.0, 0.0, 0.0)
    assert fit.cal.seconds_per_mm == pytest.approx(TRUTH.seconds_per_mm, rel=0.02)


def test_saturation_model_recovers_c_sat_and_beats_the_constant_model_on_a_saturating_bath():
    truth = SimCal("saturation", 1450.0, 1.27e-3, 40.0)
    runs = _runs(truth, water=(500.0, 300.0, 500.0, 400.0))   # different water masses, one c_sat
    fit, loo = _check(runs, "saturation", truth)
    assert fit.cal.saturation_g_per_kg == pytest.approx(40.0, rel=0.15)
    constant = leave_one_out(runs, "constant")
    assert np.mean([s.rel_rmse for s in loo]) < np.mean([s.rel_rmse for s in constant])


def test_maps_round_trip_between_units():
    cal = SimCal("saturation", 1200.0, 1.3e-3, 30.0)
    tau, vol = SHAPES["sphere"]
    t = cal.clock_s(tau, vol * cal.g_per_mm3, 500.0)
    back_tau, back_vol = cal.to_simulation(t, vol * cal.g_per_mm3, 500.0)
    np.testing.assert_allclose(back_tau, tau, atol=2e-3 * tau[-1])
    np.testing.assert_allclose(back_vol, vol, rtol=1e-12)
    const = SimCal("constant", 1200.0, 1.3e-3)
    np.testing.assert_allclose(const.to_physical(tau, vol, [-5.0, 600.0, 1e9], 500.0),
                               [0.0, np.interp(0.5, tau, vol) * 1.3e-3, vol[-1] * 1.3e-3])


@pytest.mark.parametrize("change, message", [
    (dict(mass_g=0.5), r"sphere: weighed 0.5 g over the simulated 1317.1 mm\^3 means 0.38 g/cm\^3, outside 0.8-2"),
    (dict(mass_g=3.0), r"2.28 g/cm\^3"),
    (dict(released_g=None), r"sphere: the run shows no release"),
    (dict(water_g=math.nan), r"water_g = nan must be a positive"),
])
def test_bad_shapes_are_named(change, message):
    tau, vol = SHAPES["sphere"]
    t = np.arange(0.0, 600.0, 30.0)
    fields = dict(name="sphere", tau_mm=tau, released_mm3=vol, t_s=t, released_g=np.zeros_like(t) + 1e-3,
                  mass_g=1.7, water_g=500.0)
    if "released_g" not in change:
        fields["released_g"] = np.linspace(0.0, 1.0, t.size)
    fields.update({k: v for k, v in change.items() if v is not None})
    with pytest.raises(AnalysisError, match=message):
        ShapeRun(**fields)


def test_bad_calls():
    runs = _runs()
    with pytest.raises(AnalysisError, match="model 'cubic'"):
        fit_simcal(runs, "cubic")
    with pytest.raises(AnalysisError, match="at least two"):
        leave_one_out(runs[:1])
    with pytest.raises(AnalysisError, match="unique"):
        fit_simcal([runs[0], runs[0]])
