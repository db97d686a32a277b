"""studies/exact_check.py: the independent check of a design's print fit, against analytic answers."""
import json

import numpy as np
import pytest
import trimesh

from studies import exact_check


def _box_release(tau: np.ndarray, sides: tuple[float, float, float]) -> np.ndarray:
    """A box's release: its volume less the box shrunk by tau on every face."""
    inner = np.prod([np.clip(s - 2.0 * tau, 0.0, None) for s in sides], axis=0)
    return float(np.prod(sides)) - inner


def _tilted_box(sides: tuple[float, float, float]) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=sides)
    box.apply_transform(trimesh.transformations.euler_matrix(0.3, 0.5, 0.7))
    return box.apply_translation([0.31, -0.17, 0.05])


def test_triangle_distance_known_points_and_sampled_minimum():
    tri = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    points = np.array([[0.5, 0.5, 0.7],     # above the face: its height
                       [-1.0, -1.0, 0.0],   # beyond vertex a
                       [1.0, -2.0, 1.0],    # beside edge ab: sqrt(2^2 + 1)
                       [2.0, 2.0, 0.0],     # beyond edge bc, at its midpoint (1, 1): sqrt 2
                       [3.0, -1.0, 0.0]])   # beyond vertex b
    expected = [0.7, np.sqrt(2.0), np.sqrt(5.0), np.sqrt(2.0), np.sqrt(2.0)]
    got = exact_check.triangle_distance(points, np.repeat(tri[None], len(points), axis=0))
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    # random triangles: never above the least distance to 11,476 points of the triangle, and below it by no more
    # than the sampling's spacing (the distance's Lipschitz bound)
    rng = np.random.default_rng(1)
    tris, p = rng.normal(size=(40, 3, 3)), 2.0 * rng.normal(size=(40, 3))
    u, v = np.meshgrid(np.linspace(0.0, 1.0, 151), np.linspace(0.0, 1.0, 151))
    keep = u + v <= 1.0
    u, v = u[keep], v[keep]
    got = exact_check.triangle_distance(p, tris)
    for i in range(len(p)):
        a, b, c = tris[i]
        sampled = np.linalg.norm(a + np.outer(u, b - a) + np.outer(v, c - a) - p[i], axis=1).min()
        spacing = max(np.linalg.norm(b - a), np.linalg.norm(c - a)) / 150.0
        assert got[i] <= sampled + 1e-12
        assert sampled - got[i] <= spacing


def test_inside_and_distance_of_a_tilted_box_are_exact():
    sides = (2.0, 1.5, 1.0)
    box = _tilted_box(sides)
    rng = np.random.default_rng(2)
    points = rng.uniform(box.bounds[0], box.bounds[1], size=(4000, 3))
    # the box's own frame: undo the translation, then the rotation
    local = (points - [0.31, -0.17, 0.05]) @ trimesh.transformations.euler_matrix(0.3, 0.5, 0.7)[:3, :3]
    gap = np.array(sides) / 2.0 - np.abs(local)
    truth_inside = np.all(gap > 0.0, axis=1)
    triangles = exact_check.prepared(box)
    assert len(triangles) > 12  # split: the surface is the same, the certificate's groups small
    np.testing.assert_array_equal(exact_check.inside(triangles, points), truth_inside)
    inner = points[truth_inside]
    np.testing.assert_allclose(exact_check.surface_distance(triangles, inner), gap[truth_inside].min(axis=1),
                               atol=1e-12)


def test_release_of_a_box_and_a_sphere_meet_their_analytic_curves():
    # the box's largest deviation: 0.68%, 0.22% and 0.09% of the volume at 2^14, 2^16 and 2^18 points
    points_log2, tolerance = 14, 0.01
    sides = (2.0, 1.5, 1.0)
    tau = np.linspace(0.0, 0.6, 25)
    box = exact_check.exact_release(_tilted_box(sides), tau, points_log2=points_log2)
    expected = _box_release(tau, sides)
    assert box.released_mm3[0] == 0.0
    assert np.abs(box.released_mm3 - expected).max() < tolerance * expected[-1]
    assert (box.shells, box.enclosed) == (1, 0)
    # an icosphere of 5120 faces releases as a sphere of its volume within its faceting (0.1% of the radius)
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    radius = (3.0 * sphere.volume / (4.0 * np.pi)) ** (1.0 / 3.0)
    tau = np.linspace(0.0, radius, 21)
    got = exact_check.exact_release(sphere, tau, points_log2=points_log2)
    expected = 4.0 / 3.0 * np.pi * (radius ** 3 - (radius - tau) ** 3)
    assert np.abs(got.released_mm3 - expected).max() < (tolerance + 0.003) * expected[-1]
    assert abs(got.volume_mm3 - got.mesh_volume_mm3) < tolerance * got.mesh_volume_mm3


def test_enclosed_shells_tell_a_void_from_a_second_piece():
    outer = trimesh.creation.icosphere(subdivisions=2, radius=2.0)
    void = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    void.invert()
    assert exact_check.enclosed_shells(trimesh.util.concatenate([outer, void])) == (2, 1)
    apart = trimesh.creation.icosphere(subdivisions=2, radius=1.0).apply_translation([5.0, 0.0, 0.0])
    assert exact_check.enclosed_shells(trimesh.util.concatenate([outer, apart])) == (2, 0)


def test_check_folder_recomputes_a_known_fit(tmp_path):
    # a source box and a "print" 2% wider: the fit between their analytic curves is what the check must find
    sides, wider = (2.0, 1.5, 1.0), (2.04, 1.5, 1.0)
    source = tmp_path / "source.stl"
    _tilted_box(sides).export(source)
    run = tmp_path / "run"
    run.mkdir()
    _tilted_box(wider).export(run / "design.stl")
    tau = np.linspace(0.0, 0.5, 51)
    target, printed = _box_release(tau, sides), _box_release(tau, wider)
    fit = float(np.sqrt(np.mean((printed - target) ** 2)) / target[-1])
    (run / "config.json").write_text(json.dumps({"target": str(source)}))
    (run / "summary.json").write_text(json.dumps({"rel_rmse_print": fit}))
    rows = np.column_stack([tau, target, printed, printed, printed])
    np.savetxt(run / "curves.csv", rows, delimiter=",", header="tau_mm,target_mm3,print_mm3,density_mm3,binary_mm3",
               comments="")
    row = exact_check.check_folder(run, points_log2=14)
    assert abs(float(row["difference_points"])) < 0.3
    assert float(row["exact_pct"]) == pytest.approx(100 * fit, abs=0.3)
    assert float(row["target_dev_pct"]) < 1.0 and float(row["print_dev_pct"]) < 1.0
    (run / "summary.json").write_text(json.dumps({"fit": fit}))
    with pytest.raises(SystemExit, match="rel_rmse_print"):
        exact_check.check_folder(run, points_log2=14)
