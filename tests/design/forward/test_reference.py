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

from design.errors import DesignError
from design.forward.reference import reference_release

TOLERANCE = 0.002
"""Largest |released - analytic| as a fraction of the volume."""
CELLS = 64


def _ball(r):
    return 4 / 3 * np.pi * np.clip(r, 0, None) ** 3


def _lens(a, b, d):
    """Volume of the intersection of balls of radii a and b whose centres are d apart."""
    a = np.asarray(a, float)
    b = np.broadcast_to(np.asarray(b, float), a.shape)
    out = np.zeros(a.shape)
    inner = d <= np.abs(a - b)
    out[inner] = _ball(np.minimum(a, b)[inner])
    cut = ~inner & (d < a + b)
    aa, bb = a[cut], b[cut]
    out[cut] = np.pi * (aa + bb - d) ** 2 * (d * d + 2 * d * (aa + bb) - 3 * (aa - bb) ** 2) / (12 * d)
    return out


def _radius_of(volume, per_r3):
    return (volume / per_r3) ** (1 / 3)


def sphere():
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=10.0)
    mesh.apply_translation([0.123, 0.377, -0.2])
    r = _radius_of(mesh.volume, 4 / 3 * np.pi)
    return mesh, 10.0, lambda t: mesh.volume - _ball(r - t)


def cylinder():
    n, a, height = 128, 6.0, 15.0
    mesh = trimesh.creation.cylinder(radius=a, height=height, sections=n)
    mesh.apply_translation([0.31, -0.17, 0.29])
    apothem = a * np.cos(np.pi / n)  # the regular n-gon's inradius: its offset polygons keep the shape

    def exact(t):
        return mesh.volume - n * np.tan(np.pi / n) * np.clip(apothem - t, 0, None) ** 2 * np.clip(height - 2 * t, 0, None)
    return mesh, a, exact


def box():
    dims = np.array([7.3, 11.1, 4.9])
    mesh = trimesh.creation.box(dims)
    mesh.apply_translation([0.217, 0.093, -0.311])  # off the lattice's centring
    return mesh, dims.min() / 2, lambda t: mesh.volume - np.prod(np.clip(dims - 2 * t[:, None], 0, None), axis=1)


def torus():
    major = 8.0
    mesh = trimesh.creation.torus(major_radius=major, minor_radius=3.0, major_sections=128, minor_sections=64)
    r = np.sqrt(mesh.volume / (2 * np.pi ** 2 * major))
    return mesh, 3.0, lambda t: mesh.volume - 2 * np.pi ** 2 * major * np.clip(r - t, 0, None) ** 2


def hollow():
    """A ball of radius 10 with a sealed spherical void of radius 3 centred 4 off its centre.

    The void is wetted when the outer front reaches it, at tau = w = 10 - 4 - 3; from then on the void
    grows as a ball of radius 3 + (tau - w) around its centre. What remains at tau is the ball of
    radius 10 - tau minus its intersection with the void's ball of radius max(3, 3 + tau - w).
    """
    outer = trimesh.creation.icosphere(subdivisions=4, radius=10.0)
    void = trimesh.creation.icosphere(subdivisions=4, radius=3.0)
    void.invert()
    void.apply_translation([4.0, 0.0, 0.0])
    mesh = trimesh.util.concatenate([outer, void])
    big = _radius_of(outer.volume, 4 / 3 * np.pi)
    small = _radius_of(-void.volume, 4 / 3 * np.pi)
    wet = big - 4.0 - small

    def exact(t):
        rest = np.clip(big - t, 0, None)
        return mesh.volume - (_ball(rest) - _lens(rest, small + np.clip(t - wet, 0, None), 4.0))
    return mesh, 10.0, exact


def nested():
    """A shell 6 < r < 10 around a sealed void holding a ball of radius 4 (paper Fig. 2): the shell
    dissolves as a ball until the front reaches the void at tau = 4, the ball then dissolves from 4."""
    outer = trimesh.creation.icosphere(subdivisions=4, radius=10.0)
    void = trimesh.creation.icosphere(subdivisions=4, radius=6.0)
    void.invert()
    core = trimesh.creation.icosphere(subdivisions=4, radius=4.0)
    mesh = trimesh.util.concatenate([outer, void, core])
    big, mid, small = (_radius_of(abs(m.volume), 4 / 3 * np.pi) for m in (outer, void, core))
    wet = big - mid

    def exact(t):
        shell = _ball(big) - _ball(np.maximum(big - t, mid))
        return shell + _ball(small) - _ball(small - np.clip(t - wet, 0, None))
    return mesh, 10.0, exact


@pytest.mark.parametrize("shape", [sphere, cylinder, box, torus, hollow, nested])
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
