"""The reference evaluator's release of a print with a surface offset, against analytic releases.

Tolerances: the evaluator's stated error (max |C_h - C_2h|, the curve's own error about a third of it) bounds every
comparison with an exact release; the checks below assert the measured error stays within it, plus 1e-9 of the volume
for round-off. Anisotropic growth is exact on faces and first order in the o-neighbourhood of edges
(`design.forward.offset_lattice`): there the arrival time is checked against the exact one with the bound
o |1 / a - 1| the module states.
"""
import math

import numpy as np
import pytest
import trimesh
from scipy.optimize import minimize
from scipy.stats import qmc

from design.errors import DesignError
from design.forward.distance import Surface
from design.forward.offset_lattice import PrintLattice
from design.forward.reference import metric_mesh, reference_release, signed_distance


def _steiner(mesh, r):
    """The volume of a convex polytope grown by r (Steiner's formula, exact for a convex solid)."""
    return (mesh.volume + mesh.area * r + mesh.integral_mean_curvature * r * r
            + 2.0 * math.pi / 3.0 * mesh.euler_number * r ** 3)


def _grown_convex(mesh, o, tau, plain):
    """A convex solid grown by o > 0: its shell releases first (V(o) - V(o - tau)), then every inner point o later than
    in the solid (``plain``, its exact release at ``tau - o``)."""
    whole = _steiner(mesh, o)
    shell = whole - np.array([_steiner(mesh, o - t) for t in np.minimum(tau, o)])
    inner = np.interp(np.asarray(tau) - o, plain.tau_mm, plain.released_mm3, left=0.0)
    return np.where(tau < o, shell, whole - mesh.volume + inner)


def _box_release(tau, sides, a=1.0):
    """A box's release at anisotropy a: its metric copy (z / a) shrinks by tau on every face, volumes times a."""
    metric = np.array([sides[0], sides[1], sides[2] / a])
    return a * (np.prod(metric) - np.prod(np.clip(metric - 2 * np.asarray(tau)[:, None], 0, None), axis=1))


def _within(ref, exact, other=0.0):
    """The measured error within the stated one (plus ``other``, the stated error of an evaluated exact release)."""
    err = float(np.abs(ref.released_mm3 - exact).max())
    assert err <= ref.error_mm3 + other + 1e-9 * ref.volume_mm3, (err, ref.error_mm3, other)
    return err


def test_a_box_grown_is_the_box_with_rounded_edges():
    box = trimesh.creation.box((2.0, 3.0, 4.0))
    ref = reference_release(box, offset_mm=0.3)
    plain = reference_release(box, np.linspace(0.0, 1.0, 401), cells=64)
    _within(ref, _grown_convex(box, 0.3, ref.tau_mm, plain), plain.error_mm3)
    # the print's volume is Steiner's for a box: V + A o + pi (sum of sides) o^2 + 4 pi o^3 / 3
    assert ref.volume_mm3 == pytest.approx(24 + 52 * 0.3 + math.pi * 9 * 0.09 + 4 * math.pi * 0.027 / 3,
                                           abs=ref.error_mm3)
    assert ref.method == "exact-distance, surface offset +0.3 mm" and ref.unsure_mm3 == 0.0
    assert ref.tau_mm[-1] == pytest.approx(1.0 + 0.3, abs=2 * ref.cell_mm)   # the half-width plus the offset


@pytest.mark.parametrize("a", [1.0, 0.7, 1.4])
def test_a_box_shrunk_is_a_smaller_box_at_any_anisotropy(a):
    ref = reference_release(trimesh.creation.box((2.0, 3.0, 4.0)), offset_mm=-0.3, anisotropy=a)
    _within(ref, _box_release(ref.tau_mm, (1.4, 2.4, 3.4), a))
    assert ref.volume_mm3 == pytest.approx(1.4 * 2.4 * 3.4, abs=ref.error_mm3)


@pytest.mark.parametrize("o", [0.4, -0.5])
def test_a_sphere_grown_or_shrunk(o):
    ball = trimesh.creation.icosphere(subdivisions=3, radius=2.0)
    ref = reference_release(ball, offset_mm=o)
    if o > 0:
        plain = reference_release(ball, np.linspace(0.0, 2.5, 501), cells=96)
        _within(ref, _grown_convex(ball, o, ref.tau_mm, plain), plain.error_mm3)
    else:  # a shrink keeps the points deeper than |o|, each |o| earlier: R(tau + |o|) - R(|o|)
        plain = reference_release(ball, np.concatenate([[-o], ref.tau_mm - o]), cells=96)
        _within(ref, plain.released_mm3[1:] - plain.released_mm3[0], 2 * plain.error_mm3)


def test_a_cylinder_grown():
    rod = trimesh.creation.cylinder(radius=1.0, height=6.0, sections=24)
    ref = reference_release(rod, offset_mm=0.25)
    plain = reference_release(rod, np.linspace(0.0, 1.5, 601), cells=96)
    _within(ref, _grown_convex(rod, 0.25, ref.tau_mm, plain), plain.error_mm3)


def _convex_arrival(points, half, o, c):
    """The exact arrival time in a box's metric copy (half-sides ``half``) grown by the ellipsoid of semi-axes
    (o, o, c): for a convex print, min over unit m of (its support function at m - m . y)."""
    rng = np.random.default_rng(3)
    u = rng.normal(size=(20000, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]

    def g(m, y):
        return np.abs(m) @ half + np.sqrt(o * o * (m[..., 0] ** 2 + m[..., 1] ** 2) + c * c * m[..., 2] ** 2) - m @ y

    out = np.empty(len(points))
    for i, y in enumerate(points):
        values = g(u, y)
        m0 = u[np.argmin(values)]
        start = [np.arccos(np.clip(m0[2], -1, 1)), np.arctan2(m0[1], m0[0])]
        res = minimize(lambda p: g(np.array([np.sin(p[0]) * np.cos(p[1]), np.sin(p[0]) * np.sin(p[1]), np.cos(p[0])]),
                                   y), start, method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-12})
        out[i] = min(res.fun, values.min())
    return out


@pytest.mark.parametrize("a", [0.7, 1.4])
def test_an_anisotropic_grown_box_has_the_print_s_exact_shape_and_its_arrival_within_the_stated_bound(a):
    sides, o = np.array([2.0, 3.0, 4.0]), 0.3
    box = trimesh.creation.box(sides)
    ref = reference_release(box, offset_mm=o, anisotropy=a)
    # the print is the same physical solid at any anisotropy: Steiner's volume
    assert ref.volume_mm3 == pytest.approx(_steiner(box, o), abs=ref.error_mm3)
    half, c = np.array([sides[0], sides[1], sides[2] / a]) / 2, o / a
    points = qmc.Sobol(3, seed=5).random(256) * 2 * (half + c) - (half + c)
    print_ = PrintLattice(Surface(metric_mesh(box, a)), o, a, Surface(box))
    arrive = print_.arrival(points, (1, 1, len(points)), 2.0)[0]   # a band wide enough to measure every point
    exact = _convex_arrival(points, half, o, c)
    assert np.array_equal(arrive > 0, exact > 0)   # the print's shape: exact
    inside = exact > 0
    assert np.abs(arrive - exact)[inside].max() <= o * abs(1 / a - 1)
    # exact on the faces: most points are
    assert np.mean(np.abs(arrive - exact)[inside] < 1e-6) > 0.8


def test_a_concave_crease_filled_by_growth_is_counted_in_the_stated_error():
    arm = trimesh.creation.box((4.0, 1.0, 2.0))
    other = trimesh.creation.box((1.0, 4.0, 2.0))
    other.apply_translation((1.5, 1.5, 0.0))
    ell = trimesh.boolean.union([arm, other], engine="manifold")
    ref = reference_release(ell, offset_mm=0.2, cells=64)
    assert 0.0 < ref.unsure_mm3 < 0.01 * ref.volume_mm3 and ref.error_mm3 >= ref.unsure_mm3
    # the print's volume, by exact signed distances at quasi-random points of its box
    lo, hi = ell.bounds[0] - 0.2, ell.bounds[1] + 0.2
    points = lo + qmc.Sobol(3, seed=7).random(2 ** 16) * (hi - lo)
    inside = np.mean(signed_distance(ell, points) > -0.2) * np.prod(hi - lo)
    assert ref.volume_mm3 == pytest.approx(inside, rel=0.01)   # Sobol sampling: about 0.3% at 2^16 points


def test_an_offset_with_sealed_voids_or_one_that_removes_the_print_is_refused():
    shell = trimesh.util.concatenate([trimesh.creation.box((4.0, 4.0, 4.0)),
                                      trimesh.creation.box((2.0, 2.0, 2.0))])
    shell.faces[len(shell.faces) // 2:] = shell.faces[len(shell.faces) // 2:, ::-1]
    with pytest.raises(DesignError, match="sealed voids"):
        reference_release(shell, offset_mm=0.1, cells=32)
    with pytest.raises(DesignError, match="the print is empty"):
        reference_release(trimesh.creation.box((1.0, 1.0, 1.0)), offset_mm=-0.6, cells=32)
