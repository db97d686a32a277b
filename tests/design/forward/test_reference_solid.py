"""The reference evaluator's lattice sized by the solid (`reference_release` without `cells`): the error it states,
and meets, on long rods, thin plates and thin-walled parts; its refusal of a part too thin."""
import numpy as np
import pytest
import trimesh

from design.forward.reference import reference_release
from design.forward.solid_lattice import DEFAULT_TOLERANCE, TooThinError


def _box_release(tau, dims):
    return np.prod(dims) - np.prod(np.clip(np.asarray(dims) - 2 * tau[:, None], 0, None), axis=1)


@pytest.mark.parametrize("dims", [(2.0, 2.0, 40.0), (30.0, 20.0, 0.8)], ids=["rod", "plate"])
def test_a_long_rod_and_a_thin_plate_meet_their_stated_error(dims):
    ref = reference_release(trimesh.creation.box(dims))
    exact = _box_release(ref.tau_mm, dims)
    assert ref.relative_error <= DEFAULT_TOLERANCE and "mean half-thickness" in ref.lattice
    assert np.abs(ref.released_mm3 - exact).max() <= ref.error_mm3
    # the samples run from 0 to where the solid is gone, not to half its box
    assert ref.tau_mm[0] == 0.0 and ref.released_mm3[-1] == pytest.approx(np.prod(dims), rel=1e-12)
    assert min(dims) / 2 <= ref.tau_mm[-1] < min(dims) / 2 + 4 * ref.cell_mm


def test_a_box_sized_lattice_misses_a_long_rod_by_more_than_the_solid_sized_one():
    dims = (2.0, 2.0, 40.0)
    tau = np.linspace(0.0, 1.05, 211)
    exact = _box_release(tau, dims)
    by_box = reference_release(trimesh.creation.box(dims), tau, cells=64)  # 3 cells across
    by_solid = reference_release(trimesh.creation.box(dims), tau)
    assert np.abs(by_solid.released_mm3 - exact).max() < 0.2 * np.abs(by_box.released_mm3 - exact).max()


def test_a_thin_walled_sealed_box_meets_its_stated_error():
    # 20 x 16 x 12 mm with 0.8 mm walls around a sealed void: everything is gone when the outer front reaches it
    outer = trimesh.creation.box((20.0, 16.0, 12.0))
    void = trimesh.creation.box((18.4, 14.4, 10.4))
    void.invert()
    ref = reference_release(trimesh.util.concatenate([outer, void]))
    volume = 20 * 16 * 12 - 18.4 * 14.4 * 10.4
    exact = np.minimum(_box_release(ref.tau_mm, (20.0, 16.0, 12.0)), volume)
    assert ref.method == "exact-distance-voids" and ref.relative_error <= DEFAULT_TOLERANCE
    assert np.abs(ref.released_mm3 - exact).max() <= ref.error_mm3


def test_a_part_too_thin_is_refused_with_its_thickness():
    with pytest.raises(TooThinError, match=r"foil: its features are too thin .* mean thickness 2V/A = 0.02 mm") as exc:
        reference_release(trimesh.creation.box((40.0, 40.0, 0.02)), source="foil")
    assert exc.value.thickness_mm == pytest.approx(0.02, rel=0.01) and exc.value.points > 1e7
