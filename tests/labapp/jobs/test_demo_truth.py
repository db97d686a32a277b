"""The demo compares like with like: the calibrated time scale with the calibration prints' own hidden rates, the
calibrated (effective) density with the hidden prints' grams per mm^3 of the print the model simulates."""
from types import SimpleNamespace

import pytest

from analysis.physics_grid import LAG
from design.geometry.shapes import sample_shape
from labapp.acquisition.simbench import MATERIAL_SEED, Material
from labapp.jobs import demo
from labapp.jobs.printrelease import print_volume_mm3


def _truths():
    """Each calibration print's rate 1400-1500 s/mm (mean 1450), the further print's (pill) 1700."""
    n = len(demo.CALIBRATION_SHAPES)
    rates = {**{name: 1400.0 + 100.0 * i / (n - 1) for i, name in enumerate(demo.CALIBRATION_SHAPES)}, "pill": 1700.0}
    return {name: {"seconds_per_mm": rate, "g_per_mm3": 1.4e-3 + 1e-5 * i, "mass_g": 2.0 + 0.1 * i}
            for i, (name, rate) in enumerate(rates.items())}


@pytest.mark.parametrize("offset_mm", [0.0, 0.15])
def test_the_truth_is_taken_on_the_calibration_prints_and_the_modelled_volume(offset_mm):
    truth = demo._truth_like_the_model(_truths(), SimpleNamespace(physics={"offset_mm": offset_mm}))
    assert truth["seconds_per_mm"] == pytest.approx(1450.0)           # the further print (pill) is not one of them
    volume = sum(print_volume_mm3(demo.calibration_mesh(name), offset_mm) for name in demo.CALIBRATION_SHAPES)
    n = len(demo.CALIBRATION_SHAPES)
    assert truth["effective_density_g_per_cm3"] == pytest.approx(1000.0 * sum(2.0 + 0.1 * i for i in range(n)) / volume)
    assert truth["density_g_per_cm3"] == pytest.approx(1.4 + 0.01 * (n - 1) / 2)


def test_the_calibration_set_has_the_flat_tall_and_lying_prints_plan_proposes():
    """Round prints alone confound the build-direction anisotropy with the time scale; the set has the flat and the
    tall print ``calibrate-sim --plan`` proposes for it and a bar lying down, and its meshes are the plan's and the
    samples'."""
    assert {"flat", "tall", "bar"} <= set(demo.CALIBRATION_SHAPES)
    assert len(demo.CALIBRATION_WATER_G) == len(demo.CALIBRATION_SHAPES)
    x, y, z = demo.calibration_mesh("flat").extents
    assert z < 0.5 * min(x, y)
    x, y, z = demo.calibration_mesh("tall").extents
    assert z > 2 * max(x, y)
    x, y, z = demo.calibration_mesh("bar").extents
    assert x > 3 * z and y == pytest.approx(z)
    assert demo.calibration_mesh("sphere").volume == pytest.approx(sample_shape("sphere").volume)


def test_every_print_has_its_own_draw_and_each_bench_seed_its_own_prints():
    indices = [demo.PRINT_INDEX[name] for name in demo.CALIBRATION_SHAPES] + [demo.FURTHER_INDEX]
    assert len(set(indices)) == len(indices)
    default, other = Material.draw(), Material.draw(11)
    assert default.printed(0) == Material.draw(MATERIAL_SEED).printed(0)
    rates = [m.printed(i)[0] / m.seconds_per_mm for m in (default, other) for i in range(2)]
    assert len(set(rates)) == 4            # another print, another bench: another draw


def test_the_kept_physics_are_named_with_their_units():
    physics = {"fitted": ["anisotropy", LAG], "anisotropy": 0.71357, "offset_mm": 0.0, LAG: 564.58}
    assert demo._physics_line(physics) == "anisotropy 0.714, wetting lag 565 s"
    assert demo._physics_line({"fitted": []}) == "none (isotropic)"


def test_a_step_beside_another_prints_its_lines_after_it_in_order():
    seen = []
    held = demo._HeldProgress(seen.append)
    held("4. further run")
    held("   frame 0")
    seen.append("3. calibrate-sim done")
    held.release()
    held("   frame 100")
    assert seen == ["3. calibrate-sim done", "4. further run", "   frame 0", "   frame 100"]
