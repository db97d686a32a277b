"""The design launcher's view of the optimiser's progress: the mid-slice of the design variables."""
import numpy as np

from labapp.gui.design_launcher import mid_slice


def test_mid_slice_of_variables_in_their_shape():
    cube = np.arange(4 * 6 * 8, dtype=float).reshape(4, 6, 8)  # any 3D shape (nfc, ico), not only cubes
    np.testing.assert_array_equal(mid_slice(cube, 10), cube[:, :, 4])
    square = np.arange(5 * 7, dtype=float).reshape(5, 7)  # an extruded cross-section
    np.testing.assert_array_equal(mid_slice(square, 5), square)
    assert mid_slice(cube, 3) is None and mid_slice(cube, 6, every=3) is not None
