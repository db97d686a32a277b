"""The reference evaluator against closed-form releases of meshed solids.

Each mesh is a faceted stand-in for its analytic solid; where the facets change the answer the
analytic curve is that of the faceted solid (the cylinder's 128-gon, the box) or of the solid with the
mesh's volume (the sphere's and torus' radii), so that what is compared is the quadrature, not the
meshing. Tolerance: 0.2% of the volume, the accuracy the evaluator promises at its default lattice;
these tests run a coarser lattice (64 cells across) to stay fast, and the stated error estimate must
bound the true error as well.
"""
import numpy as np
import pytest
import trimesh

from benchmarks.analytic import MESHES, box, hollow
from design.errors import DesignError
from design.forward.reference import reference_release

TOLERANCE = 0.002
"""Largest |released - analytic| as a fraction of the volume."""
CELLS = 64


@pytest.mark.parametrize("shape", MESHES)
def test_release_matches_the_analytic_curve(shape):
    mesh, depth, exact = shape()
    tau = np.linspace(0.0, 1.02 * depth, 301)
    ref = reference_release(mesh, tau, cells=CELLS)
    error = np.abs(ref.released_mm3 - exact(tau)).max()
    assert ref.volume_mm3 == pytest.approx(mesh.volume, rel=1e-12)
    assert error <= TOLERANCE * ref.volume_mm3
    assert error <= ref.error_mm3  # the stated estimate bounds the true error
    assert ref.error_mm3 <= 2 * TOLERANCE * ref.volume_mm3
    assert ref.released_mm3[0] == 0.0
    assert ref.released_mm3[-1] == pytest.approx(ref.volume_mm3, rel=1e-9)  # prefix sums round off
    assert np.all(np.diff(ref.released_mm3) >= -1e-9 * ref.volume_mm3)


@pytest.mark.parametrize("anisotropy", [0.6, 1.5])
def test_an_anisotropic_box_releases_its_faces_at_their_own_rates(anisotropy):
    # a box X x Y x Z whose z faces erode at a and side faces at 1: X Y Z - (X - 2t)(Y - 2t)(Z - 2 a t), each
    # factor at least 0
    extents = np.array([12.0, 8.0, 5.0])
    mesh = trimesh.creation.box(extents=extents)
    tau = np.linspace(0.0, 4.5, 181)
    ref = reference_release(mesh, tau, cells=CELLS, anisotropy=anisotropy)
    rates = np.array([1.0, 1.0, anisotropy])
    left = np.prod(np.clip(extents[None, :] - 2.0 * tau[:, None] * rates[None, :], 0.0, None), axis=1)
    exact = np.prod(extents) - left
    assert ref.volume_mm3 == pytest.approx(np.prod(extents), rel=1e-12)
    assert np.abs(ref.released_mm3 - exact).max() <= TOLERANCE * ref.volume_mm3
    assert ref.method == f"exact-distance, anisotropy {anisotropy:g}"
    # the isotropic release is clearly another curve (z faces at 1)
    iso = reference_release(mesh, tau, cells=CELLS).released_mm3
    assert np.abs(iso - exact).max() > 10 * TOLERANCE * ref.volume_mm3
    with pytest.raises(DesignError, match="anisotropy"):
        reference_release(mesh, tau, cells=16, anisotropy=0.0)


def test_method_names_sealed_voids():
    assert reference_release(box()[0], [0.0, 1.0], cells=16).method == "exact-distance"
    assert reference_release(hollow()[0], [0.0, 1.0], cells=16).method == "exact-distance-voids"


def test_inward_wound_mesh_is_its_solid():
    mesh = box()[0]
    tau = np.linspace(0, 3, 7)
    inverted = mesh.copy()
    inverted.invert()
    np.testing.assert_allclose(reference_release(inverted, tau, cells=24).released_mm3,
                               reference_release(mesh, tau, cells=24).released_mm3, rtol=1e-12)


def test_rejects_an_open_mesh():
    mesh = trimesh.creation.box((1.0, 1.0, 1.0))
    mesh.update_faces(np.arange(len(mesh.faces) - 1))
    with pytest.raises(DesignError, match="not closed"):
        reference_release(mesh, [0.0, 0.1])


def test_rejects_bad_arguments():
    mesh = trimesh.creation.box((1.0, 1.0, 1.0))
    with pytest.raises(DesignError, match="cells must be an integer >= 16"):
        reference_release(mesh, [0.0, 0.1], cells=8)
    with pytest.raises(DesignError, match="tau_mm must be a 1D array"):
        reference_release(mesh, [[0.0, np.nan]])
    with pytest.raises(DesignError, match="trimesh.Trimesh"):
        reference_release(np.zeros((3, 3)), [0.0])


def test_separate_bodies_all_face_the_bath():
    # two boxes apart: each releases as a box from tau = 0, no sealed void between them
    a, b = (trimesh.creation.box((2.0, 3.0, 4.0)) for _ in range(2))
    b.apply_translation([5.0, 0.1, 0.2])
    tau = np.linspace(0.0, 1.2, 25)
    ref = reference_release(trimesh.util.concatenate([a, b]), tau, cells=48)
    one = 24.0 - np.prod(np.clip(np.array([2.0, 3.0, 4.0]) - 2 * tau[:, None], 0, None), axis=1)
    assert ref.method == "exact-distance"
    assert np.abs(ref.released_mm3 - 2 * one).max() <= TOLERANCE * ref.volume_mm3
