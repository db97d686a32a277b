"""The two-material reference evaluator against analytic releases (docs/evidence/materials.md)."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from design.errors import DesignError
from design.forward.reference import ReferenceRelease, reference_release
from design.forward.twomaterial_reference import two_material_reference_release


def box(lo, hi):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return trimesh.creation.box(hi - lo).apply_translation((lo + hi) / 2)


def test_coat_delays_the_cube_by_its_thickness_over_s():
    # a 2 mm drug cube in a 1 mm coat at s = 0.5: nothing until 2, then the cube's release 8 - (2 - 2 (tau - 2))^3
    tau = np.linspace(0.0, 3.2, 65)
    ref = two_material_reference_release(box([-1] * 3, [1] * 3), box([-2] * 3, [2] * 3), 0.5, tau, tolerance=0.01)
    exact = 8.0 - np.clip(2.0 - 2.0 * (tau - 2.0), 0.0, 2.0) ** 3
    assert isinstance(ref, ReferenceRelease)
    assert np.abs(ref.released_mm3[tau < 2.0]).max() < 1e-9
    assert np.abs(ref.released_mm3 - exact).max() <= ref.error_mm3 <= 0.01 * 8.0
    assert ref.barrier_volume_mm3 == pytest.approx(56.0)


def test_speed_one_is_the_union_eroding_and_the_drug_releasing():
    # drug the lower half of a 2 mm cube, barrier the upper half, s = 1: the union's cube erodes, half of it is drug
    ref = two_material_reference_release(box([-1, -1, -1], [1, 1, 0]), box([-1, -1, 0], [1, 1, 1]), 1.0,
                                         tolerance=0.01)
    exact = 0.5 * (8.0 - np.clip(2.0 - 2.0 * ref.tau_mm, 0.0, None) ** 3)
    assert np.abs(ref.released_mm3 - exact).max() <= ref.error_mm3 <= 0.01 * 4.0
    assert ref.released_mm3[-1] == pytest.approx(4.0)


def test_slab_coated_on_its_z_faces_with_anisotropy():
    # z faces coated 0.1 mm at s = 0.5, sides open, z erodes at a: (2.4 - 2 tau)^2 (0.8 - 2 a max(tau - 0.1/(s a), 0))
    a = 0.5
    tau = np.linspace(0.0, 0.6, 31)
    ref = two_material_reference_release(box([-1.2, -1.2, -0.4], [1.2, 1.2, 0.4]), box([-1.2, -1.2, -0.5], [1.2, 1.2, 0.5]),
                                         0.5, tau, anisotropy=a, tolerance=0.01)
    left = (2.4 - 2 * tau).clip(0) ** 2 * (0.8 - 2 * a * np.maximum(tau - 0.1 / (0.5 * a), 0)).clip(0)
    assert np.abs(ref.released_mm3 - (4.608 - left)).max() <= ref.error_mm3 <= 0.01 * 4.608


def test_capped_column_releases_from_its_ends_after_the_caps():
    # a 1.2 x 1.2 x 1.6 mm drug column in a barrier box: 0.2 mm caps (0.8 mm of time at s = 0.25), 0.6 mm walls
    # (2.4 mm): each end face recedes from 0.8 on, and the sides are wetted through the drug (T = 0.8 + depth, linear
    # along them) before the walls are crossed: C = 2 x 1.44 x (tau - 0.8) until the ends meet at 1.6
    tau = np.linspace(0.0, 1.8, 37)
    ref = two_material_reference_release(box([-0.6, -0.6, -0.8], [0.6, 0.6, 0.8]), box([-1.2, -1.2, -1.0], [1.2, 1.2, 1.0]),
                                         0.25, tau, tolerance=0.01)
    exact = 2.0 * 1.44 * np.clip(tau - 0.8, 0.0, 0.8)
    assert np.abs(ref.released_mm3[tau < 0.8]).max() == 0.0
    assert np.abs(ref.released_mm3 - exact).max() <= ref.error_mm3 <= 0.01 * 2.304


def test_insoluble_barrier_seals_or_opens():
    drug = box([-1, -1, -1], [1, 1, 0])
    sealed = two_material_reference_release(drug, box([-1.5] * 3, [1.5] * 3), 0.0, [0.0, 1.0, 100.0])
    assert sealed.sealed_mm3 == pytest.approx(4.0) and sealed.sealed_regions_mm3 == pytest.approx((4.0,))
    assert np.all(sealed.released_mm3 == 0.0)
    cup = two_material_reference_release(drug, box([-1.5, -1.5, -1.5], [1.5, 1.5, 0]), 0.0,
                                         np.linspace(0.0, 1.2, 25), tolerance=0.01)
    # open on its top face only: zero order, 4 mm^3 per mm until gone
    assert np.abs(cup.released_mm3 - 4.0 * np.clip(cup.tau_mm, 0.0, 1.0)).max() <= cup.error_mm3
    assert cup.sealed_mm3 == 0.0


@pytest.mark.slow
def test_two_pulses_from_two_layers_in_a_cup():
    # layer 1 open at the top (0.5 mm), a 0.25 mm barrier layer at s = 0.25 (1 mm of time), layer 2 (0.5 mm); the
    # cup's walls (0.6 mm, 2.4 mm of time) are thick enough to keep the problem one-dimensional
    drug = trimesh.util.concatenate([box([-1, -1, -0.5], [1, 1, 0]), box([-1, -1, -1.25], [1, 1, -0.75])])
    tau = np.linspace(0.0, 2.2, 45)
    ref = two_material_reference_release(drug, box([-1.6, -1.6, -1.85], [1.6, 1.6, 0]), 0.25, tau, tolerance=0.01)
    exact = 4.0 * (np.clip(tau, 0.0, 0.5) + np.clip(tau - 1.5, 0.0, 0.5))
    assert np.abs(ref.released_mm3 - exact).max() <= ref.error_mm3 <= 0.01 * 8.0
    assert ref.straight_mm3 == 0.0


def test_sphere_in_shell_is_the_delayed_sphere():
    # the facets of the two icospheres make the shell up to R_o (1 - cos alpha) = 6e-4 mm thinner than 0.3 (alpha
    # the angle across a facet, 0.04 rad at 3 subdivisions), crossed at s = 0.5: up to 1.2e-3 mm of time early, at a
    # rate of at most 4 pi R^2 = 3.14 mm^2: 3.8e-3 mm^3 beyond the two evaluators' stated errors
    drug, shell = trimesh.creation.icosphere(3, 0.5), trimesh.creation.icosphere(3, 0.8)
    tau = np.linspace(0.0, 1.2, 49)
    ref = two_material_reference_release(drug, shell, 0.5, tau, tolerance=0.01)
    one = reference_release(drug, tau - 0.6, tolerance=0.01)
    assert np.abs(ref.released_mm3[tau < 0.59]).max() == 0.0
    assert np.abs(ref.released_mm3 - one.released_mm3).max() <= ref.error_mm3 + one.error_mm3 + 3.8e-3


def test_refusals():
    cube = box([-1] * 3, [1] * 3)
    with pytest.raises(DesignError, match="barrier speed"):
        two_material_reference_release(cube, cube, -1.0)
    with pytest.raises(DesignError, match="not closed"):
        two_material_reference_release(cube, trimesh.Trimesh(cube.vertices, cube.faces[:-1]), 0.5)
