"""The discretisation term of the print physics' uncertainty (analysis.physics_fit.refit_physics, with_discretisation).

Known answers: an anisotropic box erodes as V(tau) = (W - 2 tau)^2 (L - 2 a tau), so the "measured" runs of two
boxes (flat, tall) made with a hidden anisotropy are refitted to it from any nearby start; a simulator whose
anisotropy is biased (the voxels' error, here a known factor) is refitted to the biased value, and the difference
between the two refits, extrapolated as a first-order error, bounds the bias.
"""
import math

import numpy as np
import pytest

from analysis import AnalysisError, ShapeRun
from analysis.physics_fit import refit_physics, with_discretisation

SECONDS_PER_MM, DENSITY, WATER_G = 1500.0, 1.3e-3, 500.0
BOXES = {"flat": (16.0, 4.0), "tall": (6.0, 18.0)}   # (width W, height L), mm


def _box_release(width, height, a, tau):
    v0 = width ** 2 * height
    left = np.clip(width - 2 * tau, 0, None) ** 2 * np.clip(height - 2 * a * tau, 0, None)
    return v0 - left


def _shapes_at_factory(true_a, bias=1.0):
    def shapes_at(values):
        out = []
        for name, (w, h) in BOXES.items():
            tau = np.linspace(0.0, 0.5 * min(w, h / min(true_a, 0.5)) + 1.0, 400)
            sim = _box_release(w, h, values["anisotropy"] * bias, tau)
            t = np.arange(30.0, SECONDS_PER_MM * tau[-1], 30.0)
            mass = DENSITY * w ** 2 * h
            grams = DENSITY * _box_release(w, h, true_a, t / SECONDS_PER_MM)
            out.append(ShapeRun(name, tau, sim, t, grams, mass, WATER_G))
        return out
    return shapes_at


def test_refit_recovers_a_hidden_anisotropy_from_a_nearby_start():
    values = refit_physics(_shapes_at_factory(1.3), ["anisotropy"], {"anisotropy": 1.2, "offset_mm": 0.0,
                                                                       "swelling_mm": 0.0})
    assert values["anisotropy"] == pytest.approx(1.3, rel=0.03)
    assert values["offset_mm"] == 0.0 and values["swelling_mm"] == 0.0
    # a simulator that erodes z 10 % too fast is refitted to the anisotropy that makes up for it
    biased = refit_physics(_shapes_at_factory(1.3, bias=1.1), ["anisotropy"], {"anisotropy": 1.2, "offset_mm": 0.0,
                                                                                 "swelling_mm": 0.0})
    assert biased["anisotropy"] == pytest.approx(1.3 / 1.1, rel=0.03)
    assert refit_physics(_shapes_at_factory(1.3), [], {"anisotropy": 1.2})["anisotropy"] == 1.0


def test_discretisation_term_is_the_extrapolated_difference_in_quadrature():
    # the calibration's numbers at resolution 40 without a lag: 0.816 +- 0.011 (refits) for a hidden 0.778
    combined, bias = with_discretisation({"anisotropy": 0.011}, {"anisotropy": 0.816}, {"anisotropy": 0.800})
    assert bias["anisotropy"] == pytest.approx(0.016 * 3.0)                    # f / (f - 1) = 3 for f = 1.5
    assert combined["anisotropy"] == pytest.approx(math.hypot(0.011, 0.048))
    assert abs(0.816 - 0.778) < combined["anisotropy"]
    # a first-order error b h: the refit at h / f is b h / f, and the term recovers b h exactly
    h, b = 0.45, 0.08
    combined, bias = with_discretisation({"offset_mm": 0.0}, {"offset_mm": b * h}, {"offset_mm": b * h / 2.0}, 2.0)
    assert bias["offset_mm"] == pytest.approx(b * h) and combined["offset_mm"] == pytest.approx(b * h)
    with pytest.raises(AnalysisError, match="must be finer"):
        with_discretisation({"anisotropy": 0.1}, {"anisotropy": 1.0}, {"anisotropy": 1.0}, 1.0)
