"""A calibration mesh's print release with a surface offset: a prediction releases the print itself by the reference
evaluator (labapp.jobs.printrelease.exact_print); a calibration's search keeps the offset formula.

Truth: a box shrunk by the offset is a smaller box, released at anisotropy a by its metric copy (z / a) shrinking by
tau on every face. The formula moves every face by one mean metric offset, which is off for a box whose faces move
o and o / a (measured: 1.1% of the volume); the evaluator's release is within its stated error (measured 0.004%).
"""
import numpy as np
import trimesh

from design.files.pipeline import mesh_grid
from labapp.jobs import printrelease as pr

RESOLUTION = 24


def _box_release(tau, sides, a=1.0):
    metric = np.array([sides[0], sides[1], sides[2] / a])
    return a * (np.prod(metric) - np.prod(np.clip(metric - 2 * np.asarray(tau)[:, None], 0, None), axis=1))


def test_a_prediction_releases_the_print_itself_and_the_search_keeps_the_formula():
    box = trimesh.creation.box((6.0, 4.0, 2.0))
    physics = {"anisotropy": 0.6, "offset_mm": -0.3, "swelling_mm": 0.0}
    grid = mesh_grid(box, resolution=RESOLUTION, offset_mm=-0.3)
    tau, released = pr.print_release(box, grid, RESOLUTION, physics)
    exact = _box_release(tau, (5.4, 3.4, 1.4), 0.6)
    volume = 5.4 * 3.4 * 1.4
    ref_error = pr.exact_print(box, RESOLUTION, 0.6, -0.3)
    assert ref_error[2] == released[-1]
    predicted = np.abs(released - exact).max() / volume
    tau_f, released_f = pr.print_release(box, grid, RESOLUTION, physics, interpolated=True)
    formula = np.abs(released_f - _box_release(tau_f, (5.4, 3.4, 1.4), 0.6)).max() / volume
    assert predicted < 0.001 and formula > 5 * predicted
    # the fraction a prediction's bias and band use is the same release
    tau_r, fraction = pr.reference_fraction(box, RESOLUTION, 0.6, -0.3)
    np.testing.assert_allclose(fraction * released[-1], np.interp(tau_r, tau, released), atol=1e-9 * volume)
