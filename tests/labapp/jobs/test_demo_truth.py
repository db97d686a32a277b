"""The demo compares like with like: the calibrated time scale with the calibration prints' own hidden rates, the
calibrated (effective) density with the hidden prints' grams per mm^3 of the print the model simulates."""
from types import SimpleNamespace

import pytest

from analysis.physics_grid import LAG
from design.geometry.shapes import sample_shape
from labapp.jobs import demo
from labapp.jobs.printrelease import print_volume_mm3


def _truths():
    rates = {"sphere": 1400.0, "spinner_top": 1450.0, "csg": 1500.0, "pill": 1700.0}
    return {name: {"seconds_per_mm": rate, "g_per_mm3": 1.4e-3 + 1e-5 * i, "mass_g": 2.0 + 0.1 * i}
            for i, (name, rate) in enumerate(rates.items())}


@pytest.mark.parametrize("offset_mm", [0.0, 0.15])
def test_the_truth_is_taken_on_the_calibration_prints_and_the_modelled_volume(offset_mm):
    truth = demo._truth_like_the_model(_truths(), SimpleNamespace(physics={"offset_mm": offset_mm}))
    assert truth["seconds_per_mm"] == pytest.approx(1450.0)           # the further print (pill) is not one of them
    volume = sum(print_volume_mm3(sample_shape(name), offset_mm) for name in demo.CALIBRATION_SHAPES)
    assert truth["effective_density_g_per_cm3"] == pytest.approx(1000.0 * (2.0 + 2.1 + 2.2) / volume)
    assert truth["density_g_per_cm3"] == pytest.approx(1.41)


def test_the_kept_physics_are_named_with_their_units():
    physics = {"fitted": ["anisotropy", LAG], "anisotropy": 0.71357, "offset_mm": 0.0, LAG: 564.58}
    assert demo._physics_line(physics) == "anisotropy 0.714, wetting lag 565 s"
    assert demo._physics_line({"fitted": []}) == "none (isotropic)"
